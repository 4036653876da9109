"""Many frames per kernel (``event_batch``) against the host path (NumPy expansion, one step at a time): the
same events bit for bit and the same state after, for every pixel model (random draws, refractory period and
readout cap included), whatever the chunking; batching is refused where one frame a step is asked for; and the
converter's results do not depend on how it groups frames."""
import math

import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.plugins.pixel_model import time_order

from conftest import DEMO

W, H = 37, 23          # a width that is no power of two: the fill splits pixels into x and y

BATCHABLE = {
    "ideal": {},
    "asymmetric": {"threshold_on": 0.15, "threshold_off": 0.25},
    "mismatch-leak-lowpass-clock": {"threshold_sigma": 0.03, "leak_rate_hz": 50.0, "cutoff_hz": 200.0,
                                    "timestamp_resolution_us": 50.0, "seed": 3},
    "jitter": {"threshold_jitter": 0.02, "seed": 2},
    "refractory": {"refractory_s": 4e-4},
    "shot-noise": {"shot_noise_hz": 300.0, "seed": 5},
    "readout-cap": {"readout_cap": 3e5},
    # every effect at once: noise events meet the refractory period, the cap meets both, the clock all
    "everything": {"threshold_sigma": 0.03, "threshold_jitter": 0.02, "refractory_s": 4e-4, "leak_rate_hz": 50.0,
                   "leak_jitter": 0.1, "shot_noise_hz": 300.0, "cutoff_hz": 200.0,
                   "timestamp_resolution_us": 20.0, "readout_cap": 1e6, "seed": 7},
}


def _integrator(**pixel):
    import mitsuba as mi
    return mi.load_dict({"type": "eventfield", **pixel})


def _frames(steps=23, seed=1):
    """Log frames with up to ~8 crossings a pixel a step, and uneven frame intervals."""
    rng = np.random.default_rng(seed)
    base = rng.random(W * H) * 2
    frames = [(base + np.sin(0.3 * s + 0.01 * np.arange(W * H)) * 1.5 * rng.random()).astype(np.float32)
              for s in range(steps + 1)]
    times = np.concatenate([[0.0], np.cumsum(1e-3 * (1 + rng.random(steps)))])
    return frames, times


def _host_events(pixel, frames, times, base_us):
    import mitsuba as mi
    integ, parts = _integrator(**pixel), []
    for i, frame in enumerate(frames):
        integ.stage_log(mi.Float(frame), (W, H))
        t0, t1 = (times[i - 1] if i else times[0]), times[i]
        x, y, ts, p = integ.commit(t0, t1)
        t_us = np.rint(ts * 1e6).astype(np.int64) + base_us
        order = time_order(t_us, int(math.floor(t0 * 1e6)) + base_us)
        parts.append(integ.readout(x[order], y[order], t_us[order], p[order]))
    return [np.concatenate([q[c] for q in parts]) for c in range(4)]


def _batched_events(pixel, frames, times, chunk, base_us, own_memory=False):
    """Events of ``frames`` committed ``chunk`` at a time; with ``own_memory`` each chunk's frames are copied
    into Dr.Jit's memory first, as the converter and a render's batches hold them (an array on NumPy's memory
    has that memory's alignment, which a frozen pass records as part of its input layout)."""
    import mitsuba as mi
    from mitsuba_eventfield.plugins.event_fill import device_copy
    integ, parts = _integrator(**pixel), []
    integ.stage_log(mi.Float(frames[0]), (W, H))
    assert integ.commit_events(times[0], times[0]).count == 0 and integ.batchable
    for a in range(1, len(frames), chunk):
        b = min(a + chunk, len(frames))
        values = np.concatenate(frames[a:b])
        values = device_copy(values, mi.Float) if own_memory else mi.Float(values)
        ev = integ.commit_frames(values, times[a - 1:b], base_us=base_us)
        parts.append(ev.numpy())
    return [np.concatenate([q[c] for q in parts]) for c in range(4)], integ


