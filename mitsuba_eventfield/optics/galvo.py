"""The two-mirror galvo: ray optics of a camera behind a two-axis scanning mirror, and the exact mapping between
its views. The one home of this geometry: the ``galvo`` sensor plugin traces rays with it, and view extraction,
reconstruction, refocus, focal stacks, depth from focus, focus tracking, calibration and ground truth map
views with it.

Geometry, in the *unfolded* camera frame (the fixed rest-position reflections of both mirrors removed, so at
rest the camera looks straight down +z):

* camera centre at the origin; the X mirror pivots at (0, 0, d1) about the y axis (it pans the view), the Y
  mirror at (0, 0, d1 + s) about the x axis (it tilts the view);
* a mirror turned by a mechanical angle theta from rest reflects like the rest mirror followed by a rotation of
  2 theta about its pivot axis. Unfolded, each mirror is therefore a rigid rotation of the ray line (origin and
  direction) by the optical angle 2 theta about its pivot axis. This is exact, with no small-angle step.

Sign convention: a positive x angle turns the view towards camera +x, a positive y angle towards camera +y.
Pixel coordinates: continuous, from the film's top-left corner, so pixel (i, j) of an array covers
[i, i + 1) x [j, j + 1) and its centre is at (i + 0.5, j + 0.5). Mitsuba's image x runs towards camera -x and
image y towards camera -y.

Views of a plane. Seen through the mirrors at angles theta, the scene is the rest scene moved by a rigid
transform (the inverse mirror rotations), so a plane at depth z maps from the reference view (both angles 0:
what a pinhole camera in the camera's place sees) to any view by a 3 x 3 homography (``GalvoGeometry.homography``).
Refocusing at depth z warps every view onto the reference with its homography: exact across the whole field,
where one constant shift per view is right only on the optical axis. To first order a point at depth z moves by
2 f theta (1 - pivot / z) pixels on axis, and by 2 f theta (1 + t^2 - pivot / z) at normalised field position t
along the same axis (``GalvoGeometry.scan_scale``; ``paraxial_disparity`` keeps the on-axis part, for step-size
estimates and ``alpha`` refocus).
"""
from __future__ import annotations

import math

# views a galvo light field takes per scan period by default (from_events, the light-field commands, the demo).
# A render steps at least as often under a periodic scan (``simulate.stepping``): with fewer rendered instants
# than views, views are interpolated between them and depth from focus goes confidently wrong (galvo_static at
# 120x90: 11 steps a 4 ms period, chosen at 2 px a step for its Monte-Carlo noise, read the 0.5 m card at 0.41 m
# and the 2.5 m wall at 0.40 m; at 32 steps 0.487 and 2.46 m)
VIEWS_PER_PERIOD = 32

# the fields of a galvo set-up's optics record (the ``galvo`` sensor's ``optics_metadata``, a render's
# ``meta["optics"]``, a nominal optics file for a camera recording)
OPTICS_RECORD_KEYS = ("design", "scan", "fov_x_deg", "aperture_radius", "focus_distance", "mirror_distance",
                      "mirror_separation", "angle_convention")
# a mirror turned by a mechanical angle turns the reflected ray by twice it: a view's optical angle (its
# position in a light field) per mechanical radian of the scan curve
OPTICAL_PER_MECHANICAL = 2.0
# a galvo's pinhole's horizontal field of view is below this (its focal length falls to 0 at 180 deg)
MAX_FOV_DEG = 180.0
from dataclasses import dataclass  # noqa: E402

import numpy as np  # noqa: E402

from ..errors import ConfigError  # noqa: E402
from ..validate import number  # noqa: E402


# metres (scene units): a galvo's mirrors sit centimetres in front of its lens; millimetres written as metres
# (200 for 0.2) passed, and the light-field commands then refused every depth nearer than 200 m, naming --near
MAX_MIRROR_DISTANCE = 10.0


