"""The scene the failure sweeps (``failure``) turn their knobs on, and the exact answers they score against.

A textured card in front of a textured wall (1.5 m), both emitting their own texture (no lights, no shadows),
seen through a two-axis galvo scanning a 100 Hz circle (2 mechanical degrees, pivot 0.2 m, 40 degree field of
view) by a jitter-free stratified sampler, so the frames carry no Monte-Carlo noise and every error comes from
the method or the knob turned. Knobs: the card's depth, its sideways speed in image pixels per scan period,
the texture contrast c (radiance 0.5 (1 + c t), t a smooth random texture in [-1, 1]); the pixel's noise goes
through ``render_events``'s ``pixel``. The card keeps one angular size (a third of the field across) whatever
its depth.
"""
from __future__ import annotations

import numpy as np

from .. import backend
from ..optics import galvo as galvo_optics
from ..scene.timed import load_scene

WIDTH, HEIGHT = 96, 72
FOV = 40.0                  # degrees, horizontal
FREQUENCY = 100.0           # Hz: one scan period is 10 ms
AMPLITUDE = 2.0             # mechanical degrees
PIVOT, SEPARATION = 0.2, 0.01
WALL_DEPTH = 1.5
CARD_HALF_ANGLE = 0.16      # card half-width / depth
THRESHOLD = 0.1             # event threshold (log)


def texture(seed: int, size: int = 256, blur: float = 3.0) -> np.ndarray:
    """A smooth random texture in [-1, 1] (band-limited: no aliasing at these films)."""
    import cv2
    rng = np.random.default_rng(seed)
    t = cv2.GaussianBlur(rng.random((size, size)).astype(np.float32), (0, 0), blur)
    return (2 * (t - t.min()) / (t.max() - t.min()) - 1).astype(np.float32)


def focal_px(width: int = WIDTH) -> float:
    return galvo_optics.focal_length_px(width, FOV)


def card_velocity(px_per_period: float, depth: float, width: int = WIDTH) -> float:
    """Sideways speed (m/s) at which a card at ``depth`` moves ``px_per_period`` image pixels per scan period."""
    return px_per_period * depth / focal_px(width) * FREQUENCY


def card_scene(depth: float = 0.5, speed: float = 0.0, contrast: float = 0.5, width: int = WIDTH,
               height: int = HEIGHT, spp: int = 4):
    """The TimedScene (module docstring): card at ``depth`` (m) moving ``speed`` px per period (image -x for
    speed > 0), texture ``contrast`` in [0, 1)."""
    backend.ensure_variant()
    mi = backend.mi
    T = mi.ScalarTransform4f

    def emitter(tex, z, half):
        img = (0.5 * (1 + contrast * tex)).astype(np.float32)
        return {"type": "rectangle", "to_world": T().translate([0, 0, z]).rotate([0, 1, 0], 180).scale(half),
                "emitter": {"type": "area", "radiance": {"type": "bitmap", "bitmap": mi.Bitmap(img[..., None]),
                                                         "raw": True, "filter_type": "bilinear"}}}
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "eventfield", "threshold": THRESHOLD, "inner": {"type": "direct"}},
        "sensor": {"type": "galvo", "fov": FOV, "curve": "circle", "frequency": FREQUENCY, "amplitude": AMPLITUDE,
                   "mirror_distance": PIVOT, "mirror_separation": SEPARATION,
                   "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}},
                   "sampler": {"type": "stratified", "sample_count": spp, "jitter": False}},
        "wall": emitter(texture(1), WALL_DEPTH, 1.0),
        "card": emitter(texture(2), depth, CARD_HALF_ANGLE * depth)})
    motion = {"version": 1, "objects": {"card": {"velocity": [card_velocity(speed, depth, width), 0.0, 0.0]}}}
    return load_scene(scene, motion=motion if speed else None)


def period() -> float:
    return 1.0 / FREQUENCY


def exact_scales(optics: dict, pixel, depth: float, t_first: float, width: int = WIDTH,
                 height: int = HEIGHT) -> tuple:
    """(Sx, Sy) px per mechanical radian of the scene point seen at ``pixel`` (x, y, continuous) in the view at
    ``t_first``, on the plane z = ``depth``: the ray through the pixel at that view's mirror angles, then that
    point projected through the mirrors over a whole scan period and the track fitted against the angles (the
    calibration's linear model)."""
    from ..optics.scan import curve_from_dict
    curve = curve_from_dict(optics["scan"])
    d1, sep = optics["mirror_distance"], optics["mirror_separation"]
    a0x, a0y = curve.angles(np.float64(t_first))
    u, v = pixel[0] / width, pixel[1] / height
    d = galvo_optics.pinhole_direction(np, u, v, galvo_optics.tan_half_fov(optics["fov_x_deg"]), width / height)
    o, d = galvo_optics.galvo_transform(np, (0.0, 0.0, 0.0), d, float(a0x), float(a0y), d1, sep)
    t = (depth - o[2]) / d[2]
    point = (o[0] + t * d[0], o[1] + t * d[1], depth)
    ax, ay = curve.angles(np.linspace(0, curve.period, 720, endpoint=False))
    px, py = galvo_optics.project_point(np, point, ax, ay, d1, sep, focal_px(width), width, height)
    return abs(float(np.polyfit(ax, px, 1)[0])), abs(float(np.polyfit(ay, py, 1)[0]))


def log_error(estimate, truth, mask) -> float:
    """RMS log error over ``mask`` after removing the one free constant (the median difference)."""
    e = np.asarray(estimate, np.float64) - np.asarray(truth, np.float64)
    e = e - np.median(e[mask])
    return float(np.sqrt(np.mean(e[mask] ** 2)))
