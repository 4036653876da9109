"""Events that stay on the device: the result of ``events_from_frames(..., on_device=True)``.

A pipeline that trains on a GPU wants the events where the GPU is. Copying them to the host costs 13 bytes an
event each way, and on an H200 that trip, not the event kernels, bounds the converter at 140-160 M events/s
(benchmarks/results/gpu_h200.md). Here the time-sorted chunks are joined on the device, once, at the end, and
each column is handed over through DLPack without a copy (PyTorch's ``torch.from_dlpack``, JAX, CuPy; NumPy on
the CPU backend). ``numpy()`` gives the host :class:`EventStream`, equal to the one ``on_device=False`` returns.
Device memory holds every event (13 bytes each): the caller sizes the input to the GPU.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..events.stream import EventStream


@dataclass
class DeviceEventStream:
    """Time-sorted events as arrays of the active Dr.Jit backend: ``xy`` (UInt32, x | y << 16), ``t`` (Int64,
    microseconds), ``p`` (Int8, +1 / -1)."""
    xy: object
    t: object
    p: object
    width: int
    height: int
    meta: dict = field(default_factory=dict)

    @classmethod
    def join(cls, chunks: list, width: int, height: int, meta: dict) -> "DeviceEventStream":
        """One stream from the sink's device chunks (``plugins.event_fill.DeviceEvents``, in time order)."""
        from ..plugins.event_fill import DeviceEvents
        joined = DeviceEvents.concat(chunks)
        return cls(joined.xy, joined.t, joined.p, int(width), int(height), dict(meta))

    def __len__(self) -> int:
        import drjit as dr
        return dr.width(self.t)

    def columns(self) -> dict:
        """{"x", "y"}: Int32 (as most tensor libraries index), "t": Int64 microseconds, "p": Int8, each an array of
        the active backend (x and y unpacked by one device kernel; t and p the stream's own arrays)."""
        import drjit as dr
        u32 = type(self.xy)
        i32 = dr.int32_array_t(u32)
        return {"x": i32(self.xy & u32(0xFFFF)), "y": i32(self.xy >> 16), "t": self.t, "p": self.p}

    def torch(self) -> dict:
        """The columns as PyTorch tensors on the stream's device, shared with Dr.Jit (DLPack, no copy)."""
        return {name: col.torch() for name, col in self.columns().items()}

    def numpy(self) -> EventStream:
        """The events on the host: the :class:`EventStream` the conversion returns without ``on_device``."""
        if len(self) == 0:
            return EventStream.empty(self.width, self.height, self.meta)
        from ..plugins.event_fill import DeviceEvents
        x, y, t, p = DeviceEvents(self.xy, self.t, self.p, len(self)).numpy(owned=True)
        return EventStream(x, y, t, p, self.width, self.height, dict(self.meta))

    def equals(self, other) -> bool:
        """Same events and sensor as ``other`` (a DeviceEventStream or an EventStream)."""
        host = other.numpy() if isinstance(other, DeviceEventStream) else other
        return self.numpy().equals(host)

    def on_count(self) -> int:
        """ON events (p = +1), counted on the device."""
        import drjit as dr
        return int(dr.count(self.p > 0)[0]) if len(self) else 0

    def __repr__(self) -> str:
        return f"DeviceEventStream({len(self)} events, {self.width}x{self.height}, {type(self.t).__module__})"


def check_on_device(on_device: bool, output) -> None:
    """A device result and an output file exclude each other: one line before any work (and ``on_device`` is a
    bool: "yes" was taken as true)."""
    from ..errors import EventFieldError
    if not isinstance(on_device, (bool, np.bool_)):
        raise EventFieldError(f"on_device = {on_device!r}: must be True or False")
    if on_device and output:
        from ..errors import EventFieldError
        raise EventFieldError(f"{output}: on_device keeps the events on the device; it takes no output file")


def numpy_columns(x, y, t, p):
    """Host columns as they arrive from a host-side step (NumPy), packed for the device: (xy, t, p)."""
    packed = np.asarray(x, np.uint32) | (np.asarray(y, np.uint32) << 16)
    return packed, np.asarray(t, np.int64), np.asarray(p, np.int8)
