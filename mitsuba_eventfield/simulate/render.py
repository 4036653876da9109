"""The time-stepping loop: scene at time t -> radiance render -> event integrator -> events (memory or file).

Steps are uniform (``steps``) or adaptive: after each step the next one is sized so that the largest per-pixel
log-brightness change is predicted to stay under ``max_log_change`` x C; a step whose change exceeds twice
that is rendered again, shorter (only the render is repeated, the pixel state is untouched).

Every step renders with the same sampler seed by default: the Monte-Carlo noise pattern is then frozen, so a
static pixel never fires (independent seeds make noise fire events: docs/design.md, "Measured facts and pitfalls").
"""
from __future__ import annotations

import math
import os
import platform
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from .. import backend
from .._version import __version__
from ..atomic import check_writable
from ..errors import EventFieldError
from ..events.io import H5EventWriter, format_of, write_events
from ..events.stream import EventStream
from ..scene.timed import TimedScene, load_scene
from ..validate import MAX_DURATION_S, MAX_STEPS, available_memory

mi, dr = backend.mi, backend.dr

SEED_MODES = ("fixed", "independent")
# Memory model used to refuse a frame that cannot fit: bytes per Monte-Carlo sample in flight and per pixel
# (film, radiance tensor, pixel state). Conservative; measured peak is lower (benchmarks/bench_foundation.py).
BYTES_PER_SAMPLE = 64
BYTES_PER_PIXEL = 96
MAX_WAVEFRONT = 2**32 - 1


@dataclass
class RenderSummary:
    """What a render did: counts, timings split by stage, and where the events went."""
    events: int = 0
    on: int = 0
    off: int = 0
    duration_s: float = 0.0
    steps: int = 0
    rejected_steps: int = 0
    reused_steps: int = 0       # steps whose frame came from the one-period cache
    copied_steps: int = 0       # steps whose events were copied from the previous period (state repeated)
    dropped_readout: int = 0    # events the readout cap dropped
    dropped_refractory: int = 0  # crossings suppressed by the refractory period
    noise_events: int = 0       # shot-noise events emitted
    wall_s: float = 0.0
    render_s: float = 0.0
    events_s: float = 0.0
    motion_s: float = 0.0
    write_s: float = 0.0
    width: int = 0
    height: int = 0
    output: str | None = None
    notes: list = field(default_factory=list)

    @property
    def rate(self) -> float:
        return self.events / self.duration_s if self.duration_s > 0 else 0.0

    def as_dict(self) -> dict:
        d = {k: getattr(self, k) for k in self.__dataclass_fields__}
        d["rate_ev_per_s"] = self.rate
        return d

    def format(self) -> str:
        overhead = self.events_s + self.motion_s + self.write_s
        lines = [f"{self.events} events ({self.on} ON, {self.off} OFF) in {self.duration_s * 1e3:.3f} ms simulated "
                 f"on {self.width}x{self.height}: {self.rate:.4g} ev/s",
                 f"{self.steps} steps ({self.rejected_steps} re-rendered shorter), wall {self.wall_s:.2f} s: "
                 f"render {self.render_s:.2f} s, events {self.events_s:.2f} s, motion {self.motion_s:.2f} s, "
                 f"write {self.write_s:.2f} s (overhead {100 * overhead / max(self.render_s, 1e-9):.1f}% of render)"]
        if self.output:
            lines.append(f"wrote {self.output}")
        lines += self.notes
        return "\n".join(lines)


def _check_number(name, value, low=None, integer=False, allow_none=False):
    if value is None and allow_none:
        return None
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool) \
        and math.isfinite(value) and (not integer or float(value).is_integer())
    if not ok or (low is not None and value <= low):
        kind = "an integer" if integer else "a finite number"
        rng = f" > {low}" if low is not None else ""
        raise EventFieldError(f"{name} = {value!r}: must be {kind}{rng}")
    return int(value) if integer else float(value)


