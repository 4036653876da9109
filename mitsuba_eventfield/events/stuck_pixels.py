"""Stuck and hot pixels of a recording, found by physics rather than by a count threshold.

A pixel's events integrate to its log brightness: each ON adds the ON threshold, each OFF takes the OFF threshold
away. No event sensor spans more than about 140 dB (DAVIS346 120 dB, Prophesee Gen4 over 120 dB; ln 10^7 =
``MAX_LEVEL_SPAN``), and light cannot climb that far again every second. So a pixel whose events drive its level
one way by more than that, and by more than that every second of the recording, is not seeing light: it is
stuck (or a hot pixel firing one polarity). Such a pixel dominated every reconstruction that integrates events
(five pixels stuck ON at 20 kHz took a refocused image's 99th percentile 6x up, at 50 kHz to a black image with
five crosses, and a reconstruction's EXR held +inf); a hot pixel firing both ways does no such harm and is kept.

The level is summed with each pixel's thresholds as favourable as a real sensor's mismatch allows: the ON / OFF
ratio anywhere within ``MISMATCH`` times the nominal one either way. With the nominal thresholds alone, a good
pixel of a scanned edge (hundreds of ON and OFF events a second) drifted by its mismatch: a review found half
the pixels of a ``prophesee_gen4`` galvo render (sigma 0.03) over the range in a second. The net drift of a
pixel over its events is what is tested, not the span of its running level: a count a pixel and polarity
(two ``bincount`` passes), where the span needed every event sorted by pixel (20 s for 50 M events).
"""
from __future__ import annotations

import math
import warnings

import numpy as np

MAX_LEVEL_SPAN = math.log(1e7)      # ln of 140 dB: beyond any event sensor's dynamic range
MISMATCH = 3.0                      # a pixel's true ON / OFF threshold ratio, against the nominal: within 1/3..3


def stuck_pixels(ev, threshold_on: float, threshold_off: float, max_span: float = MAX_LEVEL_SPAN,
                 mismatch: float = MISMATCH) -> dict:
    """{(x, y): the pixel's net level change (log intensity, signed), summed with the thresholds least in its
    favour that ``mismatch`` allows} for every pixel of ``ev`` whose net change passes ``max_span`` times the
    recording's length in seconds (at least once)."""
    from ..errors import ConfigError
    from ..events.stream import EventStream
    from ..validate import number, positive
    if not isinstance(ev, EventStream):
        raise ConfigError(f"stuck_pixels: events = {type(ev).__name__}: expected an EventStream")
    threshold_on, threshold_off = positive(threshold_on, "threshold_on"), positive(threshold_off, "threshold_off")
    max_span, mismatch = positive(max_span, "max_span"), number(mismatch, "mismatch", 1.0)
    if not len(ev):
        return {}
    key = ev.y.astype(np.int64) * ev.width + ev.x
    on = np.bincount(key[ev.p > 0], minlength=ev.width * ev.height).astype(np.float64)
    off = np.bincount(key[ev.p < 0], minlength=ev.width * ev.height).astype(np.float64)
    # the ON threshold scaled by r and the OFF one by 1 / r, r within 1 / sqrt(mismatch)..sqrt(mismatch):
    # the smallest |net| over r (zero where a ratio in range balances the counts)
    r = np.sqrt(mismatch)
    up = threshold_on * on / r - threshold_off * off * r          # ON-driven, at the least ON-favourable r
    down = threshold_off * off / r - threshold_on * on * r       # OFF-driven
    net = np.where(up > 0, up, np.where(down > 0, -down, 0.0))
    limit = max_span * max(1.0, ev.duration_us * 1e-6)
    return {(int(k % ev.width), int(k // ev.width)): float(net[k]) for k in np.flatnonzero(np.abs(net) > limit)}


def without_stuck_pixels(ev, where: str):
    """``ev`` without the events of its stuck pixels (``stuck_pixels``, at its own contrast thresholds), with a
    warning that names them; ``ev`` itself where there are none."""
    from ..errors import ConfigError
    pm = (getattr(ev, "meta", None) or {}).get("pixel_model") or {}
    if pm.get("threshold_on") is None or pm.get("threshold_off") is None:
        raise ConfigError(f"{where}: no contrast thresholds in the stream's pixel_model metadata: stuck pixels are "
                          "found by the level their events integrate to (a recording: give them, e.g. --contrast)")
    found = stuck_pixels(ev, pm["threshold_on"], pm["threshold_off"])
    if not found:
        return ev
    worst = sorted(found, key=lambda p: abs(found[p]), reverse=True)
    seconds = max(1.0, ev.duration_us * 1e-6)
    named = ", ".join(f"({x}, {y}) {'ON' if found[x, y] > 0 else 'OFF'} {abs(found[x, y]) / seconds:.0f}"
                      for x, y in worst[:3])
    warnings.warn(f"{where}: {len(found)} stuck or hot pixel{'s' if len(found) > 1 else ''} left out, whose "
                  f"events drive its level one way by more than {MAX_LEVEL_SPAN / math.log(10) * 20:.0f} dB a "
                  f"second (beyond any event sensor's range; log change a second: {named}"
                  f"{', ...' if len(found) > 3 else ''})", stacklevel=2)
    drop = np.zeros(ev.width * ev.height, bool)
    drop[[y * ev.width + x for x, y in found]] = True
    keep = ~drop[ev.y.astype(np.int64) * ev.width + ev.x]
    # the recording's own span is kept (a recording of stuck pixels alone read as 0 ms long)
    return type(ev)(ev.x[keep], ev.y[keep], ev.t[keep], ev.p[keep], ev.width, ev.height,
                    dict(ev.meta, t_start_us=ev.start_us, duration_us=ev.duration_us,
                         stuck_pixels_left_out=[list(p) for p in worst]))


def nonempty(ev, where: str):
    """``ev``, refused in one line when its stuck pixels held every event (a flat image written as done): what
    the commands and ``lightfield.streams`` read after :func:`without_stuck_pixels`."""
    from ..errors import ConfigError
    if not len(ev):
        raise ConfigError(f"{where}: no events once its stuck pixels are left out: nothing to reconstruct")
    return ev
