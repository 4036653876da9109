"""Mitsuba sensor plugin ``kaleidoscope``: spatial multiplexing of n x n views on one film, in ONE render.

Parameters (lengths in scene units, i.e. metres; the optical model is in ``kaleido_optics``):

==================  =========  ==================  ==============================================================
Parameter           Type       Default             Description
==================  =========  ==================  ==============================================================
layout              string     kaleidoscope        kaleidoscope | microlens (pixel x belongs to view x mod n)
focal_length        float      0.05                main lens focal length
focus_distance      float      1.0                 main lens focus distance (> focal_length)
aperture_radius     float      1.05 x needed       main lens; must pass every sub-aperture (microlens: 0.01)
tube_width          float      0.012               kaleidoscope tube cross-section (microlens: the image plane's)
tube_height         float      width x film aspect (kaleidoscope: must match the film's aspect)
tube_length         float      0.06                tube length L
relay_distance      float      0.03                relay pupil to tube exit R; views per axis n = (R + L) / R
relay_aperture      float      0                   > 0: finite relay pupil (sub-aperture disks)
mode                string     lenses              lenses | tube_only | physical_tube (validation)
views               integer    3                   microlens layout only: n
to_world            transform  identity            camera pose
(film)              film       --                  its aspect must match the tube's
==================  =========  ==================  ==============================================================

``tube_only`` emits the folded ray from the tube entrance (z = 0, no lenses). ``physical_tube`` emits the
plain relay ray from the relay pupil (z = -(L + R)) into a scene that must contain the four mirrors: the two
must render alike, and that comparison is the validation of the unfolding.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_eventfield.validate import number

from . import kaleido_optics
from ._per_variant import per_variant, subclass
from .properties import number_prop

MODES = ("lenses", "tube_only", "physical_tube")
LAYOUTS = ("kaleidoscope", "microlens")
WHERE = "sensor 'kaleidoscope'"
KALEIDOSCOPE_ONLY = ("tube_length", "relay_distance", "relay_aperture")   # (width, height: microlens too)


class _KaleidoscopeSensorMethods:
    """The ``kaleidoscope`` sensor's methods, bound to the active variant's ``mi.Sensor`` by ``sensor_class``."""

    def __init__(self, props):
        mi.Sensor.__init__(self, props)
        g = lambda k, d: number_prop(props, k, d, WHERE)  # noqa: E731   (ranges: kaleido_geometry)
        self.layout = props.get("layout", "kaleidoscope")
        self.mode = props.get("mode", "lenses")
        if self.layout not in LAYOUTS:
            raise ValueError(f"{WHERE}: layout = {self.layout!r}: allowed values are {', '.join(LAYOUTS)}")
        if self.mode not in MODES:
            raise ValueError(f"{WHERE}: mode = {self.mode!r}: allowed values are {', '.join(MODES)}")
        size = self.film().size()
        self.film_w, self.film_h = int(size.x), int(size.y)
        if self.film_w < 1 or self.film_h < 1:           # the tube's default height divides by the width
            raise ValueError(f"{WHERE}: film {self.film_w}x{self.film_h}: each side must be at least 1 pixel")
        if self.layout == "microlens":       # read below, they would pass Mitsuba's check of unused values
            unused = [k for k in KALEIDOSCOPE_ONLY if k in props]
            if unused:
                raise ValueError(f"{WHERE}: {', '.join(unused)}: the kaleidoscope's tube and relay, not used by "
                                 "layout = 'microlens'; remove it, or use layout = 'kaleidoscope'")
        self.tube_width = g("tube_width", 0.012)
        self.tube_height = g("tube_height", self.tube_width * self.film_h / self.film_w)
        self.tube_length, self.relay_distance = g("tube_length", 0.06), g("relay_distance", 0.03)
        self.focal_length, self.focus_distance = g("focal_length", 0.05), g("focus_distance", 1.0)
        self.relay_aperture = g("relay_aperture", 0.0)
        if self.layout == "kaleidoscope":
            self._init_kaleidoscope(props)
        else:
            self._init_microlens(props)
        if self.film_w % self.n or self.film_h % self.n:
            raise ValueError(f"{WHERE}: film {self.film_w}x{self.film_h} is not a multiple of {self.n} views per "
                             "axis: views would overlap pixels; choose width and height divisible by "
                             f"{self.n}")
        self.m_needs_sample_3 = self.layout == "microlens" or self.relay_aperture > 0

    def _geometry(self, aperture):
        return kaleido_optics.kaleido_geometry(self.tube_width, self.tube_height, self.tube_length, self.relay_distance,
                                   self.focal_length, self.focus_distance, aperture, self.relay_aperture, WHERE)

    def _init_kaleidoscope(self, props):
        probe = self._geometry(1e9)
        needed = math.hypot(probe["half"] * probe["subaperture_pitch"][0],
                            probe["half"] * probe["subaperture_pitch"][1]) + probe["subaperture_radius"]
        self.aperture = number_prop(props, "aperture_radius", 1.05 * needed, WHERE)
        self.geo = self._geometry(self.aperture)
        self.n = self.geo["n"]
        tube_aspect = self.tube_width / self.tube_height
        if abs(self.film_w / self.film_h - tube_aspect) > 0.01 * tube_aspect:
            raise ValueError(f"{WHERE}: film {self.film_w}x{self.film_h} and tube {self.tube_width}x"
                             f"{self.tube_height} differ in aspect ratio; the film images the tube exit, so they "
                             "must match")

    def _init_microlens(self, props):
        self.n = number_prop(props, "views", 3, WHERE, 1, integer=True)
        for name, v in (("tube_width", self.tube_width), ("tube_height", self.tube_height)):   # the image plane
            number(v, f"{WHERE}: {name}", 0, lo_open=True, error=ValueError)
        if self.mode != "lenses":
            raise ValueError(f"{WHERE}: mode = {self.mode!r}: the tube's validation modes need layout = "
                             "'kaleidoscope'; a microlens array has lenses only")
        if self.focal_length <= 0 or self.focus_distance <= self.focal_length:
            raise ValueError(f"{WHERE}: focus_distance = {self.focus_distance} must exceed focal_length = "
                             f"{self.focal_length} > 0")
        self.aperture = number_prop(props, "aperture_radius", 0.01, WHERE)
        if not self.aperture > 0:
            raise ValueError(f"{WHERE}: aperture_radius = {self.aperture}: must be > 0 for a microlens array")
        self.geo = {"n": self.n, "lens_to_entrance": 1.0 / (1.0 / self.focal_length - 1.0 / self.focus_distance)}

    # ------------------------------------------------------------ metadata
    def view_layout(self) -> list:
        """Per view: index (i, j), film tile (x0, y0, w, h), flips, sub-aperture centre on the main lens
        (``kaleido_optics.tiles``: the indices, tiles and flips)."""
        n, views = self.n, []
        for k, cell in enumerate(kaleido_optics.tiles(n, self.film_w, self.film_h)):
            row, col = divmod(k, n)
            i, j = cell["i"], cell["j"]
            if self.layout == "kaleidoscope":
                scale = self.geo["lens_to_entrance"] / (self.relay_distance + self.tube_length)
                ax, ay = kaleido_optics.subaperture(i, j, 0.0, 0.0, self.tube_width, self.tube_height, scale, np)
                views.append({**cell, "subaperture": [float(ax), float(ay)]})
            else:
                pitch = 2 * self.aperture / n
                # the lenslet inverts: the pixel right of centre sees the main lens's -x side; the
                # view's position is the centroid of its square cell clipped by the round aperture
                views.append({"i": i, "j": j, "pixel_offset": [col, row], "stride": n,
                              "subaperture": _clipped_cell_centroid(-i * pitch, -j * pitch, pitch, self.aperture),
                              "cell_centre": [-i * pitch, -j * pitch]})
        return views

    def optics_metadata(self) -> dict:
        d = {"design": self.layout, "n": self.n, "mode": self.mode, "focal_length": self.focal_length,
             "focus_distance": self.focus_distance, "aperture_radius": self.aperture,
             "lens_to_image_plane": self.geo["lens_to_entrance"], "views": self.view_layout(),
             "image_plane_size": [self.tube_width, self.tube_height],
             "convention": "view (i, j) in tile column i + (n-1)/2 from the left, row j + (n-1)/2 from the top; "
                           "views oriented like a perspective camera; subaperture in metres on the main lens, "
                           "sensor-local frame (local +x shows on the image left); plugins/kaleido_optics.py"}
        if self.layout == "kaleidoscope":
            d.update(tube=[self.tube_width, self.tube_height, self.tube_length], relay_distance=self.relay_distance,
                     relay_aperture=self.relay_aperture)
        return d

    # ------------------------------------------------------------ rays
    def sample_ray(self, time, sample1, sample2, sample3, active=True):
        wavelengths, weight = self.sample_wavelengths(dr.zeros(mi.SurfaceInteraction3f), sample1, active)
        film = self.film()
        size, crop, offset = film.size(), film.crop_size(), film.crop_offset()
        u = (offset.x + sample2.x * crop.x) / size.x
        v = (offset.y + sample2.y * crop.y) / size.y
        if self.layout == "kaleidoscope":
            (ox, oy, oz), (dx, dy, dz), valid = self._kaleido_ray(u, v, sample3)
        else:
            (ox, oy, oz), (dx, dy, dz), valid = self._microlens_ray(sample2, sample3, offset, crop)
        to_world = self.world_transform()
        ray = mi.Ray3f(to_world @ mi.Point3f(ox, oy, oz), dr.normalize(to_world @ mi.Vector3f(dx, dy, dz)),
                       time, wavelengths)
        return ray, dr.select(valid, weight, 0.0)

    def _kaleido_ray(self, u, v, sample3):
        W, H, L, R = self.tube_width, self.tube_height, self.tube_length, self.relay_distance
        ex, ey = kaleido_optics.film_to_exit(u, v, W, H)
        qx, qy = ex * (R + L) / R, ey * (R + L) / R          # the relay is focused on the entrance plane
        if self.relay_aperture > 0:
            r = mi.warp.square_to_uniform_disk_concentric(sample3) * self.relay_aperture
            rx, ry = r.x, r.y
        else:
            rx, ry = mi.Float(0.0), mi.Float(0.0)
        # the ray from the relay pupil to q must enter the tube through its exit opening
        cx, cy = rx + (qx - rx) * R / (R + L), ry + (qy - ry) * R / (R + L)
        valid = (dr.abs(cx) <= W / 2) & (dr.abs(cy) <= H / 2)
        if self.mode == "physical_tube":
            d = dr.normalize(mi.Vector3f(qx - rx, qy - ry, R + L))
            return (rx, ry, mi.Float(-(R + L))), (d.x, d.y, d.z), valid
        i, px, sx = kaleido_optics.fold(dr, qx, W)
        j, py, sy = kaleido_optics.fold(dr, qy, H)
        if self.mode == "tube_only":
            d = dr.normalize(mi.Vector3f(sx * (qx - rx), sy * (qy - ry), R + L))
            return (px, py, mi.Float(0.0)), (d.x, d.y, d.z), valid
        scale = self.geo["lens_to_entrance"] / (R + L)
        ax, ay = kaleido_optics.subaperture(i, j, rx, ry, W, H, scale, dr, signs=(sx, sy))
        valid &= ax * ax + ay * ay <= self.aperture * self.aperture
        o, d = kaleido_optics.main_lens_ray(dr, px, py, ax, ay, self.geo["lens_to_entrance"], self.focus_distance)
        return o, d, valid

    def _microlens_ray(self, sample2, sample3, offset, crop):
        n = self.n
        fx = offset.x + sample2.x * crop.x                  # film pixel coordinates
        fy = offset.y + sample2.y * crop.y
        ix, iy = dr.floor(fx), dr.floor(fy)
        vi, vj, x, y, cx, cy = kaleido_optics.microlens_mapping(dr, ix, iy, fx - ix, fy - iy, n, self.film_w,
                                                                self.film_h, self.tube_width, self.tube_height)
        # spatial position: anywhere under the lenslet (sample3); angle: the pixel's sub-aperture cell
        lw, lh = self.tube_width * n / self.film_w, self.tube_height * n / self.film_h
        x = x + (sample3.x - 0.5) * lw
        y = y + (sample3.y - 0.5) * lh
        pitch = 2 * self.aperture / n
        ax, ay = (vi + cx) * pitch, (vj + cy) * pitch
        valid = ax * ax + ay * ay <= self.aperture * self.aperture
        o, d = kaleido_optics.main_lens_ray(dr, x, y, ax, ay, self.geo["lens_to_entrance"], self.focus_distance)
        return o, d, valid

    def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
        ray, weight = self.sample_ray(time, sample1, sample2, sample3, active)
        rd = mi.RayDifferential3f(ray)
        rd.has_differentials = False
        return rd, weight

    def traverse(self, callback):
        mi.Sensor.traverse(self, callback)
        callback.put("to_world", self.m_to_world, mi.ParamFlags.NonDifferentiable)

    def bbox(self):
        p = self.world_transform() @ mi.ScalarPoint3f(0, 0, 0)
        return mi.ScalarBoundingBox3f(p, p)

    def to_string(self):
        return f"KaleidoscopeSensor[layout={self.layout}, n={self.n}, mode={self.mode}]"

def _define_class():
    return subclass(mi.Sensor, _KaleidoscopeSensorMethods, "KaleidoscopeSensor")


sensor_class = per_variant(_define_class)   # the KaleidoscopeSensor class of the active variant


def optics_of(layout: str, params: dict, width: int, height: int) -> dict:
    """The optics record (:meth:`optics_metadata`: views, tiles, sub-apertures) of a ``layout`` set-up with
    these parameters (names of ``kaleido_optics.SETUP_PARAMETERS``, defaults as the table's) on a ``width`` x
    ``height`` film, from the sensor itself, so that a camera recording's light field takes its views from the
    same code as a render's. Raises ValueError with one line naming the parameter (the sensor's own checks)."""
    from mitsuba_eventfield.errors import plugin_message
    allowed = kaleido_optics.SETUP_PARAMETERS
    if layout not in allowed:
        raise ValueError(f"design = {layout!r}: allowed values are {', '.join(allowed)}")
    unknown = sorted(set(params) - set(allowed[layout]))
    if unknown:
        raise ValueError(f"{', '.join(unknown)}: not a parameter of the {layout} (allowed: "
                         f"{', '.join(allowed[layout])})")
    values = {}
    for name, v in params.items():
        integer = name == "views"
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or \
                (integer and v != int(v)):
            raise ValueError(f"{name} = {v!r}: expected {'an integer' if integer else 'a finite number (metres)'}")
        values[name] = int(v) if integer else float(v)
    try:
        sensor = mi.load_dict({"type": "kaleidoscope", "layout": layout, **values,
                               "film": {"type": "hdrfilm", "width": int(width), "height": int(height),
                                        "pixel_format": "luminance"}})   # as mono expects: no warning
    except RuntimeError as e:
        raise ValueError(plugin_message(e) or " ".join(str(e).split())) from None
    optics = sensor.optics_metadata()
    optics.pop("mode")          # a render's choice (validation modes), not the set-up's
    return optics


def _clipped_cell_centroid(cx, cy, pitch, radius, samples=256):
    """Centroid of the square aperture cell centred at (cx, cy) intersected with the lens disk."""
    g = (np.arange(samples) + 0.5) / samples - 0.5
    x, y = np.meshgrid(cx + g * pitch, cy + g * pitch)
    inside = x * x + y * y <= radius * radius
    if not inside.any():
        return [float(cx), float(cy)]
    return [float(x[inside].mean()), float(y[inside].mean())]


def mirror_tube_shapes(tube_width, tube_height, tube_length, to_world=None) -> dict:
    """The four mirror rectangles of the tube (entrance at local z = 0, exit at z = -L), reflecting inwards,
    as a ``mi.load_dict`` fragment: the physical reference for ``mode = physical_tube``."""
    T = mi.ScalarTransform4f
    base = to_world if to_world is not None else T()
    W, H, L = tube_width, tube_height, tube_length
    mirror = {"type": "conductor", "material": "none"}      # ideal mirror, reflectance 1
    walls = {   # rectangles are [-1, 1]^2 in local xy with normal +z; turn each to face into the tube
        "mirror_left": T().translate([-W / 2, 0, -L / 2]) @ T().rotate([0, 1, 0], 90) @ T().scale([L / 2, H / 2, 1]),
        "mirror_right": T().translate([W / 2, 0, -L / 2]) @ T().rotate([0, 1, 0], -90) @ T().scale([L / 2, H / 2, 1]),
        "mirror_bottom": T().translate([0, -H / 2, -L / 2]) @ T().rotate([1, 0, 0], -90) @ T().scale([W / 2, L / 2, 1]),
        "mirror_top": T().translate([0, H / 2, -L / 2]) @ T().rotate([1, 0, 0], 90) @ T().scale([W / 2, L / 2, 1]),
    }
    return {name: {"type": "rectangle", "to_world": base @ xf, "bsdf": mirror} for name, xf in walls.items()}
