"""``refocus.view_motion`` on repetitive texture: the scenes/galvo_static wall is lines of text, on which the
optical flow of one view pair can lock onto the next line. At a 2-degree scan (173 x 130, 32 views rendered
exactly) that read 2.1-2.3 px of motion on a static scene, a false MotionBlurWarning; with the forward-backward
check it reads below the limit, and the same card moving at 1000 px/s (4 px a scan period) still reads 4."""
import math
import warnings

import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.focus.refocus import MOTION_LIMIT_PX, MotionBlurWarning, refocus, view_motion
from mitsuba_eventfield.lightfield.model import from_galvo, galvo_view_times

SCENE = "scenes/galvo_static/galvo_static.xml"
CARD_SPEED = 2.1      # m/s along x at 0.5 m: 2.1 / 0.5 x 237.7 px focal length = 1000 px/s, 4 px a 4 ms period


def _lightfield(root, moving: bool):
    motion = {"version": 1, "duration": 0.01, "objects": {"card": {"velocity": [CARD_SPEED, 0.0, 0.0]}}} \
        if moving else None
    timed = ef.load_scene(str(root / SCENE), motion=motion, width=173, height=130, amplitude=2.0)
    optics = timed.sensor.optics_metadata()
    times = galvo_view_times(optics, 0.0, 32)
    return from_galvo(ef.render_frames(timed, times, spp=16), times, optics)


@pytest.fixture(scope="module")
def root():
    import pathlib
    return pathlib.Path(__file__).resolve().parents[2]


def test_a_static_text_wall_at_a_wide_scan_is_not_flagged(root):
    lf = _lightfield(root, moving=False)
    for depth in (0.5, 1.0, math.inf):               # measured 1.77, 1.10, 1.17 px (2.07-2.25 without the check)
        assert view_motion(lf, depth)["motion_px"] < 0.95 * MOTION_LIMIT_PX, depth
    with warnings.catch_warnings():
        warnings.simplefilter("error", MotionBlurWarning)
        refocus(lf, 1.0)


def test_the_same_card_moving_is_still_measured(root):
    lf = _lightfield(root, moving=True)
    for depth in (0.5, math.inf):                    # measured 4.06 and 4.19 px, vx -981 and -1000 px/s
        m = view_motion(lf, depth)
        assert m["motion_px"] == pytest.approx(4.0, abs=0.5), depth
        vx, vy = m["velocity_px_s"]
        assert vx == pytest.approx(-1000.0, rel=0.1) and abs(vy) < 0.2 * abs(vx), (vx, vy)
    with pytest.warns(MotionBlurWarning, match="moves 4"):
        refocus(lf, 0.5)
    assert view_motion(lf, 0.5)["moving_share"] > 0.1              # the card: measured 26 % of the blocks


def test_motion_shifts_are_relative_to_the_light_fields_mean_time():
    """``motion_shifts``: an object at (vx, vy) px/s is displaced in each view by v (t_k - mean t): refocused
    with them it sits where it was at the light field's mean time (views at 0, 1 and 5 ms; mean 2 ms)."""
    import numpy as np

    from mitsuba_eventfield.focus.refocus import motion_shifts
    from mitsuba_eventfield.lightfield.model import Disparity, LightField
    lf = LightField(np.zeros((3, 8, 8)), np.zeros((3, 2)), np.array([0.0, 1e-3, 5e-3]),
                    Disparity((0.0, 0.0), (1.0, 1.0)), "kaleidoscope", {})
    assert np.allclose(motion_shifts(lf, (1000.0, -500.0)), [[-2, 1], [-1, 0.5], [3, -1.5]], atol=1e-12)


def test_a_spatial_light_fields_disparity_takes_each_axis_pixel_pitch():
    """Thin lens: a point at depth z seen through a sub-aperture u metres off the axis lands D u (1/z - 1/S)
    metres off on the image plane; in pixels, over that axis's pitch (a 0.012 x 0.006 m plane imaged on
    40 x 20 px views has one pitch on both axes; over the x pitch the y disparity came out half)."""
    from mitsuba_eventfield.lightfield.model import Disparity
    optics = {"lens_to_image_plane": 0.05, "focus_distance": 1.0, "image_plane_size": [0.012, 0.006]}
    ax, ay = Disparity.for_spatial(optics, 40, 20).alpha(0.5)
    metres = 0.05 * (1 / 0.5 - 1 / 1.0)
    assert (ax, ay) == pytest.approx((metres * 40 / 0.012, metres * 20 / 0.006), rel=1e-12)
