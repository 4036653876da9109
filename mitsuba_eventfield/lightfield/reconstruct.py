"""Log-intensity reconstruction from events: frames L(x, t) at requested times.

Methods (``reconstruct(events, times, method=...)``; all vectorised over events, memory O(frames x pixels)):

* ``direct``: L(t) = L(t_start) + C * (ON - OFF) up to t. Exact for the ideal pixel up to one threshold; needs
  the start image (given, e.g. a frame, or zeros: then it is relative log intensity).
* ``highpass``: Scheerlinck et al.'s event-only high-pass filter: every event's contribution decays as
  exp(-2 pi f_c (t - t_e)). No start image is needed; static content fades (it carries no events).
* ``complementary``: the same filter pulled towards the latest frame: L -> L_frame at rate 2 pi f_c, events on
  top. Needs frames (log intensity) with their times.
* ``galvo``: for a static scene seen through a periodic scan, every view is the same image shifted by the known
  scan offset, so events (directional derivatives along the scan velocity) fix the start image up to a
  constant: a sparse least-squares solve (``galvo_solve``), then ``direct``. Dynamic scenes with depth, period
  by period from events alone: ``focus.galvo_periods.reconstruct_periods``.

A learned model (e.g. E2VID) plugs in with ``register_method(name, fn)``; ``fn(events, times, **kw)`` returns
(len(times), H, W) log-intensity frames.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import ConfigError
from ..events.stream import EventStream
from ..validate import MAX_THRESHOLD, number

_METHODS = {}


def register_method(name: str, fn) -> None:
    """Make ``fn(events, times, **kw) -> (T, H, W) log frames`` available as ``method=name`` (and in the CLI)."""
    _METHODS[name] = fn


def methods() -> list:
    return sorted(_METHODS)


def thresholds(events: EventStream, c_on=None, c_off=None):
    """Contrast thresholds from the arguments or the stream's pixel-model metadata."""
    pm = events.meta.get("pixel_model", {})
    c_on = c_on if c_on is not None else pm.get("threshold_on")
    c_off = c_off if c_off is not None else pm.get("threshold_off")
    if c_on is None or c_off is None:
        raise ConfigError("contrast thresholds unknown: the stream has no pixel_model metadata; pass c_on/c_off")
    # the render's own range: a 0 (a damaged file) divided every level by zero, a negative one inverted them
    return tuple(number(c, f"contrast threshold {name}", 0, MAX_THRESHOLD, lo_open=True)
                 for name, c in (("c_on", c_on), ("c_off", c_off)))


def _signed_weights(events, c_on, c_off, part=slice(None)):
    """Each event's log step (``part``: of these events only)."""
    return np.where(events.p[part] > 0, c_on, -c_off)


def _pixel_index(events, part=slice(None)):
    """Each event's flat pixel index (``part``: of these events only)."""
    return events.y[part].astype(np.int64) * events.width + events.x[part]


def _check_times(times):
    try:
        arr = np.asarray(times, dtype=np.float64)
    except (TypeError, ValueError):
        arr = None
    if arr is None or arr.ndim != 1 or len(arr) == 0 or np.any(np.diff(arr) < 0) or not np.all(np.isfinite(arr)):
        shown = np.array2string(np.asarray(arr if arr is not None else times), threshold=6)
        raise ConfigError(f"reconstruct: times = {shown}: expected a non-empty, non-decreasing 1-D array of finite "
                          "seconds")
    return arr


MAX_CUTOFF_HZ = 1e6       # the filters' cutoff (highpass, complementary), as --cutoff takes it


def _cutoff(cutoff_hz) -> float:
    return number(cutoff_hz, "reconstruct: cutoff_hz", 0, MAX_CUTOFF_HZ, lo_open=True, strict=True)


def direct(events: EventStream, times, log_start=None, t_start: float | None = None, c_on=None, c_off=None):
    """Integrate events from ``t_start`` (default: the stream's start) onto ``log_start`` (default zeros)."""
    times = _check_times(times)
    c_on, c_off = thresholds(events, c_on, c_off)
    h, w = events.height, events.width
    start = np.zeros((h, w)) if log_start is None else np.asarray(log_start, dtype=np.float64).reshape(h, w)
    t0 = events.start_s if t_start is None else t_start
    t_us = np.rint(np.concatenate([[t0], times]) * 1e6).astype(np.int64)
    # an event at exactly t belongs to the frame at t (the ideal pixel fired by then), so a start image given
    # for ``t_start`` holds the events at t_start (a galvo period's prior, chained integration). From the
    # stream's own start nothing of the stream precedes, and every event counts: a camera recording's stream
    # starts at its first event, which was dropped
    idx = np.r_[np.searchsorted(events.t, t_us[:1], side="left" if t_start is None else "right"),
                np.searchsorted(events.t, t_us[1:], side="right")]
    # only the events between the start and the last frame are weighed: one scan period of a 5 s, 53 M-event
    # recording held 16 bytes of every event of it (5.7 GiB at 1280x720 against 5.2 for 0.5 s)
    lo, hi = int(idx.min()), int(idx.max())
    pix, wts = _pixel_index(events, slice(lo, hi)), _signed_weights(events, c_on, c_off, slice(lo, hi))
    out = np.empty((len(times), h, w))
    acc = start.ravel().copy()
    for k in range(len(times)):
        s = slice(idx[k] - lo, idx[k + 1] - lo)
        acc += np.bincount(pix[s], weights=wts[s], minlength=h * w)
        out[k] = acc.reshape(h, w)
    return out


