"""Analytic oracle: an emitting plane with a sinusoidal radiance texture sliding past a pinhole camera.

The plane z = D is perpendicular to the optical axis, so image columns map affinely onto plane x. With a box
pixel filter and a non-jittered stratified sampler (the midpoint rule over each pixel), pixel column i sees

    I_i(t) = a + b * sinc * sin(2 pi (X_i - v t) / lam),   sinc = sin(pi w / lam) / (pi w / lam)

where X_i is the pixel centre on the plane and w the pixel footprint. Ground-truth events follow from the
definition of the ideal pixel applied to this exact curve, independently of the code under test.
"""
import math

import numpy as np

A, B = 1.0, 0.6                 # radiance = A + B sin(...)
D = 1.0                         # plane distance
FOV = 30.0                      # horizontal field of view, degrees
WIDTH, HEIGHT = 64, 2
LAM_PX = 16.0                   # texture period in pixels
HALF = D * math.tan(math.radians(FOV) / 2)
PIX = 2 * HALF / WIDTH          # pixel footprint on the plane
LAM = LAM_PX * PIX
PLANE_HALF = 4 * HALF           # plane half-width: covers the view for the whole motion
TEX_N = 16384                   # bitmap texels across the plane


def scene_dict(mi, velocity_px_per_s):
    # the rectangle is turned 180 degrees about y to face the camera, so texture u runs towards world -x
    u_local = -1 + (np.arange(TEX_N) + 0.5) * (2 / TEX_N)
    x_world = -PLANE_HALF * u_local
    tex = (A + B * np.sin(2 * np.pi * x_world / LAM)).astype(np.float32)
    bitmap = mi.Bitmap(np.tile(tex, (2, 1))[..., None])
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 1},
        "sensor": {"type": "perspective", "fov": FOV, "fov_axis": "x",
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=[0, 0, 1], up=[0, 1, 0]),
                   "sampler": {"type": "stratified", "sample_count": 16, "jitter": False},
                   "film": {"type": "hdrfilm", "width": WIDTH, "height": HEIGHT, "rfilter": {"type": "box"}}},
        "plane": {"type": "rectangle",
                  "to_world": mi.ScalarTransform4f().translate([0, 0, D]).scale([PLANE_HALF, PLANE_HALF, 1])
                  @ mi.ScalarTransform4f().rotate([0, 1, 0], 180),   # face the camera (normal -z)
                  "emitter": {"type": "area", "radiance": {"type": "bitmap", "bitmap": bitmap, "raw": True,
                                                           "filter_type": "bilinear", "wrap_mode": "clamp"}}},
    }


def pixel_centres_x():
    """World x of each image column's centre on the plane (Mitsuba's image x runs towards world -x)."""
    return HALF - (np.arange(WIDTH) + 0.5) * PIX


def exact_intensity(t, velocity):
    """(len(t), WIDTH) box-filtered radiance of each column at times t (plane moving at `velocity` along x)."""
    t = np.asarray(t, dtype=np.float64)[:, None]
    xc = pixel_centres_x()[None, :]
    sinc = math.sin(math.pi * PIX / LAM) / (math.pi * PIX / LAM)
    return A + B * sinc * np.sin(2 * np.pi * (xc - velocity * t) / LAM)


def ideal_events(log_curve, times, c):
    """Events of an ideal pixel with threshold c along a densely sampled log curve.

    The pixel fires whenever L reaches the reference level +-c; the reference then moves by c. Equivalently
    the lattice L(0) + k c is crossed at a level other than the current reference. Crossing times come from
    linear interpolation on the dense grid (its error is far below the tolerance tested).
    Returns per column a list of (t, polarity).
    """
    out = []
    for col in range(log_curve.shape[1]):
        L = log_curve[:, col]
        k = (L - L[0]) / c                   # position in lattice units
        ref, events = 0, []
        fl = np.floor(k)
        for j in np.nonzero(fl[1:] != fl[:-1])[0]:
            lo, hi = sorted((fl[j], fl[j + 1]))
            levels = np.arange(lo + 1, hi + 1) if fl[j + 1] > fl[j] else np.arange(hi, lo, -1)
            for lev in levels:
                if lev == ref:
                    continue
                frac = (lev - k[j]) / (k[j + 1] - k[j])
                events.append((times[j] + frac * (times[j + 1] - times[j]), int(np.sign(lev - ref))))
                ref = int(lev)
        out.append(events)
    return out
