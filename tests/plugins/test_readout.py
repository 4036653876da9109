"""The readout cap (``plugins/readout.py``): the host and device limiters drop the same events, bit for bit,
across steps that share a bin, overflow, empty and fully dropped steps; no 1 ms window passes more than the cap;
the survivors of an overfull bin are not biased in time; its state survives a checkpoint."""
import numpy as np
import pytest

from mitsuba_eventfield.plugins import readout


def _device_events(mi, dr, x, y, t, p):
    from mitsuba_eventfield.plugins import event_fill
    return event_fill.DeviceEvents(mi.UInt32(x | (y << 16)), mi.Int64(t), dr.int8_array_t(mi.Int32)(p),
                                   count=len(t))


def _steps(rng, steps=80, span_us=1500, long_every=0):
    """Time-sorted steps of random events: some empty, some far beyond the cap, bins shared between steps; every
    ``long_every``-th step 0.3 s long (2700 bins: too many to share a 32-bit sort word with the key, so the
    device sorts by key, then by bin)."""
    t0 = 0
    for s in range(steps):
        span = 300_000 if long_every and s % long_every == 3 else span_us
        n = 0 if s % 17 == 5 else int(rng.integers(0, 2000 if s % 9 == 0 else 500) * span / span_us)
        t = np.sort(rng.integers(t0, t0 + span, n)).astype(np.int64)
        yield t0, t0 + span, rng.integers(0, 300, n).astype(np.uint32), \
            rng.integers(0, 200, n).astype(np.uint32), t, rng.choice(np.array([-1, 1], np.int8), n)
        t0 += span


@pytest.mark.parametrize("cap", [3e5, 5e3], ids=["budget-30", "budget-0"])
def test_host_and_device_limiters_keep_the_same_events(cap):
    """A budget of 30 events a bin (steps that overflow, their first bin shared with the step before) and of
    0 (every event of every step dropped)."""
    import drjit as dr
    import mitsuba as mi
    host, device = readout.ReadoutLimiter(cap, seed=7), readout.ReadoutLimiter(cap, seed=7)
    overflowing = all_dropped = long_overflowing = 0
    for t0, t1, x, y, t, p in _steps(np.random.default_rng(0), long_every=20):
        keep = host.filter(t)
        got = device.filter_device(_device_events(mi, dr, x, y, t, p), [len(t)], t0 * 1e-6, t1 * 1e-6)
        expected = (x[keep].astype(np.uint16), y[keep].astype(np.uint16), t[keep], p[keep])
        assert all(np.array_equal(a, b) for a, b in zip(expected, got.numpy()))
        assert host.state() == device.state()
        overflowing += int(keep.sum() < len(t))
        all_dropped += int(len(t) > 0 and not keep.any())
        long_overflowing += int(t1 - t0 > 100_000 and keep.sum() < len(t))
    assert overflowing > 20 and host.dropped > 5000 and long_overflowing >= 3
    assert all_dropped > 50 if host.budget == 0 else all_dropped == 0


@pytest.mark.parametrize("cap", [3e5, 1e6], ids=["budget-30", "budget-100"])
def test_many_steps_at_once_keep_what_step_by_step_keeps(cap):
    """The device limiter on a chunk of consecutive steps (a batch of ``event_batch``: 1 to 12 steps, empty
    ones among them, bins shared across steps, 0.3 s steps whose bins and steps do not fit one sort word with
    the key) keeps the events the host limiter keeps step by step, and ends in the same state."""
    import drjit as dr
    import mitsuba as mi
    host, device = readout.ReadoutLimiter(cap, seed=5), readout.ReadoutLimiter(cap, seed=5)
    steps = list(_steps(np.random.default_rng(3), steps=120, long_every=25))
    rng, i, overflowing = np.random.default_rng(9), 0, 0
    while i < len(steps):
        chunk = steps[i:i + int(rng.integers(1, 13))]
        i += len(chunk)
        expected, counts = [], []
        for t0, t1, x, y, t, p in chunk:
            keep = host.filter(t)
            overflowing += int(keep.sum() < len(t))
            expected.append((x[keep].astype(np.uint16), y[keep].astype(np.uint16), t[keep], p[keep]))
            counts.append(len(t))
        joined = [np.concatenate([q[c] for q in chunk]) for c in range(2, 6)]
        got = device.filter_device(_device_events(mi, dr, *joined), counts, chunk[0][0] * 1e-6, chunk[-1][1] * 1e-6)
        for c in range(4):
            assert np.array_equal(np.concatenate([e[c] for e in expected]), got.numpy()[c])
        assert host.state() == device.state()
    least_overflowing, least_dropped = (20, 3000) if host.budget == 30 else (3, 100)
    assert overflowing > least_overflowing and host.dropped > least_dropped, (overflowing, host.dropped)