def check_memory(width: int, height: int, spp: int, where: str = "film") -> int:
    """Refuse a frame whose render buffers cannot fit; return the estimated bytes."""
    samples = width * height * spp
    if samples > MAX_WAVEFRONT:
        raise EventFieldError(f"{where}: {width}x{height} pixels x {spp} spp = {samples} samples per frame exceeds "
                              f"Mitsuba's single-wavefront limit of {MAX_WAVEFRONT}; lower the resolution or spp")
    need = samples * BYTES_PER_SAMPLE + width * height * BYTES_PER_PIXEL
    avail = available_memory()
    if need > 0.8 * avail:
        raise EventFieldError(f"{where}: {width}x{height} pixels x {spp} spp needs about {need / 2**30:.1f} GiB of "
                              f"render buffers, more than 80% of the {avail / 2**30:.1f} GiB available")
    return need


def _event_integrator(timed: TimedScene, threshold, threshold_on, threshold_off, linlog_threshold, preset=None,
                      pixel=None):
    """The scene's eventfield integrator (or one wrapping its radiance integrator), configured for this render:
    the scene's own pixel settings, then ``preset``, then explicit values (never an earlier render's)."""
    from ..plugins import pixel_model
    from ..plugins.event_integrator import integrator_class, is_event_integrator
    integ = timed.scene.integrator()
    if not is_event_integrator(integ):  # any scene: wrap its radiance integrator
        integ = integrator_class()(_props_with_inner(integ))
    overrides = {} if preset is not None else dict(integ.scene_overrides)
    explicit = {"threshold_on": threshold_on if threshold_on is not None else threshold,
                "threshold_off": threshold_off if threshold_off is not None else threshold,
                "linlog_threshold": linlog_threshold}
    explicit.update(pixel or {})
    for name, v in explicit.items():
        if v is not None:
            overrides[name] = v
    try:
        config = pixel_model.pixel_config(preset or integ.scene_preset, "pixel model", **overrides)
    except ValueError as e:
        raise EventFieldError(str(e)) from None
    integ.configure(config)
    return integ


def _props_with_inner(inner):
    props = mi.Properties("eventfield")
    props["inner"] = inner
    return props


class _Sink:
    """Where a step's events go: an in-memory list or a streaming HDF5 writer (other formats: at the end)."""

    def __init__(self, output, fmt, width, height, meta):
        self.output, self.width, self.height, self.meta = output, width, height, meta
        self.fmt = format_of(output, fmt) if output else None
        self.writer = H5EventWriter(output, width, height, meta) if self.fmt == "h5" else None
        self.parts = []

    def add(self, x, y, t, p, complete_until_us):
        if self.writer is not None:
            self.writer.append(x, y, t, p, complete_until_us)
        elif len(t):
            self.parts.append((x, y, t, p))

    def stream(self, meta):
        if not self.parts:
            return EventStream.empty(self.width, self.height, meta)
        return EventStream(*(np.concatenate([part[i] for part in self.parts]) for i in range(4)),
                           self.width, self.height, meta)

    def finish(self, end_us, meta):
        if self.writer is not None:
            self.writer.close(end_us=end_us, meta=meta)
            return None
        ev = self.stream({**self.meta, **meta})
        if self.output:
            write_events(self.output, ev, self.fmt)
        return ev

    def abort(self):
        if self.writer is not None:
            self.writer.abort()


def _advance(bar, elapsed_s: float) -> None:
    """Move the progress bar to ``elapsed_s`` of simulated time: set from the position, not summed steps, so
    float round-off never takes it past its total (tqdm warns then)."""
    bar.update(min(round(elapsed_s * 1e3, 6), bar.total) - bar.n)


