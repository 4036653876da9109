"""Conversion with the events left on the device (``events_from_frames(..., on_device=True)``,
simulate/device_stream.py): the same events as the host result, against the closed-form ramp instants too; the
columns handed over through DLPack without a copy; host-made steps uploaded; bad use refused in one line."""
import numpy as np
import pytest
from test_convert import C, _ramp_truth, _ramps

import mitsuba_eventfield as ef
from mitsuba_eventfield.plugins.event_integrator import host_path


def _stack(frames=30, width=64, height=48, seed=0):
    """A moving texture (every pixel crosses several times) at 1 kHz."""
    rng = np.random.default_rng(seed)
    tex = rng.random((height, width + frames)).astype(np.float32)
    return np.stack([0.05 + tex[:, i:i + width] for i in range(frames)]), np.arange(frames) / 1000.0


@pytest.mark.parametrize("pixel", [None, {"refractory_s": 2e-4, "shot_noise_hz": 3.0, "seed": 4}],
                         ids=["ideal", "refractory_noise"])
def test_device_result_equals_the_host_result(pixel):
    stack, t = _stack()
    host = ef.events_from_frames(stack, t, threshold=C, pixel=pixel)
    dev = ef.events_from_frames(stack, t, threshold=C, pixel=pixel, on_device=True)
    assert isinstance(dev, ef.DeviceEventStream) and len(dev) == len(host) > 20_000
    assert dev.equals(host) and dev.numpy().equals(host)
    assert dev.on_count() == int(np.count_nonzero(host.p > 0)) == dev.meta["render"]["on"]
    assert dev.meta["render"]["events"] == len(host) and (dev.width, dev.height) == (64, 48)


def _read(column):
    """A device column read through DLPack: NumPy takes the CPU backend's memory itself; NumPy cannot hold
    CUDA memory ("Unsupported device in DLTensor", H100 2026-11-26), so a CUDA column crosses into PyTorch."""
    import mitsuba as mi
    if mi.variant().startswith("cuda"):
        torch = pytest.importorskip("torch")
        return torch.from_dlpack(column).cpu().numpy()
    return np.from_dlpack(column)


def test_columns_cross_by_dlpack_without_a_copy():
    stack, t, rates = _ramps()
    dev = ef.events_from_frames(stack, t, threshold=C, on_device=True)
    cols = {k: _read(v) for k, v in dev.columns().items()}
    assert {k: v.dtype for k, v in cols.items()} == {"x": np.int32, "y": np.int32, "t": np.int64, "p": np.int8}
    # the closed-form instants, read straight from the device columns
    truth = _ramp_truth(rates, t[-1])
    assert len(cols["t"]) == 3 * sum(len(v) for v in truth.values()) and (cols["p"] == 1).all()
    for x, expected in truth.items():
        got = np.sort(cols["t"][(cols["x"] == x) & (cols["y"] == 1)])
        assert len(got) == len(expected) and np.abs(got - expected).max() <= 1.0
    # the DLPack view is the stream's own memory, not a copy: two exports point at one buffer (on the CPU
    # backend, where NumPy can take the device's memory; a copying export would give two)
    import mitsuba as mi
    if mi.variant().startswith("llvm"):
        first, second = np.from_dlpack(dev.t), np.from_dlpack(dev.t)
        assert first.ctypes.data == second.ctypes.data and not first.flags.writeable
    else:                                 # on the GPU: two PyTorch views of one device buffer
        torch = pytest.importorskip("torch")
        first, second = torch.from_dlpack(dev.t), torch.from_dlpack(dev.t)
        assert first.is_cuda and first.data_ptr() == second.data_ptr()


def test_host_made_steps_are_uploaded(monkeypatch):
    """The NumPy host path (a step at a time on the host) reaches the device result too, in time order."""
    from mitsuba_eventfield.simulate import sink
    uploads = []
    real = sink.numpy_columns
    monkeypatch.setattr(sink, "numpy_columns", lambda *c: uploads.append(len(c[2])) or real(*c))
    stack, t = _stack(frames=12, seed=2)
    plain = ef.events_from_frames(stack, t, threshold=C)
    assert uploads == []
    with host_path():
        dev = ef.events_from_frames(stack, t, threshold=C, on_device=True, event_buffer_mb=0.05)
    assert len(uploads) == 11 and sum(uploads) == len(dev)       # a step at a time, each uploaded
    assert len(dev) > 5000 and dev.equals(plain) and dev.numpy().is_sorted


