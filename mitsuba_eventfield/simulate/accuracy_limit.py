"""Which factor limits a render's timestamp accuracy: the time step or Monte-Carlo noise.

Two estimates, from the first frames of a uniform render (one extra render of the first instant with another
seed; no other cost):

- **noise**: a crossing's time moves by about sigma_L / |dL/dt|, where sigma_L is the pixel's Monte-Carlo noise
  in log brightness (half the difference of two seeds' renders, times sqrt 2) and dL/dt its log slope, taken over
  a time baseline where the error stops growing with it (:func:`event_slopes`: the first step's difference read
  the frames' own noise as change, and made the estimate 2.5-10x optimistic on the rendered demo);
- **steps**: linear interpolation between rendered instants misplaces a crossing by about
  dt^2 |L''| / (8 |L'|) (the error bound of linear interpolation), from the second difference of three frames.

Medians over the events: each changing pixel's estimate weighted by its slope, which its event count follows.
On the analytic scene (benchmarks/results/accuracy.md) the estimates are within about 2x of the measured errors
and name the right limit at 20, 80 and 320 steps, for a noise-free sampler and for 4 and 16 spp. More steps do
not lower a noise limit; four times the samples halve it.
"""
from __future__ import annotations

import itertools
import math

import numpy as np

MIN_STEPS = 3
# a slope baseline resolves a pixel whose error is E when it is at least RESOLVE x E (frames' noise as its own):
# the slope's noise, sqrt 2 sigma_f / baseline, is then at most 0.35 of the slope sigma / E (event_slopes). At
# 2.8 (half) the demo's 4-spp render read 171 us where two seeds differ by 319; at 4, 213; at 5.7, 286 but the
# demo at 48x36 took 6.4 ms baselines over 10 ms and read 814 us where two seeds say 491 (docs/design.md,
# measured before the plateau rule)
RESOLVE = 4.0
SELECT_SAMPLE = 65536      # pixels of a larger image that event_slopes chooses its baseline on
FLAT = 0.5                 # a plateau: the error grows at most as baseline^FLAT between two (event_slopes)
MAX_BASELINES = 12         # frames a render keeps for slopes: its steps 4, 8, 16, ... (powers of two)
# the most seed-to-seed spread (log) of a sampler that renders one image for every seed: a jitter-free stratified
# sampler still orders its strata by the seed, and the sums' rounding differs by ~1e-7
NOISE_FLOOR = 1e-5
MEDIAN_SAMPLE = 16384      # pixels of the random sample that brackets a large image's weighted median
MEDIAN_MARGINS = (0.05, 0.2)   # the brackets tried: the sample's weighted quantiles 0.5 -/+ each


def _sorted_median(values, weights, below: float = 0.0, half: float | None = None) -> float:
    """The value where the cumulative weight, in ascending order of value and starting at ``below``, first
    reaches ``half`` (default: half its own total; the last value if rounding leaves it short)."""
    order = np.argsort(values, kind="stable")
    cum = below + np.cumsum(weights[order], dtype=np.float64)
    half = 0.5 * cum[-1] if half is None else half
    return float(values[order][min(int(np.searchsorted(cum, half)), len(cum) - 1)])


def _sample(n: int) -> np.ndarray:
    """``MEDIAN_SAMPLE`` pixel indices drawn with a fixed seed (a regular stride followed the image's columns:
    a value that changes with the column made the bracket miss)."""
    return np.random.default_rng(0).integers(0, n, MEDIAN_SAMPLE)


def event_median(values: np.ndarray, weights: np.ndarray) -> float:
    """The weighted median of per-pixel ``values`` with each pixel counted by ``weights`` (its event rate): the
    value, in ascending order, where the cumulative weight first reaches half the total.

    Sorting every changing pixel cost 60 ms a median at 1280x720 on a GPU machine's host, at the end of every
    render (0.15 s of the fan's 1.4 s render, two medians). A random sample's weighted quantiles bracket the
    median instead (``MEDIAN_MARGINS``, a wider bracket where the narrow one misses); only the pixels inside the bracket are sorted, after the weight below it is summed. Where
    the bracket misses (the sample's weights unlike the image's), every pixel is sorted: the same value either
    way, but where a partial sum equals half the total exactly, when the two sums' rounding may pick its
    neighbour (tests/simulate/test_accuracy_limit_steps.py)."""
    values = np.asarray(values, np.float64).ravel()
    weights = np.asarray(weights, np.float64).ravel()
    n = len(values)
    if n > 4 * MEDIAN_SAMPLE:
        half = 0.5 * float(weights.sum())
        pick = _sample(n)
        sv, sw = values[pick], weights[pick]
        order = np.argsort(sv, kind="stable")
        with np.errstate(invalid="ignore", divide="ignore"):          # an infinite weight: inf / inf
            cum = np.cumsum(sw[order]) / float(sw.sum())
        for margin in MEDIAN_MARGINS:      # a wider one where heavy-tailed weights moved the sample's quantiles
            lo, hi = (sv[order][min(int(np.searchsorted(cum, q)), len(cum) - 1)] for q in (0.5 - margin, 0.5 + margin))
            under = values < lo
            inside = ~under & (values <= hi)
            below = float(weights[under].sum())
            if below < half <= below + float(weights[inside].sum()):
                return _sorted_median(values[inside], weights[inside], below, half)
    return _sorted_median(values, weights)


