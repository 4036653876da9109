"""The ideal pixel's pure functions on hand-computed cases."""
import numpy as np

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
