"""The ideal pixel's pure functions on hand-computed cases."""
import numpy as np
import pytest

import mitsuba_eventfield  # noqa: F401  (configures Dr.Jit)
from mitsuba_eventfield.plugins import pixel_model as pm


def test_several_crossings_in_one_step_are_timed_by_interpolation():
    # L goes 0 -> 0.65 over (0, 1] s with C = 0.2: ON events at 0.2, 0.4, 0.6 -> t = 0.2/0.65, ...
    pix, t, p = pm.expand_crossings([5], [3], [0.0], [0.65], [0.0], [0.2], [0.2], 0.0, 1.0)
    assert list(pix) == [5, 5, 5] and list(p) == [1, 1, 1]
    assert np.allclose(t, np.array([0.2, 0.4, 0.6]) / 0.65)


def test_off_events_below_reference():
    # reference 0.1 (last event), L from 0.05 to -0.5, C_off = 0.3: OFF at -0.2 only
    pix, t, p = pm.expand_crossings([0], [-1], [0.05], [-0.5], [0.1], [0.2], [0.3], 2.0, 3.0)
    assert list(p) == [-1]
    assert np.allclose(t, 2.0 + (0.05 + 0.2) / 0.55)


def test_count_crossings_and_exact_reference():
    import drjit as dr
    import mitsuba as mi
    n = pm.count_crossings(dr, mi.Int32, mi.Float([0.65, -0.45, 0.1]), mi.Float([0.0, 0.0, 0.0]),
                           mi.Float([0.2] * 3), mi.Float([0.2] * 3))
    assert list(n.numpy()) == [3, -2, 0]
    # the reference is a function of the integer counts: up 3 and down 3 is exactly back to the anchor
    c = mi.Float([0.2, 0.2, 0.3])
    ref = pm.reference_level(dr, mi.Float, mi.Float([0.1234567] * 3), mi.Int32([3, 5, 3]), mi.Int32([3, 2, 3]),
                             c, mi.Float([0.2, 0.2, 0.2]))
    assert ref.numpy()[0] == np.float32(0.1234567)
    assert np.isclose(ref.numpy()[1], 0.1234567 + 3 * 0.2)
    assert np.isclose(ref.numpy()[2], 0.1234567 + 3 * 0.3 - 3 * 0.2)


def test_linlog_is_continuous_and_finite():
    i = np.array([0.0, 5e-4, 1e-3, 2e-3])
    v = pm.linlog_np(i, 1e-3)
    assert np.isfinite(v).all()
    assert np.isclose(v[2], np.log(1e-3)) and np.isclose(v[3], np.log(2e-3))
    assert np.isclose(v[1], np.log(1e-3) - 0.5)


def test_device_crossing_times_equal_the_host_twins_to_the_bit():
    """event_select.crossing_time (every device path) and pixel_model.expand_crossings (the host path) give the
    same float64 seconds, bit for bit, before any rounding to microseconds: the host and device events can only
    be identical if the twins are (a division on one side and a multiply by the reciprocal on the other differ
    by an ulp in about a quarter of these times: this test fails then). Random steps with up to five crossings, both polarities, per
    pixel thresholds, and flat steps (an infinite 1 / rise)."""
    import mitsuba as mi

    from mitsuba_eventfield.plugins.event_select import crossing_time, inverse_rise
    rng = np.random.default_rng(11)
    size = 4000
    lp = rng.normal(0.0, 1.0, size).astype(np.float32)
    ln = (lp + rng.normal(0.0, 0.6, size)).astype(np.float32)
    ln[:20] = lp[:20]
    ref = (lp + rng.uniform(-0.2, 0.2, size)).astype(np.float32)
    c_on, c_off = (rng.uniform(0.1, 0.3, size).astype(np.float32) for _ in range(2))
    n = rng.integers(1, 6, size) * rng.choice([-1, 1], size)
    t0, t1 = 0.0, 1 / 2000          # from 0: a later t0's own rounding would absorb a fraction's ulp
    pix, t_host, _ = pm.expand_crossings(np.arange(size), n, lp, ln, ref, c_on, c_off, t0, t1)
    counts = np.abs(n)
    k = np.arange(len(pix)) - (np.cumsum(counts) - counts)[pix] + 1
    lp_d, ref_d = mi.Float64(lp[pix].astype(np.float64)), mi.Float64(ref[pix].astype(np.float64))
    step = np.where(n > 0, c_on, c_off)[pix].astype(np.float64)
    t_dev = crossing_time(mi.Int64(k), mi.Int32(np.sign(n)[pix].astype(np.int32)), lp_d,
                          inverse_rise(lp_d, mi.Float64(ln[pix].astype(np.float64))), ref_d, mi.Float64(step),
                          mi.Float64(t0), mi.Float64(t1))
    assert len(t_host) == counts.sum() > 10_000
    assert np.array_equal(t_dev.numpy(), t_host)


def test_the_linlog_inverse_has_one_numpy_twin_that_light_fields_use():
    """A lin-log level below the knee is not exp's: a reconstruction's dark view (zero radiance) came back as
    0.37 of the knee's radiance through a light field's plain exp."""
    import drjit as dr
    import mitsuba as mi

    from mitsuba_eventfield.lightfield.model import from_galvo
    from mitsuba_eventfield.plugins.pixel_model import linlog_inverse, linlog_inverse_np, linlog_np
    knee = 1e-3
    radiance = np.array([0.0, 1e-5, 5e-4, 1e-3, 0.02, 3.0])
    levels = linlog_np(radiance, knee)
    assert linlog_inverse_np(levels, knee) == pytest.approx(radiance, abs=1e-15, rel=1e-12)
    assert linlog_inverse_np(levels, knee) == pytest.approx(
        np.asarray(linlog_inverse(dr, mi.Float(levels.astype(np.float32)), knee)), rel=1e-5, abs=1e-9)
    optics = {"design": "galvo", "fov_x_deg": 40.0, "mirror_distance": 0.1, "mirror_separation": 0.01,
              "scan": {"curve": "circle", "frequency": 250.0, "amplitude": 0.5, "phase": 0.0}}
    views = np.broadcast_to(radiance, (2, 4, 6))
    lf = from_galvo(linlog_np(views, knee), [0.0, 0.002], optics, linear_below=knee)
    assert lf.views == pytest.approx(views, abs=1e-15, rel=1e-12)
    assert from_galvo(linlog_np(views, knee), [0.0, 0.002], optics).views[0, 0, 0] == pytest.approx(knee / np.e)
