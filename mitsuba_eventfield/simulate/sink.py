"""Where a render's events go: memory, or an event file. Steps made on the device are kept there until a chunk
of about ``buffer_events`` has gathered (one device-to-host copy per chunk, not per step; from a GPU, a kernel
batch larger than that crosses in pieces of that size); chunks are written
(HDF5, npz, text, AEDAT4: ``events.streaming``) by a background thread (``events.writer``) while the next steps
render. Camera recordings (RAW, DAT) are written at the end. In memory, each chunk is copied into one
``events.buffer.EventBuffer`` as it leaves the device buffer, so the engine's arrays are freed and reused (no
join at the end, and a peak of one copy of the events). Left on the device (``on_device``), the steps stay as
they are until the end, then are joined once and their ON events counted with one read."""
from __future__ import annotations

import numpy as np

from ..errors import raise_if_stopped
from ..events.buffer import EventBuffer
from ..events.io import format_of, write_events
from ..events.streaming import STREAMED, open_writer
from ..events.stream import EventStream
from ..events.writer import BackgroundWriter
from ..plugins.event_fill import DeviceEvents, device_copy, int8_array
from ..validate import positive
from .checkpoint import SegmentWriter
from .device_stream import DeviceEventStream, numpy_columns

DEFAULT_EVENT_BUFFER_MB = 64.0
DEVICE_BYTES_PER_EVENT = 13          # xy (UInt32), t (Int64), p (Int8) while an event waits on the device
# Chunks that may wait for each of the background writer's threads (``BackgroundWriter``'s depth), on the CPU
# and from a GPU. From a GPU a step batch's events cross at once, in several pieces of the buffer's size (the
# fan at 1280x720: about 16 M events a batch, three pieces): on an H200 the render waited 0.43 s of its 2.5 s
# for a queue of 2 although the writer was busy only 1.8 s, and 0.09 s with 4 (best of two alternating renders
# each: benchmarks/results/fan_writer_h200.md; the second run there tried no depth but 4). On the CPU the
# writer keeps up with 2. Host memory is what depth costs: up to that many buffers' worth of events more, whatever
# the duration (the H200's fan stayed flat over 10x the duration: 1.050x).
WRITER_DEPTH = {"cpu": 2, "gpu": 4}


def _cpu() -> bool:
    import mitsuba as mi
    return not mi.variant().startswith("cuda")


def _pieces(chunk: DeviceEvents, size: int):
    """``chunk`` as pieces of at most ``size`` events, each with whether it is the last: the buffer is the
    user's bound on a chunk that crosses to the host, and one kernel batch can make more events than that (on
    CUDA up to 60 M pixel-steps a batch: ``event_batch.LANE_STEPS``). Each piece is gathered on the device
    when it is asked for (its start an opaque scalar: one kernel for every piece), so that only one extra
    piece exists at a time."""
    if chunk.count <= size:
        yield chunk, True
        return
    import drjit as dr
    import mitsuba as mi

    from ..plugins.event_fill import _opaque
    for start in range(0, chunk.count, size):
        n = min(size, chunk.count - start)
        index = dr.arange(mi.UInt32, n) + _opaque(start, mi.UInt32)
        cols = [dr.gather(type(c), c, index) for c in (chunk.xy, chunk.t, chunk.p)]
        dr.eval(*cols)
        yield DeviceEvents(*cols, count=n), start + n == chunk.count


def buffer_events(buffer_mb: float) -> int:
    """Events a device buffer of ``buffer_mb`` MiB holds (at least one step's worth is always kept)."""
    return max(1, int(buffer_mb * (1 << 20) / DEVICE_BYTES_PER_EVENT))


