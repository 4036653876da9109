"""A scene author's typing slips in the sensor plugins' parameters (``plugins/properties.py``): one line naming
the plugin, the parameter, the value and the allowed range, where Python's own message named none of them
("could not convert string to float: 'two'"), a count was cut without a word (4.7 lines became 4) or a huge one
ran out of memory (lines = 1e8: 95 GiB); and the kaleidoscope's documented defaults hold."""
import re

import pytest


def _mi():
    import mitsuba as mi
    return mi


def _load(sensor_type, film=(96, 96), **params):
    mi = _mi()
    sensor = dict({"type": sensor_type, "film": {"type": "hdrfilm", "width": film[0], "height": film[1]}}, **params)
    return mi.load_dict({"type": "scene", "sensor": sensor}).sensors()[0]


@pytest.mark.parametrize("params, message", [
    ({"amplitude": "two"}, "sensor 'galvo': amplitude = 'two': must be a number"),
    ({"focus_distance": "far"}, "sensor 'galvo': focus_distance = 'far': must be a number (0, inf)"),
    ({"curve": "raster", "lines": 4.7}, "sensor 'galvo': lines = 4.7: must be a whole number"),
    ({"curve": "raster", "lines": 100_000_000}, "sensor 'galvo': lines = 100000000: allowed range is [1, 65536]"),
    ({"curve": "raster", "lines": 65536, "samples_per_line": 256},
     "lines = 65536, samples_per_line = 256: a table of 33554432 points; at most 2097152"),
    ({"curve": "moore", "order": 8, "samples_per_segment": 1000}, "a table of 65536000 points; at most 2097152"),
    ({"fov": 0.0}, "sensor 'galvo': fov = 0.0: allowed range is (0, 180]"),
    ({"fov": 180.0}, "sensor 'galvo': fov = 180: allowed range is (0, 180) degrees"),
    ({"damping": -1.0}, "sensor 'galvo': damping = -1.0: allowed range is (0, inf)"),
    ({"max_angle": "wide"}, "sensor 'galvo': max_angle = 'wide': must be a number"),
])
def test_galvo_parameters_are_named_with_their_range(params, message):
    with pytest.raises(Exception, match=re.escape(message)):
        _load("galvo", **params)


@pytest.mark.parametrize("params, message", [
    ({"focal_length": "fifty"}, "sensor 'kaleidoscope': focal_length = 'fifty': must be a number"),
    ({"layout": "microlens", "views": 3.5}, "sensor 'kaleidoscope': views = 3.5: must be a whole number [1, inf)"),
    ({"layout": "microlens", "tube_width": 0.0}, "sensor 'kaleidoscope': tube_width = 0.0: allowed range is (0, inf)"),
    ({"layout": "microlens", "mode": "tube_only"}, "mode = 'tube_only': the tube's validation modes need layout"),
    ({"layout": "microlens", "tube_length": 0.05, "relay_distance": 0.02},
     "sensor 'kaleidoscope': tube_length, relay_distance: the kaleidoscope's tube and relay, not used by layout = "
     "'microlens'"),
])
def test_kaleidoscope_parameters_are_named(params, message):
    with pytest.raises(Exception, match=re.escape(message)):
        _load("kaleidoscope", **params)


def test_a_numeric_string_and_a_whole_float_are_their_numbers():
    """As Mitsuba reads its own XML defaults: "0.2" is 0.2, 8.0 lines are 8."""
    galvo = _load("galvo", curve="raster", lines=8.0, mirror_distance="0.05")
    assert galvo.mirror_distance == 0.05 and galvo.scan_description["lines"] == 8


def test_the_tube_height_defaults_to_the_width_times_the_film_aspect():
    """The documented default: tube_width 0.02 on a square film made a 0.02 x 0.012 tube (the default width's
    height), which the aspect check then refused."""
    square = _load("kaleidoscope", tube_width=0.02)
    assert square.tube_height == pytest.approx(0.02)
    wide = _load("kaleidoscope", film=(96, 48), tube_width=0.02)
    assert wide.tube_height == pytest.approx(0.01)


def test_a_scan_that_hardly_repeats_is_named_when_the_scene_loads():
    """100 and 141.4213562 Hz repeat every 3207.5 s: the render was silent and refocus said so only later."""
    from mitsuba_eventfield.plugins.galvo_sensor import ScanPeriodWarning
    with pytest.warns(ScanPeriodWarning, match=r"the lissajous scan repeats only every 3208 s"):
        _load("galvo", curve="lissajous", freq_x=100.0, freq_y=141.4213562)
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error", ScanPeriodWarning)
        _load("galvo", curve="lissajous", freq_x=200.0, freq_y=300.0)          # 10 ms: no word


@pytest.mark.parametrize("params, message", [
    ({"threshold": "two"}, "integrator 'eventfield': threshold = 'two': must be a number"),
    ({"seed": 4.7}, "integrator 'eventfield': seed = 4.7: must be a whole number"),
])
def test_the_event_integrators_numbers_are_named(params, message):
    mi = _mi()
    with pytest.raises(Exception, match=re.escape(message)):
        mi.load_dict({"type": "scene", "integrator": dict({"type": "eventfield"}, **params),
                      "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 8, "height": 8}}})
