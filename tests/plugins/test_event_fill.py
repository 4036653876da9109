"""Events made on the device (count, prefix sum, fill, sort in Dr.Jit) against the host path, the analytic
ramp, and through the render loop and its chunked, background-written output."""
import math
import os

import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.plugins.pixel_model import time_order

W, H = 40, 30


def _integrator(**pixel):
    import mitsuba as mi
    return mi.load_dict({"type": "eventfield", **pixel})


def _host_step(integ, t0, t1):
    """The host path exactly as the render loop runs it: commit, microseconds, stable order, readout."""
    x, y, ts, p = integ.commit(t0, t1)
    t_us = np.rint(ts * 1e6).astype(np.int64)
    order = time_order(t_us, int(math.floor(t0 * 1e6)))
    return integ.readout(x[order], y[order], t_us[order], p[order])


PIXELS = {
    "ideal": {},
    "asymmetric": {"threshold_on": 0.15, "threshold_off": 0.25},
    "mismatch-jitter-leak-lowpass-clock": {"threshold_sigma": 0.03, "threshold_jitter": 0.02, "leak_rate_hz": 50.0,
                                           "cutoff_hz": 200.0, "timestamp_resolution_us": 50.0, "seed": 3},
    "refractory": {"refractory_s": 4e-4},
    "shot-noise": {"shot_noise_hz": 300.0, "seed": 5},
    "refractory-noise-cap": {"refractory_s": 3e-4, "shot_noise_hz": 300.0, "readout_cap": 3e5, "seed": 7},
    "davis346": {"preset": "davis346", "shot_noise_hz": 200.0},
}


@pytest.mark.parametrize("pixel", PIXELS.values(), ids=PIXELS.keys())
def test_device_events_bit_identical_to_host(pixel):
    """Same frames into two integrators: every step's events (x, y, t, p, dtype and order) agree bit for bit,
    multi-crossing steps (up to ~8 crossings a pixel) included, and so do the refractory drops, the shot-noise
    events and the readout cap's drops where the pixel model has them."""
    from mitsuba_eventfield.plugins.event_integrator import device_path
    host, device = _integrator(**pixel), _integrator(**pixel)
    with device_path():                 # on the CPU, noise and refractory models default to the host path
        _run_both(host, device, whole_periods=not pixel)


def _run_both(host, device, whole_periods):
    import mitsuba as mi
    assert device.device_resident
    rng = np.random.default_rng(1)
    base = rng.random(W * H) * 2
    t, total, multi = 0.0, 0, 0
    for s in range(25):
        frame = (base + np.sin(0.3 * s + 0.01 * np.arange(W * H)) * 1.5 * rng.random()).astype(np.float32)
        t1 = t + 1e-3 * (1 + rng.random())
        for integ in (host, device):
            integ.stage_log(mi.Float(frame), (W, H))
        expected = list(_host_step(host, t, t1))
        base_us = 7_000_000 * s if whole_periods else 0    # whole periods added (phase grid: ideal pixels only)
        expected[2] = expected[2] + base_us
        got = device.commit_events(t, t1, base_us=base_us).numpy()
        for a, b in zip(expected, got):
            assert a.dtype == b.dtype and np.array_equal(a, b)
        total += len(got[2])
        if len(got[2]):
            multi += int(np.bincount(got[0].astype(np.int64) + W * got[1]).max() > 1)
        t = t1
    assert total > 4000 and multi > 5
    cfg = device.config
    assert (device.refractory_dropped > 100) == bool(cfg.refractory_s)
    assert (device.noise_events > 50) == bool(cfg.shot_noise_hz)
    assert (device.readout_dropped() > 100) == bool(cfg.readout_cap)
    assert (host.refractory_dropped, host.noise_events, host.readout_dropped()) == \
        (device.refractory_dropped, device.noise_events, device.readout_dropped())


def test_device_timestamps_keep_microseconds_after_hours():
    """A pixel whose log brightness ramps linearly crosses C at an exactly known instant; at t = 3 h 20 min
    (float32 seconds would be 0.5 ms coarse there) the device path still gives the nearest microsecond."""
    import mitsuba as mi
    integ = _integrator(threshold=0.2)
    t0, dt = 12_000.0, 1e-3
    integ.stage_log(mi.Float(np.zeros(4, np.float32)), (4, 1))
    integ.commit_device(t0, t0)
    # pixel 2 rises by 0.5 in the step: crossings at 0.2 / 0.5 and 0.4 / 0.5 of it
    integ.stage_log(mi.Float(np.array([0, 0, 0.5, 0], np.float32)), (4, 1))
    x, y, t_us, p = integ.commit_device(t0, t0 + dt).numpy()
    expected = [round((t0 + f * dt) * 1e6) for f in (0.2 / 0.5, 0.4 / 0.5)]
    assert list(x) == [2, 2] and list(p) == [1, 1]
    assert np.abs(t_us - np.array(expected)).max() <= 1


