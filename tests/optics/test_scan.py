"""Scan curves: geometry, derivatives, periods, inverse time, NumPy = Dr.Jit, bandwidth, validation."""
import math
import re

import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.optics import envelope, scan, tabulated

CURVES = {
    "circle": dict(frequency=250.0, amplitude=2.0, phase=30.0),
    "lissajous": dict(freq_x=300.0, freq_y=200.0, amplitude_x=1.5, amplitude_y=1.0, phase_x=10.0, phase_y=50.0),
    "line": dict(frequency=100.0, amplitude=1.0, axis="x"),
    "raster": dict(frequency=400.0, lines=4, amplitude_x=0.8, amplitude_y=0.5),   # inside the 400 Hz envelope
    "moore": dict(frequency=20.0, order=3, amplitude=1.0),
}
PERIODS = {"circle": 1 / 250, "lissajous": 1 / 100, "line": 1 / 100, "raster": 4 / 400, "moore": 1 / 20}


@pytest.mark.parametrize("name", sorted(CURVES))
def test_period_and_periodicity(name):
    c = scan.make_curve(name, **CURVES[name])
    assert math.isclose(c.period, PERIODS[name], rel_tol=1e-12)
    t = np.linspace(0, c.period, 777)
    a0, a1 = np.array(c.angles(t)), np.array(c.angles(t + c.period))
    assert np.allclose(a0, a1, atol=1e-12)


@pytest.mark.parametrize("name", sorted(CURVES))
def test_velocity_is_the_derivative(name):
    c = scan.make_curve(name, **CURVES[name])
    t = np.linspace(0, c.period, 501)[1:-1] + 1e-7        # away from table knots
    h = 1e-9
    num = (np.array(c.angles(t + h)) - np.array(c.angles(t - h))) / (2 * h)
    assert np.allclose(np.array(c.velocity(t)), num, rtol=1e-4, atol=1e-6 * np.abs(num).max())


def test_circle_geometry_and_time_of():
    c = scan.make_curve("circle", frequency=250.0, amplitude=2.0, phase=30.0)
    t = np.linspace(0, c.period, 100)
    x, y = c.angles(t)
    assert np.allclose(np.hypot(x, y), math.radians(2.0))
    assert np.allclose(np.arctan2(y[0], x[0]), math.radians(30.0))
    for t0 in (0.0, 0.0011, 0.0037):
        assert abs(c.time_of(c.angles(t0)) - t0) < 1e-12
    assert c.peak_angle_deg() == pytest.approx(2.0)


def test_lissajous_self_crossings_have_several_times():
    c = scan.make_curve("lissajous", freq_x=300.0, freq_y=200.0, amplitude_x=1.0, amplitude_y=1.0,
                        phase_x=0.0, phase_y=0.0)
    ts = c.times_of((0.0, 0.0))      # the origin is crossed more than once per period
    assert len(ts) >= 2
    for t in ts:
        assert np.allclose(c.angles(t), (0.0, 0.0), atol=1e-12)


@pytest.mark.parametrize("name", sorted(CURVES))
def test_numpy_and_drjit_agree(name):
    import mitsuba as mi
    c = scan.make_curve(name, **CURVES[name])
    t = np.linspace(0, 2 * c.period, 1001)
    a_np = np.array(c.angles(t))
    a_dr = np.array([np.array(v) for v in c.angles(mi.Float(t.astype(np.float32)))])
    a_np32 = np.array(c.angles(t.astype(np.float32).astype(np.float64)))
    atol = 2e-6 * np.abs(a_np).max()
    if isinstance(c, scan.Lissajous):
        # a sinusoid's float32 argument w t + phi is rounded before the sine, an error that grows with |arg|
        # (up to about |arg| 2^-22 rad after the multiply, the add and w's own rounding), and CUDA's sine is the
        # hardware's sin.approx.f32 (absolute error <= 2^-20.5 for |arg| <= 100 pi, PTX ISA): the bound is the
        # amplitude times their sum. Lissajous here: |arg| <= 38 rad, 2.6e-7 rad (a pixel is ~1e-3 rad); a wrong
        # frequency, phase or amplitude errs by 1e-3 of the amplitude or more.
        wx, wy, ax, ay, px, py, _, _ = c._params()
        arg = max(abs(wx) * t.max() + abs(px), abs(wy) * t.max() + abs(py))
        atol = max(atol, max(abs(ax), abs(ay)) * (arg * 2.0 ** -22 + 2.0 ** -20))
    assert np.allclose(a_dr, a_np32, atol=atol), np.abs(a_dr - a_np32).max()


def test_moore_curve_is_closed_space_filling_and_unit_step():
    v = tabulated.moore_vertices(3)
    assert len(v) == 4 ** 3
    step = np.diff(np.vstack([v, v[:1]]), axis=0)
    assert np.allclose(np.abs(step).sum(axis=1), 2 / 7)      # unit grid moves, including the closing one
    assert len({tuple(p) for p in np.round(v, 9)}) == 64     # visits every cell once


