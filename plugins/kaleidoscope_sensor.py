"""Mitsuba sensor plugin ``kaleidoscope``: spatial multiplexing of n x n views on one film, in ONE render.

XML (lengths in scene units, i.e. metres; see ``kaleido_optics`` for the optical model)::

    <sensor type="kaleidoscope">
        <string name="layout" value="kaleidoscope"/>   <!-- or "microlens" (x_s = x // n) -->
        <float name="focal_length" value="0.05"/>      <!-- main lens -->
        <float name="focus_distance" value="1.0"/>
        <float name="aperture_radius" value="0.01"/>   <!-- main lens; must pass every sub-aperture -->
        <float name="tube_width" value="0.012"/>       <!-- kaleidoscope tube cross-section and length -->
        <float name="tube_height" value="0.012"/>
        <float name="tube_length" value="0.06"/>
        <float name="relay_distance" value="0.03"/>    <!-- relay pupil to tube exit: n = (R + L) / R -->
        <float name="relay_aperture" value="0"/>       <!-- > 0: finite relay pupil (sub-aperture disks) -->
        <string name="mode" value="lenses"/>           <!-- lenses | tube_only | physical_tube (validation) -->
        <integer name="views" value="3"/>              <!-- microlens layout only: n -->
        <film type="hdrfilm"> ... </film>
    </sensor>

``tube_only`` emits the folded ray from the tube entrance (z = 0, no lenses). ``physical_tube`` emits the
plain relay ray from the relay pupil (z = -(L + R)) into a scene that must contain the four mirrors: the two
must render alike, and that comparison is the validation of the unfolding.
"""
from __future__ import annotations

import math

import drjit as dr
import numpy as np
import mitsuba as mi

from . import kaleido_optics as ko
from ._per_variant import per_variant

MODES = ("lenses", "tube_only", "physical_tube")
LAYOUTS = ("kaleidoscope", "microlens")
WHERE = "sensor 'kaleidoscope'"


