"""One scan envelope (mitsuba_eventfield/optics/envelope.py): the simulator refuses exactly the scans the device
layer refuses, with the same reason, and accepts the rest; a scene names the galvo model it simulates."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import mitsuba_eventfield as ef
from mitsuba_eventfield.device import GalvoController, GalvoSpec, SafetyError
from mitsuba_eventfield.optics import scan
from mitsuba_eventfield.optics.envelope import GALVO_MODELS, EnvelopeError


def _simulator(kind, params, volts_per_deg=None):
    """None if a scene's galvo sensor renders this scan (its own code path, without Mitsuba), else its refusal."""
    from mitsuba_eventfield.plugins.galvo_sensor import curve_from_props
    props = dict(params, curve=kind)
    if volts_per_deg is not None:
        props["volts_per_deg"] = volts_per_deg
    try:
        curve_from_props(props)
        return None
    except EnvelopeError as e:
        return str(e)


def _raw_curve(kind, params):
    """The curve as plain geometry, built without any check (what a buggy caller could hand the device)."""
    if kind == "circle":
        return scan.circle(**params)
    if kind == "line":
        f, a = params["frequency"], params["amplitude"]
        x = params["axis"] == "x"
        return scan.Lissajous(freq_x=f, freq_y=f, amplitude_x=a if x else 0.0, amplitude_y=0.0 if x else a,
                              phase_x=0.0, phase_y=0.0, kind="line")
    return scan.Lissajous(**params)


def _device(kind, params, volts_per_deg=0.8):
    """None if the device layer would drive this scan, else its refusal (plan(): nothing is connected)."""
    try:
        GalvoController(None, "keysight", GalvoSpec(volts_per_deg=volts_per_deg)).plan(_raw_curve(kind, params))
        return None
    except SafetyError as e:
        return str(e)


scans = st.one_of(
    st.tuples(st.just("circle"), st.fixed_dictionaries({
        "frequency": st.floats(1, 3000), "amplitude": st.floats(0, 14), "phase": st.floats(-300, 300),
        "offset_x": st.floats(-13, 13), "offset_y": st.floats(-13, 13)})),
    st.tuples(st.just("line"), st.fixed_dictionaries({
        "frequency": st.floats(1, 3000), "amplitude": st.floats(0, 14), "axis": st.sampled_from("xy")})),
    st.tuples(st.just("lissajous"), st.fixed_dictionaries({
        "freq_x": st.floats(1, 3000), "freq_y": st.floats(1, 3000), "amplitude_x": st.floats(-1, 14),
        "amplitude_y": st.floats(0, 14), "phase_x": st.floats(-400, 400), "phase_y": st.floats(-300, 300)})))


@settings(max_examples=400, deadline=None)
@given(scans, st.sampled_from([None, 0.5, 0.8, 1.0]))
def test_the_simulator_refuses_what_the_device_refuses_with_the_same_reason(request, volts_per_deg):
    """Two code paths: the scene sensor's (curve_from_props -> make_curve -> the envelope) and the device's
    (plan(): per-axis sines -> GalvoSpec with the rig's driver scaling), on curves built without any check."""
    kind, params = request
    simulated = _simulator(kind, params, volts_per_deg)
    driven = _device(kind, params, 0.8 if volts_per_deg is None else volts_per_deg)
    # the one envelope gives both the same verdict; the device alone also refuses what no generator plays
    # (device.spec.check_playable: a sine under 1 mVpp at the first ramp step), which a simulated mirror shows
    generator_only = driven is not None and "smallest sine" in driven
    assert (simulated is None) == (driven is None or generator_only), (kind, params, volts_per_deg, simulated,
                                                                       driven)
    if driven is not None and not generator_only:
        assert simulated == f"sensor 'galvo': {driven}"


@pytest.mark.parametrize("frequency, amplitude, refused", [
    (30.0, 12.0, False), (100.0, 7.0, False), (250.0, 2.0, False), (250.0, 2.2, True),
    (1000.0, 0.2, False), (1000.0, 0.21, True), (1200.0, 0.05, True)])
