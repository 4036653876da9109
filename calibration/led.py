"""An LED's track from its events alone (the depth calibration's measurement, ``eventfield calibrate depth``).

An LED is a bright point on a dark background, so no start image has to be solved for: every pixel it sweeps
over sees the background at some instant of the scan period, and the background's log brightness is known
(the pixel's lin-log response to no light). Each pixel's net event count since the period's start,
C N(x, t), therefore gives its log brightness above the background exactly (to one threshold C):

    G(x, t) = C N(x, t) - min_t' C N(x, t')                   (pixels that see the background)

Pixels the LED never leaves (an LED image wider than the scan circle) never see the background; they reach
the LED's full brightness instead, the largest level G of the pixels that do, so G(x, t) = G_full +
C N(x, t) - max_t' C N(x, t') for them (and G = G_full where the LED covers a pixel all period, with no event).
Which pixels these are is plain from the events: a pixel that goes dark again swings by about the LED's whole
log contrast (~ln(50 / 1e-3) = 11 for the bundled LED, 55 events), one that stays lit by at most the log of
its partial coverage.

The linear brightness above the background, linlog^-1(L_bg + G) - linlog^-1(L_bg), weights the centroid of
each instant; the centroids follow the scan curve, ``c(t) = c0 + S a(tau0 + t - t_0)``, and ``fit_point_track``
fits c0, tau0 and the scales S (px per mechanical radian) by least squares with the same refusals as the
patch fit (``galvo._check_fit``).

Why not the start-image solver (``reconstruct.galvo``): it assumes one depth for the whole scene (infinity by
default) and relates the views by that depth's view-to-view map, so the frames it reconstructs move by that
depth's scale, whatever depth the LED is at: the scale the depth calibration is there to measure. An LED at
0.4 m measured 532 px/rad (exact: 357) through it, and the fitted depth model came out inverted.
"""
from __future__ import annotations

import math

import numpy as np

from .galvo import CalibrationError, GalvoCalibration, _check_fit, _curve_dict, fit_std

CONTRAST_SPLIT = 0.5        # a pixel swinging by more than this share of the largest swing sees the background
# an LED lights a ring along its scan circle: 0.3-2.8 % of the film in the tests and README (7.8 % at fov 13,
# amplitude 2; ~20 % for a 2-3 cm sphere at 0.15-0.3 m, wider than the circle: a review); a textured
# scene changes everywhere (galvo_static: most of the film), and its "track" put the pivot behind the camera,
# which the depth fit then blamed on the depth labels (a new user)
MAX_FOOTPRINT_SHARE = 0.25


def _level_extremes(events, t_start: float, t_end: float, c_on: float, c_off: float):
    """Per pixel, the lowest and highest log change C N(x, t) over (t_start, t_end], the start (0) included."""
    t_us = events.t
    lo, hi = np.searchsorted(t_us, np.rint(np.array([t_start, t_end]) * 1e6).astype(np.int64), side="right")
    pix = events.y[lo:hi].astype(np.int64) * events.width + events.x[lo:hi]
    wts = np.where(events.p[lo:hi] > 0, c_on, -c_off)
    n = events.width * events.height
    low, high = np.zeros(n), np.zeros(n)
    if len(pix):
        order = np.argsort(pix, kind="stable")               # time order kept within each pixel
        p, level = pix[order], np.cumsum(wts[order])
        starts = np.r_[0, np.flatnonzero(np.diff(p)) + 1]
        level -= np.repeat(np.r_[0.0, level[starts[1:] - 1]], np.diff(np.r_[starts, len(p)]))
        low[p[starts]] = np.minimum(np.minimum.reduceat(level, starts), 0.0)
        high[p[starts]] = np.maximum(np.maximum.reduceat(level, starts), 0.0)
    return low.reshape(events.height, events.width), high.reshape(events.height, events.width)