def render_events(scene, duration: float | None = None, *, steps: int | None = None, adaptive: bool = False,
                  max_log_change: float = 0.5, min_step: float | None = None, max_step: float | None = None,
                  spp: int = 4, seed: int = 0, seed_mode: str = "fixed", threshold: float | None = None,
                  threshold_on: float | None = None, threshold_off: float | None = None,
                  linlog_threshold: float | None = None, output: str | None = None, fmt: str | None = None,
                  progress: bool = False, t_start: float = 0.0, reuse: bool = True, preset: str | None = None,
                  pixel: dict | None = None, extra_meta: dict | None = None):
    """Render the event stream of ``scene`` over [t_start, t_start + duration] seconds.

    Returns an :class:`EventStream` when ``output`` is None; otherwise streams to ``output`` (format by
    extension; HDF5 is written in chunks while rendering, the others at the end) and returns a
    :class:`RenderSummary`. Either way the summary is also in ``stream.meta["render"]``.

    ``reuse``: when the scene is static and the view periodic (galvo scan, or a fixed camera), render one
    period and feed its frames again (identical events, much faster); False renders every step.

    ``preset`` ("ideal", "davis346", "prophesee_gen4") and ``pixel`` (PixelConfig fields, e.g.
    ``{"refractory_s": 1e-4, "shot_noise_hz": 2}``) choose the event pixel; default: the scene's own.
    """
    timed = load_scene(scene)
    if duration is None:
        duration = timed.motion.duration if timed.motion and timed.motion.duration else None
        if duration is None:
            raise EventFieldError("duration not given (pass duration=..., --duration, or set `duration` in the "
                                  "motion file)")
    duration = _check_number("duration", duration, low=0)
    if duration > MAX_DURATION_S:
        raise EventFieldError(f"duration = {duration:g} s: allowed range is (0, {MAX_DURATION_S:g}] simulated seconds "
                              "per render (the event file indexes every millisecond; split longer captures)")
    t_start = _check_number("t_start", t_start)
    spp = _check_number("spp", spp, low=0, integer=True)
    seed = _check_number("seed", seed, low=-1, integer=True)
    if seed_mode not in SEED_MODES:
        raise EventFieldError(f"seed_mode = {seed_mode!r}: allowed values are {', '.join(SEED_MODES)}")
    if adaptive:
        max_log_change = _check_number("max_log_change", max_log_change, low=0)
        max_step = _check_number("max_step", max_step if max_step is not None else duration / 20, low=0)
        min_step = _check_number("min_step", min_step if min_step is not None else min(1e-6, max_step), low=0)
        if min_step > max_step:
            raise EventFieldError(f"min_step = {min_step} is larger than max_step = {max_step}")
    else:
        steps = _check_number("steps", steps if steps is not None else 100, low=0, integer=True)
        if steps > MAX_STEPS:
            raise EventFieldError(f"steps = {steps}: allowed range is [1, {MAX_STEPS}] (each step renders the film)")
    width, height = timed.film_size
    check_memory(width, height, spp, where=f"{timed.path or 'scene'}: film")
    if output:
        check_writable(output, "event file")
        format_of(output, fmt)
    integ = _event_integrator(timed, threshold, threshold_on, threshold_off, linlog_threshold, preset, pixel)
    integ.reset()

    summary = RenderSummary(width=width, height=height, duration_s=duration, output=os.path.abspath(output) if output else None)
    if not adaptive:
        _warn_coarse_scan_steps(timed.scan_period, duration, steps, summary.notes)
    meta = _metadata(timed, integ, duration=duration, t_start=t_start, spp=spp, seed=seed, seed_mode=seed_mode,
                     stepping=({"mode": "adaptive", "max_log_change": max_log_change, "min_step_s": min_step,
                                "max_step_s": max_step} if adaptive else {"mode": "uniform", "steps": steps}))
    if extra_meta:
        meta.update(extra_meta)
    t_end = t_start + duration
    end_us = int(round(t_end * 1e6))
    sink = _Sink(output, fmt, width, height, meta)
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=round(duration * 1e3, 6), unit="ms", unit_scale=False, desc="rendering", file=sys.stderr,
                   bar_format="{l_bar}{bar}| {n:.3f}/{total:.3f} ms sim [{elapsed}<{remaining}]{postfix}")
    wall0 = time.perf_counter()
    reuse = None if adaptive or not reuse or seed_mode != "fixed" else _reuse_plan(timed, duration, steps, width, height, summary.notes)
    cache = []                                          # log-brightness frames of one period, for reuse
    # periodic view on a uniform grid: timestamps from the in-period phase plus whole periods (integers), so an
    # event copied from the previous period is bit-identical to one computed
    # (not for pixel models with state across steps, e.g. refractory: they need absolute times, and their
    # events are never copied anyway)
    grid = None if adaptive or not integ.deterministic else _phase_grid(timed, duration, steps, t_start)
    period_events, copy_from, prev_key, period_block = {}, None, None, None
    try:
        def render_at(t, step_index):
            if reuse and step_index >= reuse:           # the view repeats: feed the cached frame, no render
                integ.stage_log(cache[step_index % reuse], (width, height))
                summary.reused_steps += 1
                return
            t0 = time.perf_counter()
            timed.set_time(t)
            t1 = time.perf_counter()
            step_seed = seed if seed_mode == "fixed" else seed + step_index
            mi.render(timed.scene, integrator=integ, seed=step_seed, spp=spp)
            dr.sync_thread()
            t2 = time.perf_counter()
            summary.motion_s += t1 - t0
            summary.render_s += t2 - t1
            if reuse:
                frame = mi.Float(integ.staged)
                dr.eval(frame)
                integ.staged = frame                    # commit() uses the evaluated frame: no second evaluation
                cache.append(frame)

        render_at(t_start, 0)
        integ.commit(t_start, t_start)   # initialises every pixel's reference; fires nothing
        t, k = t_start, 0
        dt = (duration / steps) if not adaptive else max(min_step, max_step / 16)
        c_min = min(integ.threshold_on, integ.threshold_off)
        while t < t_end - 1e-12:
            if adaptive:
                dt = min(dt, t_end - t)
                t_next = t + dt
            else:
                t_next = t_start + (k + 1) * duration / steps
            if grid:
                K, period_us, base_us = grid
                p_idx, j = divmod(k, K)
            if copy_from is not None:                    # the pixel state repeats: copy whole periods, shifted
                block = min(K - j, steps - k)            # j == 0 here: copying starts at a period boundary
                x, y, t_us, p = period_block(block)
                t_next = t_start + (k + block) * duration / steps
                tw = time.perf_counter()
                sink.add(x, y, t_us + (p_idx - copy_from) * period_us, p,
                         complete_until_us=int(math.floor(t_next * 1e6)))
                summary.write_s += time.perf_counter() - tw
                _count(summary, p)
                summary.copied_steps += block
                if bar is not None:
                    _advance(bar, t_next - t_start)
                t, k = t_next, k + block
                continue
            render_at(t_next, k + 1)
            if adaptive:
                change = integ.staged_max_change()
                if change > 2 * max_log_change * c_min and dt > min_step * (1 + 1e-9):
                    dt = max(min_step, 0.9 * dt * max_log_change * c_min / change)
                    summary.rejected_steps += 1
                    continue
            te = time.perf_counter()
            if grid:
                x, y, ts, p = integ.commit(j * (duration / steps), (j + 1) * (duration / steps))
                t_us = np.rint(ts * 1e6).astype(np.int64) + (base_us + p_idx * period_us)
            else:
                x, y, ts, p = integ.commit(t, t_next)
                t_us = np.rint(ts * 1e6).astype(np.int64)
            order = _time_order(t_us, int(math.floor(t * 1e6)))
            x, y, t_us, p = integ.readout(x[order], y[order], t_us[order], p[order])
            if reuse and grid:
                period_events[j] = (x, y, t_us, p)
                if j == K - 1:                           # end of a period: has the pixel state come back?
                    key = integ.periodic_key()
                    if key is not None and prev_key is not None and bool((key == prev_key).numpy().all()):
                        copy_from = p_idx
                        period_block = _period_blocks([period_events[i] for i in range(K)])
                        summary.notes.append(f"pixel state repeated after period {p_idx + 1}: the events of the "
                                             "later periods are exact copies, shifted by whole periods")
                    prev_key = key
            tw = time.perf_counter()
            sink.add(x, y, t_us, p, complete_until_us=int(math.floor(t_next * 1e6)))
            summary.write_s += time.perf_counter() - tw
            summary.events_s += tw - te
            _count(summary, p)
            if adaptive:
                rate = change / dt
                grow = min(max_step, 2 * dt)
                dt = min(grow, max(min_step, 0.9 * max_log_change * c_min / rate)) if rate > 0 else grow
            if bar is not None:
                _advance(bar, t_next - t_start)
                bar.set_postfix_str(f"{summary.events} events")
            t, k = t_next, k + 1
        summary.steps = k
        summary.dropped_readout, summary.dropped_refractory = integ.readout_dropped(), integ.refractory_dropped
        summary.noise_events = integ.noise_events
        if summary.dropped_readout:
            total = summary.events + summary.dropped_readout
            summary.notes.append(f"readout cap dropped {summary.dropped_readout} of {total} events "
                                 f"({100 * summary.dropped_readout / total:.1f}%)")
        summary.wall_s = time.perf_counter() - wall0
        if timed.is_static and timed.scan_period == 0.0:
            summary.notes.append("static scene seen by a fixed view: events can only come from Monte-Carlo noise "
                                 "(none with a fixed seed)")
        meta["render"] = summary.as_dict()
        tw = time.perf_counter()
        stream = sink.finish(end_us, {"render": meta["render"]})
        summary.write_s += time.perf_counter() - tw
        summary.wall_s = time.perf_counter() - wall0   # the file's copy lacks only this final write
    except BaseException:
        sink.abort()
        raise
    finally:
        if bar is not None:
            bar.close()
    if stream is not None:
        stream.meta = meta
        stream.meta["render"] = summary.as_dict()
        return stream if output is None else summary
    return summary


