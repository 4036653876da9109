"""The two-mirror galvo geometry (mitsuba_eventfield/optics/galvo.py) against independent ray traces: the
view-to-view homographies, and refocus of an off-axis plane ray-traced through the mirrors."""
import math

import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.focus.measures import focus_measure, refine_peak
from mitsuba_eventfield.lightfield.model import Disparity, LightField
from mitsuba_eventfield.optics import galvo as galvo_optics

W, H, FOV, D1, SEP = 96, 72, 40.0, 0.2, 0.01


def _geometry():
    return galvo_optics.GalvoGeometry(W, H, galvo_optics.focal_length_px(W, FOV), D1, D1 + SEP)


@pytest.mark.parametrize("depth", [0.4, 1.3, math.inf])
def test_homography_matches_the_ray_traced_projection(depth):
    g, rng = _geometry(), np.random.default_rng(3)
    for _ in range(20):
        tx, ty = rng.normal(0, 0.03, 2)
        u, v = rng.uniform(0, W), rng.uniform(0, H)
        z = depth if math.isfinite(depth) else 1e9
        p = ((W / 2 - u) / g.focal_px * z, (H / 2 - v) / g.focal_px * z, z)   # the reference pixel's point
        want = galvo_optics.project_point(np, p, tx, ty, D1, SEP, g.focal_px, W, H)
        q = g.homography(tx, ty, depth) @ (u, v, 1.0)
        assert q[:2] / q[2] == pytest.approx(want, abs=1e-6)


def test_view_to_view_composes_and_first_order_matches():
    g = _geometry()
    a, b = (0.01, -0.02), (-0.015, 0.005)
    m = g.view_to_view(a, b, 0.8)
    # through the reference: view a -> reference -> view b
    back = np.linalg.inv(g.array_homography(*a, 0.8))
    assert m == pytest.approx(g.array_homography(*b, 0.8) @ back / (g.array_homography(*b, 0.8) @ back)[2, 2])
    # on axis, a small turn moves a point at depth z by 2 f theta (1 - pivot / z) (x, and y with its pivot)
    theta, z = 1e-4, 0.8
    shift = g.image_shift([theta], [theta], z)[0]
    assert shift / (2 * g.focal_px * theta) == pytest.approx([1 - D1 / z, 1 - (D1 + SEP) / z], rel=1e-3)
    ax, ay = g.paraxial_disparity()
    assert (ax[0] + ay[0] / z) == pytest.approx(g.focal_px * (1 - D1 / z))


def _traced_view(theta_x, theta_y, depth, texture):
    """The view through the mirrors of a textured plane at ``depth`` by forward ray tracing (galvo_transform,
    the sensor plugin's own ray code), 4x4 supersampled: an oracle independent of the homographies."""
    s = 4
    u = (np.arange(W * s) + 0.5) / (W * s)
    v = (np.arange(H * s) + 0.5) / (H * s)
    uu, vv = np.meshgrid(u, v)
    d = galvo_optics.pinhole_direction(np, uu, vv, math.tan(math.radians(FOV) / 2), W / H)
    zero = np.zeros_like(uu)
    (ox, oy, oz), (dx, dy, dz) = galvo_optics.galvo_transform(np, (zero, zero, zero), d, theta_x, theta_y, D1, SEP)
    t = (depth - oz) / dz
    img = texture(ox + t * dx, oy + t * dy)
    return img.reshape(H, s, W, s).mean(axis=(1, 3))


def test_refocus_of_an_off_axis_plane_is_exact_where_one_shift_per_view_is_not():
    # a band-limited texture (wavelengths 3-6 px) on a plane at 0.9 m, seen 12-20 degrees off axis (image corner)
    k = np.random.default_rng(5).uniform(-260, 260, (12, 2))                  # rad per metre
    texture = lambda x, y: 1.5 + sum(np.cos(a * x + b * y + i) for i, (a, b) in enumerate(k)) / 12  # noqa: E731
    depth, views = 0.9, 24
    phase = 2 * np.pi * np.arange(views) / views
    amp = math.radians(2.0)
    angles = np.stack([amp * np.cos(phase), amp * np.sin(phase)], axis=-1)
    stack = np.array([_traced_view(a, b, depth, texture) for a, b in angles])
    g = _geometry()
    exact = LightField(stack, 2 * angles, np.zeros(views), Disparity(*g.paraxial_disparity()), "galvo", {}, g)
    shift_only = LightField(stack, 2 * angles, np.zeros(views), exact.disparity, "galvo")
    planes = ef.depth_planes(0.5, 2.0, 48)
    corner = (slice(6, 24), slice(6, 30))            # top-left: ~15 degrees off axis
    found = {}
    for name, lf in (("exact", exact), ("shift", shift_only)):
        scores = np.array([focus_measure(ef.refocus(lf, float(z)), "tenengrad")[corner].mean() for z in planes])
        found[name] = 1 / refine_peak(1 / planes, scores, int(np.argmax(scores)))
    assert found["exact"] == pytest.approx(depth, rel=0.01)          # measured 0.896 m (-0.4 %)
    assert found["shift"] > 1.08 * depth                            # one shift per view: measured 1.023 m