def checked_optics(fov_x_deg, mirror_distance, mirror_separation, where: str, error=ConfigError,
                   names=("fov_x_deg", "mirror_distance", "mirror_separation")) -> tuple:
    """The galvo's three geometric parameters, each checked against its one range (the ``galvo`` sensor plugin,
    nominal optics files): fov in (0, ``MAX_FOV_DEG``) degrees, pivot distance and mirror separation in
    [0, ``MAX_MIRROR_DISTANCE``] scene units (0 separation: both mirrors at one pivot). ``error`` names ``where``
    and the field as ``names`` has it (the sensor's XML calls the first ``fov``)."""
    fov = number(fov_x_deg, f"{where}: {names[0]}", 0, lo_open=True, strict=True, error=error)
    if fov >= MAX_FOV_DEG:
        raise error(f"{where}: {names[0]} = {fov_x_deg!r}: allowed range is (0, {MAX_FOV_DEG:g}) degrees")
    return (fov, *(number(v, f"{where}: {name}", 0, MAX_MIRROR_DISTANCE, strict=True, error=error)
                   for name, v in ((names[1], mirror_distance), (names[2], mirror_separation))))


# ------------------------------------------------------------------ ray optics (NumPy or Dr.Jit through ``xp``)
def tan_half_fov(fov_x_deg: float) -> float:
    """tan(fov / 2) of a horizontal field of view in degrees: half the film's width over the focal length."""
    return math.tan(math.radians(fov_x_deg) / 2)


def focal_length_px(width: int, fov_x_deg: float) -> float:
    """Focal length in pixels of a pinhole ``width`` pixels wide with a horizontal field of view in degrees."""
    return width / 2 / tan_half_fov(fov_x_deg)


def pinhole_direction(xp, u, v, tan_half_fov_x, aspect):
    """Unit direction in camera space through film point (u, v) in [0,1]^2 of the full film."""
    x = (1.0 - 2.0 * u) * tan_half_fov_x
    y = (1.0 - 2.0 * v) * tan_half_fov_x / aspect
    n = xp.sqrt(x * x + y * y + 1.0)
    return x / n, y / n, 1.0 / n


def pixel_ray_slopes(width: int, height: int, fov_x_deg: float):
    """(x/z, y/z) of the pinhole ray through every pixel centre, (H, W) each, in camera space."""
    f = focal_length_px(width, fov_x_deg)
    xs = (width / 2 - (np.arange(width) + 0.5)) / f
    ys = (height / 2 - (np.arange(height) + 0.5)) / f
    return np.meshgrid(xs, ys)


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
    """Image position (continuous pixels from the top-left corner) of a camera-frame point p seen through the
    galvo at the given mechanical angles: the inverse of ``galvo_transform``, by ray geometry alone."""
    x, y, z = p
    x, y, z = rotate_about_x(xp, x, y, z, -2.0 * theta_y, d1 + s)
    x, y, z = rotate_about_y(xp, x, y, z, -2.0 * theta_x, d1)
    return width / 2 - focal_px * x / z, height / 2 - focal_px * y / z


# ------------------------------------------------------------------ views of a plane: homographies
def _rotation_about(axis: str, angle, pivot_z: float) -> np.ndarray:
    """4 x 4 rigid rotation about the axis through (0, 0, pivot_z) along x or y (``rotate_about_x``/``_y``);
    an array of angles gives a stack (..., 4, 4), so a whole scan is one NumPy expression."""
    angle = np.asarray(angle, np.float64)
    c, s = np.cos(angle), np.sin(angle)
    m = np.zeros(angle.shape + (4, 4))
    m[..., 3, 3] = 1.0
    i, j, k = (0, 2, 1) if axis == "y" else (1, 2, 0)     # the rotated pair (i, j) and the fixed axis k
    m[..., i, i], m[..., i, j], m[..., j, i], m[..., j, j], m[..., k, k] = c, s, -s, c, 1.0
    # about the pivot: z -> z - pivot, rotate, z -> z + pivot (only the translation column changes)
    m[..., :3, 3] = -pivot_z * m[..., :3, 2]
    m[..., 2, 3] += pivot_z
    return m