def test_bandwidth_shrinks_and_delays():
    cmd = scan.make_curve("circle", frequency=250.0, amplitude=2.0)
    # critically damped second order: gain falls and lag grows monotonically with f / fn
    # (at zeta 0.7 the gain peaks slightly above 1 at low f / fn)
    slow = scan.make_curve("circle", frequency=250.0, amplitude=2.0, bandwidth_hz=2500.0, damping=1.0)
    fast = scan.make_curve("circle", frequency=250.0, amplitude=2.0, bandwidth_hz=500.0, damping=1.0)
    h = envelope.second_order_response(250.0, 500.0, 1.0)
    assert abs(h) == pytest.approx(1 / (1 + 0.5 ** 2))                 # |H| = 1 / (1 + (f/fn)^2) at zeta 1
    assert fast.amplitude_x == pytest.approx(2.0 * abs(h))
    assert fast.amplitude_x < slow.amplitude_x < cmd.amplitude_x
    assert fast.phase_x < slow.phase_x < cmd.phase_x
    # tabulated curves are filtered harmonic by harmonic: a pure sine table gets the same gain
    r = scan.make_curve("raster", frequency=100.0, lines=2, amplitude_x=1.0, amplitude_y=1.0, bandwidth_hz=300.0)
    assert r.peak_angle_deg() < 1.0


@pytest.mark.parametrize("kwargs, message", [
    # the range names the galvo's own ceiling (it said (0, inf) while 1000 Hz was refused as over the limit)
    (dict(name="circle", frequency=0.0), "frequency (Hz) = 0.0: allowed range is (0, 1000]"),
    (dict(name="circle", frequency=2000.0), "2000 Hz is above the galvo's 1000 Hz limit"),
    (dict(name="raster", frequency=math.inf, lines=2), "frequency (Hz) = inf: must be a finite number in (0, 1000]"),
    (dict(name="moore", frequency=math.inf), "frequency (Hz) = inf: must be a finite number in (0, 1000]"),
    (dict(name="circle", frequency=-5.0), "frequency (Hz) = -5.0"),
    (dict(name="circle", amplitude=12.0), "amplitude 12 deg at 250 Hz exceeds the galvo's derated limit"),
    (dict(name="circle", amplitude=12.0, galvo_model="ideal"), "exceeds the mechanical travel of +-10 deg"),
    (dict(name="spiral"), "unknown curve 'spiral'; allowed: circle, lissajous, line, raster, moore"),
    (dict(name="circle", freq_x=3.0), "'freq_x' does not apply to a circle scan"),
    (dict(name="moore", order=12), "order = 12: allowed range is [1, 8]"),
])
def test_validation(kwargs, message):
    name = kwargs.pop("name")
    with pytest.raises(ef.ConfigError, match=re.escape(message)):
        scan.make_curve(name, **kwargs)


@pytest.mark.parametrize("name", sorted(CURVES))
def test_dict_round_trip(name):
    c = scan.make_curve(name, bandwidth_hz=800.0, **CURVES[name])
    d = scan.curve_to_dict(scan.make_curve(name, **CURVES[name]), 800.0, 0.7)
    c2 = scan.curve_from_dict(d)
    t = np.linspace(0, c.period, 50)
    assert np.allclose(np.array(c.angles(t)), np.array(c2.angles(t)))


@pytest.mark.parametrize("name", ["raster", "moore"])
def test_filtered_table_keeps_its_bandwidth_through_a_dict(name):
    """A table that is already filtered must not come back unfiltered (the mirror's lag would vanish)."""
    filtered = scan.make_curve(name, bandwidth_hz=300.0, **CURVES[name])
    back = scan.curve_from_dict(scan.curve_to_dict(filtered))
    t = np.linspace(0, filtered.period, 50)
    assert np.allclose(np.array(filtered.angles(t)), np.array(back.angles(t)))
    commanded = scan.make_curve(name, **CURVES[name])
    assert not np.allclose(np.array(commanded.angles(t)), np.array(back.angles(t)), atol=1e-3)


def test_phase_time_is_exact_one_period_apart():
    """Instants one period apart give the same sensor time (what makes period reuse bit-exact), also where
    fmod lands a hair below the period."""
    c = scan.make_curve("circle", frequency=250.0, amplitude=1.0)
    dt = c.period / 20
    for k in range(0, 2000, 7):
        assert c.phase_time(k * dt) == c.phase_time((k + 20) * dt)
        assert 0.0 <= c.phase_time(k * dt) < c.period
    assert c.phase_time(0.2) == 0.0 and c.phase_time(50 * c.period) == 0.0


def test_a_one_frequency_curve_has_its_period_at_any_frequency_and_counts_are_whole():
    """A circle or line repeats every 1 / f whatever f is (1e-5 Hz and 123.4567891 Hz had no period: no fraction
    with a denominator under 10,000 came near them, so their scenes counted as aperiodic); a raster's lines and
    a Moore curve's order are counts (lines = 2.5 made 2 lines); a bandwidth is 0 (an ideal mirror) or > 0."""
    for f in (1e-5, 123.4567891, 250.0):
        assert ef.make_curve("circle", frequency=f, amplitude=0.5).period == pytest.approx(1 / f, rel=1e-12)
        assert ef.make_curve("line", frequency=f, amplitude=0.5).period == pytest.approx(1 / f, rel=1e-12)
    assert ef.make_curve("lissajous", freq_x=100, freq_y=150, amplitude_x=0.5, amplitude_y=0.5).period == \
        pytest.approx(0.02)
    with pytest.raises(ef.EventFieldError, match=r"scan: lines = 2\.5: must be a whole number \[1, 65536\]"):
        ef.make_curve("raster", frequency=100, amplitude_x=0.2, amplitude_y=0.2, lines=2.5)
    assert ef.make_curve("raster", frequency=100, amplitude_x=0.2, amplitude_y=0.2, lines=3.0).period == \
        pytest.approx(0.03)
    with pytest.raises(ef.EventFieldError, match=r"bandwidth \(Hz; 0: an ideal mirror\) = -1: allowed range is "
                                                 r"\[0, inf\)"):
        ef.make_curve("circle", frequency=100, amplitude=0.5, bandwidth_hz=-1)