class Sink:
    """Where a step's events go, in time order: an in-memory list, or an event file written in the background
    (segments under ``<output>.resume`` for a checkpointed render). ``count`` is called with each chunk's polarities as it leaves the buffer (the render's ON/OFF totals)."""

    def __init__(self, output, fmt, width, height, meta, count=None, buffer_mb: float = DEFAULT_EVENT_BUFFER_MB,
                 segments: list | None = None, on_device: bool = False, emit_from_us: int | None = None):
        self.capacity = buffer_events(positive(buffer_mb, "event_buffer_mb"))     # refused before any file opens
        self.output, self.width, self.height, self.meta = output, width, height, meta
        self.fmt = format_of(output, fmt) if output else None
        self.writer = None
        # on_device (no output): chunks stay on the device, joined there at the end (simulate/device_stream.py)
        self.on_device = bool(on_device) and not output
        self.device_chunks: list = []
        depth = WRITER_DEPTH["cpu" if _cpu() else "gpu"]
        if segments is not None:         # a checkpointed render: segments under <output>.resume, merged at the end
            self.writer = BackgroundWriter(SegmentWriter(output, width, height, meta, segments), depth=depth)
        elif self.fmt in STREAMED:       # HDF5, npz, text, AEDAT4: written while rendering
            self.writer = BackgroundWriter(open_writer(output, self.fmt, width, height, meta), depth=depth)
        self.memory = EventBuffer() if self.writer is None and not self.on_device else None   # in-memory result
        self.count = count or (lambda p: None)
        self.device_parts, self.device_events, self.until = [], 0, None
        # a warm-up's events (before the render's own start) are dropped on the host, before they are counted
        self.emit_from_us = None if emit_from_us is None else int(emit_from_us)

    def report(self, summary) -> None:
        """The background writer's timings into a ``RenderSummary`` (after ``drain``; zero without a writer)."""
        for name in ("wait_s", "busy_s", "tail_s", "copy_s"):
            setattr(summary, f"writer_{name}", getattr(self.writer, name) if self.writer is not None else 0.0)

    def add_device(self, events: DeviceEvents, complete_until_us: int) -> None:
        """Keep a step's device-side events; move the buffer to the host when it is full (left on the device,
        they stay as they are until the end)."""
        if events.count:
            self.device_parts.append(events)
            self.device_events += events.count
        self.until = complete_until_us
        if self.device_events >= self.capacity and not self.on_device:
            self.flush_device()

    def flush_device(self) -> None:
        if not self.device_parts and self.until is None:
            return
        parts, until = self.device_parts, self.until
        self.device_parts, self.device_events, self.until = [], 0, None
        if self.on_device:
            # at the end (or a checkpoint): every step joined once and its ON events counted with one read. A
            # join at each full buffer and again at the end copied each event twice; a count a part read one
            # number back a chunk, each a sync with the device
            self._keep_on_device(DeviceEvents.concat(parts))
            return
        if _cpu() and self.writer is None:      # in memory on the CPU: each part's views copied into the buffer
            for part in parts:
                self._add_host(*part.numpy(), until)
            return
        if _cpu():      # to a writer on the CPU (the device is the host): the parts' views joined once there
            self._add_host(*DeviceEvents.host_columns(parts), until)
            return
        # from a GPU the parts are joined on the device first, so that one copy crosses into Dr.Jit's pinned
        # host memory. A writer borrows that chunk: its copier thread copies it out and this thread frees it,
        # where Dr.Jit can reuse it (events.writer: freed on the writer's thread, host memory grew with the events)
        chunk = DeviceEvents.concat(parts)
        counted = self.emit_from_us is None     # (a warm-up's chunks are counted on the host, once cut)
        if counted:
            self.count(chunk.p)                 # on the device: one number crosses, not a byte an event
        for piece, last in _pieces(chunk, self.capacity):
            self._add_host(*piece.numpy(), until if last else None, borrowed=True, counted=counted)

    def add_step(self, events, complete_until_us: int) -> None:
        """A step's events from ``EventIntegrator.commit_events``: device-side ones are buffered there."""
        if isinstance(events, DeviceEvents):
            self.add_device(events, complete_until_us)
        else:
            self.add(*events.numpy(), complete_until_us)

    def add(self, x, y, t, p, complete_until_us):
        """A chunk already on the host (after anything still buffered on the device: time order is kept). Left on
        the device, it goes up (a sequential pixel model's steps, a galvo's reused periods) and joins the device's
        steps in order."""
        if self.on_device:
            import mitsuba as mi
            xy, t, p = numpy_columns(x, y, t, p)
            if len(t):
                self.add_device(DeviceEvents(device_copy(xy, mi.UInt32), device_copy(t, mi.Int64),
                                             device_copy(p, int8_array()), len(t)), complete_until_us)
            return
        self.flush_device()
        self._add_host(x, y, t, p, complete_until_us)

    def _keep_on_device(self, chunk: DeviceEvents) -> None:
        if chunk.count:
            self.count(chunk.p)                  # the ON / OFF totals, counted on the device
            self.device_chunks.append(chunk)

    def _after_warmup(self, x, y, t, p, until, borrowed: bool):
        """The events at or after ``emit_from_us`` (a chunk is in time order), copied where cut (a borrowed
        chunk's memory goes back to Dr.Jit once the writer has copied it), and a promise of completeness
        before the kept start dropped (an HDF5 file's millisecond index began at the warm-up); the cut ends
        once a chunk starts there."""
        if self.emit_from_us is None:
            return x, y, t, p, until, borrowed
        if until is not None and until < self.emit_from_us:
            until = None
        if not len(t):
            return x, y, t, p, until, borrowed
        if t[0] >= self.emit_from_us:
            self.emit_from_us = None
            return x, y, t, p, until, borrowed
        k = int(np.searchsorted(t, self.emit_from_us))
        return (*(np.array(c[k:]) for c in (x, y, t, p)), until, False)

    def _add_host(self, x, y, t, p, complete_until_us, borrowed: bool = False, counted: bool = False):
        x, y, t, p, complete_until_us, borrowed = self._after_warmup(x, y, t, p, complete_until_us, borrowed)
        if not counted:
            self.count(p)
        if self.writer is not None:
            (self.writer.append_borrowed if borrowed else self.writer.append)(x, y, t, p, complete_until_us)
        elif len(t):
            self.memory.append(x, y, t, p)

    def wait_for_writer(self) -> None:
        """Everything buffered moved out and written, the writer kept for more (a checkpoint)."""
        self.flush_device()
        if self.writer is not None:
            self.writer.wait()

    def drain(self) -> None:
        """Everything buffered moved out and written (the writer's timings are final after this)."""
        self.flush_device()
        if self.writer is not None:
            self.writer.drain()

    def stream(self, meta):
        if not len(self.memory):
            return EventStream.empty(self.width, self.height, meta)
        return EventStream(*self.memory.take(), self.width, self.height, meta)

    def finish(self, end_us, meta):
        self.drain()
        raise_if_stopped()        # nothing is published after a stop signal, even one whose interrupt was lost
        if self.on_device:
            return DeviceEventStream.join(self.device_chunks, self.width, self.height, {**self.meta, **meta})
        if self.writer is not None:
            self.writer.close(end_us=end_us, meta=meta)
            return None
        ev = self.stream({**self.meta, **meta})
        if self.output:
            write_events(self.output, ev, self.fmt)
        return ev

    def abort(self):
        if self.writer is not None:
            self.writer.abort()

