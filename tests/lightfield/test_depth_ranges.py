"""Depth from focus measures planes beyond the range searched (``focus.depth._outer_planes``); every one of them
must be a depth the light field refocuses at (``LightField.depth_range``)."""
import math

import numpy as np
import pytest
from lf_scenes import texture

import mitsuba_eventfield as ef
from mitsuba_eventfield.lightfield.model import Disparity, LightField
from mitsuba_eventfield.optics.galvo import GalvoGeometry


def test_planes_beyond_the_range_stay_where_a_calibrated_galvo_refocuses():
    """A depth calibration gave the runner pivots of 0.199 m (x) and 0.211 m (y). Searched from 0.4 m, the
    plane at half that depth passed the x disparity's sign test and was then refused by refocus (depths from the
    farther pivot on): ``scanrate-depth --calibration`` stopped with "depth = 0.2: ... in [0.211157, ...]"."""
    geometry = GalvoGeometry(48, 48, 60.0, 0.199, 0.211157)
    angle = np.linspace(0, 2 * math.pi, 8, endpoint=False)
    positions = 0.02 * np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    views = np.repeat(texture(3, size=48)[None], 8, axis=0)
    lf = LightField(views, positions, np.zeros(8), Disparity(*geometry.paraxial_disparity()), "galvo", {}, geometry)
    assert math.isclose(lf.depth_range()[0], 0.211157)
    dm = ef.depth_from_focus(lf, 0.4, 4.0, 8, "tenengrad")       # through refocus, which checks each depth
    assert dm.depth.shape == (48, 48) and np.all(np.isfinite(dm.depth))


def test_the_solvers_default_range_reaches_down_to_the_pivot_and_no_nearer():
    """``galvo_periods.default_depth_range``: from twice the Y mirror's pivot distance to 1000, nearer where a
    caller needs it (``--near``), but never nearer than the pivot itself (there the mirrors show nothing).
    Pivots from the geometry: mirror_distance 0.2 + separation 0.01 (the Y mirror's)."""
    from mitsuba_eventfield.focus.galvo_periods import default_depth_range
    optics = {"design": "galvo", "fov_x_deg": 40.0, "mirror_distance": 0.2, "mirror_separation": 0.01,
              "scan": {"curve": "circle", "frequency": 250.0, "amplitude": 1.0}}
    pivot = 0.21
    assert default_depth_range(optics) == pytest.approx((2 * pivot, 1000.0))
    assert default_depth_range(optics, nearest=0.3) == pytest.approx((0.3, 1000.0))
    assert default_depth_range(optics, nearest=pivot / 2) == pytest.approx((pivot, 1000.0))
    assert default_depth_range(optics, nearest=5.0) == pytest.approx((2 * pivot, 1000.0))


def test_track_focus_smooths_in_inverse_depth_towards_the_previous_choice(monkeypatch):
    """``smooth`` s: each light field's inverse depth is (1 - s) times its own plus s times the previous
    choice (an exponential filter in inverse depth, where a galvo's view shift is affine). The per-light-field
    measurement is replaced by known depths (1.0, then 0.5 m), so the filter alone is scored."""
    from mitsuba_eventfield.focus import tracking
    geometry = GalvoGeometry(48, 48, 60.0, 0.2, 0.21)
    angle = np.linspace(0, 2 * math.pi, 8, endpoint=False)
    positions = 0.02 * np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    views = np.repeat(texture(3, size=48)[None], 8, axis=0)
    lfs = [LightField(views, positions, np.zeros(8) + k, Disparity(*geometry.paraxial_disparity()), "galvo", {},
                      geometry) for k in range(2)]
    measured = iter([1.0, 2.0])                                  # inverse depths: 1.0 m, then 0.5 m
    monkeypatch.setattr(tracking, "_best_depth", lambda *a: (next(measured), False))
    depths, images, _, _ = ef.track_focus(lfs, [0.4, 0.6, 1.0, 2.0], (8, 8, 40, 40), smooth=0.25)
    assert depths == pytest.approx([1.0, 1.0 / (0.75 * 2.0 + 0.25 * 1.0)], rel=1e-12) and images.shape[0] == 2


def test_mitsubas_depth_of_a_wall_facing_the_camera_is_its_distance_everywhere():
    """``truth.truth_depth`` turns Mitsuba's ray distance into z depth through each pixel's slope, x and y: the
    galvo_static wall (a plane facing the camera at z = 2.5 m) reads 2.5 at every wall pixel, its top and
    bottom rows included (at fov 40 deg their rays are 14 deg off the axis in y alone: 3 % long)."""
    from conftest import ROOT

    from mitsuba_eventfield.evaluation.truth import truth_depth
    timed = ef.load_scene(f"{ROOT}/scenes/galvo_static/galvo_static.xml", width=64, height=48)
    z = truth_depth(timed, 0.0)
    wall = z > 2.0
    assert wall[0].sum() > 40 and wall[-1].sum() > 40              # top and bottom rows see the wall
    # 2.4999 everywhere (float32 ray distances): the same at the edges as at the centre, to 1e-5
    assert np.allclose(z[wall], 2.5, rtol=1e-4) and np.ptp(z[wall]) < 2.5e-5
