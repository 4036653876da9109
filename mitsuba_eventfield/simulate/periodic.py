"""Periodic views in the time-stepping loop: a static scene under a periodic scan (or a fixed camera) repeats
its frames every period, and an ideal pixel whose state comes back repeats its events. These helpers decide
when that is exact. (Steps too coarse for a scan: ``image_motion.note_image_motion``.)"""
from __future__ import annotations

import numpy as np

from ..scene.timed import TimedScene
from ..validate import available_memory
from .stepping import is_whole, whole_number


def period_blocks(steps_events):
    """The events of one period's steps, concatenated once; ``block(n)``: those of its first n steps."""
    ends = np.cumsum([len(e[2]) for e in steps_events])
    whole = [np.concatenate([e[i] for e in steps_events]) for i in range(4)]

    def block(n):
        m = int(ends[n - 1]) if n else 0
        return tuple(a[:m] for a in whole)
    return block


def phase_grid(timed: TimedScene, duration: float, steps: int, t_start: float):
    """(steps per period, period in us, start in us) when a periodic view meets the uniform step grid in
    whole microseconds; else None."""
    period = timed.scan_period
    if not period:
        return None
    k_float, period_us, base_us = period / (duration / steps), period * 1e6, t_start * 1e6
    if not (whole_number(k_float) and is_whole(period_us) and is_whole(base_us)):
        return None
    return int(round(k_float)), int(round(period_us)), int(round(base_us))


def reuse_plan(timed: TimedScene, duration: float, steps: int, width: int, height: int, notes: list):
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
        k = whole_number(period / (duration / steps))
        if not k:
            notes.append(f"static scene, but the step ({duration / steps * 1e6:.4g} us) does not divide the scan "
                         f"period ({period * 1e6:.4g} us): every step rendered")
            return None
    if k >= steps:
        return None
    if k * width * height * 4 > 0.25 * available_memory():
        notes.append(f"static scene, but caching {k} frames would need too much memory: every step rendered")
        return None
    what = "one frame" if period == 0.0 else f"one scan period ({k} frames, {period * 1e3:.4g} ms)"
    notes.append(f"static scene: rendered {what} and reused it for the other {steps + 1 - k} of the render's "
                 f"{steps + 1} frames ({steps} steps; events identical to rendering every frame)")
    return k
