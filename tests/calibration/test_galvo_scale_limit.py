"""``galvo_scale_limit``: the largest scan curve (px per mechanical radian) a galvo can show, which fits beyond
are refused. Its docstring's law: 2 f (optical angles twice the mechanical) x the keystone 1 + t^2 at the film's
corner (t: half the diagonal over f) x the margin. At 160x120, fov 90 deg: f = 80 px, t = 1.25, 1.25 x 160 x
2.5625 = 512.5 px/rad. The oracle that the keystone belongs there: the exact image motion per radian of a small
turn of either mirror (or both), at infinity with the pivots at the camera (the most a galvo shows), is 160
px/rad on the axis but 341.8 px/rad at a corner (x mirror; 2 f sqrt((1 + t_x^2)^2 + (t_x t_y)^2)), beyond
2 f (margin included: 200); the limit without its margin (410) bounds every one of them (largest 406.5 px/rad,
a diagonal turn at a corner)."""
import math

import numpy as np
import pytest

from mitsuba_eventfield.calibration import galvo_scale_limit
from mitsuba_eventfield.optics import galvo as galvo_optics

W, H, FOV = 160, 120, 90.0


def _largest_motion_per_radian():
    """The largest exact image motion (px per mechanical radian of the turn) over the film's centre, corners
    and edge midpoints, for small turns of the X mirror, the Y mirror and both."""
    g = galvo_optics.GalvoGeometry(W, H, galvo_optics.focal_length_px(W, FOV), 0.0, 0.0)
    theta = 1e-7
    most = 0.0
    for x, y in ((W / 2, H / 2), (0, 0), (W, 0), (0, H), (W, H), (0, H / 2), (W / 2, 0)):
        for dx, dy in ((1, 0), (0, 1), (math.sqrt(0.5), math.sqrt(0.5)), (math.sqrt(0.5), -math.sqrt(0.5))):
            shift = g.image_shift([theta * dx], [theta * dy], math.inf, x, y)[0]
            most = max(most, float(np.hypot(*shift)) / theta)
    return most, g.focal_px


def test_the_scale_limit_carries_the_corner_keystone():
    limit = galvo_scale_limit({"width": W, "height": H, "fov_x_deg": FOV})
    f = galvo_optics.focal_length_px(W, FOV)
    t = math.hypot(W, H) / 2 / f                                   # the corner's normalised field position
    assert limit == pytest.approx(1.25 * 2 * f * (1 + t * t), rel=1e-12)
    assert limit == pytest.approx(512.5, rel=1e-12)
    most, f = _largest_motion_per_radian()
    print(f"limit {limit:.1f} px/rad (without margin {limit / 1.25:.1f}); exact motion on axis {2 * f:.1f}, "
          f"largest over the film {most:.1f}")
    assert most > 2 * 1.25 * f                  # the keystone matters: 2 f with the margin is not enough
    assert most <= limit / 1.25                 # the law bounds what the optics show, without its margin
    assert galvo_scale_limit({"width": W, "height": H, "fov_x_deg": FOV}, margin=1.0) == pytest.approx(limit / 1.25)