@dataclass(frozen=True)
class GalvoGeometry:
    """A camera behind a two-axis galvo, in pixels: what maps any view onto any other.

    ``pivot_x``/``pivot_y``: distances from the camera centre to the X and Y mirror pivots (scene units);
    ``gain_x``/``gain_y``: mechanical angle turned per unit of the angle a view records (1 for the nominal
    optics; a depth calibration sets them from the measured scan scale).
    """
    width: int
    height: int
    focal_px: float
    pivot_x: float
    pivot_y: float
    gain_x: float = 1.0
    gain_y: float = 1.0

    @classmethod
    def from_optics(cls, optics: dict, width: int, height: int) -> "GalvoGeometry":
        """From a galvo sensor's optics metadata (``fov_x_deg``, ``mirror_distance``, ``mirror_separation``), or
        the pivots and gains a depth calibration put there (``calibrated_geometry``: calibration.calibrated_optics)."""
        f = focal_length_px(width, float(optics["fov_x_deg"]))
        cal = optics.get("calibrated_geometry")
        if isinstance(cal, dict):
            return cls(int(width), int(height), f, *(float(cal[k]) for k in ("pivot_x", "pivot_y", "gain_x",
                                                                              "gain_y")))
        d1, s = float(optics["mirror_distance"]), float(optics["mirror_separation"])
        return cls(int(width), int(height), f, d1, d1 + s)

    def with_pivots(self, pivot_x: float, pivot_y: float, gain_x: float = 1.0, gain_y: float = 1.0):
        return GalvoGeometry(self.width, self.height, self.focal_px, pivot_x, pivot_y, gain_x, gain_y)

    # ---------------------------------------------------------- the exact model
    def _scene_to_view(self, theta_x, theta_y) -> np.ndarray:
        """4 x 4 rigid transform taking a camera-frame point to where the rest camera sees it in this view
        (a stack of them for arrays of angles)."""
        return (_rotation_about("y", -2.0 * self.gain_x * np.asarray(theta_x, np.float64), self.pivot_x)
                @ _rotation_about("x", -2.0 * self.gain_y * np.asarray(theta_y, np.float64), self.pivot_y))

    def homography(self, theta_x, theta_y, depth: float) -> np.ndarray:
        """3 x 3 map from reference-view pixels (continuous, top-left origin) to the pixels of the view at
        mechanical angles (theta_x, theta_y), for points on the plane z = ``depth`` (math.inf allowed); arrays of
        angles give a stack (N, 3, 3)."""
        f, w, h = self.focal_px, self.width, self.height
        if math.isinf(depth):          # directions: the plane at infinity
            lift = np.array([[-1 / f, 0, w / (2 * f)], [0, -1 / f, h / (2 * f)], [0, 0, 1], [0, 0, 0]])
        else:                           # pixel -> point on the plane z = depth
            z = float(depth)
            lift = np.array([[-z / f, 0, z * w / (2 * f)], [0, -z / f, z * h / (2 * f)], [0, 0, z], [0, 0, 1]])
        project = np.array([[-f, 0, w / 2, 0], [0, -f, h / 2, 0], [0, 0, 1, 0]])
        m = project @ self._scene_to_view(theta_x, theta_y) @ lift
        return m / m[..., 2:3, 2:3]

    def array_homography(self, theta_x: float, theta_y: float, depth: float) -> np.ndarray:
        """``homography`` in array indices (pixel centres at integers), as OpenCV's warps expect."""
        to_continuous = np.array([[1, 0, 0.5], [0, 1, 0.5], [0, 0, 1.0]])
        to_index = np.array([[1, 0, -0.5], [0, 1, -0.5], [0, 0, 1.0]])
        m = to_index @ self.homography(theta_x, theta_y, depth) @ to_continuous
        return m / m[2, 2]

    def view_to_view(self, angles_from, angles_to, depth: float) -> np.ndarray:
        """3 x 3 map (array indices) from the pixels of one view to another's, for points at ``depth``."""
        h_from = self.array_homography(*angles_from, depth)
        h_to = self.array_homography(*angles_to, depth)
        m = h_to @ np.linalg.inv(h_from)
        return m / m[2, 2]

    def image_shift(self, theta_x, theta_y, depth: float = math.inf, x=None, y=None) -> np.ndarray:
        """Exact displacement (pixels, x right / y down) from the reference view of a point at ``depth`` seen
        at reference pixel (x, y) (default: the image centre), for each pair of angles: (N, 2)."""
        tx, ty = np.atleast_1d(np.asarray(theta_x, np.float64)), np.atleast_1d(np.asarray(theta_y, np.float64))
        px = self.width / 2 if x is None else float(x)
        py = self.height / 2 if y is None else float(y)
        q = self.homography(tx, ty, depth) @ np.array([px, py, 1.0])          # (N, 3), all angles at once
        return np.stack([q[:, 0] / q[:, 2] - px, q[:, 1] / q[:, 2] - py], axis=1)

    # ---------------------------------------------------------- first order
    def field_factors(self, x=None, y=None) -> tuple:
        """(1 + t_x^2, 1 + t_y^2) at reference pixel (x, y) (default: the image centre), t the pixel's normalised
        field position (pixels from the centre over the focal length): what a scan's first-order image motion
        there gains over the axis, per axis (``scan_scale``)."""
        tx = (self.width / 2 - (self.width / 2 if x is None else float(x))) / self.focal_px
        ty = (self.height / 2 - (self.height / 2 if y is None else float(y))) / self.focal_px
        return 1.0 + tx * tx, 1.0 + ty * ty

    def scan_scale(self, depth: float = math.inf, x=None, y=None) -> tuple:
        """(S_x, S_y): pixels a point at ``depth`` seen at reference pixel (x, y) moves per mechanical radian of
        each mirror, to first order in the angle: S = 2 f g (k - pivot / z), k = ``field_factors``. A mirror
        turning the ray by phi moves the point's slope X / Z by phi ((Z - pivot) / Z + (X / Z)^2): the
        keystone's t^2 adds to the on-axis 1 - pivot / z, it does not multiply it. The scale an LED track
        measures (``calibration.led``) and the one a depth calibration inverts (``calibration.depth``). Left
        out: the cross term, the other axis moving by 2 f g t_x t_y per radian (at a 160x120 corner, fov 40 deg,
        about 9 % of S): a circle's amplitude sees it at second order (0.4 %); refocus and depth use the exact
        homography instead."""
        kx, ky = self.field_factors(x, y)
        inv_z = 0.0 if math.isinf(depth) else 1.0 / float(depth)
        return (2 * self.focal_px * self.gain_x * (kx - self.pivot_x * inv_z),
                2 * self.focal_px * self.gain_y * (ky - self.pivot_y * inv_z))

    def paraxial_disparity(self):
        """((alpha_x at infinity, alpha_y at infinity), (per inverse depth x, y)): on-axis image displacement
        per unit of *optical* angle, alpha(z) = at_infinity + per_inverse_depth / z = f g (1 - pivot / z)."""
        f = self.focal_px
        return ((f * self.gain_x, f * self.gain_y),
                (-f * self.gain_x * self.pivot_x, -f * self.gain_y * self.pivot_y))


