"""Ground truth from the renderer itself, for scoring the applications (depth, textured pixels).

Depth is Mitsuba's own: the ``aov`` integrator (``dd:depth``, distance along the ray) through a pinhole with the
sensor's field of view and pose, i.e. the centre view that light-field refocus is aligned to (for the galvo:
zero mirror angles), converted from ray distance to z.
"""
from __future__ import annotations

import math

import numpy as np


def truth_depth(timed, t: float, spp: int = 1) -> np.ndarray:
    """z depth (H, W) of the sensor's centre view at time ``t`` (s); inf where the ray hits nothing."""
    import mitsuba as mi
    sensor = timed.sensor
    optics = sensor.optics_metadata()
    if "fov_x_deg" not in optics:
        raise ValueError(f"truth_depth needs a sensor with a field of view (fov_x_deg); got {optics.get('design')}")
    size = sensor.film().size()
    w, h = int(size[0]), int(size[1])
    pinhole = mi.load_dict({
        "type": "perspective", "fov": optics["fov_x_deg"], "fov_axis": "x", "near_clip": 1e-4,
        "to_world": mi.ScalarTransform4f(np.array(sensor.world_transform().matrix).reshape(4, 4)),
        "film": {"type": "hdrfilm", "width": w, "height": h, "rfilter": {"type": "box"}, "pixel_format": "luminance"},
        "sampler": {"type": "stratified", "sample_count": spp, "jitter": False}})
    aov = mi.load_dict({"type": "aov", "aovs": "dd:depth"})
    timed.set_time(t)
    dist = np.array(mi.render(timed.scene, sensor=pinhole, integrator=aov))[..., 0].astype(np.float64)
    tan_half = math.tan(math.radians(optics["fov_x_deg"]) / 2)
    x = ((np.arange(w) + 0.5) / w * 2 - 1) * tan_half
    y = ((np.arange(h) + 0.5) / h * 2 - 1) * tan_half * h / w
    xx, yy = np.meshgrid(x, y)
    z = dist / np.sqrt(1 + xx * xx + yy * yy)
    return np.where(dist > 0, z, np.inf)


def textured(log_image: np.ndarray, threshold: float = 0.1) -> np.ndarray:
    """Pixels whose log image changes by more than ``threshold`` per pixel (Sobel gradient magnitude): where
    focus and depth can be measured at all."""
    import cv2
    img = np.asarray(log_image, np.float32)
    gx = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3) / 8
    gy = cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3) / 8
    return np.hypot(gx, gy) > threshold