def render_frames(scene, times, spp: int = 4, seed: int = 0, log: bool = True,
                  linlog_threshold: float | None = None, rgb: bool = False, sensor=None) -> np.ndarray:
    """Frames of the scene at the given times (seconds): (T, H, W) log brightness exactly as the event pixel
    sees it (lin-log, fixed seed), or linear radiance with ``log=False``. Ground truth for reconstruction, and
    the frame input of the complementary filter. ``rgb=True`` (with ``log=False``, scene loaded in a colour
    variant): (T, H, W, 3) linear RGB, what a colour camera sees. ``sensor``: another Mitsuba sensor to look
    through (e.g. ``truth.centre_pinhole``: a conventional camera beside the event camera)."""
    if rgb and log:
        raise EventFieldError("render_frames: rgb=True needs log=False (the event pixel's log is of luminance)")
    from ..plugins import pixel_model
    from ..plugins.event_integrator import DEFAULT_LINLOG, is_event_integrator
    timed = load_scene(scene)
    spp = _check_number("spp", spp, low=0, integer=True)
    integ = timed.scene.integrator()
    if linlog_threshold is None:
        linlog_threshold = (pixel_model.pixel_config(integ.scene_preset, **integ.scene_overrides).linlog_threshold
                            if is_event_integrator(integ) else DEFAULT_LINLOG)
    inner = integ.inner if is_event_integrator(integ) else integ
    frames = []
    for t in np.atleast_1d(np.asarray(times, dtype=np.float64)):
        timed.set_time(float(t))
        img = mi.render(timed.scene, integrator=inner, seed=seed, spp=spp, sensor=sensor or timed.scene.sensors()[0])
        arr = np.array(img)
        if rgb:
            if arr.shape[-1] < 3:
                raise EventFieldError("render_frames: rgb=True needs the scene loaded in a colour variant "
                                      f"(load_scene(..., color=True)); the active variant is {mi.variant()}")
            frames.append(arr[..., :3])
            continue
        lum = arr[..., 0] if arr.shape[-1] == 1 else arr[..., 0] * 0.212671 + arr[..., 1] * 0.715160 + arr[..., 2] * 0.072169
        frames.append(pixel_model.linlog_np(lum, linlog_threshold) if log else lum)
    return np.stack(frames)