def _error(first, frame, baseline, sigma, pick=None):
    """(sigma / |dL/dt| over the events, seconds; the slopes) of one baseline, over the pixels ``pick`` (all:
    None). The error is None where no pixel changes."""
    if pick is not None:
        first, frame, sigma = first[pick], frame[pick], sigma[pick]
    slope = np.abs(frame - first) / baseline
    active = slope > 0
    return (event_median(sigma[active] / slope[active], slope[active]) if active.any() else None), slope


def event_slopes(first, later, sigma, longest: float = math.inf) -> dict | None:
    """Per-pixel |dL/dt| for the noise estimate: ``first`` frame (log brightness) against ``later`` ones,
    ``[(baseline_s, frame), ...]`` in ascending order (those past ``longest`` seconds left out: a scan's
    quarter period, past which a frame difference is no slope), and the noise-timing error sigma / |dL/dt|
    they give (the median over events, seconds). ``sigma``: the frames' own noise (a render's spp; a plan's
    probe frames, the finest probe's).

    Over growing baselines b the error E(b) grows in proportion to b wherever it is wrong, and stops growing
    where it is right:
    - the frames' noise: a slope carries sqrt 2 sigma / b of it, which makes slow pixels steep (noise / b)
      until b is several times E (74 us predicted at 64 spp on the demo at 48x36 from a 50 us baseline, 486 us
      measured by two seeds' renders: benchmarks/results/timing_model.md);
    - a few jumping pixels: at fine steps pixels where one sample crosses an edge jump by whole contrasts, and
      their slope jump / b carried 90 % of the weight (the same demo at 16 spp over 400 or 1000 steps: 3.3 or
      1.3 us read, 741 us measured);
    - a change that is not linear over b (an edge passed, a scan turned): contrast / b.
    So the first pair of consecutive baselines over which E grows by at most b^``FLAT`` (a plateau, or E
    falling), the longer of them resolved (b >= ``RESOLVE`` E: the median event's slope within about a third),
    is taken, with the longer one's slopes. Where none is, the longest (``resolved`` False; while noise
    dominates the error grows with the baseline, so the longest is the closest). Noise-free frames (sigma 0)
    take the first baseline: nothing to resolve.
    Static pixels of a frozen sampler have no difference and no slope. A single baseline is taken if it
    resolves.

    The choice is made on ``SELECT_SAMPLE`` random pixels of a larger image (a median at 1280x720 takes
    ~25 ms, and a long render keeps up to 14 baselines), the returned error on every pixel. Returns {slope,
    baseline_s, error_s, resolved}, or None when no pixel changes."""
    first, sigma = np.ravel(first), np.ravel(sigma)
    pick = np.random.default_rng(1).integers(0, len(first), SELECT_SAMPLE) if len(first) > SELECT_SAMPLE else None
    scored = []                  # (baseline, frame, error on the sample) where some pixel changes
    for baseline, frame in later:
        if baseline > longest and scored:
            break
        frame = np.ravel(frame)
        error = _error(first, frame, baseline, sigma, pick)[0]
        if error is not None:
            scored.append((baseline, frame, error))
    if not scored:
        return None

    def resolves(k):
        return scored[k][0] >= RESOLVE * scored[k][2]

    def flat(k):                 # from baseline k - 1 to k: E grows by at most (b1 / b0)^FLAT
        (b0, _, e0), (b1, _, e1) = scored[k - 1], scored[k]
        return e0 > 0 and math.log(max(e1, 1e-300) / e0) <= FLAT * math.log(b1 / b0)
    if not noisy(sigma):
        chosen = [0]
    else:
        chosen = [k for k in range(len(scored)) if resolves(k) and (len(scored) == 1 or k and flat(k))]
    k = chosen[0] if chosen else len(scored) - 1
    error, slope = _error(first, scored[k][1], scored[k][0], sigma)
    return {"slope": slope, "baseline_s": scored[k][0], "error_s": error,
            "resolved": bool(chosen) and scored[k][0] <= longest}        # (a first step longer than that: no)


