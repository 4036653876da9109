"""Ground truth from the renderer itself, for scoring the applications (depth, textured pixels).

Depth is Mitsuba's own: the ``aov`` integrator (``dd:depth``, distance along the ray) through a pinhole with the
sensor's field of view and pose, i.e. the centre view that light-field refocus is aligned to (for the galvo:
zero mirror angles), converted from ray distance to z.
"""
from __future__ import annotations

import numpy as np

from ..errors import ConfigError
from ..optics.galvo import pixel_ray_slopes
from ..simulate.render import render_frames


def centre_pinhole(timed, spp: int = 1, scale: int = 1):
    """A perspective sensor with the scene sensor's field of view, pose (at the scene's current time: call
    ``timed.set_time`` first) and film size (times ``scale`` on each axis): the galvo's centre view (zero mirror
    angles), which refocus and depth maps are aligned to, i.e. what a conventional camera in its place would
    see."""
    import mitsuba as mi
    sensor = timed.sensor
    optics = sensor.optics_metadata()
    if "fov_x_deg" not in optics:
        raise ConfigError(f"a centre pinhole needs a sensor with a field of view (fov_x_deg); got "
                         f"{optics.get('design')}")
    size = [int(v) * int(scale) for v in sensor.film().size()]
    return mi.load_dict({
        "type": "perspective", "fov": optics["fov_x_deg"], "fov_axis": "x", "near_clip": 1e-4,
        "to_world": mi.ScalarTransform4f(np.array(sensor.world_transform().matrix).reshape(4, 4)),
        "film": {"type": "hdrfilm", "width": int(size[0]), "height": int(size[1]), "rfilter": {"type": "box"},
                 "pixel_format": "luminance"},
        "sampler": {"type": "stratified", "sample_count": spp, "jitter": False}})


def truth_depth(timed, t: float, spp: int = 1, scale: int = 1) -> np.ndarray:
    """z depth (H, W) of the sensor's centre view at time ``t`` (s), through each pixel's centre (or, with
    ``scale``, of a ``scale`` times finer grid: (H scale, W scale)); inf where the ray hits nothing."""
    import mitsuba as mi
    if isinstance(scale, bool) or not isinstance(scale, int) or scale < 1:
        raise ConfigError(f"truth_depth: scale = {scale!r}: expected a whole number >= 1")
    timed.set_time(t)
    pinhole = centre_pinhole(timed, spp, scale)
    w, h = (int(v) for v in pinhole.film().size())
    aov = mi.load_dict({"type": "aov", "aovs": "dd:depth"})
    dist = np.array(mi.render(timed.scene, sensor=pinhole, integrator=aov))[..., 0].astype(np.float64)
    xx, yy = pixel_ray_slopes(w, h, timed.sensor.optics_metadata()["fov_x_deg"])
    z = dist / np.sqrt(1 + xx * xx + yy * yy)
    return np.where(dist > 0, z, np.inf)


def check_planes_seen(timed, planes: dict, times, tolerance: float, where: str, min_pixels: int = 16,
                      depth_at=None) -> None:
    """Refuse, before any rendering of events, a named plane ({name: depth}) on which no part of the scene lies
    at any of ``times`` (s; fewer than ``min_pixels`` pixels within ``tolerance``, relative, of its depth in
    Mitsuba's depth): its scores came out NaN after the whole render (``highspeed --plane fan=0.05``).
    ``depth_at(t)``: the depth map at time t where the centre pinhole (``truth_depth``) does not apply, e.g. a
    kaleidoscope's centre view."""
    times = np.atleast_1d(np.asarray(times, np.float64))
    zs = [(depth_at or (lambda t: truth_depth(timed, t)))(float(t)) for t in times]
    for name, depth in planes.items():
        if max(np.count_nonzero(np.abs(z / depth - 1) < tolerance) for z in zs) < min_pixels:
            when = ", ".join(f"{t * 1e3:g}" for t in times)
            raise ConfigError(f"plane {name!r} at {depth:g}: no part of {where} lies within {tolerance:g} "
                              f"(relative) of that depth at {when} ms (Mitsuba's depth)")


def truth_depth_range(timed, t: float, sub: int = 4) -> tuple:
    """(nearest, farthest) z depth (H, W) within each pixel's footprint at time ``t``: ``sub`` x ``sub`` rays a
    pixel. Where a pixel straddles an occluding edge, both depths are the truth; scoring against the centre
    ray alone counts a pixel a card half covers as wrong at the card's depth."""
    z = truth_depth(timed, t, scale=sub)
    h, w = z.shape[0] // sub, z.shape[1] // sub
    blocks = z.reshape(h, sub, w, sub)
    return blocks.min(axis=(1, 3)), blocks.max(axis=(1, 3))


def centre_frame(timed, t: float, log: bool = True, spp: int = 4) -> np.ndarray:
    """The centre view at time ``t``: the pixel's log brightness (``log``) or linear radiance; where textured
    pixels are found for scoring depth maps and refocus aligned to the centre."""
    timed.set_time(t)
    return render_frames(timed, [t], spp=spp, log=log, sensor=centre_pinhole(timed))[0]


def conventional_frame(timed, t_mid: float, fps: float = 60.0, samples: int = 16, spp: int = 4) -> np.ndarray:
    """What a conventional camera in the event camera's place records: the centre view's linear radiance
    averaged over one exposure of 1 / ``fps`` seconds centred on ``t_mid`` (``samples`` instants): motion blurs.
    The camera itself stays at its pose at ``t_mid``."""
    if not (fps > 0 and samples >= 1):
        raise ConfigError(f"fps = {fps}, samples = {samples}: need fps > 0 and samples >= 1")
    times = t_mid + ((np.arange(samples) + 0.5) / samples - 0.5) / fps
    timed.set_time(t_mid)
    return render_frames(timed, times, spp=spp, log=False, sensor=centre_pinhole(timed)).mean(axis=0)


def textured(log_image: np.ndarray, threshold: float = 0.1) -> np.ndarray:
    """Pixels whose log image changes by more than ``threshold`` per pixel (Sobel gradient magnitude): where
    focus and depth can be measured at all."""
    from ..focus.measures import log_gradient
    return log_gradient(log_image) > threshold
