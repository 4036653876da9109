"""A render's time stepping, validated: uniform steps, or adaptive steps set by what moves.

* uniform: ``steps`` equal steps;
* the default (no ``steps``, not adaptive): as many steps as the known image motion needs, uniform, or placed
  by the motion where it varies and no scan needs uniform steps (``default_steps``; 100 where the motion is not
  known before rendering);
* adaptive by image motion (``adaptive=True`` where the motion is known, or ``"motion"``): the instants are
  placed before rendering so the image moves at most ``px_per_step`` pixels between two of them, from the
  motion that is known analytically (the galvo scan, the moving objects' projected bounds;
  ``image_motion.motion_schedule``). Where nothing moves the steps grow to ``max_step``; a fast part of a
  Lissajous scan or a passing object gets short steps only while it lasts. This is what "where change
  happens" means for events: interpolating log brightness between instants is exact while an edge moves
  less than a pixel;
* adaptive by log change (``"log-change"``, and ``True`` where the motion is not known, e.g. a moving sensor):
  after each step the next is sized so the largest per-pixel log change stays under ``max_log_change`` x C.
  Global: one sharp moving edge anywhere sets every step (under a galvo scan that is ~100x the steps of the
  motion criterion, docs/design.md).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import EventFieldError
from ..validate import MAX_DURATION_S, MAX_SEED, MAX_SPP, MAX_STEPS, finite, number, positive

SEED_MODES = ("fixed", "independent")


def step_seed(seed: int, step: int) -> int:
    """The sampler's seed of step ``step`` under ``seed_mode="independent"``: a hash of both (32 bits, what
    Mitsuba's samplers take). It was ``seed + step``, so the render of seed s + 1 drew, at step k, the noise
    of seed s at step k + 1 (63 % of their events shared, 8 % between unrelated seeds)."""
    from ..plugins.counter_rng import hash_words
    return hash_words(seed, step)


ADAPTIVE_MODES = (False, True, "motion", "log-change")


@dataclass(frozen=True)
class Stepping:
    """A render's validated time stepping and sampling. ``adaptive``: log-change stepping decided while
    rendering; ``schedule``: instants fixed before rendering (motion stepping); else ``steps`` uniform steps."""
    duration: float
    t_start: float
    spp: int
    seed: int
    seed_mode: str
    adaptive: bool
    steps: int | None
    max_log_change: float
    min_step: float | None
    max_step: float | None
    schedule: tuple | None = None
    px_per_step: float | None = None
    chosen: dict | None = field(default=None, compare=False)   # why ``default_steps`` chose ``steps``

    def t_next(self, k: int) -> float:
        """The end of step k (uniform or scheduled)."""
        if self.schedule is not None:
            return self.schedule[k + 1]
        return self.t_start + (k + 1) * self.duration / self.steps

    def as_meta(self) -> dict:
        if self.schedule is not None:
            return {"mode": "adaptive", "criterion": "image motion", "px_per_step": self.px_per_step,
                    "steps": len(self.schedule) - 1, "max_step_s": self.max_step,
                    **({"chosen": self.chosen} if self.chosen else {})}
        if self.adaptive:
            return {"mode": "adaptive", "criterion": "log change", "max_log_change": self.max_log_change,
                    "min_step_s": self.min_step, "max_step_s": self.max_step}
        return {"mode": "uniform", "steps": self.steps, **({"chosen": self.chosen} if self.chosen else {})}

    @property
    def needs_default_steps(self) -> bool:
        """Neither steps nor adaptive stepping asked for: ``default_steps`` decides."""
        return self.steps is None and not self.adaptive and self.schedule is None


def _duration(timed, duration):
    if duration is None:
        duration = timed.motion.duration if timed.motion and timed.motion.duration else None
        if duration is None:
            raise EventFieldError("duration not given (pass duration=..., --duration, or set `duration` in the "
                                  "motion file)")
    duration = positive(duration, "duration")
    if duration > MAX_DURATION_S:
        raise EventFieldError(f"duration = {duration:g} s: allowed range is (0, {MAX_DURATION_S:g}] simulated seconds "
                              "per render (the event file indexes every millisecond; split longer captures)")
    return duration


def _say_held_poses(timed, t_start, duration):
    """Warn where the render runs outside an object's keyframes: there it holds a pose (``Motion.held_poses``),
    which on a keyframed fall or throw is an object stopped in mid-air."""
    from ..scene.motion import MotionHeldWarning
    motion = getattr(timed, "motion", None)
    for name, first, last in (motion.held_poses(t_start, t_start + duration) if motion is not None else ()):
        warnings.warn(f"{motion.source or 'motion'}: object '{name}' has keyframes from {first:g} to {last:g} s; "
                      f"the render runs {t_start:g} to {t_start + duration:g} s, and outside them the object "
                      "holds its first or last pose", MotionHeldWarning, stacklevel=3)


def stepping(timed, duration, steps, adaptive, max_log_change, min_step, max_step, spp, seed, seed_mode,
             t_start, px_per_step: float = 1.0) -> Stepping:
    """Every stepping and sampling argument checked, with the duration from the motion file if not given."""
    from .image_motion import motion_schedule
    duration = _duration(timed, duration)
    if seed_mode not in SEED_MODES:
        raise EventFieldError(f"seed_mode = {seed_mode!r}: allowed values are {', '.join(SEED_MODES)}")
    if not any(adaptive is m or adaptive == m for m in ADAPTIVE_MODES):
        raise EventFieldError(f"adaptive = {adaptive!r}: allowed values are False, True, 'motion', 'log-change'")
    if adaptive and steps is not None:      # (the command line's --steps and --adaptive exclude each other)
        raise EventFieldError(f"steps = {steps!r} and adaptive = {adaptive!r}: give one (adaptive stepping "
                              "chooses the steps itself)")
    t_start = finite(t_start, "t_start")
    _say_held_poses(timed, t_start, duration)
    schedule = None
    if adaptive:
        max_log_change = positive(max_log_change, "max_log_change")
        # log change: at most duration/20 per step (the controller needs a start); motion: no cap unless asked
        by_motion_default = duration if (adaptive is True or adaptive == "motion") else duration / 20
        max_step = positive(max_step if max_step is not None else by_motion_default, "max_step")
        min_step = positive(min_step if min_step is not None else min(1e-6, max_step), "min_step")
        if min_step > max_step:
            raise EventFieldError(f"min_step = {min_step} is larger than max_step = {max_step}")
        if adaptive is True or adaptive == "motion":
            px_per_step = positive(px_per_step, "px_per_step")
            schedule = motion_schedule(timed, t_start, duration, px_per_step, max_step, min_step)
            if schedule is None and adaptive == "motion":
                raise EventFieldError("adaptive = 'motion': this scene's image motion is not known before "
                                      "rendering (no galvo scan and no moving object seen through a pinhole); use "
                                      "adaptive = 'log-change' or uniform steps")
            if schedule is not None and len(schedule) - 1 > MAX_STEPS:
                raise EventFieldError(f"adaptive by image motion needs {len(schedule) - 1} steps of at most "
                                      f"{px_per_step:g} px: allowed at most {MAX_STEPS} (raise px_per_step or "
                                      "shorten the render)")
    elif steps is not None:       # (each step renders the film)
        steps = int(number(steps, "steps", 1, MAX_STEPS, integer=True, strict=True))
    return Stepping(duration, t_start, int(number(spp, "spp", 1, MAX_SPP, integer=True, strict=True)),
                    int(number(seed, "seed", 0, MAX_SEED, integer=True, strict=True)), seed_mode,
                    bool(adaptive) and schedule is None, steps, max_log_change, min_step, max_step,
                    tuple(schedule) if schedule is not None else None, px_per_step if schedule is not None else None)


# The default time stepping, measured on the speed-against-accuracy suite (docs/design.md, "Default steps"):
# steps (uniform under a periodic scan, which keeps its phase grid: period reuse, static pixels; placed by the
# motion without one, where that saves PLACED_SAVING) as many as keep the fastest known image motion (scan
# plus objects) under FINE_PX_PER_STEP pixels a step, or NOISY_PX_PER_STEP where Monte-Carlo noise is large
# against the threshold. The analytic scene (noise 0.035 C at 4 spp): 0.5 px a
# step 0.7 % event-count error and 41 us p99 timing, 1 px 3.8 % and 125 us. Noisy renders (4 spp; the demo
# 0.40 C, the fan 0.48 C): every step re-samples the noise of the pixels the motion sweeps, and the per-pixel
# count error falls from 0.5 to 2 px a step (fan 48x36 0.22 / 0.18 / 0.16, 96x72 0.14 / 0.12 / 0.11, demo
# 0.89 / 0.66 / 0.48; the fan at 346x260 is best at 1.3-2.6 px), then rises (demo 3 px 0.50, fan 2.7 px 0.18);
# at 2 px the timing error is still about the noise's (the accuracy-limit note: fan 217 us noise, 97 us step).
FINE_PX_PER_STEP, NOISY_PX_PER_STEP = 0.5, 2.0
NOISE_LIMITED = 0.25       # median Monte-Carlo noise in log brightness, as a fraction of the smaller threshold:
#                            two independent draws differ by more than C in ~0.5 % of pixels at 0.25 C
UNKNOWN_MOTION_STEPS = 100  # motion not known before rendering (aperiodic view, moving sensor)
MIN_PLACED_STEP = 1e-6     # s: as adaptive stepping's default: no two placed instants closer (an object passing
#                            right by the camera may then move more than the bound in a step: the note says so)
PLACED_SAVING = 0.1        # steps placed by the motion (not uniform) where they save at least this fraction: the
#                            demo's object motion slows down, and 2 px steps placed by it are 12 against 14
#                            uniform, for the same count error (0.475 +- 0.023 against 0.492 +- 0.018, 5 seeds)
SHOT_NOISE_PER_STEP = 0.1  # a noisy pixel's chance of a shot-noise event in one step, at most (two in a step
#                            would be one event: a Poisson draw has two or more in 0.5 % of steps at 0.1)
MIN_DEFAULT_STEPS = 1      # a slow scene needs no more: the kaleidoscope grid (0.9 px in 20 ms, 4 spp) has
#                            count error 0.49 at 1 step, 0.56 at 2, 0.68 at 3, 0.95 at 10 (under 3 steps the
#                            accuracy-limit note, which needs three frames, is not made)


def default_steps(st: Stepping, timed, integ, probe_spp: int | None = None, frozen=None) -> tuple:
    """(``st`` with ``steps`` chosen, the probe or None): the steps an unasked render takes. The probe, when
    the noise was measured: (noise map, the first instant's radiance at the render's seed), for the
    accuracy-limit note and the loop's first frame, which then cost no render of their own.

    The rule (docs/design.md, "Default steps"):

    * as many steps as keep the fastest known image motion (scan plus objects) under 0.5 px a step, or 2 px
      where the first instant's Monte-Carlo noise (two seeds at ``probe_spp``, default the render's spp;
      ``accuracy_limit.noise_map``) has a median of at least NOISE_LIMITED x C;
    * under a periodic scan, at least ``optics.galvo.VIEWS_PER_PERIOD`` steps a period (a light-field view
      interpolated between instants reads depth confidently wrong);
    * with a low-pass pixel (``cutoff_hz``) no step longer than two of its time constants, 1 / (pi f_c): the
      filter is stepped with its input held over a step (davis346, 300 Hz, on the demo: 95 steps of 1.05 ms
      against 12 gave inter-event intervals 0.042 against 0.063 KS at 16 spp, 0.016 against 0.083 at 64);
      waived where the noise is large (at 4 spp, 0.40 C, 12 steps were closer to the reference in count, rate
      and intervals: 0.55 / 0.34 / 0.161 against 0.60 / 0.43 / 0.164; ``chosen["waived_for_noise"]``);
    * with shot noise, steps short enough that a pixel fires one in a step with a probability of at most
      SHOT_NOISE_PER_STEP; at least MIN_DEFAULT_STEPS;
    * under a periodic scan, uniform and a whole number per period (period reuse, static pixels); without
      one, placed by the motion (``Stepping.schedule``, ``image_motion.motion_schedule``: each step at most
      the bound) where that saves PLACED_SAVING of the uniform steps, i.e. where the motion varies;
    * where the motion is not known before rendering, UNKNOWN_MOTION_STEPS.

    Why is recorded in ``Stepping.chosen`` (the metadata). ``frozen``: the loop's frozen step render, which
    the probe records."""
    from .accuracy_limit import noise_map
    speed, sampled = _fastest_motion(st, timed)
    if speed is None:
        chosen = {"by": "default for motion not known before rendering", "steps": UNKNOWN_MOTION_STEPS}
        return replace(st, steps=UNKNOWN_MOTION_STEPS, chosen=chosen), None
    floors = _floors(st, integ.config, timed)
    fine = _steps_for(speed, st.duration, FINE_PX_PER_STEP)
    sigma, first, noise, bound = None, None, None, FINE_PX_PER_STEP
    others = max(v for k, v in floors.items() if k != "low-pass pixel")
    if fine > others:                      # the bound decides: is the noise large against the threshold?
        # the probe's first frame is step 0's: at step 0's seed (an independent-seed render's differs)
        seed0 = st.seed if st.seed_mode == "fixed" else step_seed(st.seed, 0)
        sigma, first = noise_map(timed, probe_spp or st.spp, seed0, st.t_start, integ,
                                 frozen if probe_spp is None else None)    # the frozen render is at st.spp
        noise = float(np.median(sigma)) / min(integ.threshold_on, integ.threshold_off)
        bound = NOISY_PX_PER_STEP if noise >= NOISE_LIMITED else FINE_PX_PER_STEP
    noisy = noise is not None and noise >= NOISE_LIMITED
    waived = ["low-pass pixel"] if noisy and floors["low-pass pixel"] > others else []
    floor = max(1, max(v for k, v in floors.items() if k not in waived))
    for_motion = _steps_for(speed, st.duration, bound)
    steps = max(floor, for_motion)
    decided_by = "image motion" if for_motion >= floor else max(floors, key=lambda k: -1 if k in waived else floors[k])
    chosen = {"by": decided_by, "px_per_step": bound,
              "largest_image_speed_px_per_s": speed, "noise_over_threshold": noise,
              "steps_for_motion": for_motion, **{_steps_key(k): v for k, v in floors.items()},
              **({"waived_for_noise": waived} if waived else {})}
    probe = (sigma, first) if sigma is not None else None
    placed = _placed_by_motion(st, timed, bound, floor, for_motion, sampled) if for_motion > floor else None
    if placed is not None:
        times, d = sampled                 # each placed step's image path, for the coarse-step note
        path = np.interp(placed, times, np.concatenate([[0.0], np.cumsum(d)]))
        return replace(st, schedule=tuple(placed), px_per_step=bound, max_step=st.duration / floor,
                       min_step=min(MIN_PLACED_STEP, st.duration / floor),
                       chosen=dict(chosen, placed="by image motion", steps=len(placed) - 1,
                                   largest_px_per_step=float(np.diff(path).max()))), probe
    steps = whole_per_period(steps, st.duration, timed.scan_period)   # the coarse-step note says if MAX_STEPS binds
    return replace(st, steps=steps, chosen=dict(chosen, steps=steps)), probe


WHOLE_REL = 1e-6      # a ratio of times within this share of a whole number is that number (float round-off)


def is_whole(value: float) -> bool:
    """``value`` within ``WHOLE_REL`` of a whole number (relative; absolute below 1)."""
    return abs(value - round(value)) <= WHOLE_REL * max(1.0, abs(value))


def whole_number(value: float) -> int:
    """The whole number >= 1 that ``value`` is (``is_whole``), else 0: the scan periods a duration holds, the
    steps a period holds. The one test of the scan's phase grid (period reuse, static pixels, ``--auto``)."""
    return int(round(value)) if round(value) >= 1 and is_whole(value) else 0


