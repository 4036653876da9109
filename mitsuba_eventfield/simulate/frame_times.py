"""The times of frames a user already has: a timestamps file or array (seconds) or a frame rate, checked (one
clock, strictly increasing, one time a frame, a span the event files can index), for ``frame_sources``."""
from __future__ import annotations

import os

import numpy as np

from ..errors import EventFieldError
from ..validate import MAX_CONVERT_S, number


def uniform_rate(fps: float | None, where: str) -> float:
    """The frame rate, checked: frames without times need one."""
    if fps is None:
        raise EventFieldError(f"{where}: give the frame rate (--fps / fps=) or the frames' times (--times FILE / "
                              "times=): the frames carry no times")
    return number(fps, f"{where}: fps", 0, lo_open=True, error=EventFieldError)


def check_times(times, count: int | None, where: str, name: str = "times", unit: str = "seconds") -> np.ndarray:
    """``times`` as float64, one a frame (``count`` frames; None: not known yet, at least 2), finite and
    strictly increasing; else one line naming the first value that is not (``name`` and ``unit`` as the
    caller's input calls them)."""
    try:
        t = np.asarray(times, dtype=np.float64)
    except (TypeError, ValueError):
        raise EventFieldError(f"{where}: {name}: expected numbers ({unit}), got {np.asarray(times).dtype}") from None
    if t.ndim != 1:
        raise EventFieldError(f"{where}: {name}: shape {t.shape}: expected one value a frame (a 1-D array)")
    if count is not None and len(t) != count:
        raise EventFieldError(times_mismatch(where, len(t), count, name))
    if len(t) < 2:
        raise EventFieldError(f"{where}: {name}: {len(t)} values: a conversion needs at least 2 frames")
    bad = np.flatnonzero(~np.isfinite(t))
    if len(bad):
        raise EventFieldError(f"{where}: {name}[{bad[0]}] = {float(t[bad[0]])!r}: {name} must be finite ({unit})")
    back = np.flatnonzero(np.diff(t) <= 0)
    if len(back):
        i = back[0] + 1
        raise EventFieldError(f"{where}: {name}[{i}] = {float(t[i])!r} is not after {name}[{i - 1}] = "
                              f"{float(t[i - 1])!r}: {name} must be strictly increasing ({unit})")
    return t


def times_mismatch(where: str, given: int, frames, name: str = "times") -> str:
    """The one message for times that do not match the frames one to one (``frames``: a count, or text such as
    "more than 29" where the end is not known yet)."""
    return f"{where}: {name}: {given} values for {frames} frames: give one time a frame"


def read_times(times):
    """Frame times in seconds from an array, or from a file: ``.npy``, or text with one time a line (blank lines
    and ``#`` comments skipped; a timestamps file as ESIM's and rpg_vid2e's tools write). None stays None."""
    if times is None or not isinstance(times, (str, os.PathLike)):
        return times
    import warnings
    path = os.fspath(times)
    try:
        if path.lower().endswith(".npy"):
            return np.load(path, allow_pickle=False)
        with warnings.catch_warnings():     # an empty file: NumPy warns, and check_times says it in one line
            warnings.simplefilter("ignore", UserWarning)
            # utf-8-sig: a byte-order mark from a Windows editor is not part of the first number
            return np.loadtxt(path, dtype=np.float64, comments="#", ndmin=1, encoding="utf-8-sig")
    except OSError as e:
        raise EventFieldError(f"{path}: cannot read the frame times ({e.strerror or type(e).__name__})") from None
    except ValueError as e:
        text = not path.lower().endswith(".npy")        # a .npy's own reason (an object array), not its bytes
        why = (text and _bad_line(path)) or " ".join(str(e).split())[:100]
        raise EventFieldError(f"{path}: frame times: expected one number (seconds) a line ({why})") from None


def _bad_line(path: str) -> str | None:
    """"line N: 'text'" of the first line of a times file that is not one number (N counted from 1 over every
    line: NumPy's own message counts rows from 0, and without the blank and comment lines)."""
    with open(path, encoding="utf-8-sig", errors="replace") as f:
        for n, line in enumerate(f, 1):
            text = line.split("#", 1)[0].strip()
            try:
                if text:
                    float(text)
            except ValueError:
                return f"line {n}: {text[:40]!r}"
    return None


def one_clock(times, fps, where: str) -> None:
    """Refuse times given together with a frame rate: one of them would be ignored."""
    if times is not None and fps is not None:
        raise EventFieldError(f"{where}: fps = {fps!r} and times given: give the frames' times or their rate, "
                              "not both")


def times_of(times, count: int | None, fps, where: str):
    """(time of frame i, span in seconds or None): from ``times`` (seconds, checked against ``count`` frames
    where known) or else the frame rate."""
    if times is None:
        rate = uniform_rate(fps, where)
        return (lambda i: i / rate), ((count - 1) / rate if count else None)
    t = check_times(times, count, where)

    def time_of(i):
        if i >= len(t):
            raise EventFieldError(times_mismatch(where, len(t), f"more than {len(t)}"))
        return float(t[i])
    return time_of, float(t[-1] - t[0])


# First frame intervals outside these (seconds) are most likely a unit slip, and said: milliseconds read as
# seconds put a 30 fps video's frames 33 s apart (its events then spread over hours, each brightness change
# interpolated over half a minute), seconds read as microseconds put them below the events' 1 us clock tick.
LIKELY_FRAME_INTERVAL_S = (1e-6, 1.0)


class FrameTimesWarning(UserWarning):
    """Frame times whose spacing suggests a unit slip (``LIKELY_FRAME_INTERVAL_S``)."""


def note_interval(where: str, interval_s: float) -> None:
    """Warn when the first frame interval lies outside ``LIKELY_FRAME_INTERVAL_S`` (the conversion goes on:
    a time-lapse may mean it)."""
    lo, hi = LIKELY_FRAME_INTERVAL_S
    if lo <= interval_s <= hi:
        return
    import warnings
    slip = ("milliseconds read as seconds?" if interval_s > hi else
            "seconds read as microseconds? an .npz's 'timestamps_us' are microseconds")
    warnings.warn(f"{where}: the first two frames are {interval_s:.6g} s apart ({slip}); frame times are seconds "
                  f"(an .npz's 'times', --times files, fps in Hz): events from frames further apart than "
                  f"{hi:g} s or closer than {lo:g} s are most likely a unit slip", FrameTimesWarning, stacklevel=3)


def check_span(where: str, span_s: float | None) -> None:
    """Frames spanning more than ``MAX_CONVERT_S`` are refused (before any work where the span is known, else
    when a frame passes it): an HDF5 file indexes every millisecond (8 bytes each), and ``--fps 1e-9`` asked
    for 36 TiB of index."""
    if span_s is not None and span_s > MAX_CONVERT_S:
        raise EventFieldError(f"{where}: the frames span {span_s:.6g} s: allowed up to {MAX_CONVERT_S:g} s in one "
                              "conversion (check the times' unit or the frame rate; split longer inputs)")
