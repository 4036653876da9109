"""The sink's GPU branch (simulate/sink.py), run on the CPU by making the sink take it. A chunk from the device
arrives in Dr.Jit's memory (pinned host buffers on a GPU) and is lent to the background writer: its copier
thread copies it into NumPy's own memory before writing, and the render's thread drops the last reference to the
borrowed buffers (on a GPU, buffers freed on the writer's thread left Dr.Jit's reuse, and the fan's host memory
grew with its events: events/writer.py). The file holds the same events as the in-memory render."""
import threading

import numpy as np
from conftest import FreedOn

import mitsuba_eventfield as ef
from mitsuba_eventfield.events import hdf5 as hdf5_mod
from mitsuba_eventfield.plugins import event_batch
from mitsuba_eventfield.plugins.event_fill import DeviceEvents
from mitsuba_eventfield.simulate import sink as sink_mod


def _owns_its_memory(a) -> bool:
    while isinstance(a.base, np.ndarray):
        a = a.base
    return a.base is None          # a view of Dr.Jit's memory ends in Dr.Jit's capsule, not in None


def test_the_writer_copies_borrowed_chunks_and_the_render_thread_frees_them(tmp_path, demo_small, monkeypatch):
    # at most 16 steps a chunk on either backend (CUDA's default of up to 200 would make the 200 steps one or
    # two chunks), so that several chunks are lent
    monkeypatch.setattr(event_batch, "MAX_FRAMES_PER_KERNEL", {"llvm": 16, "cuda": 16})
    memory = ef.render_events(demo_small, 0.02, steps=200, event_buffer_mb=0.0005)

    freed, lent, written = [], [0], []
    real_numpy, real_append = DeviceEvents.numpy, hdf5_mod.H5EventWriter.append

    def tracked_numpy(self, owned=False):
        cols = real_numpy(self, owned)
        if not owned and self.count:
            lent[0] += 1
            cols = tuple(np.asarray(FreedOn(np.array(c), freed)) for c in cols)
        return cols

    def append(self, x, y, t, p, complete_until_us=None):
        if len(t):
            written.append((threading.get_ident(), [_owns_its_memory(c) for c in (x, y, t, p)]))
        return real_append(self, x, y, t, p, complete_until_us)
    monkeypatch.setattr(DeviceEvents, "numpy", tracked_numpy)
    monkeypatch.setattr(hdf5_mod.H5EventWriter, "append", append)
    monkeypatch.setattr(sink_mod, "_cpu", lambda: False)
    out = str(tmp_path / "gpu_branch.h5")
    summary = ef.render_events(demo_small, 0.02, steps=200, output=out, event_buffer_mb=0.0005)

    render_thread = threading.get_ident()
    assert lent[0] > 3 and len(written) >= lent[0]
    assert all(thread != render_thread and all(owned) for thread, owned in written)   # copied on the writer's
    assert len(freed) == 4 * lent[0] and set(freed) == {render_thread}                 # freed on the render's
    assert ef.read_events(out).equals(memory) and len(memory) > 500
    assert summary.writer_copy_s > 0 and "copying chunks from the GPU" in summary.format()
    # the ON / OFF totals, counted on the device before the chunk crossed
    assert (summary.on, summary.off) == (np.count_nonzero(memory.p > 0), np.count_nonzero(memory.p < 0))

    # and the check itself tells Dr.Jit's memory from NumPy's: the CPU branch's in-memory path hands views
    import mitsuba as mi

    from mitsuba_eventfield.plugins.event_fill import polarity
    ev = DeviceEvents(mi.UInt32([1 | 2 << 16, 3 | 4 << 16]), mi.Int64([5, 6]), polarity(mi.Bool([True, False])), 2)
    assert not any(_owns_its_memory(c) for c in ev.numpy())
    assert all(_owns_its_memory(c) for c in ev.numpy(owned=True))
    assert [c.tolist() for c in ev.numpy(owned=True)] == [[1, 3], [2, 4], [5, 6], [1, -1]]


def test_a_batch_larger_than_the_buffer_crosses_in_pieces_of_the_buffer(tmp_path, demo_small, monkeypatch):
    """The event buffer bounds every chunk that crosses to the host, also when one kernel batch makes more
    events than it holds (CUDA batches up to 200 frames): the batch is handed over in pieces of the buffer's
    size, in order, and the file holds the in-memory render's events."""
    monkeypatch.setattr(event_batch, "MAX_FRAMES_PER_KERNEL", {"llvm": 64, "cuda": 64})
    memory = ef.render_events(demo_small, 0.02, steps=128)
    capacity = sink_mod.buffer_events(0.01)                      # 806 events
    sizes = []
    real_append = hdf5_mod.H5EventWriter.append

    def append(self, x, y, t, p, complete_until_us=None):
        sizes.append(len(t))
        return real_append(self, x, y, t, p, complete_until_us)
    monkeypatch.setattr(hdf5_mod.H5EventWriter, "append", append)
    monkeypatch.setattr(sink_mod, "_cpu", lambda: False)
    out = str(tmp_path / "pieces.h5")
    ef.render_events(demo_small, 0.02, steps=128, output=out, event_buffer_mb=0.01)
    assert len(memory) > 4 * capacity                        # the two batches each hold several buffers' worth
    assert max(sizes) <= capacity and sum(sizes) == len(memory) and sizes.count(capacity) >= 4
    assert ef.read_events(out).equals(memory)


def test_the_writer_queues_are_deeper_from_a_gpu(tmp_path, monkeypatch):
    """From a GPU a step batch's events cross at once in several buffer-sized pieces: each of the writer's
    queues (to its copier, to its writing thread) takes ``WRITER_DEPTH["gpu"]`` chunks there, 2 on the CPU
    (benchmarks/results/fan_writer_h200.md), for every streamed format and for checkpoint segments."""
    import os
    assert sink_mod.WRITER_DEPTH == {"cpu": 2, "gpu": 4}
    for cpu, depth in ((True, 2), (False, 4)):
        monkeypatch.setattr(sink_mod, "_cpu", lambda cpu=cpu: cpu)
        for name, segments in (("events.h5", None), ("events.npz", None), ("resumable.h5", [])):
            sink = sink_mod.Sink(str(tmp_path / name), None, 64, 48, {}, segments=segments)
            assert sink.writer.queue.maxsize == sink.writer.inbox.maxsize == depth, (name, cpu)
            sink.abort()
    assert not [f for f in os.listdir(tmp_path) if not f.endswith(".resume")]
