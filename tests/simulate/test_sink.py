"""The sink's GPU branch (simulate/sink.py), run on the CPU by making the sink take it: a chunk handed to the
background writer is in NumPy's own memory, so the writer's thread never frees a Dr.Jit buffer (on a GPU that
left the pinned buffers out of Dr.Jit's reuse, and the fan's host memory grew with its events: DeviceEvents.numpy),
and the file holds the same events as the in-memory render."""
import numpy as np

import mitsuba_eventfield as ef
from mitsuba_eventfield.events import writer as writer_mod
from mitsuba_eventfield.simulate import sink as sink_mod


def _owns_its_memory(a) -> bool:
    while isinstance(a.base, np.ndarray):
        a = a.base
    return a.base is None          # a view of Dr.Jit's memory ends in Dr.Jit's capsule, not in None


def test_chunks_for_the_writer_are_numpys_own_memory_on_the_gpu_branch(tmp_path, demo_small, monkeypatch):
    seen = []
    real_append = writer_mod.BackgroundWriter.append

    def append(self, x, y, t, p, complete_until_us=None):
        seen.append([_owns_its_memory(c) for c in (x, y, t, p)] if len(t) else None)
        return real_append(self, x, y, t, p, complete_until_us)
    monkeypatch.setattr(writer_mod.BackgroundWriter, "append", append)
    memory = ef.render_events(demo_small, 0.02, steps=200, event_buffer_mb=0.0005)

    out = str(tmp_path / "gpu_branch.h5")
    monkeypatch.setattr(sink_mod, "_cpu", lambda: False)
    ef.render_events(demo_small, 0.02, steps=200, output=out, event_buffer_mb=0.0005)
    chunks = [s for s in seen if s is not None]
    assert len(chunks) > 3 and all(all(s) for s in chunks)
    assert ef.read_events(out).equals(memory) and len(memory) > 500

    # and the check itself tells Dr.Jit's memory from NumPy's: the CPU branch's in-memory path hands views
    import mitsuba as mi

    from mitsuba_eventfield.plugins.event_fill import DeviceEvents, polarity
    ev = DeviceEvents(mi.UInt32([1 | 2 << 16, 3 | 4 << 16]), mi.Int64([5, 6]), polarity(mi.Bool([True, False])), 2)
    assert not any(_owns_its_memory(c) for c in ev.numpy())
    assert all(_owns_its_memory(c) for c in ev.numpy(owned=True))
    assert [c.tolist() for c in ev.numpy(owned=True)] == [[1, 3], [2, 4], [5, 6], [1, -1]]
