"""EventStream: the in-memory event container every module exchanges.

Conventions (docs/design.md, "Conventions"): ``x``, ``y`` uint16 pixel coordinates (x to the right, y down, origin at
the top-left pixel), ``t`` int64 microseconds, ``p`` int8 +1 (ON, brighter) / -1 (OFF), sorted by time;
``meta`` carries everything needed to interpret the stream without its scene (optics, pixel model, seed, ...).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError
from ..validate import crop_window, cut_window, number


MAX_SENSOR = 65536         # x, y are uint16


def _column(values, name: str, dtype, where: str = "event stream") -> np.ndarray:
    """One of x, y, t, p as a 1-D array of ``dtype``: refused (ConfigError) when not numbers, not 1-D, not
    finite, not whole, outside ``dtype``'s range, or (x, y) negative, rather than wrapped around, truncated
    or failing inside NumPy (x = 65539 became 3, a uint8 polarity 255 became -1, t = 1.9 became 1)."""
    a = values if isinstance(values, np.ndarray) and values.dtype == dtype else np.asarray(values)
    if a.dtype == dtype and a.ndim == 1:
        return np.ascontiguousarray(a)
    if a.ndim != 1 or not (np.issubdtype(a.dtype, np.number) or a.dtype == bool):
        raise ConfigError(f"{where}: {name} must be a 1-D array of numbers (got shape {a.shape}, {a.dtype})")
    if not len(a) or a.dtype == bool:
        return np.ascontiguousarray(a, dtype=dtype)
    if np.issubdtype(a.dtype, np.complexfloating):
        raise ConfigError(f"{where}: {name} must be real numbers (got {a.dtype})")
    if np.issubdtype(a.dtype, np.floating):
        if not np.all(np.isfinite(a)):
            raise ConfigError(f"{where}: {name} contains NaN or infinite values")
        if not np.array_equal(a, np.trunc(a)):
            raise ConfigError(f"{where}: {name} must be whole numbers (round them first, e.g. np.rint)")
    lo, hi = a.min(), a.max()
    if name in "xy" and lo < 0:
        raise ConfigError(f"{where}: {name} = {lo}: coordinates must be >= 0")
    info = np.iinfo(dtype)
    # a float at int64's top (2^63 - 1 rounds up to 2^63) overflows the cast: there the bound is exclusive
    top_rounds_up = np.issubdtype(a.dtype, np.floating) and int(float(info.max)) != info.max
    if lo < info.min or hi > info.max or (top_rounds_up and hi >= float(info.max)):
        bad = lo if lo < info.min else hi
        raise ConfigError(f"{where}: {name} = {bad}: allowed range is [{info.min}, {info.max}]")
    return np.ascontiguousarray(a, dtype=dtype)


def first_out_of_order(t) -> int | None:
    """The index of the first timestamp earlier than the one before it, or None when ``t`` is in time order: the
    one order check of streams, writers and readers (a comparison of neighbours, one byte an event: np.diff's
    int64 array cost 3.5x as much)."""
    if len(t) < 2:
        return None
    back = np.less(t[1:], t[:-1])
    return int(np.argmax(back)) + 1 if back.any() else None


def chunk_columns(where: str, width: int, height: int, x, y, t, p) -> tuple:
    """A chunk handed to an event writer, checked as an :class:`EventStream` checks its columns (and their
    one length, and the sensor's bounds), before any of it is written: an append of x = 100 to a 4x4 file, or
    of x and y of different lengths (h5py broadcast the shorter), wrote a file that read back wrong or not at
    all. Polarity may be +1/-1 or 1/0 (> 0 is ON). Returns (x, y, t, p) as uint16, uint16, int64, int8."""
    x, y = _column(x, "x", np.uint16, where), _column(y, "y", np.uint16, where)
    t, p = _column(t, "t", np.int64, where), _column(p, "p", np.int8, where)
    if not (len(x) == len(y) == len(p) == len(t)):
        raise ConfigError(f"{where}: x, y, t, p must have one length (got {len(x)}, {len(y)}, {len(t)}, {len(p)})")
    if len(t) and (x.max() >= width or y.max() >= height):
        raise ConfigError(f"{where}: coordinates exceed the {width}x{height} sensor (x up to {x.max()}, "
                          f"y up to {y.max()})")
    return x, y, t, p


@dataclass
class EventStream:
    x: np.ndarray
    y: np.ndarray
    t: np.ndarray
    p: np.ndarray
    width: int
    height: int
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        if not isinstance(self.meta, dict):
            raise ConfigError(f"event stream: meta must be a dict (got {type(self.meta).__name__})")
        self.x, self.y = _column(self.x, "x", np.uint16), _column(self.y, "y", np.uint16)
        self.t, self.p = _column(self.t, "t", np.int64), _column(self.p, "p", np.int8)
        self.width = int(number(self.width, "event stream: width", 0, MAX_SENSOR, integer=True, strict=True))
        self.height = int(number(self.height, "event stream: height", 0, MAX_SENSOR, integer=True, strict=True))
        n = len(self.t)
        if not (len(self.x) == len(self.y) == len(self.p) == n):
            raise ConfigError(f"event stream: x, y, t, p must have one length (got {len(self.x)}, {len(self.y)}, {n}, {len(self.p)})")
        if n and (self.x.max() >= self.width or self.y.max() >= self.height):
            raise ConfigError(f"event stream: coordinates exceed the {self.width}x{self.height} sensor")
        if n and (self.p.min() < -1 or self.p.max() > 1 or not np.all(self.p)):
            raise ConfigError("event stream: polarity must be +1 or -1")

    @classmethod
    def empty(cls, width, height, meta=None):
        z = np.empty(0)
        return cls(z, z, z, z, width, height, dict(meta or {}))

    def __len__(self) -> int:
        return len(self.t)

    @property
    def duration_us(self) -> int:
        """Rendered duration if recorded in the metadata, else the span of the timestamps."""
        recorded = self.meta.get("duration_us")
        if isinstance(recorded, (int, float, np.integer, np.floating)) and np.isfinite(recorded) and recorded >= 0:
            return int(recorded)
        return int(self.t[-1] - self.t[0]) if len(self) else 0

    @property
    def start_us(self) -> int:
        """Start of the stream in microseconds: the metadata's ``t_start_us``, else its first event's time (the
        origin ``duration_us`` counts from; 0 without events). The one reading of it: callers took 0 where the
        metadata had none, so a camera recording starting at 5 s ended at its span, not at its last event."""
        recorded = self.meta.get("t_start_us")
        if isinstance(recorded, (int, float, np.integer, np.floating)) and np.isfinite(recorded):
            return int(recorded)
        return int(self.t[0]) if len(self) else 0

    @property
    def start_s(self) -> float:
        """``start_us`` in seconds."""
        return self.start_us * 1e-6

    @property
    def end_s(self) -> float:
        """End of the stream in seconds: ``start_us`` + ``duration_us``."""
        return self.start_s + self.duration_us * 1e-6

    @property
    def is_sorted(self) -> bool:
        return first_out_of_order(self.t) is None

    def time_window(self, t0_us=None, t1_us=None) -> "EventStream":
        """Events with t0 <= t < t1 (microseconds; None = open end; t0 = t1: none), with the window (within the
        stream's span) as their ``t_start_us`` / ``duration_us``. Requires sorted timestamps; a reversed window
        is refused (it returned no events, as if the stream had none there)."""
        t0_us, t1_us = (None if v is None else number(v, f"time_window: {name}", strict=True)
                        for name, v in (("t0_us", t0_us), ("t1_us", t1_us)))
        if t0_us is not None and t1_us is not None and t1_us < t0_us:
            raise ConfigError(f"time_window: t1_us = {t1_us:g} is before t0_us = {t0_us:g}: the window must have "
                              "t0 <= t1")
        i0 = 0 if t0_us is None else int(np.searchsorted(self.t, t0_us, side="left"))
        i1 = len(self) if t1_us is None else int(np.searchsorted(self.t, t1_us, side="left"))
        s = slice(i0, i1)
        meta = dict(self.meta)
        if t0_us is not None or t1_us is not None:     # the window's own span: a cut kept the whole stream's
            start, end = self.start_us, self.start_us + self.duration_us   # (its rate and periods read from it)
            lo = start if t0_us is None else min(max(start, int(np.ceil(t0_us))), end)
            hi = end if t1_us is None else max(min(end, int(np.ceil(t1_us))), lo)
            meta.update(t_start_us=lo, duration_us=hi - lo)
        return EventStream(self.x[s], self.y[s], self.t[s], self.p[s], self.width, self.height, meta)

    def crop(self, x0: int, y0: int, width: int, height: int, where: str = "crop") -> "EventStream":
        """The events inside the window [x0, x0 + width) x [y0, y0 + height) of the sensor, with coordinates
        from its corner, as a sensor of that size: a kaleidoscope's tube image on part of a larger sensor (its
        views are tiles of the image, not of the sensor). ``meta["crop"]`` records the window on the whole sensor
        (an earlier crop's composed in), which :meth:`crop_frame` applies to the sensor's frames. A stream that
        carries optics is refused: they describe its whole film. ``where``: what the refusals call the call."""
        if self.meta.get("optics"):
            raise ConfigError(f"{where}: the stream carries {self.meta['optics'].get('design')} optics, which "
                              f"describe its whole {self.width}x{self.height} film: crop a camera recording, before "
                              "its optics")
        x0, y0, w, h = crop_window((x0, y0, width, height), self.width, self.height, where)
        keep = (self.x >= x0) & (self.x < x0 + w) & (self.y >= y0) & (self.y < y0 + h)
        whole = [self.width, self.height]
        prior = self.meta.get("crop") or {"window": [0, 0, *whole], "sensor": whole}
        window = [prior["window"][0] + x0, prior["window"][1] + y0, w, h]
        meta = dict(self.meta, crop={"window": window, "sensor": list(prior["sensor"])})
        return EventStream(self.x[keep] - x0, self.y[keep] - y0, self.t[keep], self.p[keep], w, h, meta)

    def crop_frame(self, frame, where: str = "frame") -> np.ndarray:
        """A frame of the stream's sensor cut to the stream's :meth:`crop` window; a frame of the window's own
        size is taken as it is; any other size is refused in one line naming ``where``."""
        frame = np.asarray(frame)
        crop = self.meta.get("crop")
        if frame.shape[:2] == (self.height, self.width):
            return frame
        if crop and frame.shape[:2] == tuple(crop["sensor"][::-1]):
            return cut_window(frame, crop["window"])
        sensor = f" or the whole {crop['sensor'][0]}x{crop['sensor'][1]} sensor it was cropped from" if crop else ""
        raise ConfigError(f"{where}: a frame of {frame.shape[1]}x{frame.shape[0]}; the stream's sensor is "
                          f"{self.width}x{self.height}{sensor}")

    def counts(self, polarity: int | None = None) -> np.ndarray:
        """(height, width) number of events per pixel, of one polarity or of both."""
        sel = slice(None) if polarity is None else (self.p == polarity)
        flat = np.bincount(self.y[sel].astype(np.int64) * self.width + self.x[sel], minlength=self.width * self.height)
        return flat.reshape(self.height, self.width)

    def signed_counts(self) -> np.ndarray:
        """(height, width) net events per pixel (ON minus OFF): the log change divided by C, to within one."""
        flat = np.bincount(self.y.astype(np.int64) * self.width + self.x, weights=self.p,
                           minlength=self.width * self.height)
        return flat.reshape(self.height, self.width).astype(np.int64)

    def summary(self) -> dict:
        return self.summary_of(len(self), int(np.count_nonzero(self.p > 0)), self.width, self.height,
                               self.duration_us)

    @staticmethod
    def summary_of(events: int, on: int, width: int, height: int, duration_us: int) -> dict:
        """The summary of a stream of ``events`` (``on`` of them ON) over ``duration_us``: also of a file not
        held in memory (``hdf5_read.h5_summary``)."""
        return {"events": int(events), "on": int(on), "off": int(events) - int(on), "width": width, "height": height,
                "duration_s": duration_us * 1e-6, "rate_ev_per_s": (events / (duration_us * 1e-6)) if duration_us > 0
                else 0.0}

    def equals(self, other: "EventStream") -> bool:
        """Same events and same sensor size (metadata ignored); False for anything that is not a stream."""
        if not isinstance(other, EventStream):
            return False
        return (self.width, self.height) == (other.width, other.height) and len(self) == len(other) and all(
            np.array_equal(a, b) for a, b in ((self.x, other.x), (self.y, other.y), (self.t, other.t), (self.p, other.p)))

    def scan_angles(self, actual: bool = True):
        """Galvo mirror angles (x, y), mechanical radians, of every event (see ``scan.event_angles``)."""
        from ..optics.scan import event_angles
        return event_angles(self, actual)

    @staticmethod
    def concatenate(streams) -> "EventStream":
        streams = list(streams)
        if not streams:
            raise ConfigError("EventStream.concatenate: no streams given (it takes the first one's sensor size)")
        first = streams[0]
        return EventStream(*(np.concatenate([getattr(s, k) for s in streams]) for k in "xytp"),
                           first.width, first.height, dict(first.meta))