def test_derating_points_both_ways(frequency, amplitude, refused):
    """The GVS01x-class figures: 12.5 deg to 35 Hz, 6.25 deg at 130 Hz, 0.2 deg at 1 kHz, log-log between."""
    params = {"frequency": frequency, "amplitude": amplitude}
    assert (_simulator("circle", params) is not None) == refused
    assert (_device("circle", params) is not None) == refused


def test_a_scene_sensor_refuses_like_the_device_and_names_its_model():
    import mitsuba as mi
    film = {"type": "hdrfilm", "width": 8, "height": 8}
    params = {"frequency": 500.0, "amplitude": 1.5}
    driven = _device("circle", params)
    assert driven is not None and "derated limit" in driven
    with pytest.raises(Exception) as refused:
        mi.load_dict({"type": "galvo", "film": film, **params})
    assert "sensor 'galvo': " + driven in str(refused.value)
    # the rig's driver scaling: at 1 V/deg, 11 deg at 10 Hz is 11 V, beyond the +-10 V input
    slow = {"frequency": 10.0, "amplitude": 11.0}
    assert _simulator("circle", slow) is None and _device("circle", slow) is None
    driven = _device("circle", slow, 1.0)
    assert "11 V exceeds the +-10 V command input" in driven
    assert _simulator("circle", slow, 1.0) == f"sensor 'galvo': {driven}"
    with pytest.raises(Exception, match="11 V exceeds"):
        mi.load_dict({"type": "galvo", "film": film, "volts_per_deg": 1.0, **slow})
    # the ideal mirror renders it, and the event metadata records which galvo was simulated
    ideal = mi.load_dict({"type": "galvo", "film": film, "galvo_model": "ideal", **params})
    assert ideal.scan_description["galvo_model"] == "ideal"
    assert mi.load_dict({"type": "galvo", "film": film}).scan_description["galvo_model"] == "gvs01x"


def test_a_lightly_damped_mirror_may_not_overshoot_its_travel():
    ef.make_curve("circle", frequency=100.0, amplitude=5.0, bandwidth_hz=100.0, damping=0.7)
    with pytest.raises(EnvelopeError, match="as the mirror responds .* exceeds the mechanical travel"):
        ef.make_curve("circle", frequency=100.0, amplitude=5.0, bandwidth_hz=100.0, damping=0.1)   # 25 deg


def test_tabulated_scans_are_checked_conservatively():
    """A raster's fast axis is a triangle at its frequency: derated like a sine of that frequency (a triangle
    needs more acceleration, never less); the Moore curve by its faster axis's back-and-forth rate."""
    limit = GALVO_MODELS["gvs01x"].derated_amplitude_deg(400.0)
    ef.make_curve("raster", frequency=400.0, lines=4, amplitude_x=0.95 * limit, amplitude_y=0.5)
    with pytest.raises(EnvelopeError, match="raster scan: amplitude .* at 400 Hz"):
        ef.make_curve("raster", frequency=400.0, lines=4, amplitude_x=1.05 * limit, amplitude_y=0.5)
    moore = ef.make_curve("moore", frequency=10.0, order=3, amplitude=1.0)
    assert moore.fundamental_hz() > 10.0 * 3            # order 3: the x axis turns back many times per period
    assert math.isclose(ef.make_curve("moore", frequency=10.0, order=3, amplitude=1.0,
                                      galvo_model="ideal").peak_angle_deg(), 1.0)


def test_metadata_round_trip_keeps_the_model_and_old_records_read_as_ideal():
    curve = ef.make_curve("circle", frequency=250.0, amplitude=1.0)
    d = ef.scan.curve_to_dict(curve)
    assert d["galvo_model"] == "gvs01x" and d["max_angle_deg"] == 12.5
    assert ef.curve_from_dict(d).galvo_model == "gvs01x"
    old = {"curve": "circle", "frequency": 1000.0, "amplitude": 0.5, "phase": 0.0, "max_angle_deg": 10.0}
    assert ef.curve_from_dict(old).galvo_model == "ideal"       # written before galvo models: still readable
    np.testing.assert_allclose(ef.curve_from_dict(old).angles(np.array([0.0]))[1], 0.0)