def _define_class():
    class KaleidoscopeSensor(mi.Sensor):
        def __init__(self, props):
            super().__init__(props)
            g = lambda k, d: float(props.get(k, d))  # noqa: E731
            self.layout = props.get("layout", "kaleidoscope")
            self.mode = props.get("mode", "lenses")
            if self.layout not in LAYOUTS:
                raise ValueError(f"{WHERE}: layout = {self.layout!r}: allowed values are {', '.join(LAYOUTS)}")
            if self.mode not in MODES:
                raise ValueError(f"{WHERE}: mode = {self.mode!r}: allowed values are {', '.join(MODES)}")
            size = self.film().size()
            self.film_w, self.film_h = int(size.x), int(size.y)
            self.W, self.H = g("tube_width", 0.012), g("tube_height", 0.012 * self.film_h / self.film_w)
            self.L, self.R = g("tube_length", 0.06), g("relay_distance", 0.03)
            self.f, self.S = g("focal_length", 0.05), g("focus_distance", 1.0)
            self.relay_aperture = g("relay_aperture", 0.0)
            if self.layout == "kaleidoscope":
                probe = ko.kaleido_geometry(self.W, self.H, self.L, self.R, self.f, self.S, 1e9,
                                            self.relay_aperture, WHERE)
                needed = math.hypot(probe["half"] * probe["subaperture_pitch"][0],
                                    probe["half"] * probe["subaperture_pitch"][1]) + probe["subaperture_radius"]
                self.aperture = g("aperture_radius", 1.05 * needed)
                self.geo = ko.kaleido_geometry(self.W, self.H, self.L, self.R, self.f, self.S, self.aperture,
                                               self.relay_aperture, WHERE)
                self.n = self.geo["n"]
                if abs(self.film_w / self.film_h - self.W / self.H) > 0.01 * self.W / self.H:
                    raise ValueError(f"{WHERE}: film {self.film_w}x{self.film_h} and tube {self.W}x{self.H} differ "
                                     "in aspect ratio; the film images the tube exit, so they must match")
            else:
                self.n = int(props.get("views", 3))
                if self.n < 1:
                    raise ValueError(f"{WHERE}: views = {self.n}: must be an integer >= 1")
                if self.f <= 0 or self.S <= self.f:
                    raise ValueError(f"{WHERE}: focus_distance = {self.S} must exceed focal_length = {self.f} > 0")
                self.aperture = g("aperture_radius", 0.01)
                if not self.aperture > 0:
                    raise ValueError(f"{WHERE}: aperture_radius = {self.aperture}: must be > 0 for a microlens array")
                self.geo = {"n": self.n, "lens_to_entrance": 1.0 / (1.0 / self.f - 1.0 / self.S)}
            if self.film_w % self.n or self.film_h % self.n:
                raise ValueError(f"{WHERE}: film {self.film_w}x{self.film_h} is not a multiple of {self.n} views per "
                                 "axis: views would overlap pixels; choose width and height divisible by "
                                 f"{self.n}")
            self.m_needs_sample_3 = self.layout == "microlens" or self.relay_aperture > 0

        # ------------------------------------------------------------ metadata
        def view_layout(self) -> list:
            """Per view: index (i, j), film tile (x0, y0, w, h), flips, sub-aperture centre on the main lens."""
            n, tw, th = self.n, self.film_w // self.n, self.film_h // self.n
            half = (n - 1) // 2
            views = []
            for row in range(n):
                for col in range(n):
                    i, j = col - half, row - half
                    if self.layout == "kaleidoscope":
                        scale = self.geo["lens_to_entrance"] / (self.R + self.L)
                        ax, ay = ko.subaperture(i, j, 0.0, 0.0, self.W, self.H, scale, np)
                        views.append({"i": i, "j": j, "tile": [col * tw, row * th, tw, th], 
                                      "flip_x": bool(i % 2), "flip_y": bool(j % 2), "subaperture": [float(ax), float(ay)]})
                    else:
                        pitch = 2 * self.aperture / n
                        # the lenslet inverts: the pixel right of centre sees the main lens's -x side; the
                        # view's position is the centroid of its square cell clipped by the round aperture
                        views.append({"i": i, "j": j, "pixel_offset": [col, row], "stride": n,
                                      "subaperture": _clipped_cell_centroid(-i * pitch, -j * pitch, pitch,
                                                                            self.aperture),
                                      "cell_centre": [-i * pitch, -j * pitch]})
            return views

        def optics_metadata(self) -> dict:
            d = {"design": self.layout, "n": self.n, "mode": self.mode, "focal_length": self.f,
                 "focus_distance": self.S, "aperture_radius": self.aperture,
                 "lens_to_image_plane": self.geo["lens_to_entrance"], "views": self.view_layout(),
                 "image_plane_size": [self.W, self.H],
                 "convention": "view (i, j) in tile column i + (n-1)/2 from the left, row j + (n-1)/2 from the top; "
                               "views oriented like a perspective camera; subaperture in metres on the main lens, "
                               "sensor-local frame (local +x shows on the image left); plugins/kaleido_optics.py"}
            if self.layout == "kaleidoscope":
                d.update(tube=[self.W, self.H, self.L], relay_distance=self.R, relay_aperture=self.relay_aperture)
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
            W, H, L, R = self.W, self.H, self.L, self.R
            ex, ey = ko.film_to_exit(u, v, W, H)
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
            i, px, sx = ko.fold(dr, qx, W)
            j, py, sy = ko.fold(dr, qy, H)
            if self.mode == "tube_only":
                d = dr.normalize(mi.Vector3f(sx * (qx - rx), sy * (qy - ry), R + L))
                return (px, py, mi.Float(0.0)), (d.x, d.y, d.z), valid
            scale = self.geo["lens_to_entrance"] / (R + L)
            ax, ay = ko.subaperture(i, j, rx, ry, W, H, scale, dr, signs=(sx, sy))
            valid &= ax * ax + ay * ay <= self.aperture * self.aperture
            o, d = ko.main_lens_ray(dr, px, py, ax, ay, self.geo["lens_to_entrance"], self.S)
            return o, d, valid

        def _microlens_ray(self, sample2, sample3, offset, crop):
            n = self.n
            fx = offset.x + sample2.x * crop.x                  # film pixel coordinates
            fy = offset.y + sample2.y * crop.y
            ix, iy = dr.floor(fx), dr.floor(fy)
            vi, vj, x, y, cx, cy = ko.microlens_mapping(dr, ix, iy, fx - ix, fy - iy, n, self.film_w, self.film_h,
                                                        self.W, self.H)
            # spatial position: anywhere under the lenslet (sample3); angle: the pixel's sub-aperture cell
            lw, lh = self.W * n / self.film_w, self.H * n / self.film_h
            x = x + (sample3.x - 0.5) * lw
            y = y + (sample3.y - 0.5) * lh
            pitch = 2 * self.aperture / n
            ax, ay = (vi + cx) * pitch, (vj + cy) * pitch
            valid = ax * ax + ay * ay <= self.aperture * self.aperture
            o, d = ko.main_lens_ray(dr, x, y, ax, ay, self.geo["lens_to_entrance"], self.S)
            return o, d, valid

        def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
            ray, weight = self.sample_ray(time, sample1, sample2, sample3, active)
            rd = mi.RayDifferential3f(ray)
            rd.has_differentials = False
            return rd, weight

        def traverse(self, callback):
            super().traverse(callback)
            callback.put("to_world", self.m_to_world, mi.ParamFlags.NonDifferentiable)

        def bbox(self):
            p = self.world_transform() @ mi.ScalarPoint3f(0, 0, 0)
            return mi.ScalarBoundingBox3f(p, p)

        def to_string(self):
            return f"KaleidoscopeSensor[layout={self.layout}, n={self.n}, mode={self.mode}]"

    return KaleidoscopeSensor


sensor_class = per_variant(_define_class)   # the KaleidoscopeSensor class of the active variant


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