def test_render_same_events_on_device_and_host_and_in_any_chunking(tmp_path, demo_small):
    """The render loop's device path, its chunking (a chunk for each committed batch of steps, or the whole
    render) and the background HDF5 writer change nothing: the file equals the host-path render (NumPy
    expansion, a step at a time), event for event. 160 steps: batches of at most 64 at 48x36, so several
    chunks."""
    from mitsuba_eventfield.plugins.event_integrator import host_path
    from mitsuba_eventfield.simulate import sink as sink_mod
    kw = dict(duration=0.01, steps=160, reuse=False)
    device = ef.render_events(demo_small, **kw)
    batch_chunks = str(tmp_path / "small.h5")
    chunks, real_add = [], sink_mod.Sink._add_host
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(sink_mod.Sink, "_add_host", lambda self, *a, **k: (chunks.append(len(a[2])), real_add(self, *a, **k)))
        summary = ef.render_events(demo_small, **kw, output=batch_chunks, event_buffer_mb=1e-6)
    with host_path():
        host = ef.render_events(demo_small, **kw)
    assert len(chunks) >= 3 and sum(chunks) == len(device)
    assert len(device) > 1500 and device.equals(host)
    assert ef.read_events(batch_chunks).equals(device)
    assert summary.events == len(device) and summary.writer_busy_s > 0
    assert summary.on == int((device.p > 0).sum())
    assert os.listdir(tmp_path) == ["small.h5"]


def test_galvo_render_with_motion_same_on_device_and_host():
    """The fan (moving blades, 250 Hz galvo scan): per-period phase timestamps plus whole periods on the
    device equal the host's, event for event, and a period-reusing static galvo render too."""
    from mitsuba_eventfield.scene import bundled_scene
    fan = ef.load_scene(bundled_scene("fan/fan.xml"), width=48, height=36)
    static = ef.load_scene(bundled_scene("galvo_static/galvo_static.xml"), width=48, height=36)
    device = [ef.render_events(fan, 0.004, steps=32, reuse=False), ef.render_events(static, 0.008, steps=64)]
    from mitsuba_eventfield.plugins.event_integrator import host_path
    with host_path():
        host = [ef.render_events(fan, 0.004, steps=32, reuse=False), ef.render_events(static, 0.008, steps=64)]
    assert device[1].meta["render"]["reused_steps"] > 0
    for d, h in zip(device, host):
        assert len(d) > 500 and d.equals(h)


def test_background_writer_error_reaches_the_caller_and_leaves_no_file(tmp_path):
    from mitsuba_eventfield.events.hdf5 import H5EventWriter
    from mitsuba_eventfield.events.writer import BackgroundWriter
    path = str(tmp_path / "e.h5")
    w = BackgroundWriter(H5EventWriter(path, 4, 4))
    w.append(np.zeros(2, np.uint16), np.zeros(2, np.uint16), np.array([5, 6]), np.ones(2, np.int8), 6)
    w.append(np.zeros(1, np.uint16), np.zeros(1, np.uint16), np.array([1]), np.ones(1, np.int8), 6)   # out of order
    with pytest.raises(ValueError, match="time order"):
        w.close()
    w.abort()
    assert os.listdir(tmp_path) == []



@pytest.mark.parametrize("pass_bits", [20, 11, 8], ids=["llvm-width", "11-bit", "cuda-width"])
@pytest.mark.parametrize("bound", [255, 700, 50_000, 3_000_000, 3_000_000_000])
@pytest.mark.parametrize("n", [5000, 70_000], ids=["small", "large"])
def test_stable_order_is_numpy_stable_argsort(bound, pass_bits, n, monkeypatch):
    """One to four radix passes of each width (or the narrow ones of a small sort, ``event_fill.SMALL_SORT``):
    the permutation NumPy's stable sort gives (ties in index order). Under CUDA (EVENTFIELD_TEST_VARIANT) the
    CPU width set here does not apply and the CUDA width is what is tested: its passes must be stable
    (a pass too wide for Dr.Jit's stable CUDA histogram reorders ties)."""
    import mitsuba as mi
    from mitsuba_eventfield.plugins import event_fill
    from mitsuba_eventfield.plugins.event_fill import stable_order
    monkeypatch.setitem(event_fill.PASS_BITS, "llvm", pass_bits)
    rng = np.random.default_rng(bound % 97)
    key = rng.integers(0, bound, n, dtype=np.int64).astype(np.uint32)
    key[::7] = key[3]                                   # many ties
    got = stable_order(mi.UInt32(key), bound).numpy()
    assert np.array_equal(got, np.argsort(key, kind="stable"))