def _filtered(events, times, cutoff_hz, c_on, c_off, frames=None, frame_times=None):
    """Shared core of the high-pass (frames None) and complementary filters, exact between events."""
    times = _check_times(times)
    h, w = events.height, events.width
    alpha = 2 * math.pi * cutoff_hz
    pix, wts = _pixel_index(events), _signed_weights(events, c_on, c_off)
    t_ev = events.t * 1e-6
    t0 = events.start_s
    if frames is not None:
        frame_times = np.asarray(frame_times, dtype=np.float64)
        frames = np.asarray(frames, dtype=np.float64).reshape(len(frame_times), h * w)
        t0 = frame_times[0]           # the first frame already contains every earlier event
    # breakpoints: output times and frame times (the target changes there)
    marks = sorted(set(times.tolist()) | (set(frame_times.tolist()) if frames is not None else set()))
    state = frames[0].copy() if frames is not None else np.zeros(h * w)
    target = frames[0] if frames is not None else np.zeros(h * w)
    out, k_out, t_prev = np.empty((len(times), h, w)), 0, t0
    # from the stream's own start every event counts (as in ``direct``); the first frame holds those at its time
    i1 = np.searchsorted(t_ev, t0, side="left" if frames is None else "right")
    for t in marks:
        i0, i1 = i1, np.searchsorted(t_ev, t, side="right")
        decay = math.exp(-alpha * (t - t_prev))
        state = target + (state - target) * decay
        if i1 > i0:
            state += np.bincount(pix[i0:i1], weights=wts[i0:i1] * np.exp(-alpha * (t - t_ev[i0:i1])),
                                 minlength=h * w)
        if frames is not None:
            hit = np.nonzero(frame_times == t)[0]
            if len(hit):
                target = frames[hit[-1]]
        while k_out < len(times) and times[k_out] == t:
            out[k_out] = state.reshape(h, w)
            k_out += 1
        t_prev = t
    return out


def highpass(events: EventStream, times, cutoff_hz: float = 5.0, c_on=None, c_off=None):
    c_on, c_off = thresholds(events, c_on, c_off)
    return _filtered(events, times, _cutoff(cutoff_hz), c_on, c_off)


def complementary(events: EventStream, times, frames, frame_times, cutoff_hz: float = 5.0, c_on=None, c_off=None):
    """Events between frames, pulled towards the latest frame (log intensity) at ``cutoff_hz``."""
    c_on, c_off = thresholds(events, c_on, c_off)
    if frames is None or frame_times is None or len(frame_times) == 0:
        raise ConfigError("reconstruct: method 'complementary' needs frames and frame_times (log frames to pull "
                          "towards, and their times in seconds)")
    return _filtered(events, times, _cutoff(cutoff_hz), c_on, c_off, frames=frames, frame_times=frame_times)


def galvo_start_image(events: EventStream, t_start: float, samples: int = 16, depth=math.inf,
                      damp: float = 1e-4, c_on=None, c_off=None, iterations: int = 1000, tolerance: float = 1e-4):
    """Start image L(t_start) (up to a constant) of a static scene under a periodic galvo scan, at one depth
    (or an (H, W) depth map): ``galvo_solve.start_image`` with pairs one sample and a quarter period apart and
    the constant fixed by a small Tikhonov term (``damp``). Dynamic scenes with depth:
    ``focus.galvo_periods.reconstruct_periods``."""
    from .galvo_solve import start_image
    return start_image(events, t_start, samples, depth, prior_weight=damp ** 2, c_on=c_on, c_off=c_off,
                       iterations=iterations, tolerance=tolerance)[0]


def galvo(events: EventStream, times, t_start: float | None = None, samples: int = 16, depth: float = math.inf,
          c_on=None, c_off=None):
    """Static-scene galvo reconstruction: solve the start image, then integrate events onto it."""
    t0 = events.start_s if t_start is None else t_start
    start = galvo_start_image(events, t0, samples, depth, c_on=c_on, c_off=c_off)
    return direct(events, times, start, t0, c_on, c_off)


def method_function(method: str):
    """The function registered as ``method`` (its signature: the method's keywords)."""
    if method not in _METHODS:
        raise ConfigError(f"unknown reconstruction method {method!r}; available: {', '.join(methods())}")
    return _METHODS[method]


def reconstruct(events: EventStream, times, method: str = "direct", **kw):
    """Log-intensity frames of ``events`` at ``times`` (seconds) by a registered method."""
    from ..validate import check_allocation
    if method not in _METHODS:
        raise ConfigError(f"unknown reconstruction method {method!r}; available: {', '.join(methods())}")
    import inspect
    try:            # a keyword the method does not take (cutoff_hz for direct) was a raw TypeError inside it
        inspect.signature(_METHODS[method]).bind(events, times, **kw)
    except TypeError as e:
        params = [p for p in inspect.signature(_METHODS[method]).parameters][2:]
        raise ConfigError(f"reconstruct: method {method!r}: {e}; it takes {', '.join(params) or 'nothing more'}") \
            from None
    n = np.size(times)
    # a few float64 frames per requested time (the result plus the methods' working copies)
    check_allocation(3 * 8.0 * n * events.width * events.height,
                     f"{n} reconstructed frames of {events.width}x{events.height}")
    return _METHODS[method](events, times, **kw)


register_method("direct", direct)
register_method("highpass", highpass)
register_method("complementary", complementary)
register_method("galvo", galvo)
