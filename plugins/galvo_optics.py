"""Ray optics of a camera behind a two-axis galvo, as pure functions (NumPy or Dr.Jit through ``xp``).

Geometry, in the *unfolded* camera frame (the fixed rest-position reflections of both mirrors removed, so at
rest the camera looks straight down +z):

* camera centre at the origin; the X mirror pivots at (0, 0, d1) about the y axis (it pans the view), the Y
  mirror at (0, 0, d1 + s) about the x axis (it tilts the view);
* a mirror turned by a mechanical angle theta from rest reflects like the rest mirror followed by a rotation of
  2 theta about its pivot axis. Unfolded, each mirror is therefore a rigid rotation of the ray line (origin and
  direction) by the optical angle 2 theta about its pivot axis. This is exact, with no small-angle step.

Sign convention: a positive x angle turns the view towards camera +x, a positive y angle towards camera +y. To
first order a point at depth z then moves in the image by 2 f theta (1 - pivot / z) pixels, so the X mirror
(pivot d1) and the Y mirror (pivot d1 + s) trace an ellipse whose size depends on depth.
"""
from __future__ import annotations

import math


def pinhole_direction(xp, u, v, tan_half_fov_x, aspect):
    """Unit direction in camera space through film point (u, v) in [0,1]^2 of the full film.

    Mitsuba's image x runs towards camera -x and image y towards camera -y (image top = +y).
    """
    x = (1.0 - 2.0 * u) * tan_half_fov_x
    y = (1.0 - 2.0 * v) * tan_half_fov_x / aspect
    n = xp.sqrt(x * x + y * y + 1.0)
    return x / n, y / n, 1.0 / n


def rotate_about_y(xp, x, y, z, angle, cz):
    """Rotate points/vectors about the axis through (0, 0, cz) along +y (cz = 0 for directions)."""
    c, s = xp.cos(angle), xp.sin(angle)
    zr = z - cz
    return x * c + zr * s, y, -x * s + zr * c + cz


def rotate_about_x(xp, x, y, z, angle, cz):
    """Rotate about the axis through (0, 0, cz) along +x, with positive angle turning +z towards +y."""
    c, s = xp.cos(angle), xp.sin(angle)
    zr = z - cz
    return x, y * c + zr * s, -y * s + zr * c + cz


def galvo_transform(xp, o, d, theta_x, theta_y, d1, s):
    """Apply both mirrors (mechanical angles in radians) to a camera ray (o, d), each a tuple of 3 arrays.

    Returns the outgoing ray; its origin is moved onto the exit pivot plane z = d1 + s, so nothing between
    the camera and the galvo (inside the device) can be hit.
    """
    ox, oy, oz = rotate_about_y(xp, *o, 2.0 * theta_x, d1)
    dx, dy, dz = rotate_about_y(xp, *d, 2.0 * theta_x, 0.0)
    ox, oy, oz = rotate_about_x(xp, ox, oy, oz, 2.0 * theta_y, d1 + s)
    dx, dy, dz = rotate_about_x(xp, dx, dy, dz, 2.0 * theta_y, 0.0)
    t = (d1 + s - oz) / dz
    return (ox + t * dx, oy + t * dy, oz + t * dz), (dx, dy, dz)


def project_point(xp, p, theta_x, theta_y, d1, s, focal_px, width, height):
    """Inverse model: image position (pixels, from the top-left corner) of a camera-frame point p seen
    through the galvo at the given mechanical angles; used by tests and calibration as the geometric oracle."""
    x, y, z = p
    x, y, z = rotate_about_x(xp, x, y, z, -2.0 * theta_y, d1 + s)
    x, y, z = rotate_about_y(xp, x, y, z, -2.0 * theta_x, d1)
    return width / 2 - focal_px * x / z, height / 2 - focal_px * y / z


def focal_length_px(width: int, fov_x_deg: float) -> float:
    return width / 2 / math.tan(math.radians(fov_x_deg) / 2)