def test_nothing_to_fire_and_bad_use():
    flat = np.full((5, 8, 8), 0.5, np.float32)
    dev = ef.events_from_frames(flat, np.arange(5) / 100.0, threshold=C, on_device=True)
    assert len(dev) == 0 and dev.on_count() == 0 and len(dev.numpy()) == 0 and dev.numpy().width == 8
    with pytest.raises(ef.EventFieldError, match=r"out\.h5: on_device keeps the events on the device"):
        ef.events_from_frames(flat, np.arange(5) / 100.0, output="out.h5", on_device=True)


def test_torch_tensors_share_the_columns():
    torch = pytest.importorskip("torch")           # not a dependency: PyTorch users have it
    stack, t = _stack(frames=8)
    dev = ef.events_from_frames(stack, t, threshold=C, on_device=True)
    tensors = dev.torch()
    host = dev.numpy()
    assert tensors["t"].dtype == torch.int64 and np.array_equal(tensors["t"].cpu().numpy(), host.t)
    assert np.array_equal(tensors["x"].cpu().numpy(), host.x.astype(np.int32))


@pytest.mark.parametrize("name", ["demo/demo.xml", "galvo_static/galvo_static.xml"])
def test_a_render_left_on_the_device_equals_the_host_render(name, monkeypatch):
    """render_events(on_device=True): the same events as in memory, for a moving scene (steps in batches) and a
    static galvo scene whose later scan periods reuse the first period's events (kept and shifted on the host,
    so they are uploaded)."""
    import os

    from conftest import ROOT

    from mitsuba_eventfield.simulate import sink
    uploads = []
    real = sink.numpy_columns
    monkeypatch.setattr(sink, "numpy_columns", lambda *c: uploads.append(len(c[2])) or real(*c))
    path = os.path.join(ROOT, "scenes", name)
    host = ef.render_events(ef.load_scene(path, width=40, height=30), 0.012, steps=48)
    uploads.clear()
    dev = ef.render_events(ef.load_scene(path, width=40, height=30), 0.012, steps=48, on_device=True)
    assert len(host) > 500 and dev.equals(host) and dev.meta["render"]["events"] == len(host)
    assert (sum(uploads) > 0) == ("galvo_static" in name)       # the reused periods came from the host
    with pytest.raises(ef.EventFieldError, match="on_device keeps the events on the device"):
        ef.render_events(ef.load_scene(path, width=8, height=6), 0.001, steps=2, output="x.h5", on_device=True)


def test_device_frames_are_taken_a_group_at_a_time():
    """Frames on the device enter a chunk's kernel as one gather of the group's consecutive frames: no kernel a
    frame (on an H200 those were 199 of the converter's 287 launches for 200 frames, and most of its time)."""
    import collections

    import drjit as dr
    import mitsuba as mi
    stack, t = _stack(frames=48, seed=2)
    frame_size = stack.shape[1] * stack.shape[2]
    tensor = mi.TensorXf(stack)
    ef.events_from_frames(tensor, t, threshold=C, frames_per_kernel=12)        # compile
    dr.kernel_history()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        ev = ef.events_from_frames(tensor, t, threshold=C, frames_per_kernel=12)
        kinds = collections.Counter((str(k["type"]).split(".")[-1], k.get("size")) for k in dr.kernel_history())
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert len(ev) > 1000
    # a frame-sized kernel a frame was 58 here (47 steps); now the first frame's and each chunk's state
    assert kinds[("JIT", frame_size)] <= 3 * 4 + 2, kinds
    # and the frozen write pass does not copy a chunk's slot array (8 bytes an event) before filling it: it was
    # one Memcpy of the whole array a chunk (event_batch.Chunk.write)
    assert not [size for (kind, size), n in kinds.items() if kind == "Memcpy" and size >= 8 * 1000], kinds