def led_start_level(changes, low, high, c_on: float, c_off: float):
    """(G0, footprint): the LED's log brightness above the background at the period's start per pixel, and the
    pixels it lights during the period (module docstring), from the log changes since the start at instants
    over the period ``changes`` (K, H, W) and their extremes ``low``/``high`` over all events (H, W). Refuses a
    period with no LED in it."""
    from scipy import ndimage
    swing = high - low
    if not swing.max() > 2 * max(c_on, c_off):
        raise CalibrationError("no LED in the scan period: no pixel's brightness changes by more than two "
                               "thresholds (the LED is outside the view, too dim, or the period holds no events)")
    dark_too = swing > CONTRAST_SPLIT * swing.max()           # the LED comes and goes: the pixel sees background
    full = float(swing[dark_too].max())                       # the LED's full level above the background
    footprint = ndimage.binary_fill_holes(dark_too)
    start = np.where(dark_too, -low, 0.0)
    lit_share = np.mean(changes - low > swing / 2, axis=0)    # share of the period a pixel is lit
    inner, count = ndimage.label(footprint & ~dark_too, structure=np.ones((3, 3)))
    for k in range(1, count + 1):
        # never dark: lit all period (an LED image wider than the scan circle), or the hole an LED image
        # narrower than the circle goes round; the pixels around the first are lit more than half the period
        part = inner == k
        rim = ndimage.binary_dilation(part, structure=np.ones((3, 3))) & dark_too
        if rim.any() and lit_share[rim].mean() > 0.5:
            start[part] = full - high[part]
        else:
            footprint[part] = False
    if footprint.mean() > MAX_FOOTPRINT_SHARE:
        raise CalibrationError(f"no single LED in the scan period: {footprint.mean():.0%} of the film changes "
                               f"brightness (an LED and its scan circle light at most {MAX_FOOTPRINT_SHARE:.0%}): a "
                               "capture of a scene, not of an LED?")
    return start, footprint


def track_led(events, times, t_start: float, period: float, c_on=None, c_off=None) -> np.ndarray:
    """Centroid (x, y; continuous pixels) of the LED's linear brightness above the background at each of
    ``times`` (s) within the scan period from ``t_start``, from the events alone: (K, 2)."""
    from mitsuba_eventfield.lightfield.reconstruct import direct, thresholds
    from mitsuba_eventfield.plugins.pixel_model import linlog_inverse_np, linlog_np, stream_linlog_threshold
    times = np.asarray(times, dtype=np.float64)
    if len(times) == 0 or times.min() < t_start or times.max() > t_start + period:
        raise CalibrationError("the track's times must lie in the scan period they are measured over")
    c_on, c_off = thresholds(events, c_on, c_off)
    linear_below = stream_linlog_threshold(events.meta)
    changes = direct(events, times, None, t_start, c_on, c_off)
    start, footprint = led_start_level(changes, *_level_extremes(events, t_start, t_start + period, c_on, c_off),
                                       c_on, c_off)
    levels = float(linlog_np(0.0, linear_below)) + start + changes      # the background's level + G
    light = np.where(footprint, np.maximum(linlog_inverse_np(levels, linear_below), 0.0), 0.0)   # background: 0
    total = light.sum(axis=(1, 2))
    if not np.all(total > 0):
        raise CalibrationError("an instant of the period shows no LED: it left the view")
    ys, xs = np.mgrid[0:events.height, 0:events.width] + 0.5
    return np.stack([(light * xs).sum(axis=(1, 2)) / total, (light * ys).sum(axis=(1, 2)) / total], axis=-1)


def _fit_at(tau0: float, curve, dt, centres):
    """Least-squares (c0, S) per axis for the curve time ``tau0`` of the first instant: (params, residuals)."""
    a = np.stack(curve.angles(tau0 + dt), axis=-1)
    params, resid = [], []
    for axis in range(2):
        basis = np.c_[np.ones_like(dt), a[:, axis]]
        (c0, s), *_ = np.linalg.lstsq(basis, centres[:, axis], rcond=None)
        params.append((c0, s))
        resid.append(basis @ (c0, s) - centres[:, axis])
    return params, np.concatenate(resid)


