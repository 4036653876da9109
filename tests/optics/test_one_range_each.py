"""A parameter checked in several places has one range (optics.galvo.checked_optics, validate.MAX_THRESHOLD):
a nominal optics file took fov 200 deg (a negative focal length) and refused a mirror separation of 0, which
the sensor renders; --contrast took any positive number and a stream's own thresholds were not checked at all
(0 divided the reconstruction's levels by zero)."""
import json
import os

import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield import cli
from mitsuba_eventfield.calibration.nominal import nominal_optics
from mitsuba_eventfield.lightfield.reconstruct import thresholds

GALVO = os.path.join(ROOT, "scenes", "led_depth", "led.xml")   # declares fov and both mirror distances
SCAN = {"curve": "circle", "frequency": 250.0, "amplitude": 0.5, "phase": 0.0}


def _nominal(tmp_path, **fields):
    path = tmp_path / "optics.json"
    path.write_text(json.dumps({"design": "galvo", "fov_x_deg": 40.0, "mirror_distance": 0.1,
                                "mirror_separation": 0.01, "scan": SCAN, **fields}))
    return str(path)


def test_galvo_optics_have_one_range_in_the_sensor_and_in_a_nominal_file(tmp_path):
    # both mirrors at one pivot: the sensor renders it, and a nominal file now takes it too
    assert nominal_optics(_nominal(tmp_path, mirror_separation=0.0), 64, 48)["mirror_separation"] == 0.0
    ef.load_scene(GALVO, width=16, height=12, mirror_separation=0.0)
    with pytest.raises(ef.EventFieldError, match=r"optics.json: fov_x_deg = 200(\.0)?: allowed range is \(0, 180\) "
                                                 r"degrees"):
        nominal_optics(_nominal(tmp_path, fov_x_deg=200.0), 64, 48)
    ef.load_scene(GALVO, width=16, height=12, fov=179.5)           # (Mitsuba itself refuses 180 and above)
    from mitsuba_eventfield.optics.galvo import checked_optics
    with pytest.raises(ValueError, match=r"sensor 'galvo': fov = 180\.0: allowed range is \(0, 180\) degrees"):
        checked_optics(180.0, 0.1, 0.0, "sensor 'galvo'", ValueError, ("fov", "mirror_distance", "mirror_separation"))
    with pytest.raises(ef.EventFieldError, match=r"mirror_distance = -0\.1: allowed range is \[0, 10\]"):
        nominal_optics(_nominal(tmp_path, mirror_distance=-0.1), 64, 48)
    # millimetres written as metres: refused where they are written, not at the first depth searched
    with pytest.raises(ef.EventFieldError, match=r"optics\.json: mirror_distance = 200(\.0)?: allowed range is "
                                                 r"\[0, 10\]"):
        nominal_optics(_nominal(tmp_path, mirror_distance=200.0), 64, 48)
    with pytest.raises(ef.EventFieldError, match=r"mirror_distance = 200(\.0)?: allowed range is \[0, 10\]"):
        ef.load_scene(GALVO, width=16, height=12, mirror_distance=200.0)


def test_contrast_thresholds_have_the_renders_range_wherever_they_come_from(tmp_path, capsys):
    stream = ef.EventStream([1, 2], [1, 2], [10, 20], [1, -1], 8, 6,
                            meta={"pixel_model": {"threshold_on": 0.0, "threshold_off": 0.2}})
    with pytest.raises(ef.EventFieldError, match=r"contrast threshold c_on = 0\.0: allowed range is \(0, 10\]"):
        thresholds(stream)
    assert thresholds(stream, c_on=0.3) == (0.3, 0.2)
    with pytest.raises(ef.EventFieldError, match=r"c_off = 11: allowed range is \(0, 10\]"):
        thresholds(stream, 0.2, 11)
    path = str(tmp_path / "e.h5")
    ef.write_events(path, stream)
    assert cli.main(["reconstruct", path, "-o", str(tmp_path / "r.npz"), "--contrast", "11"]) == 2
    assert "--contrast" in capsys.readouterr().err and not (tmp_path / "r.npz").exists()


@pytest.mark.parametrize("scan, missing", [
    ({"curve": "circle", "amplitude": 2.0}, "frequency"),
    ({"curve": "circle", "frequency": 100.0}, "amplitude"),
    ({"curve": "lissajous", "freq_x": 100.0, "freq_y": 100.0, "amplitude_x": 1.0}, "amplitude_y"),
])
def test_a_nominal_scan_without_its_rate_or_size_is_refused(tmp_path, scan, missing):
    """A recording's scan record without its frequency took 250 Hz (a 100 Hz rig's cards read at 0.94 / 0.73 m
    for 0.5 / 1.2), without its amplitude 1 deg: defaults for curves built in code, not any rig's. Refused in
    one line as a missing optics field is; a record that gives them (phase left out) is taken."""
    with pytest.raises(ef.EventFieldError) as e:
        nominal_optics(_nominal(tmp_path, scan=scan), 64, 48)
    assert f"optics.json: scan: a {scan['curve']} record without {missing} (it needs " in str(e.value)
    assert "\n" not in str(e.value)
    taken = nominal_optics(_nominal(tmp_path, scan={"curve": "circle", "frequency": 100.0, "amplitude": 2.0}), 64, 48)
    assert taken["scan"]["frequency"] == 100.0
