"""Mitsuba sensor plugin ``galvo``: a pinhole or thin-lens camera looking through a two-axis scanning mirror.

Parameters (angles in mechanical degrees, lengths in scene units, frequencies in Hz; the ray optics are
``mitsuba_eventfield.optics.galvo``, the limits ``mitsuba_eventfield.optics.envelope``):

=================  =========  ==========  ===============================================================
Parameter          Type       Default     Description
=================  =========  ==========  ===============================================================
fov                float      (Mitsuba)   field of view in degrees along fov_axis (default x); or focal_length
                                          (e.g. "35mm"); neither: Mitsuba's perspective default (50 mm)
aperture_radius    float      0           > 0: thin lens focused at focus_distance
focus_distance     float      1           thin-lens focus distance
mirror_distance    float      0.03        camera centre to the X mirror pivot
mirror_separation  float      0.01        X mirror pivot to Y mirror pivot
curve              string     circle      circle | lissajous | line | raster | moore
frequency          float      250         scan frequency (circle, line, raster, moore)
amplitude          float      1           scan radius / half-width
phase              float      0           start angle on the curve (degrees)
galvo_model        string     gvs01x      the galvo simulated: gvs01x (the device layer's envelope) | ideal
max_angle          float      (model's)   narrows a real galvo's travel, or sets an ideal mirror's
volts_per_deg      float      (model's)   the driver's scaling (0.1-2 V per degree), as the rig is set
bandwidth          float      0           > 0: second-order mirror response, natural frequency
damping            float      0.7         damping of that response
far_clip           float      1e4         longest ray
to_world           transform  identity    camera pose (animated by the motion file)
=================  =========  ==========  ===============================================================

A scan outside the named model's envelope (travel, frequency derating, drive voltage) is refused when the
scene loads, with the reason the device layer gives for the same scan.

Other curve parameters are those of ``mitsuba_eventfield.optics.scan.make_curve`` (freq_x, amplitude_y, phase, lines,
order, ...). The scan instant comes from the opaque parameter ``<id>.time`` (set by the time-stepping loop,
reduced modulo the scan period on the host), plus the ray's own time within the shutter. Changing it never
recompiles a kernel.
"""
from __future__ import annotations


import drjit as dr
import mitsuba as mi

from mitsuba_eventfield.optics import galvo as galvo_optics

from ._per_variant import per_variant, subclass
from .properties import number_prop

WHERE = "sensor 'galvo'"

_FLOAT_PARAMS = ("frequency", "amplitude", "phase", "offset_x", "offset_y", "freq_x", "freq_y", "amplitude_x",
                 "amplitude_y", "phase_x", "phase_y")
_INT_PARAMS = ("lines", "order", "samples_per_line", "samples_per_segment")


def curve_from_props(props) -> tuple:
    """(scan curve as the mirror moves, description dict) from the plugin's properties. The commanded curve
    must fit the envelope of the named galvo model (``optics.envelope``), exactly as the device layer checks."""
    from dataclasses import replace

    from mitsuba_eventfield.optics.envelope import (DEFAULT_DAMPING, DEFAULT_GALVO_MODEL, VOLTS_PER_DEG_RANGE,
                                                    galvo_model)
    from mitsuba_eventfield.optics.scan import curve_to_dict, make_curve
    from mitsuba_eventfield.validate import number
    where = "sensor 'galvo'"
    name = props.get("curve", "circle")
    # counts stay as given: make_curve refuses a fraction and names their ranges (int() made 4.7 lines 4)
    params = {k: number_prop(props, k, None, where, integer=k in _INT_PARAMS)
              for k in _FLOAT_PARAMS + _INT_PARAMS if k in props}
    if "axis" in props:
        params["axis"] = props.get("axis")
    envelope = galvo_model(props.get("galvo_model", DEFAULT_GALVO_MODEL), where,
                           number_prop(props, "max_angle", None, where, 0, lo_open=True))
    if "volts_per_deg" in props:         # the rig's driver scaling, as `eventfield device --volts-per-deg`
        envelope = replace(envelope, volts_per_deg=number(props.get("volts_per_deg"), f"{where}: volts_per_deg",
                                                          *VOLTS_PER_DEG_RANGE))
    limits = {"envelope": envelope, "where": where}
    bandwidth = number_prop(props, "bandwidth", 0.0, where, 0)
    damping = number_prop(props, "damping", DEFAULT_DAMPING, where, 0, lo_open=True)
    commanded = make_curve(name, **limits, **params)
    _warn_long_period(commanded, where)
    moving = make_curve(name, bandwidth_hz=bandwidth, damping=damping, **limits, **params) if bandwidth else commanded
    return moving, curve_to_dict(commanded, bandwidth, damping)


LONG_PERIOD_S = 1.0      # a scan that repeats less often than this is of no use to the light-field commands


class ScanPeriodWarning(UserWarning):
    """A scan whose period is longer than ``LONG_PERIOD_S`` (or that never repeats)."""


def _warn_long_period(curve, where: str) -> None:
    """Lissajous frequencies without a small whole-number ratio (100 and 141.4213562 Hz) repeat after an hour
    or never: the render is fine, but refocus, depth and reconstruct need a whole scan period of events, and
    said so only then ("the stream spans 10 ms, less than one whole scan period of 3.2075e+06 ms")."""
    import warnings
    period = curve.period
    if period is not None and period <= LONG_PERIOD_S:
        return
    warnings.warn(f"{where}: the {curve.name} scan repeats {'never' if period is None else f'only every {period:.4g} s'}"
                  ": light fields (refocus, depth, reconstruct) need a whole scan period of events; frequencies in a "
                  "small whole-number ratio (e.g. 200 and 300 Hz) repeat within milliseconds", ScanPeriodWarning,
                  stacklevel=2)