def whole_per_period(steps: int, duration: float, period) -> int:
    """``steps`` rounded up to a whole number per scan period where ``duration`` is whole periods of a periodic
    scan (the scan's phase grid: period reuse, static pixels, the views of a light field at the same phases
    every period), at most ``MAX_STEPS``. The one rounding of the default rule and of ``--auto``."""
    periods = whole_number(duration / period) if period else 0
    if periods:
        steps = min(int(math.ceil(steps / periods)), max(1, MAX_STEPS // periods)) * periods
    return min(steps, MAX_STEPS)


def uniform_default_steps(timed, duration: float, spp: int, integ) -> tuple:
    """(steps, why) for ``eventfield render --auto``, which states one uniform count: the default rule's image
    motion under its fine bound (``FINE_PX_PER_STEP``, 0.5 px a step everywhere: auto favours accuracy and does
    not take the 2 px a noise-limited default allows) and the pixel model's floors. The same motion and floors
    as an unasked render (:func:`default_steps`), not a rule of its own, and its whole number a scan period
    (:func:`whole_per_period`; a moving scene under a scan got 302 steps over five periods)."""
    st = stepping(timed, duration, None, False, 0.5, None, None, spp, 0, "fixed", 0.0)
    speed, _ = _fastest_motion(st, timed)
    floors = _floors(st, integ.config, timed)
    if speed is None:
        steps = max(UNKNOWN_MOTION_STEPS, *floors.values())
        return min(steps, MAX_STEPS), {"by": "default for motion not known before rendering"
                                       if steps == UNKNOWN_MOTION_STEPS else max(floors, key=floors.get)}
    for_motion = _steps_for(speed, st.duration, FINE_PX_PER_STEP)
    steps = whole_per_period(max(for_motion, *floors.values()), st.duration, timed.scan_period)
    by = "image motion" if for_motion >= max(floors.values()) else max(floors, key=floors.get)
    return steps, {"by": by, "px_per_step": FINE_PX_PER_STEP, "largest_image_speed_px_per_s": speed}


def _steps_for(speed: float, duration: float, px_per_step: float) -> int:
    """Uniform steps that keep an image moving at ``speed`` px/s under ``px_per_step`` over ``duration`` (an exact
    multiple is not rounded up by float round-off)."""
    return int(math.ceil(speed * duration / px_per_step * (1 - 1e-9)))


def _steps_key(floor: str) -> str:
    """The metadata key of a floor's step count ("low-pass pixel" -> "steps_for_lowpass_pixel")."""
    return f"steps_for_{floor.replace(' ', '_').replace('-', '')}"


def _fastest_motion(st: Stepping, timed) -> tuple:
    """(the fastest image motion in px/s or None where unknown, ``image_motion.sampled_motion``'s samples or
    None): without a scan the samples the steps may be placed by give the speed too; under a scan
    ``largest_image_speed`` samples every period."""
    from .image_motion import largest_image_speed, sampled_motion
    if timed.scan_period != 0.0:
        return largest_image_speed(timed, st.t_start, st.duration), None
    sampled = sampled_motion(timed, st.t_start, st.duration)
    times, d = sampled
    return (None if d is None else float(d.max() / (times[1] - times[0]))), sampled


def _floors(st: Stepping, pixel, timed) -> dict:
    """The fewest steps the pixel model and the light field need, whatever the motion (``default_steps``)."""
    from ..optics.galvo import VIEWS_PER_PERIOD
    period = timed.scan_period
    return {"minimum": MIN_DEFAULT_STEPS,
            # a rendered instant for each of a scan period's light-field views (optics.galvo.VIEWS_PER_PERIOD)
            "light-field views": int(math.ceil(st.duration / period * VIEWS_PER_PERIOD - 1e-9)) if period else 0,
            "low-pass pixel": int(math.ceil(st.duration * math.pi * pixel.cutoff_hz - 1e-9)),
            # shot noise fires at most one event a pixel a step, with probability rate x dt (the Poisson mean
            # while that is at most 1): keep it under SHOT_NOISE_PER_STEP
            "shot noise": int(math.ceil(st.duration * pixel.shot_noise_hz * max(1.0, pixel.shot_noise_bright_factor)
                                        / SHOT_NOISE_PER_STEP - 1e-9))}


def _placed_by_motion(st: Stepping, timed, bound: float, floor: int, uniform: int, sampled):
    """The default's instants placed by the image motion (``image_motion.motion_schedule`` at ``bound`` px, no
    step longer than the floors allow), where that saves at least PLACED_SAVING of the ``uniform`` steps the
    fastest motion needs and no periodic scan needs a phase grid; else None (uniform steps)."""
    from .image_motion import motion_schedule
    if sampled is None:                    # a scan: uniform steps keep its phase grid (period reuse, static pixels)
        return None
    allowed = min(MAX_STEPS, uniform * (1 - PLACED_SAVING))
    if sampled[1].sum() / bound > allowed + 1:     # the motion's path needs too many: no schedule built
        return None
    try:
        placed = motion_schedule(timed, st.t_start, st.duration, bound, st.duration / floor,
                                 min(MIN_PLACED_STEP, st.duration / floor), sampled)
    except EventFieldError:                # more than MAX_STEPS: uniform steps, capped, with the coarse-step note
        return None
    if placed is None or len(placed) - 1 > allowed:
        return None
    return placed
