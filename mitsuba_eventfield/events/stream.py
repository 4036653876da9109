"""EventStream: the in-memory event container every module exchanges.

Conventions (docs/design.md, "Conventions"): ``x``, ``y`` uint16 pixel coordinates (x to the right, y down, origin at
the top-left pixel), ``t`` int64 microseconds, ``p`` int8 +1 (ON, brighter) / -1 (OFF), sorted by time;
``meta`` carries everything needed to interpret the stream without its scene (optics, pixel model, seed, ...).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError
from ..validate import number


MAX_SENSOR = 65536         # x, y are uint16


def _column(values, name: str, dtype) -> np.ndarray:
    """One of x, y, t, p as a 1-D array of ``dtype``: refused (ConfigError) when not numbers, not 1-D, not
    finite, or (x, y) negative, rather than wrapped around or failing inside NumPy."""
    a = values if isinstance(values, np.ndarray) and values.dtype == dtype else np.asarray(values)
    if a.dtype == dtype and a.ndim == 1:
        return np.ascontiguousarray(a)
    if a.ndim != 1 or not (np.issubdtype(a.dtype, np.number) or a.dtype == bool):
        raise ConfigError(f"event stream: {name} must be a 1-D array of numbers (got shape {a.shape}, {a.dtype})")
    if len(a) and np.issubdtype(a.dtype, np.inexact) and not np.all(np.isfinite(a)):
        raise ConfigError(f"event stream: {name} contains NaN or infinite values")
    if len(a) and name in "xy" and a.min() < 0:
        raise ConfigError(f"event stream: {name} = {a.min()}: coordinates must be >= 0")
    return np.ascontiguousarray(a, dtype=dtype)


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
        if "duration_us" in self.meta:
            return int(self.meta["duration_us"])
        return int(self.t[-1] - self.t[0]) if len(self) else 0

    @property
    def is_sorted(self) -> bool:
        return bool(np.all(np.diff(self.t) >= 0))

    def time_window(self, t0_us=None, t1_us=None) -> "EventStream":
        """Events with t0 <= t < t1 (microseconds; None = open end). Requires sorted timestamps."""
        i0 = 0 if t0_us is None else int(np.searchsorted(self.t, t0_us, side="left"))
        i1 = len(self) if t1_us is None else int(np.searchsorted(self.t, t1_us, side="left"))
        s = slice(i0, i1)
        return EventStream(self.x[s], self.y[s], self.t[s], self.p[s], self.width, self.height, dict(self.meta))

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
        n_on = int(np.count_nonzero(self.p > 0))
        dur = self.duration_us
        return {"events": len(self), "on": n_on, "off": len(self) - n_on, "width": self.width,
                "height": self.height, "duration_s": dur * 1e-6,
                "rate_ev_per_s": (len(self) / (dur * 1e-6)) if dur > 0 else 0.0}

    def equals(self, other: "EventStream") -> bool:
        """Same events and same sensor size (metadata ignored)."""
        return (self.width, self.height) == (other.width, other.height) and len(self) == len(other) and all(
            np.array_equal(a, b) for a, b in ((self.x, other.x), (self.y, other.y), (self.t, other.t), (self.p, other.p)))

    def scan_angles(self, actual: bool = True):
        """Galvo mirror angles (x, y), mechanical radians, of every event (see ``scan.event_angles``)."""
        from ..optics.scan import event_angles
        return event_angles(self, actual)

    @staticmethod
    def concatenate(streams) -> "EventStream":
        streams = list(streams)
        first = streams[0]
        return EventStream(*(np.concatenate([getattr(s, k) for s in streams]) for k in "xytp"),
                           first.width, first.height, dict(first.meta))