class _GalvoSensorMethods:
    """The ``galvo`` sensor's methods, bound to the active variant's ``mi.Sensor`` by ``sensor_class``."""

    def __init__(self, props):
        mi.Sensor.__init__(self, props)
        self.curve, self.scan_description = curve_from_props(props)
        size = self.film().size()
        self.aspect = size.x / size.y
        if number_prop(props, "fov", 1.0, WHERE, 0, 180, lo_open=True) == 180:    # (Mitsuba's lists 0 as allowed)
            raise ValueError(f"{WHERE}: fov = 180: allowed range is (0, 180) degrees")
        self.fov_x = float(mi.parse_fov(props, self.aspect))
        self.tan_half = galvo_optics.tan_half_fov(self.fov_x)
        self.aperture_radius = number_prop(props, "aperture_radius", 0.0, WHERE, 0)     # 0: a pinhole
        self.focus_distance = number_prop(props, "focus_distance", 1.0, WHERE, 0, lo_open=True)
        self.mirror_distance = number_prop(props, "mirror_distance", 0.03, WHERE)
        self.mirror_separation = number_prop(props, "mirror_separation", 0.01, WHERE)
        self.far_clip = number_prop(props, "far_clip", 1e4, WHERE, 0, lo_open=True)
        galvo_optics.checked_optics(self.fov_x, self.mirror_distance, self.mirror_separation, WHERE,
                                    error=ValueError, names=("fov", "mirror_distance", "mirror_separation"))
        self.m_needs_sample_3 = self.aperture_radius > 0
        self.scan_time = mi.Float(0.0)
        dr.make_opaque(self.scan_time)

    # ------------------------------------------------------------ parameters
    def traverse(self, callback):
        mi.Sensor.traverse(self, callback)
        callback.put("time", self.scan_time, mi.ParamFlags.NonDifferentiable)
        callback.put("to_world", self.m_to_world, mi.ParamFlags.NonDifferentiable)   # camera motion

    def parameters_changed(self, keys=[]):
        dr.make_opaque(self.scan_time)
        mi.Sensor.parameters_changed(self, keys)

    @property
    def period(self):
        return self.curve.period

    def phase_time(self, t: float) -> float:
        return self.curve.phase_time(t)

    def optics_metadata(self) -> dict:
        return {"design": "galvo", "scan": self.scan_description, "fov_x_deg": self.fov_x,
                "aperture_radius": self.aperture_radius, "focus_distance": self.focus_distance,
                "mirror_distance": self.mirror_distance, "mirror_separation": self.mirror_separation,
                "angle_convention": "mechanical radians; optical deflection = 2x; +x pans the view to camera "
                                    "+x, +y tilts it to camera +y (mitsuba_eventfield/optics/galvo.py)"}

    # ------------------------------------------------------------ rays
    def _camera_ray(self, sample2, sample3):
        film = self.film()
        size, crop, offset = film.size(), film.crop_size(), film.crop_offset()
        u = (offset.x + sample2.x * crop.x) / size.x
        v = (offset.y + sample2.y * crop.y) / size.y
        dx, dy, dz = galvo_optics.pinhole_direction(dr, u, v, self.tan_half, self.aspect)
        if self.aperture_radius <= 0:
            return (mi.Float(0.0), mi.Float(0.0), mi.Float(0.0)), (dx, dy, dz)
        lens = mi.warp.square_to_uniform_disk_concentric(sample3) * self.aperture_radius
        k = self.focus_distance / dz                       # focus plane z = focus_distance
        fx, fy, fz = dx * k - lens.x, dy * k - lens.y, dz * k
        n = dr.sqrt(fx * fx + fy * fy + fz * fz)
        return (lens.x, lens.y, mi.Float(0.0)), (fx / n, fy / n, fz / n)

    def sample_ray(self, time, sample1, sample2, sample3, active=True):
        wavelengths, weight = self.sample_wavelengths(dr.zeros(mi.SurfaceInteraction3f), sample1, active)
        o, d = self._camera_ray(sample2, sample3)
        theta_x, theta_y = self.curve.angles(self.scan_time + (time - self.shutter_open()))
        o, d = galvo_optics.galvo_transform(dr, o, d, theta_x, theta_y, self.mirror_distance, self.mirror_separation)
        to_world = self.world_transform()
        ray = mi.Ray3f(to_world @ mi.Point3f(*o), dr.normalize(to_world @ mi.Vector3f(*d)), time, wavelengths)
        ray.maxt = self.far_clip
        return ray, weight

    def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
        ray, weight = self.sample_ray(time, sample1, sample2, sample3, active)
        rd = mi.RayDifferential3f(ray)
        rd.has_differentials = False
        return rd, weight

    def bbox(self):
        p = self.world_transform() @ mi.ScalarPoint3f(0, 0, 0)
        return mi.ScalarBoundingBox3f(p, p)

    def to_string(self):
        return (f"GalvoSensor[fov_x={self.fov_x}, curve={self.scan_description}, "
                f"mirrors=({self.mirror_distance}, {self.mirror_separation}), aperture={self.aperture_radius}]")

def _define_class():
    return subclass(mi.Sensor, _GalvoSensorMethods, "GalvoSensor")


sensor_class = per_variant(_define_class)   # the GalvoSensor class of the active variant