MIN_STEPS_PER_SCAN_PERIOD = 16


def _warn_coarse_scan_steps(period, duration, steps, notes):
    """A scan period cut into a handful of steps misses events: measured on the fan (250 Hz circle), 4 steps per
    period give 29 % fewer events than a converged run, 80 steps still 7.7 % fewer. Say so, in the summary (and so
    in the metadata) and on stderr, instead of returning a silently poor result."""
    if not period:
        return
    per_period = steps * period / duration
    if per_period < MIN_STEPS_PER_SCAN_PERIOD:
        need = int(math.ceil(MIN_STEPS_PER_SCAN_PERIOD * duration / period))
        note = (f"warning: only {per_period:.3g} steps per {period * 1e3:g} ms scan period (fewer than "
                f"{MIN_STEPS_PER_SCAN_PERIOD}): events are missed; use --steps {need} or more")
        notes.append(note)
        print(f"eventfield: {note}", file=sys.stderr)


def _period_blocks(steps_events):
    """The events of one period's steps, concatenated once; ``block(n)``: those of its first n steps."""
    ends = np.cumsum([len(e[2]) for e in steps_events])
    whole = [np.concatenate([e[i] for e in steps_events]) for i in range(4)]

    def block(n):
        m = int(ends[n - 1]) if n else 0
        return tuple(a[:m] for a in whole)
    return block