def scan_image_path_px(optics: dict, width: int, height: int) -> float:
    """How far, in pixels, the scan moves the image in one period: the longest path over the image centre and
    corners (where the exact shift is largest), at infinity (the largest shift of a two-mirror scan). The
    steps a period needs for at most p pixels of scan motion per step is this over p."""
    from .scan import curve_from_dict, scan_period
    geometry = GalvoGeometry.from_optics(optics, width, height)
    ax, ay = curve_from_dict(optics["scan"]).angles(np.linspace(0.0, scan_period(optics["scan"]), 2049))
    return float(field_step_shifts(geometry, ax, ay).sum(axis=1).max())


def field_step_shifts(geometry: GalvoGeometry, ax, ay) -> np.ndarray:
    """(5, len(ax) - 1): how far the image moves between consecutive mirror angles (ax, ay; mechanical rad) at
    the image centre and each corner, at infinity: where a two-mirror scan's exact shift is largest. The one
    probe of the scan's image motion (``scan_image_path_px``, ``simulate.image_motion.scan_displacements``)."""
    w, h = geometry.width, geometry.height
    return np.stack([np.hypot(*np.diff(geometry.image_shift(ax, ay, math.inf, x, y), axis=0).T)
                     for x, y in ((w / 2, h / 2), (0.0, 0.0), (w, 0.0), (0.0, h), (w, h))])


def scan_parallax_px(optics: dict, width: int, height: int, depth: float) -> dict:
    """How far a galvo's views move a point at half and at twice ``depth`` against one at ``depth`` over a scan
    period (the largest such shift at the image centre, pixels; keys "0.5x", "2x"): what refocusing at ``depth``
    separates depths with. The bundled designs galvo (0.1 deg at 3-4 cm pivots) moves them 0.088 / 0.044 px at
    144 px: there its refocus is the image (``apps.designs`` says so)."""
    from .scan import curve_from_dict, scan_period
    geometry = GalvoGeometry.from_optics(optics, width, height)
    ax, ay = curve_from_dict(optics["scan"]).angles(np.linspace(0.0, scan_period(optics["scan"]), 257))
    at = {z: geometry.image_shift(ax, ay, z) for z in (depth / 2, depth, 2 * depth)}
    return {f"{z / depth:g}x": float(np.hypot(*(at[z] - at[depth]).T).max()) for z in (depth / 2, 2 * depth)}