def test_no_millisecond_passes_more_than_the_cap():
    cap = 2e5
    lim = readout.ReadoutLimiter(cap, seed=1)
    kept = []
    for _, _, _, _, t, _ in _steps(np.random.default_rng(2), steps=60):
        kept.append(t[lim.filter(t)])
    kept = np.concatenate(kept)
    window_counts = np.searchsorted(kept, kept + 1000, side="left") - np.arange(len(kept))   # [t, t + 1 ms)
    assert window_counts.max() <= cap * 1e-3 and len(kept) > 0.5 * cap * 1e-3 * 60 * 1.5


def test_survivors_of_an_overfull_bin_are_not_biased_in_time():
    """A flood of events spread evenly over each bin: the first and the second half of a bin keep alike (a
    limiter that kept the earliest would keep only first halves)."""
    lim = readout.ReadoutLimiter(1e5, seed=3)              # budget 10 an event bin of 111 us
    first_half = second_half = 0
    for s in range(200):
        t = np.sort(np.random.default_rng(s).integers(s * 1000, s * 1000 + 1000, 400)).astype(np.int64)
        keep = lim.filter(t)
        phase = np.mod(t, lim.bin_us) / lim.bin_us
        first_half += int(np.count_nonzero(keep & (phase < 0.5)))
        second_half += int(np.count_nonzero(keep & (phase >= 0.5)))
    total = first_half + second_half
    assert total > 10_000 and abs(first_half - second_half) < 0.05 * total


def test_keys_agree_on_both_sides_and_are_uniform():
    import mitsuba as mi
    word = readout.step_word(11, 5)
    k = readout.keys_np(200_000, word)
    import drjit as dr
    assert np.array_equal(k, readout.keys_dr(mi, dr.arange(mi.UInt32, 200_000), mi.UInt32(word)).numpy())
    assert abs(k.mean() / 2**32 - 0.5) < 0.005 and len(np.unique(k)) > 199_000
    assert not np.array_equal(k, readout.keys_np(200_000, readout.step_word(11, 6)))


def test_a_capped_pixel_keeps_its_events_on_the_device_and_its_state_in_a_checkpoint():
    import mitsuba as mi
    from mitsuba_eventfield.errors import ConfigError
    from mitsuba_eventfield.plugins import event_fill, pixel_state
    from mitsuba_eventfield.plugins.event_integrator import device_path
    integ = mi.load_dict({"type": "eventfield", "readout_cap": 3e5})
    rng = np.random.default_rng(4)
    with device_path():
        for s in range(4):
            integ.stage_log(mi.Float((rng.random(40 * 30) * 4).astype(np.float32)), (40, 30))
            events = integ.commit_events(s * 1e-3, (s + 1) * 1e-3)
            assert isinstance(events, event_fill.DeviceEvents)
    assert integ.readout_dropped() > 100
    state = integ.get_state()
    other = mi.load_dict({"type": "eventfield", "readout_cap": 3e5})
    other.set_state(state)
    assert other.limiter.state() == integ.limiter.state()
    old = dict(state, limiter=np.array('{"rng": {}, "open_bin": 3, "used": 1, "dropped": 0}'))
    with pytest.raises(ConfigError, match="random generator"):
        pixel_state.set_state(other, old)


def test_events_outside_their_step_are_refused_not_scattered_out_of_bounds():
    """The device limiter sizes its bin counts from the step's interval; events spanning more are a caller's
    error, refused in one line (the counting scatter is masked, so nothing is written out of bounds)."""
    import drjit as dr
    import mitsuba as mi
    t = np.sort(np.random.default_rng(0).integers(0, 100_000, 1000)).astype(np.int64)
    events = _device_events(mi, dr, np.zeros(1000, np.uint32), np.zeros(1000, np.uint32), t, np.ones(1000, np.int8))
    with pytest.raises(ValueError, match=r"events span \d+ bins, more than their steps .* allow \(13\)"):
        readout.ReadoutLimiter(3e5).filter_device(events, [1000], 0.0, 0.001)