def _count(summary: RenderSummary, p: np.ndarray) -> None:
    n_on = int(np.count_nonzero(p > 0))
    summary.events += len(p)
    summary.on += n_on
    summary.off += len(p) - n_on


def _phase_grid(timed: TimedScene, duration: float, steps: int, t_start: float):
    """(steps per period, period in us, start in us) when a periodic view meets the uniform step grid in
    whole microseconds; else None."""
    period = timed.scan_period
    if not period:
        return None
    k_float, period_us, base_us = period / (duration / steps), period * 1e6, t_start * 1e6
    whole = lambda v: abs(v - round(v)) <= 1e-6 * max(1.0, abs(v))  # noqa: E731
    if round(k_float) < 1 or not (whole(k_float) and whole(period_us) and whole(base_us)):
        return None
    return int(round(k_float)), int(round(period_us)), int(round(base_us))


def _reuse_plan(timed: TimedScene, duration: float, steps: int, width: int, height: int, notes: list):
    """Number of steps after which every rendered frame repeats (static scene, periodic view), or None.

    Reuse is exact: the galvo reduces time to the scan phase on the host (rounded to 1 ns), so a render one
    period later is bit-identical to the cached frame; the integrator then sees the same input either way.
    """
    if not timed.is_static:
        return None
    period = timed.scan_period
    if period is None:
        notes.append("static scene, but the scan is not periodic: every step rendered")
        return None
    if period == 0.0:
        k = 1
    else:
        k_float = period / (duration / steps)
        k = int(round(k_float))
        if k < 1 or abs(k_float - k) > 1e-6 * k_float:
            notes.append(f"static scene, but the step ({duration / steps * 1e6:.4g} us) does not divide the scan "
                         f"period ({period * 1e6:.4g} us): every step rendered")
            return None
    if k >= steps:
        return None
    if k * width * height * 4 > 0.25 * available_memory():
        notes.append(f"static scene, but caching {k} frames would need too much memory: every step rendered")
        return None
    what = "one frame" if period == 0.0 else f"one scan period ({k} steps, {period * 1e3:.4g} ms)"
    notes.append(f"static scene: rendered {what} and reused it for the other {steps + 1 - k} steps "
                 "(events identical to rendering every step)")
    return k


def _time_order(t_us: np.ndarray, step_start_us: int) -> np.ndarray:
    """Stable time order of one step's events. Offsets within a step usually fit 16 bits, where NumPy's
    stable sort is a radix sort (about 8x faster than comparison sorting here)."""
    offset = t_us - step_start_us
    if len(offset) and offset.min() >= 0 and offset.max() < 2**16:
        return np.argsort(offset.astype(np.uint16), kind="stable")
    return np.argsort(t_us, kind="stable")


def _metadata(timed: TimedScene, integ, **run) -> dict:
    sensor = timed.sensor
    optics = sensor.optics_metadata() if hasattr(sensor, "optics_metadata") else {"design": "conventional camera",
                                                                                   "sensor": type(sensor).__name__}
    for key in timed.params.keys():  # first-level sensor parameters worth recording (e.g. sensor.x_fov)
        name = key.split(".")[-1]
        if key.count(".") == 1 and name in ("x_fov", "focus_distance", "aperture_radius") \
                and key.startswith(_sensor_id(timed)):
            optics[name] = float(timed.params[key][0])
    return {"package": "mitsuba-eventfield", "package_version": __version__, "mitsuba_version": mi.__version__,
            "drjit_version": dr.__version__, "variant": mi.variant(), "python": platform.python_version(),
            "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "width": timed.film_size[0],
            "height": timed.film_size[1], "duration_us": int(round(run["duration"] * 1e6)),
            "t_start_us": int(round(run["t_start"] * 1e6)), "optics": optics,
            "pixel_model": integ.pixel_model_metadata(), "spp": run["spp"], "seed": run["seed"],
            "seed_mode": run["seed_mode"], "stepping": run["stepping"], "scene": timed.describe(),
            "command": " ".join(sys.argv) if sys.argv and sys.argv[0] else None}


def _sensor_id(timed: TimedScene) -> str:
    sid = timed.sensor.id()
    return sid + "." if sid else "sensor."
