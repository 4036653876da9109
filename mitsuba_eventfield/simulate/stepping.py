"""A render's time stepping, validated: uniform steps, or adaptive steps set by what moves.

* uniform: ``steps`` equal steps;
* adaptive by image motion (``adaptive=True`` where the motion is known, or ``"motion"``): the instants are
  placed before rendering so the image moves at most ``px_per_step`` pixels between two of them, from the
  motion that is known analytically (the galvo scan, the moving objects' projected bounds;
  ``image_motion.motion_schedule``). Where nothing moves the steps grow to ``max_step``; a fast part of a
  Lissajous scan or a passing object gets short steps only while it lasts. This is what "where change
  happens" means for events: interpolating log brightness between instants is exact while an edge moves
  less than a pixel;
* adaptive by log change (``"log-change"``, and ``True`` where the motion is not known, e.g. the kaleidoscope):
  after each step the next is sized so the largest per-pixel log change stays under ``max_log_change`` x C.
  Global: one sharp moving edge anywhere sets every step (under a galvo scan that is ~100x the steps of the
  motion criterion, docs/design.md).
"""
from __future__ import annotations

from dataclasses import dataclass

from ..errors import EventFieldError
from ..validate import MAX_DURATION_S, MAX_STEPS, finite, number, positive

SEED_MODES = ("fixed", "independent")
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

    def t_next(self, k: int) -> float:
        """The end of step k (uniform or scheduled)."""
        if self.schedule is not None:
            return self.schedule[k + 1]
        return self.t_start + (k + 1) * self.duration / self.steps

    def as_meta(self) -> dict:
        if self.schedule is not None:
            return {"mode": "adaptive", "criterion": "image motion", "px_per_step": self.px_per_step,
                    "steps": len(self.schedule) - 1, "max_step_s": self.max_step}
        if self.adaptive:
            return {"mode": "adaptive", "criterion": "log change", "max_log_change": self.max_log_change,
                    "min_step_s": self.min_step, "max_step_s": self.max_step}
        return {"mode": "uniform", "steps": self.steps}


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


def stepping(timed, duration, steps, adaptive, max_log_change, min_step, max_step, spp, seed, seed_mode,
             t_start, px_per_step: float = 1.0) -> Stepping:
    """Every stepping and sampling argument checked, with the duration from the motion file if not given."""
    from .image_motion import motion_schedule
    duration = _duration(timed, duration)
    if seed_mode not in SEED_MODES:
        raise EventFieldError(f"seed_mode = {seed_mode!r}: allowed values are {', '.join(SEED_MODES)}")
    if not any(adaptive is m or adaptive == m for m in ADAPTIVE_MODES):
        raise EventFieldError(f"adaptive = {adaptive!r}: allowed values are False, True, 'motion', 'log-change'")
    t_start = finite(t_start, "t_start")
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
    else:
        steps = positive(steps if steps is not None else 100, "steps", integer=True)
        if steps > MAX_STEPS:
            raise EventFieldError(f"steps = {steps}: allowed range is [1, {MAX_STEPS}] (each step renders the film)")
    return Stepping(duration, t_start, positive(spp, "spp", integer=True),
                    number(seed, "seed", 0, integer=True, strict=True), seed_mode,
                    bool(adaptive) and schedule is None, steps, max_log_change, min_step, max_step,
                    tuple(schedule) if schedule is not None else None, px_per_step if schedule is not None else None)