def fit_point_track(centres, times, curve, max_phase_std_deg: float = 5.0, max_scale_rel_std: float = 0.05,
                    scale_limit: float | None = None) -> GalvoCalibration:
    """Fit ``c(t) = c0 + S a(tau0 + t - times[0])`` to a point's positions ``centres`` (K, 2) at ``times`` (s):
    the first instant's curve time tau0 (a grid over the period, as the curve is periodic, then least squares)
    and the scales S, with a free centre c0 (each centroid carries its own error: none is the reference).
    Refusals as ``galvo.fit_tracks``'s."""
    from scipy.optimize import least_squares
    centres, times = np.asarray(centres, dtype=np.float64), np.asarray(times, dtype=np.float64)
    period = curve.period
    if period is None:
        raise CalibrationError("the scan curve is not periodic")
    if centres.shape != (len(times), 2):
        raise CalibrationError(f"positions of shape {centres.shape} for {len(times)} times: need (K, 2)")
    if len(times) < 5:
        raise CalibrationError(f"{len(times)} positions: at least 5 are needed (5 unknowns: tau0, two scales, "
                               "the centre)")
    if not (np.all(np.isfinite(centres)) and np.all(np.isfinite(times))):
        raise CalibrationError("the positions or their times contain NaN or infinite values")
    dt = times - times[0]
    grid = [(float(np.sum(r ** 2)), tau) for tau in np.linspace(0, period, 144, endpoint=False)
            for p, r in [_fit_at(tau, curve, dt, centres)] if p[0][1] > 0 and p[1][1] > 0]
    if not grid:
        raise CalibrationError("no phase gives positive curve scales: the point does not follow the scan curve")
    tau = min(grid)[1]
    (cx, sx), (cy, sy) = _fit_at(tau, curve, dt, centres)[0]

    def residuals(q):
        a = np.stack(curve.angles(q[0] + dt), axis=-1)
        return (q[3:5] + q[1:3] * a - centres).T.ravel()

    fit = least_squares(residuals, x0=[tau, sx, sy, cx, cy], x_scale=[period / 20, sx, sy, 1.0, 1.0])
    std = fit_std(fit)
    tau0, sx, sy = fit.x[0] % period, fit.x[1], fit.x[2]
    result = GalvoCalibration(curve=_curve_dict(curve), t_first=float(times[0]), tau0=float(tau0),
                              phase_deg=float(tau0 / period * 360), scale_px_per_rad=(float(sx), float(sy)),
                              std={"phase_deg": float(std[0] / period * 360), "scale_x": float(std[1]),
                                   "scale_y": float(std[2])},
                              rms_px=float(np.sqrt(np.mean(fit.fun ** 2))), frames_used=len(times),
                              patches=[[float(fit.x[3]), float(fit.x[4])]])
    return _check_fit(result, max_phase_std_deg, max_scale_rel_std, scale_limit)


def fit_led(events, period_index: int = 0, samples: int = 24, scale_limit: float | None = None,
            **limits) -> GalvoCalibration:
    """The scan phase and curve scales of an LED capture (a galvo event stream) from its events alone: the
    LED's track at ``samples`` instants of scan period ``period_index`` (``track_led``), fitted to the curve of
    the stream's metadata (``fit_point_track``; ``scale_limit``: ``galvo.galvo_scale_limit`` of its optics)."""
    from mitsuba_eventfield.lightfield.model import galvo_period_starts, galvo_view_times
    from mitsuba_eventfield.optics.scan import curve_from_dict
    optics = events.meta.get("optics") or {}
    if optics.get("design") != "galvo":
        raise CalibrationError("an LED capture through the galvo is needed (the stream's optics.design is "
                               f"{optics.get('design')!r})")
    curve = curve_from_dict(optics["scan"], where="event metadata")
    try:
        t0 = galvo_period_starts(events, [period_index])[period_index]
    except ValueError as e:
        raise CalibrationError(str(e)) from None
    times = galvo_view_times(optics, t0, samples)           # the instants a galvo light field's views are at
    centres = track_led(events, times, t0, curve.period)
    return fit_point_track(centres, times, curve, scale_limit=scale_limit, **limits)