def test_events_left_on_the_device_are_joined_once_and_counted_with_one_read(monkeypatch):
    """Every event is copied into the result once, and the ON / OFF totals take one read from the device: the
    sink keeps the steps as they are, however small its buffer, and joins and counts them at the end (joined
    at each full buffer and again at the end, each event was copied twice: 0.56 ms of a 3.3 ms chunk at
    346x260 on the CPU; counted a part at a time, each chunk synced with the device)."""
    from mitsuba_eventfield.plugins.event_fill import DeviceEvents
    from mitsuba_eventfield.simulate.summary import RenderSummary
    stack, t = _stack(frames=40, seed=3)
    copied, counted, real_concat, real_count = [], [], DeviceEvents.concat, RenderSummary.count

    def concat(parts):
        full = [q.count for q in parts if q.count]
        copied.append(sum(full) if len(full) > 1 else 0)      # one part is returned as it is
        return real_concat(parts)

    def count(self, p):
        counted.append(type(p).__module__.split(".")[0])
        return real_count(self, p)
    monkeypatch.setattr(DeviceEvents, "concat", staticmethod(concat))
    monkeypatch.setattr(RenderSummary, "count", count)
    ev = ef.events_from_frames(stack, t, threshold=C, on_device=True, event_buffer_mb=0.05, frames_per_kernel=3)
    assert len(ev) > 40_000 > 0.05 * (1 << 20) / 13          # the buffer would have been full many times
    assert sum(copied) == len(ev), copied
    assert counted == ["drjit"], counted
    host = ef.events_from_frames(stack, t, threshold=C)
    assert ev.numpy().equals(host)
    assert (ev.meta["render"]["on"], ev.meta["render"]["off"]) == (np.count_nonzero(host.p > 0),
                                                                   np.count_nonzero(host.p < 0))


@pytest.mark.parametrize("frames_per_kernel", [None, 1], ids=["batched", "a_frame_a_step"])
def test_frames_already_on_the_device_give_the_host_events(frames_per_kernel):
    """A Dr.Jit tensor of frames (where a GPU pipeline has them) converts without a host copy of the frames,
    to the events of the same frames as a NumPy array, batched or a frame a step, into the host or left on the
    device; against the closed-form ramp instants too."""
    import mitsuba as mi
    stack, t = _stack(frames=24, seed=5)
    host = ef.events_from_frames(stack, t, threshold=C, frames_per_kernel=frames_per_kernel)
    tensor = mi.TensorXf(stack)
    dev = ef.events_from_frames(tensor, t, threshold=C, frames_per_kernel=frames_per_kernel)
    assert len(host) > 20_000 and dev.equals(host) and dev.meta["source"] == {"kind": "device array"}
    assert ef.events_from_frames(tensor, t, threshold=C, on_device=True,
                                 frames_per_kernel=frames_per_kernel).equals(host)
    ramp, rt, rates = _ramps()
    ev = ef.events_from_frames(mi.TensorXf(ramp), rt, threshold=C)
    truth = _ramp_truth(rates, rt[-1])
    assert len(ev) == 3 * sum(len(v) for v in truth.values())
    for x, expected in truth.items():
        got = np.sort(ev.t[(ev.x == x) & (ev.y == 1)])
        assert len(got) == len(expected) and np.abs(got - expected).max() <= 1.0


@pytest.mark.parametrize("make, kw, message", [
    (lambda mi: mi.TensorXf(np.full((3, 4, 4), np.nan, np.float32)), {"fps": 10}, "finite and >= 0"),
    (lambda mi: mi.TensorXf(np.full((3, 4, 4), -1.0, np.float32)), {"fps": 10}, "finite and >= 0"),
    (lambda mi: mi.TensorXf(np.ones((3, 4, 4, 3), np.float32)), {"fps": 10}, r"shape \(3, 4, 4, 3\)"),
    (lambda mi: mi.TensorXf(np.ones((1, 4, 4), np.float32)), {"fps": 10}, "T >= 2"),
    (lambda mi: mi.TensorXf(np.ones((3, 4, 4), np.float32)), {"fps": 10, "srgb": True}, "srgb"),
    (lambda mi: mi.TensorXf(np.ones((3, 4, 4), np.float32)), {}, "frame rate"),
    (lambda mi: mi.TensorXf(np.ones((3, 4, 4), np.float32)), {"times": [0, 1, 1]}, "strictly increasing"),
], ids=["nan", "negative", "colour", "one_frame", "srgb", "no_rate", "times"])
def test_bad_device_frames_are_one_line(make, kw, message):
    import mitsuba as mi
    with pytest.raises(ef.EventFieldError, match=message) as e:
        ef.events_from_frames(make(mi), threshold=C, **kw)
    assert "\n" not in str(e.value) and str(e.value).startswith("frames: ")
