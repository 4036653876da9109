"""A pixel that has been running before the render starts (``render_events(warmup=)``, ``render --warmup``).

The pixel's state starts settled on the first frame: its photoreceptor low-pass at the first frame's level,
its reference there. A real camera has been running: under a scan or motion its low-pass is in a running
state, which the model's intensity-dependent cutoff (fast when bright, slow when dim) biases upwards, so a
render from a settled start fires an excess of ON events while it drifts there (galvo_static at 64x48 with
davis346 without its readout cap, 4 ms windows: 2966 ON / 389 OFF in the first, 447 / 345 in the fifth; after
warm-ups of 0.1, 0.2 and 0.4 s: 90 / 93, 74 / 72, 75 / 65, where it stays; without the low-pass 3852 / 3870 from
the first). A render of a few scan periods from a settled start is therefore mostly that transient. A warm-up
renders that long before the start and drops its events on the host before they are counted or written; the
recorded start and duration stay the caller's.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import EventFieldError
from ..validate import MAX_DURATION_S, number

SETTLE_TIME_CONSTANTS = 5          # a first-order filter within e^-5 (0.7 %) of where it is driven
# the brightness whose cutoff sets the settling: dark pixels are the slowest (the dark side of every edge a scan
# sweeps); the median's cutoff said 5 ms on galvo_static, whose events settled over 100-200 ms
SETTLE_PERCENTILE = 10


def warmup_seconds(warmup, on_device: bool) -> float:
    """``warmup`` (seconds) checked: >= 0, within a render's longest duration; not for events left on the
    device (the cut is made on the host)."""
    w = number(warmup, "warmup (s)", 0, MAX_DURATION_S)
    if w and on_device:
        raise EventFieldError("warmup: not with on_device (a warm-up's events are dropped on the host)")
    return w


def warmup_window(warmup: float, steps, duration: float, scan_period: float | None) -> tuple:
    """(the warm-up used, the steps of warm-up and render together) for a warm-up of at least ``warmup`` s:
    whole steps of ``duration / steps`` when uniform steps are given, whole scan periods under a scan (the
    default steps keep a phase grid), so that the kept start is a step's end and period reuse still holds (a
    warm-up of 1.3 ms at 125 us a step made 124 us steps, which divide no scan period: every step rendered)."""
    if not warmup:
        return 0.0, steps
    if steps is not None:
        n = int(math.ceil(int(steps) * warmup / duration - 1e-9))
        return n * duration / int(steps), int(steps) + n
    if scan_period:
        return math.ceil(warmup / scan_period - 1e-9) * scan_period, None
    return warmup, None


def kept_stepping(stepping_meta: dict, st, warmup: float) -> dict:
    """A render's ``stepping`` metadata for the span it keeps: uniform steps counted without the warm-up's
    (``warmup_steps`` beside them), so that duration / steps is still the step; otherwise the warm-up named.
    (The summary's ``steps`` counts every step rendered, the warm-up's too: the work done.)"""
    if not warmup:
        return stepping_meta
    if stepping_meta.get("mode") == "uniform":
        n = int(round(warmup * st.steps / st.duration))
        return dict(stepping_meta, steps=st.steps - n, warmup_steps=n)
    return dict(stepping_meta, includes_warmup_s=warmup)


def settle_time(config, intensity) -> float:
    """Seconds a low-pass pixel takes to settle (``SETTLE_TIME_CONSTANTS`` time constants of its first-order
    filter at the ``SETTLE_PERCENTILE``-th percentile of the linear ``intensity``); 0 without a low-pass."""
    if not config.cutoff_hz:
        return 0.0
    dark = float(np.percentile(np.asarray(intensity, np.float64), SETTLE_PERCENTILE))
    from ..plugins.pixel_model import lowpass_cutoff
    f = float(lowpass_cutoff(np, dark, config.cutoff_hz, config.bright_intensity, config.cutoff_min_fraction))
    return SETTLE_TIME_CONSTANTS / (2 * math.pi * f)


def note_settling(summary, config, timed, t_start: float, warmup: float) -> None:
    """A note when a low-pass pixel under a scan or motion started settled and ran shorter than a warm-up
    would have settled it (its brightness from one frame at the render's start, one sample a pixel)."""
    if not config.cutoff_hz or timed.is_static and timed.scan_period == 0.0:
        return
    from .frames import render_frames
    settle = settle_time(config, render_frames(timed, [t_start], spp=1, log=False)[0])
    if settle > warmup:
        summary.notes.append(
            f"the photoreceptor low-pass started settled on the first frame; under the scan or motion it drifts to "
            f"its running state over about {settle * 1e3:.3g} ms ({SETTLE_TIME_CONSTANTS} time constants of the "
            "darkest tenth of the pixels), and its events until then are not a running camera's (an excess of ON "
            "events): --warmup / warmup= that long renders before the start and drops them")