def noisy(sigma) -> bool:
    """Whether a noise map holds Monte-Carlo noise: any pixel past ``NOISE_FLOOR`` (else every seed renders the
    same image, up to rounding)."""
    return bool(np.max(sigma, initial=0.0) > NOISE_FLOOR)


def longest_baseline(period: float | None) -> float:
    """The longest slope baseline under a scan of ``period`` seconds (None or 0: no scan): a quarter of it; a
    frame difference across a period is no slope (galvo_static in 5 steps over two periods took 6.4 ms and read
    145 us where two seeds measure 9.2)."""
    return period / 4 if period else math.inf


def other_seed(seed: int) -> int:
    """The second seed of a noise measurement: the next one, within the sampler's 32 bits (the largest seed's
    next, 2^32, crashed in Dr.Jit)."""
    return (int(seed) + 1) & 0xFFFFFFFF


def noise_map(timed, spp: int, seed: int, t: float, integ=None, frozen=None):
    """Per-pixel Monte-Carlo noise in log brightness at time ``t``: two seeds' renders (``seed``, ``seed + 1``)
    differ by |a - b|, sqrt 2 times one render's spread.

    With ``integ`` (the render's event integrator) the frames are rendered by its inner integrator and taken to
    log through its own pixel (``stage``), and the result is (map, the radiance at ``seed``): the render's first
    frame, which the time-stepping loop stages instead of rendering it again (``stepping.default_steps``).
    ``frozen``: the loop's frozen step render (``frames.frozen_render``, at ``spp``): the probe's two frames are
    its two recordings (a freshly loaded scene records twice), so the loop replays it from its first step on."""
    if integ is None:
        from .render import render_frames
        a, b = (render_frames(timed, [t], spp=spp, seed=s)[0] for s in (seed, other_seed(seed)))
        return np.abs(a - b) / math.sqrt(2)
    from .. import backend
    mi, dr = backend.mi, backend.dr

    def render(s):
        if frozen is not None:
            return frozen(timed.scene, timed.sensor, dr.opaque(mi.UInt32, s))
        return mi.render(timed.scene, sensor=timed.sensor, integrator=integ.inner, seed=s, spp=spp)
    timed.set_time(t)
    frames, logs = [], []
    for s in (seed, other_seed(seed)):
        frames.append(render(s))
        integ.stage(frames[-1])
        logs.append(integ.staged.numpy())
    integ.staged = integ.staged_intensity = None          # a probe, not a step: nothing is committed
    return np.abs(logs[0] - logs[1]) / math.sqrt(2), frames[0]


def _host(frame) -> np.ndarray:
    """A kept frame as NumPy (a Dr.Jit Float is read back; NumPy passes)."""
    return frame if isinstance(frame, np.ndarray) else frame.numpy()