@pytest.mark.parametrize("pixel", BATCHABLE.values(), ids=BATCHABLE.keys())
@pytest.mark.parametrize("chunk", [1, 3, 7, 30])
def test_batched_events_bit_identical_to_the_host_path(pixel, chunk):
    frames, times = _frames()
    base_us = 1_000_000 if pixel == {} else 0
    expected = _host_events(pixel, frames, times, base_us)
    got, integ = _batched_events(pixel, frames, times, chunk, base_us)
    # a real workload: about a crossing a pixel a step, several in some (a refractory period or a readout cap
    # drops most of them: the drops are asserted below)
    lossy = bool(pixel.get("refractory_s") or pixel.get("readout_cap"))
    assert len(expected[2]) > (3000 if lossy else 20 * W * H // 2)
    for name, a, b in zip("xytp", expected, got):
        assert a.dtype == b.dtype and np.array_equal(a, b), _first_difference(name, a, b)
    assert np.bincount(got[0].astype(np.int64) + W * got[1].astype(np.int64)).max() > (5 if lossy else 23)
    # the state after the chunks is the state after the steps: the next frame fires the same events
    host = _host_integrator(pixel, frames, times)
    for name in ("log_prev", "k_on", "k_off", "offset", "last_emit", "held_on", "held_off", "noise_left", "noise_k"):
        if getattr(host, name) is not None:
            assert np.array_equal(np.asarray(getattr(host, name)), np.asarray(getattr(integ, name))), name
    if host.limiter is not None:
        assert host.limiter.state() == integ.limiter.state() and host.limiter.dropped > 100
    assert (host.refractory_dropped, host.noise_events) == (integ.refractory_dropped, integ.noise_events)
    assert host.refractory_dropped > 100 if pixel.get("refractory_s") else host.refractory_dropped == 0
    assert host.noise_events > 100 if pixel.get("shot_noise_hz") else host.noise_events == 0


def _first_difference(name, a, b):
    """Where two event columns part (read from a failure on another backend)."""
    if len(a) != len(b):
        return f"{name}: {len(a)} host events against {len(b)} batched"
    i = int(np.flatnonzero(a != b)[0])
    return f"{name}: {np.count_nonzero(a != b)} of {len(a)} differ; first at {i}: {a[i]} host, {b[i]} batched"


def _host_integrator(pixel, frames, times):
    """The integrator after the host path's steps over ``frames`` (events read out, as ``_host_events``)."""
    import mitsuba as mi
    host = _integrator(**pixel)
    for i, frame in enumerate(frames):
        host.stage_log(mi.Float(frame), (W, H))
        x, y, ts, p = host.commit(times[i - 1] if i else times[0], times[i])
        t_us = np.rint(ts * 1e6).astype(np.int64)
        order = time_order(t_us, int(math.floor((times[i - 1] if i else times[0]) * 1e6)))
        host.readout(x[order], y[order], t_us[order], p[order])
    return host


@pytest.mark.parametrize("pixel", BATCHABLE.values(), ids=BATCHABLE.keys())
def test_a_chunk_whose_few_firing_pixels_are_filled_alone_equals_the_host_path(pixel, monkeypatch):
    """Frames where a fifth of the pixels change: the fill steps only the pixels that fire in the chunk (their
    state, thresholds and generator gathered), and the events and the state after are still the host's."""
    from mitsuba_eventfield.plugins import event_batch
    frames, times = _frames(steps=12, seed=8)
    still = np.arange(W * H) % 5 != 0
    frames = [np.where(still, frames[0], f).astype(np.float32) for f in frames]
    if pixel.get("shot_noise_hz"):      # noise fires anywhere: at 5 Hz about one still pixel in thirty a chunk
        pixel = dict(pixel, shot_noise_hz=5.0)  # (with the leak's, 390-430 of the 851 pixels fire a chunk; at
        # 20 Hz the second chunk's 424 sat 1.5 pixels under half, where a chunk is filled alone)
    subsets = []
    real = event_batch.Chunk.only_firing

    def recorded(self, fired):
        real(self, fired)
        subsets.append(None if self.pixels is None else len(self.pixels))
    monkeypatch.setattr(event_batch.Chunk, "only_firing", recorded)
    expected = _host_events(pixel, frames, times, 0)
    got, integ = _batched_events(pixel, frames, times, 4, 0)
    assert len(expected[2]) > 1000
    for name, a, b in zip("xytp", expected, got):
        assert np.array_equal(a, b), _first_difference(name, a, b)
    # (the leak fires still pixels too: with every effect on, a chunk may hold more than half: all stepped;
    # on a GPU every pixel is stepped: Chunk.only_firing)
    import mitsuba as mi
    filled_alone = [k for k in subsets if k is not None]
    if mi.variant().startswith("cuda"):
        assert subsets and not filled_alone
    else:
        assert len(filled_alone) >= 2 and all(W * H // 5 - 20 <= k <= W * H // 2 for k in filled_alone), subsets
    host = _host_integrator(pixel, frames, times)
    for name in ("log_prev", "k_on", "k_off", "offset", "last_emit"):
        if getattr(host, name) is not None:
            assert np.array_equal(np.asarray(getattr(host, name)), np.asarray(getattr(integ, name))), name


def test_batching_is_refused_where_one_frame_a_step_or_the_host_path_is_asked_for():
    import mitsuba as mi
    from mitsuba_eventfield.plugins.event_batch import one_frame_a_step
    from mitsuba_eventfield.plugins.event_integrator import host_path
    integ = _integrator(**BATCHABLE["everything"])
    integ.stage_log(mi.Float(np.zeros(W * H, np.float32)), (W, H))
    integ.commit_events(0.0, 0.0)
    assert integ.batchable
    for context in (one_frame_a_step, host_path):
        with context():
            assert not integ.batchable
            with pytest.raises(ValueError, match="one at a time"):
                integ.commit_frames(mi.Float(np.zeros(W * H, np.float32)), [0.0, 1e-3])


def test_a_still_chunk_fires_nothing_and_too_few_values_are_refused():
    import mitsuba as mi
    integ = _integrator()
    integ.stage_log(mi.Float(np.ones(W * H, np.float32)), (W, H))
    integ.commit_events(0.0, 0.0)
    assert integ.commit_frames(mi.Float(np.ones(3 * W * H, np.float32)), [0.0, 1e-3, 2e-3, 3e-3]).count == 0
    with pytest.raises(ValueError, match="values for 4 frames"):
        integ.commit_frames(mi.Float(np.ones(3 * W * H, np.float32)), [0.0, 1e-3, 2e-3, 3e-3, 4e-3])


def test_values_past_the_frames_are_not_read():
    """A render's step batch passes its whole buffer, fewer steps than it holds after a scan period's end:
    what lies past the steps' frames (here a frame that would fire in every pixel) changes nothing."""
    import mitsuba as mi
    frames, times = _frames(steps=3)
    out = []
    for tail in ([], [np.full(W * H, 9.0, np.float32)]):
        integ = _integrator()
        integ.stage_log(mi.Float(frames[0]), (W, H))
        integ.commit_events(times[0], times[0])
        out.append(integ.commit_frames(mi.Float(np.concatenate(frames[1:3] + tail)), times[:3]).numpy())
    assert len(out[0][2]) > 100 and all(np.array_equal(a, b) for a, b in zip(*out))


def test_converter_events_do_not_depend_on_grouping(monkeypatch):
    """Frames to events through the converter: one frame a kernel, five, all of them, the host path and the
    per-step device path agree bit for bit; the groups are what was asked (17 steps: 1 + 3 x 5 + 2 frames)."""
    from mitsuba_eventfield.plugins import event_batch
    frames, times = _frames(steps=17, seed=4)
    stack = np.exp(np.stack(frames).reshape(-1, H, W))
    groups, real = [], event_batch.commit_frames

    def counted(integ, log_frames, times_, base_us=0):
        groups.append(len(times_) - 1)
        return real(integ, log_frames, times_, base_us)
    monkeypatch.setattr(event_batch, "commit_frames", counted)
    runs = []
    for k, expected in ((1, []), (5, [5, 5, 5, 2]), (64, [17])):
        groups.clear()
        runs.append(ef.events_from_frames(stack, times, frames_per_kernel=k))
        assert groups == expected
    assert len(runs[0]) > 5000 and all(r.equals(runs[0]) for r in runs[1:])
    from mitsuba_eventfield.plugins.event_batch import one_frame_a_step
    from mitsuba_eventfield.plugins.event_integrator import host_path
    with host_path():
        assert ef.events_from_frames(stack, times).equals(runs[0])
    with one_frame_a_step():
        assert ef.events_from_frames(stack, times).equals(runs[0])
    with pytest.raises(ef.ConfigError, match="frames_per_kernel"):
        ef.events_from_frames(stack, times, frames_per_kernel=0)


@pytest.mark.parametrize("size", [(1, 1 << 15), (1 << 16, 1)], ids=["32768 rows", "65536 columns"])
def test_films_at_the_packed_coordinates_keep_x_y_and_polarity(size):
    """Events carry x | y << 16 | ON << 31 in one word on the device: the largest x and y come back, with
    both polarities (OFF must not touch the y bits), on the per-step and the batched path."""
    import mitsuba as mi
    n = size[0] * size[1]
    for chunk in (None, 2):
        integ = _integrator()
        integ.stage_log(mi.Float(np.zeros(n, np.float32)), size)
        assert integ.commit_events(0.0, 0.0).count == 0
        up, down = np.full(n, 1.0, np.float32), np.full(n, -1.0, np.float32)    # 5 ON, then 10 OFF a pixel
        if chunk:
            x, y, t, p = integ.commit_frames(mi.Float(np.concatenate([up, down])), [0.0, 1e-3, 2e-3]).numpy()
        else:
            parts = []
            for frame, t1 in ((up, 1e-3), (down, 2e-3)):
                integ.stage_log(mi.Float(frame), size)
                parts.append(integ.commit_events(t1 - 1e-3, t1).numpy())
            x, y, t, p = (np.concatenate([q[c] for q in parts]) for c in range(4))
        assert len(t) == 15 * n and (p[:5 * n] == 1).all() and (p[5 * n:] == -1).all()
        assert x.max() == size[0] - 1 and y.max() == size[1] - 1
        assert np.array_equal(np.bincount(x.astype(np.int64) + size[0] * y.astype(np.int64)), np.full(n, 15))


def test_films_beyond_the_packed_coordinates_are_refused_before_any_event(tmp_path):
    import mitsuba as mi
    tall = _integrator()
    tall.stage_log(mi.Float(np.zeros((1 << 15) + 1, np.float32)), (1, (1 << 15) + 1))
    with pytest.raises(ValueError, match="at most 65536 x 32768"):
        tall.commit_events(0.0, 0.0)
    out = tmp_path / "tall.h5"
    with pytest.raises(ef.EventFieldError, match="frames: 1x32769 pixels: events hold at most 65536 x 32768"):
        ef.events_from_frames(np.ones((2, (1 << 15) + 1, 1), np.float32), fps=100.0, output=str(out))
    with pytest.raises(ef.EventFieldError, match="film: 1x32769 pixels: events hold at most"):
        ef.render_events(ef.load_scene(DEMO, width=1, height=(1 << 15) + 1), 0.01, steps=2, output=str(out))
    assert not out.exists()


def test_time_lapse_spans_beyond_32_bit_microseconds():
    """Frames an hour apart: a chunk spans more than 2^32 us, so the sort key takes 64 bits; timestamps and
    order equal the host path's (one step at a time, int64 sort) whatever the grouping."""
    frames, _ = _frames(steps=5, seed=6)
    times = np.arange(6) * 3600.0
    expected = _host_events({}, frames, times, 0)
    assert expected[2].max() > 1 << 32
    for chunk in (1, 2, 5):
        got, _ = _batched_events({}, frames, times, chunk, 0)
        for a, b in zip(expected, got):
            assert np.array_equal(a, b)


def test_device_events_join_on_the_device_and_on_the_host():
    """``DeviceEvents.concat`` (a GPU's join before the copy) and ``host_columns`` (the CPU's) give the same
    columns as the parts one after the other."""
    import mitsuba as mi
    from mitsuba_eventfield.plugins.event_fill import DeviceEvents
    frames, times = _frames(steps=4, seed=2)
    integ, parts = _integrator(), []
    integ.stage_log(mi.Float(frames[0]), (W, H))
    integ.commit_events(times[0], times[0])
    for i in range(1, 5):
        integ.stage_log(mi.Float(frames[i]), (W, H))
        parts.append(integ.commit_events(times[i - 1], times[i]))
    expected = [np.concatenate([q.numpy()[c] for q in parts]) for c in range(4)]
    for joined in (DeviceEvents.concat(parts).numpy(), DeviceEvents.host_columns(parts)):
        for a, b in zip(expected, joined):
            assert a.dtype == b.dtype and np.array_equal(a, b)
    assert len(expected[0]) > W * H


def test_default_grouping_keeps_one_radix_pass_on_the_cpu():
    """The default frames per kernel: about LANE_STEPS lane-steps, at least 3, capped at 64 (CUDA: 200), and on
    the CPU never a chunk whose span needs more radix passes than one frame (2^20 us a pass: at 30 fps 31 frames
    fit one; 0.4 s frames: 2)."""
    import mitsuba as mi

    from mitsuba_eventfield.plugins import event_batch
    if mi.variant().startswith("cuda"):
        # on a GPU (the suite under EVENTFIELD_TEST_VARIANT=cuda_ad_mono): 60 M lane-steps, no radix-pass limit
        assert event_batch.default_frames_per_kernel(1280 * 720, 1 / 2000) == 65
        assert event_batch.default_frames_per_kernel(1280 * 720, 0.4) == 65
        assert event_batch.default_frames_per_kernel(346 * 260, 1 / 30) == 200
        return
    assert event_batch.default_frames_per_kernel(346 * 260, 1 / 2000) == 4
    assert event_batch.default_frames_per_kernel(346 * 260, 1 / 30) == 4
    assert event_batch.default_frames_per_kernel(32 * 24, 1 / 30) == 31        # more would need a second pass
    assert event_batch.default_frames_per_kernel(32 * 24, 2.0) == 64           # one frame takes two already
    assert event_batch.default_frames_per_kernel(64 * 48, 1e-5) == 64
    assert event_batch.default_frames_per_kernel(1280 * 720, 1 / 2000) == 3     # the fewest
    assert event_batch.default_frames_per_kernel(1280 * 720, 0.4) == 2           # 3 would need a second pass


@pytest.mark.parametrize("pixel", [BATCHABLE["ideal"], BATCHABLE["everything"]], ids=["ideal", "everything"])
def test_chunk_passes_are_replayed_and_equal_the_traced_ones(pixel, monkeypatch):
    """A chunk's count and write passes are frozen (``event_batch._frozen``): after a few recordings of a chunk
    shape the later chunks of it replay them (were each chunk recorded, freezing would only add cost), on
    dense chunks and on sparse ones (whose write pass steps a firing subset of another length every chunk),
    and the events and the state after equal those of tracing every chunk (``EVENTFIELD_FREEZE=0``)."""
    from mitsuba_eventfield.plugins import event_batch
    from mitsuba_eventfield.plugins.frozen import FrozenCache
    dense, times = _frames(steps=60, seed=4)
    still = np.arange(W * H) % 5 != 0          # a fifth of the pixels change: the write pass steps a subset
    sparse = [np.where(still, dense[0], f).astype(np.float32) for f in dense]
    runs = {}
    for freeze in ("1", "0"):
        monkeypatch.setenv("EVENTFIELD_FREEZE", freeze)
        monkeypatch.setattr(event_batch, "_PASSES", FrozenCache())
        runs[freeze] = [_batched_events(pixel, frames, times, 3, base_us=17, own_memory=True)
                        for frames in (dense, sparse)]
        if freeze == "1":
            passes = event_batch._PASSES
            assert {key[0][0] for key in passes} == {"count", "write"}
            # 40 chunks of one shape: a new integrator's first chunk, whose state was made on the host, records
            # again, and so may a first chunk of sparse frames (measured: 2-4 recordings a pass); then replays
            assert all(0 < fn.n_recordings <= 8 and fn.refused is None for fn in passes.values()), \
                {key[0][0]: (fn.n_recordings, fn.refused) for key, fn in passes.items()}
            if pixel:
                # another seed: other thresholds and generator streams, which are arguments: the same passes,
                # replayed after at most a new integrator's first-chunk recordings
                before = {key: fn.n_recordings for key, fn in passes.items()}
                other, _ = _batched_events(dict(pixel, seed=pixel["seed"] + 1), dense, times, 3, 17,
                                           own_memory=True)
                assert set(passes) == set(before) and len(other[0]) != len(runs["1"][0][0][0])
                assert all(fn.n_recordings <= before[key] + 2 for key, fn in passes.items()), \
                    [(before[key], fn.n_recordings) for key, fn in passes.items()]
                runs["1"].append(other)
        else:
            assert not any(hasattr(fn, "n_recordings") for fn in event_batch._PASSES.values())
            if pixel:     # the other seed traced: a replay that baked in the first seed's draws would differ
                runs["0"].append(_batched_events(dict(pixel, seed=pixel["seed"] + 1), dense, times, 3, 17,
                                                 own_memory=True)[0])
    if pixel:
        other_frozen, other_traced = runs["1"].pop(), runs["0"].pop()
        assert all(np.array_equal(a, b) for a, b in zip(other_frozen, other_traced))
    for (frozen, f_integ), (traced, t_integ) in zip(runs["1"], runs["0"]):
        assert len(frozen[0]) > W * H
        for a, b in zip(frozen, traced):
            assert a.dtype == b.dtype and np.array_equal(a, b)
        assert np.array_equal(f_integ.log_prev.numpy(), t_integ.log_prev.numpy())
        for name in ("held_on", "noise_left", "noise_k"):
            if getattr(t_integ, name) is not None:
                assert np.array_equal(getattr(f_integ, name).numpy(), getattr(t_integ, name).numpy()), name
