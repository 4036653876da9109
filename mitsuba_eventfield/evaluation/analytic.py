"""Analytic oracle: an emitting plane with a sinusoidal radiance texture sliding past a pinhole camera.

The plane z = D is perpendicular to the optical axis, so image columns map affinely onto plane x. With a box
pixel filter and a non-jittered stratified sampler (the midpoint rule over each pixel), pixel column i sees

    I_i(t) = a + b * sinc * sin(2 pi (X_i - v t) / lam),   sinc = sin(pi w / lam) / (pi w / lam)

where X_i is the pixel centre on the plane and w the pixel footprint. Ground-truth events follow from the
definition of the ideal pixel applied to this exact curve, independently of the code under test
(:func:`ideal_events`); :func:`score` compares a render's events with them. The scene is the reference of the
timing-accuracy measurements (``benchmarks/bench_accuracy.py``) and of the integrator's exactness tests.
"""
from __future__ import annotations

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


MIDPOINT_SAMPLER = {"type": "stratified", "sample_count": 16, "jitter": False}   # noise-free: the midpoint rule


def scene_dict(mi, velocity_px_per_s, sampler=None):
    """The scene (``sampler``: a Mitsuba sampler dict; default the noise-free midpoint rule, where the pixel
    values are exactly :func:`exact_intensity`; any other sampler adds Monte-Carlo noise to them)."""
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
                   "sampler": dict(sampler or MIDPOINT_SAMPLER),
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


def truth_events(velocity, duration, c, samples_per_second=2e6):
    """The exact ideal-pixel events of every column over [0, duration] (per column a list of (t s, polarity))."""
    times = np.linspace(0, duration, int(round(duration * samples_per_second)) + 1)
    return ideal_events(np.log(exact_intensity(times, velocity)), times, c)


def score(ev, truth) -> dict:
    """A render's events against :func:`truth_events`, pixel by pixel: the count error (events too many or too
    few, summed over pixels, relative to the exact count), the timestamp error of every exact event to the
    nearest rendered event of its pixel and polarity (median and 99th percentile, microseconds: one missing or
    extra event does not shift the pairing of all later ones) and whether the polarities agree in order."""
    count_diff, errors, pol_ok = [], [], True
    for row in range(HEIGHT):
        for col in range(WIDTH):
            sel = (ev.x == col) & (ev.y == row)
            t_sim, p_sim = ev.t[sel] * 1e-6, ev.p[sel]
            t_true = np.array([e[0] for e in truth[col]])
            p_true = np.array([e[1] for e in truth[col]])
            count_diff.append(len(t_sim) - len(t_true))
            n = min(len(t_sim), len(t_true))
            pol_ok &= bool(np.array_equal(p_sim[:n], p_true[:n]))
            for pol in (1, -1):
                sim, true = t_sim[p_sim == pol], t_true[p_true == pol] if len(t_true) else t_true
                if len(sim) and len(true):
                    i = np.clip(np.searchsorted(sim, true), 1, len(sim) - 1) if len(sim) > 1 else np.zeros(
                        len(true), int)
                    nearest = np.minimum(np.abs(sim[i] - true), np.abs(sim[np.maximum(i - 1, 0)] - true))
                    errors.append(nearest)
    err = np.concatenate(errors) * 1e6 if errors else np.zeros(0)
    n_true = HEIGHT * sum(len(e) for e in truth)
    return {"events": len(ev), "exact_events": n_true, "count_diff": np.array(count_diff),
            "count_error": float(np.abs(count_diff).sum() / max(n_true, 1)),
            "timing_median_us": float(np.median(err)) if len(err) else float("nan"),
            "timing_p99_us": float(np.percentile(err, 99)) if len(err) else float("nan"),
            "timing_errors_us": err, "polarity_ok": pol_ok}