def test_cuda_pass_width_keeps_dr_jits_stable_histogram():
    """Dr.Jit's CUDA block_mkperm is stable only while one histogram per warp, 32 warps of a 1024-thread block,
    fits in a block's shared memory; 48 KiB is what every CUDA GPU gives. A wider pass runs the form that is
    stable only within 32 elements, and an LSD radix sort then misorders ties (seen at 15 bits on an H200)."""
    from mitsuba_eventfield.plugins import event_fill
    buckets = 1 << event_fill.PASS_BITS["cuda"]
    assert buckets * 4 * 32 <= 48 * 1024


@pytest.mark.parametrize("pixel", [PIXELS["ideal"], PIXELS["refractory-noise-cap"], PIXELS["davis346"]],
                         ids=["ideal", "refractory-noise-cap", "davis346"])
def test_pixel_state_round_trip_continues_identically(pixel):
    """A checkpoint's pixel state (get_state, through NumPy, set_state into a fresh integrator) makes the same
    later events as the integrator that never stopped: noise generator, last emissions, limiter included."""
    import mitsuba as mi
    rng = np.random.default_rng(2)
    frames = [(rng.random(W * H) * 2 + 0.3 * s).astype(np.float32) for s in range(12)]
    from mitsuba_eventfield.plugins.event_integrator import event_path
    for path in ("device", "host"):
        with event_path(path):
            _round_trip(pixel, mi, frames)


def _round_trip(pixel, mi, frames):
    whole, first = _integrator(**pixel), _integrator(**pixel)
    for s in range(6):
        for integ in (whole, first):
            integ.stage_log(mi.Float(frames[s]), (W, H))
            integ.commit_events(s * 1e-3, (s + 1) * 1e-3)
    resumed = _integrator(**pixel)
    resumed.set_state({k: np.array(v) for k, v in first.get_state().items()})
    for s in range(6, 12):
        outs = []
        for integ in (whole, resumed):
            integ.stage_log(mi.Float(frames[s]), (W, H))
            outs.append(integ.commit_events(s * 1e-3, (s + 1) * 1e-3).numpy())
        assert len(outs[0][0]) > 0 and all(np.array_equal(a, b) for a, b in zip(*outs))
    assert (whole.refractory_dropped, whole.noise_events, whole.readout_dropped()) == \
        (resumed.refractory_dropped, resumed.noise_events, resumed.readout_dropped())


@pytest.mark.parametrize("pixel", [{"leak_rate_hz": 3000.0, "refractory_s": 1e-4, "seed": 2},
                                   {"shot_noise_hz": 500.0, "seed": 2}], ids=["leak-refractory", "noise-only"])
def test_device_matches_host_on_still_frames(pixel):
    """Frames that never change: with a strong leak every pixel's crossings all fall at one instant (the log
    does not move, so the interpolation clips), the refractory stride is infinite and one crossing is kept;
    with shot noise alone a step has noise events and no crossing. Device and host agree bit for bit."""
    import mitsuba as mi
    from mitsuba_eventfield.plugins.event_integrator import device_path
    host, device = _integrator(**pixel), _integrator(**pixel)
    frame = np.full(W * H, -1.2, np.float32)
    total, t = 0, 0.0
    with device_path():
        for s in range(8):
            t1 = t + 1e-3
            for integ in (host, device):
                integ.stage_log(mi.Float(frame), (W, H))
            expected = _host_step(host, t, t1)
            got = device.commit_events(t, t1).numpy()
            for a, b in zip(expected, got):
                assert a.dtype == b.dtype and np.array_equal(a, b)
            total += len(got[2])
            t = t1
    assert total > 2 * W * H if "leak_rate_hz" in pixel else total > 20
    assert (device.refractory_dropped > W * H) == ("refractory_s" in pixel)
    assert (device.noise_events == total) == ("shot_noise_hz" in pixel)


def test_rounded_hands_every_product_on_bit_for_bit():
    """``event_select.rounded`` in its CUDA form (a select on the product's own NaN test, which ptxas cannot fold
    into an FMA) returns each product as it is: finite, signed zero, infinite and NaN. That it stops the fusion
    is checked under CUDA by test_event_batch's refractory cases (their float64 state was an ulp off without
    it)."""
    import drjit as dr
    import mitsuba as mi
    from mitsuba_eventfield.plugins.event_select import rounded
    values = np.array([1.5, -0.0, np.inf, -np.inf, np.nan, 1e-300, 0.1, -7.25e7])
    x = mi.Float64(values)
    for fusing in (True, False, None):
        got = rounded(x * mi.Float64(3.0), fusing=fusing)
        assert dr.width(got) == len(values)
        assert np.array_equal(got.numpy().view(np.int64), (values * 3.0).view(np.int64)), fusing