class AccuracyLimit:
    """Collects the frames the estimates need while the render runs; :meth:`note` writes the verdict."""

    def __init__(self, dt, spp: int, active: bool = True):
        """``dt``: the step, or the first two steps (d1, d2) of steps placed by the image motion."""
        self.dts = tuple(dt) if isinstance(dt, (tuple, list)) else (dt, dt)
        self.spp, self.active = spp, active
        self.frames, self.sigma, self.probed, self.other = [], None, None, None
        self.baselines = []        # (seconds since the first frame, frame) at steps 4, 8, 16, ...: event_slopes
        self.longest = math.inf    # the longest slope baseline: a quarter of a scan period (for_stepping)
        self.chosen = None         # the last estimate's event_slopes (its baseline and per-pixel slope)

    @classmethod
    def for_stepping(cls, st, sigma: np.ndarray | None = None, period: float | None = None) -> "AccuracyLimit":
        """Active for fixed-seed renders of at least MIN_STEPS steps known before rendering (uniform, or placed
        by the image motion: the default's or ``adaptive="motion"``, whose estimate takes the first two steps,
        the shortest where the motion is fastest, so later longer steps may do worse); otherwise every method
        does nothing (log-change steps and independent seeds have no steps or frozen noise to speak of).
        ``sigma``: the noise map already measured (``noise_map``, by ``stepping.default_steps``): not again."""
        if st.adaptive or (st.steps is None and st.schedule is None):
            dts, steps = 0.0, 0
        elif st.schedule is not None:
            dts, steps = tuple(float(d) for d in np.diff(st.schedule[:3])), len(st.schedule) - 1
        else:
            dts, steps = st.duration / st.steps, st.steps
        limit = cls(dts, st.spp, active=steps >= MIN_STEPS and st.seed_mode == "fixed")
        limit.probed = sigma
        limit.longest = longest_baseline(period)
        return limit

    def first_frame(self, loop, t_start: float) -> None:
        """Keep the first frame (the pixels' initial brightness) and render it again with another seed."""
        if not self.active:
            return
        from .. import backend
        integ, st = loop.integ, loop.st
        self.frames.append(integ.log_prev)
        if self.probed is not None:
            self.sigma = self.probed
            return
        loop.timed.set_time(t_start)
        loop.render_frame(other_seed(st.seed), once=True)
        self.other = integ.staged            # sigma from it at the end (:meth:`estimate`): no read-back now,
        backend.dr.eval(self.other)          # only queued: the rendered image it reads is released
        integ.staged = integ.staged_intensity = None          # not a step: nothing is committed

    @property
    def wants_frames(self) -> bool:
        """True from the first frame (:meth:`first_frame`; a resumed render gets the frames its checkpoint kept,
        :meth:`restore`) until the first two steps' frames are kept (:meth:`step_frame`)."""
        return self.active and 1 <= len(self.frames) < 3

    def step_frame(self, log_now) -> None:
        """Keep the log brightness (Dr.Jit Float) a step ended at, for the first two steps. Kept on the device
        and read at the end: a read here waited for the step's render on a GPU (a sync a step, twice a render)."""
        if self.wants_frames:
            self.frames.append(log_now)

    def step_held(self, integ, dt: float) -> None:
        """:meth:`step_frame` for a step held for a batch (``step_batch``), whose pixels have not moved yet:
        its staged frame, under a low-pass blended into the last frame kept as the batch's kernel will blend
        it (``pixel_step.lowpassed``, over the step's ``dt`` seconds). Until 2026-11-27 a low-pass committed
        the first two steps one at a time for this, each with its own event kernels and read-back."""
        if not self.wants_frames:
            return
        from .. import backend
        from ..plugins import pixel_step
        mi, dr = backend.mi, backend.dr
        last = self.frames[-1]
        if isinstance(last, np.ndarray):        # restored from a checkpoint: back onto the device
            last = type(integ.log_prev)(last)
        end = pixel_step.lowpassed(integ, last, integ.staged, integ.staged_intensity,
                                   dr.opaque(mi.Float, dt))
        dr.eval(end)       # its own small kernel now (queued, not waited for): the frames it reads can go
        self.step_frame(end)

    def baseline_frame(self, integ, steps_done: int, elapsed: float) -> None:
        """After step ``steps_done`` (1-based), ``elapsed`` seconds after the first frame: keep the frame for a
        longer slope baseline (:func:`event_slopes`) at steps 4, 8, 16, ... (at most ``MAX_BASELINES``; the first
        two are ``step_frame``'s). Called before the step is committed or held: its staged frame, the rendered
        log brightness the noise map measures (a low-pass's state would differ between a step committed and one
        held for a batch), evaluated now (a queued kernel; the frame also goes on to the commit or the batch)."""
        if not (self.active and self.frames and steps_done >= 4 and steps_done & (steps_done - 1) == 0
                and len(self.baselines) < MAX_BASELINES and elapsed <= self.longest):
            return
        from .. import backend
        frame = type(integ.staged)(integ.staged)
        backend.dr.eval(frame)
        self.baselines.append((elapsed, frame))

    def state(self) -> dict:
        """The frames kept so far as NumPy arrays (``limit_*`` keys) for a checkpoint: a resumed render keeps
        longer baselines after it and estimates as the uninterrupted one does (:meth:`restore`)."""
        if not (self.active and self.frames):
            return {}
        self.estimate()                    # the other seed's frame into sigma; every frame read back once
        out = {f"limit_frame_{i}": _host(f) for i, f in enumerate(self.frames)}
        out.update({f"limit_baseline_{i}": _host(f) for i, (_, f) in enumerate(self.baselines)})
        out["limit_baseline_s"] = np.array([b for b, _ in self.baselines], np.float64)
        if self.sigma is not None:
            out["limit_sigma"] = self.sigma
        return out

    def restore(self, state: dict) -> None:
        """The frames of :meth:`state` back, from a checkpoint's arrays (keys without ``limit_`` ignored)."""
        if "limit_frame_0" not in state:
            return
        self.frames = [state[f"limit_frame_{i}"] for i in range(3) if f"limit_frame_{i}" in state]
        self.baselines = [(float(b), state[f"limit_baseline_{i}"]) for i, b in enumerate(state["limit_baseline_s"])]
        self.sigma = state.get("limit_sigma")

    def slopes(self) -> dict | None:
        """``event_slopes`` of the frames kept (read back by :meth:`estimate`)."""
        (l0, l1, l2), (d1, d2) = self.frames, self.dts
        return event_slopes(l0, itertools.chain([(d1, l1), (d1 + d2, l2)], self.baselines), self.sigma,
                            self.longest)

    def estimate(self) -> dict | None:
        if self.other is not None:           # the other seed's first frame, kept on the device until now
            self.sigma, self.other = np.abs(_host(self.frames[0]) - _host(self.other)) / math.sqrt(2), None
        if self.sigma is None or len(self.frames) < 3:
            return None
        self.frames = [_host(f) for f in self.frames]      # read back once (a checkpoint estimates at each save)
        self.baselines = [(b, _host(f)) for b, f in self.baselines]
        l0, l1, l2 = self.frames
        d1, d2 = self.dts
        slope = np.abs(l1 - l0) / d1
        active = slope > 0
        slopes = self.chosen = self.slopes()      # (kept: a plan divides every sampler's noise by its slope)
        if not active.any() or slopes is None:
            return None
        rate = slope[active]
        # the second divided difference (uniform steps: (l2 - 2 l1 + l0) / dt^2), and the first steps' length
        curvature = np.abs((l2 - l1) / d2 - (l1 - l0) / d1)[active] * 2 / (d1 + d2)
        dt = (d1 + d2) / 2
        # each pixel's error, the median over its events: a pixel fires about |L'| T / C times, so it counts by
        # its slope. The median over pixels (of the noise, then of the slopes) was that of a pixel barely
        # changing, which seldom fires, and grew as the steps shrank: the fan at 96x72 read 172, 481 and
        # 1312 us at 16, 55 and 480 steps (now 22, 23, 13)
        noise_us = float(slopes["error_s"]) * 1e6
        steps_us = event_median(dt ** 2 * curvature / (8 * rate), rate) * 1e6
        return {"limit": "Monte-Carlo noise" if noise_us > steps_us else "steps", "noise_us": noise_us,
                "steps_us": steps_us, "spp": self.spp, "slope_baseline_us": float(slopes["baseline_s"]) * 1e6,
                "slope_resolved": bool(slopes["resolved"]), "noise_free": not noisy(self.sigma)}

    def note(self, summary) -> None:
        est = self.estimate() if self.active else None
        if est is None and summary.timing_limit is not None:
            est = summary.timing_limit             # resumed from a checkpoint that kept no frames (before 11-28)
        summary.timing_limit = est
        if est is None:
            return
        if not est.get("slope_resolved", True):      # (a checkpoint's estimate from before 2026-11-28 has none)
            summary.notes.append(f"timing: no time baseline of the kept frames (up to "
                                 f"{est['slope_baseline_us'] / 1e3:.3g} ms) resolved the pixels' slopes (it needs "
                                 "4x the error and a steady error): the noise estimate below is uncertain")
        if est.get("noise_free"):           # a jitter-free sampler: every seed renders the same image
            summary.notes.append(f"timing accuracy is limited by the time step: about {est['steps_us']:.3g} us; the "
                                 "sampler renders the same image for every seed (no Monte-Carlo noise), and the "
                                 "sampling pattern's own fixed error is not estimated")
        elif est["limit"] == "steps":
            summary.notes.append(f"timing accuracy is limited by the time step: about {est['steps_us']:.3g} us "
                                 f"(Monte-Carlo noise about {est['noise_us']:.3g} us); twice the steps quarter it")
        else:
            summary.notes.append(f"timing accuracy is limited by Monte-Carlo noise: about {est['noise_us']:.3g} us "
                                 f"at {self.spp} spp (the step alone: about {est['steps_us']:.3g} us); more "
                                 "steps do not help, four times the samples halve it")
