"""Stuck and hot pixels of a recording, found by physics rather than by a count threshold.

A pixel's events integrate to its log brightness: each ON adds the ON threshold, each OFF takes the OFF threshold
away. No event sensor spans more than about 140 dB (DAVIS346 120 dB, Prophesee Gen4 over 120 dB), so a pixel
whose running level spans more than ``MAX_LEVEL_SPAN`` (ln 10^7, 140 dB) within a second (``WINDOW_S``) is not
seeing light: it is stuck or hot.
Such a pixel dominated every reconstruction that integrates events (a recording with five pixels stuck ON at
20 kHz refocused to an image whose 99th percentile was 6x the clean one's, at 50 kHz to a black image with five
crosses, and a reconstruction's EXR held +inf), while a hot pixel that fires both ways (its level stays in range)
does no such harm and is kept.

Cost: one pass over the events (a weighted count a pixel) picks the few pixels that could span that much; only
their events are summed in order.
"""
from __future__ import annotations

import math
import warnings

import numpy as np

MAX_LEVEL_SPAN = math.log(1e7)      # ln of 140 dB: beyond any event sensor's dynamic range
WINDOW_S = 1.0                      # the span is measured within windows this long: a stuck pixel crosses the
#                                     range in a fraction of one (5 kHz at C = 0.1: 0.03 s), while the drift
#                                     of a good pixel's leak or noise (0.1-1 Hz) crosses it only over minutes,
#                                     and a whole long recording would have been left out


def stuck_pixels(ev, threshold_on: float, threshold_off: float, max_span: float = MAX_LEVEL_SPAN,
                 window_s: float = WINDOW_S) -> dict:
    """{(x, y): the largest span of the pixel's running level (log intensity) within one ``window_s`` window}
    for every pixel of ``ev`` whose level spans more than ``max_span`` within a window."""
    from ..errors import ConfigError
    from ..events.stream import EventStream
    from ..validate import positive
    if not isinstance(ev, EventStream):
        raise ConfigError(f"stuck_pixels: events = {type(ev).__name__}: expected an EventStream")
    threshold_on, threshold_off = positive(threshold_on, "threshold_on"), positive(threshold_off, "threshold_off")
    max_span, window_s = positive(max_span, "max_span"), positive(window_s, "window_s")
    if not len(ev):
        return {}
    key = ev.y.astype(np.int64) * ev.width + ev.x
    step = np.where(ev.p > 0, threshold_on, -threshold_off)
    reach = np.bincount(key, weights=np.abs(step), minlength=ev.width * ev.height)
    candidate = reach > max_span                          # a span needs at least that much in events
    if not candidate.any():
        return {}
    sel = np.flatnonzero(candidate[key])
    order = np.argsort(key[sel], kind="stable")            # each pixel's events, still in time order
    keys, level = key[sel][order], np.cumsum(step[sel][order])
    window = (ev.t[sel][order] - int(ev.t[0])) // int(window_s * 1e6)
    starts = np.flatnonzero(np.r_[True, (keys[1:] != keys[:-1]) | (window[1:] != window[:-1])])
    level -= np.repeat(np.r_[0.0, level[starts[1:] - 1]], np.diff(np.r_[starts, len(keys)]))   # from 0 a window
    span = np.maximum(np.maximum.reduceat(level, starts), 0.0) - np.minimum(np.minimum.reduceat(level, starts), 0.0)
    found = {}
    for k, v in zip(keys[starts], span):
        if v > max_span and v > found.get(k, 0.0):
            found[k] = float(v)
    return {(int(k % ev.width), int(k // ev.width)): v for k, v in found.items()}


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
    worst = sorted(found, key=found.get, reverse=True)
    named = ", ".join(f"({x}, {y}) {found[x, y] / math.log(10) * 20:.0f} dB" for x, y in worst[:3])
    warnings.warn(f"{where}: {len(found)} stuck or hot pixel{'s' if len(found) > 1 else ''} left out, whose "
                  f"events integrate to a level spanning more than {MAX_LEVEL_SPAN / math.log(10) * 20:.0f} dB "
                  f"(beyond any event sensor's range): {named}{', ...' if len(found) > 3 else ''}", stacklevel=2)
    drop = np.zeros(ev.width * ev.height, bool)
    drop[[y * ev.width + x for x, y in found]] = True
    keep = ~drop[ev.y.astype(np.int64) * ev.width + ev.x]
    return type(ev)(ev.x[keep], ev.y[keep], ev.t[keep], ev.p[keep], ev.width, ev.height,
                    dict(ev.meta, stuck_pixels_left_out=[list(p) for p in worst]))
