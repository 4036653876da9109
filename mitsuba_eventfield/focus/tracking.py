"""Focus tracking over time: refocus a sequence of light fields on an object as it moves in depth (and, with
``follow``, across the image), from the light fields alone; a region with nothing to focus on or follow is
flagged (``TrackingWarning``), not given a depth."""
from __future__ import annotations

import math
import warnings

import cv2
import numpy as np

from ..errors import ConfigError
from ..validate import finite, number
from .measures import IMAGE_MEASURES, focus_measure, refine_peak
from .refocus import _depth_list, check_lightfield, focal_stack, refocus

# track_focus: a focus curve over the depths whose peak stands less than this share above its lowest value
# cannot tell depth (a textureless region: every refocused image alike); a match below this normalised
# correlation is no match (here and in calibration.galvo: the one threshold of a trusted match)
MIN_FOCUS_CONTRAST = 0.05
MIN_MATCH_SCORE = 0.6


class TrackingWarning(UserWarning):
    """track_focus could not measure: the ROI has no texture to focus on or to follow."""


def _follow(template: np.ndarray, image: np.ndarray, roi, search: float = 1.0):
    """The ROI of the same size where ``template`` best matches ``image`` (normalised cross-correlation),
    searched within ``search`` ROI sizes of the old position."""
    x0, y0, x1, y1 = roi
    h, w = image.shape[:2]
    rw, rh = x1 - x0, y1 - y0
    sx0, sy0 = max(0, x0 - int(search * rw)), max(0, y0 - int(search * rh))
    sx1, sy1 = min(w, x1 + int(search * rw)), min(h, y1 + int(search * rh))
    window = image[sy0:sy1, sx0:sx1]
    if window.ndim == 3:
        window, template = window.mean(-1), template.mean(-1)
    if not np.std(template) > 1e-6 * (abs(float(np.mean(template))) + 1e-30):
        return roi                       # a flat template matches anywhere: stay where it was
    score = cv2.matchTemplate(window.astype(np.float32), template.astype(np.float32), cv2.TM_CCOEFF_NORMED)
    _, best, _, (bx, by) = cv2.minMaxLoc(score)
    if not best >= MIN_MATCH_SCORE:     # no match worth the name: stay where it was
        return roi
    return (sx0 + bx, sy0 + by, sx0 + bx + rw, sy0 + by + rh)


def _best_depth(lf, depths, roi, measure, motion):
    x0, y0, x1, y1 = roi
    stack = focal_stack(lf, depths, motion, on_motion="ignore")
    scores = np.array([focus_measure(s if s.ndim == 2 else s.mean(-1), measure)[y0:y1, x0:x1].mean()
                       for s in stack])
    k = int(np.argmax(scores))
    top, level = float(scores.max()), float(np.mean(stack[:, y0:y1, x0:x1]))
    # flat: no focus at all (rounding noise against the image's own scale) or a peak hardly above the rest
    flat = not top > 1e-9 * max(level * level, level, 1e-30) or (top - float(scores.min())) / top < MIN_FOCUS_CONTRAST
    return refine_peak(1.0 / depths, scores, k), flat


def _check_track(lightfields, depths, roi, measure, smooth):
    """track_focus's arguments: light fields (one or more), depths (at least two), an ROI inside the views,
    an image focus measure, smoothing in [0, 1)."""
    lightfields = list(lightfields) if np.iterable(lightfields) else lightfields
    if not isinstance(lightfields, list) or not lightfields:
        raise ConfigError(f"track_focus: lightfields = {lightfields!r}: expected one or more LightField")
    for lf in lightfields:
        check_lightfield(lf, "track_focus")
    depths = _depth_list(depths, "track_focus: depths")
    h, w = lightfields[0].shape
    if isinstance(roi, str) or not np.iterable(roi) or len(roi) != 4:
        raise ConfigError(f"track_focus: roi = {roi!r}: expected (x0, y0, x1, y1) pixels")
    roi = tuple(int(number(v, "track_focus: roi", 0, integer=True, strict=True)) for v in roi)
    if not (roi[0] < roi[2] <= w and roi[1] < roi[3] <= h):
        raise ConfigError(f"track_focus: roi = {roi}: need 0 <= x0 < x1 <= {w} and 0 <= y0 < y1 <= {h}")
    if measure not in IMAGE_MEASURES:
        raise ConfigError(f"track_focus: measure = {measure!r}; allowed: {', '.join(IMAGE_MEASURES)}")
    if not 0 <= finite(smooth, "track_focus: smooth") < 1:
        raise ConfigError(f"track_focus: smooth = {smooth!r}: allowed range is [0, 1)")
    return lightfields, depths, roi


def track_focus(lightfields, depths, roi, measure: str = "tenengrad", smooth: float = 0.0, follow: bool = False,
                compensate_motion: bool = True):
    """Refocus a sequence of light fields on the object inside ``roi`` = (x0, y0, x1, y1) pixels as it moves in
    depth: for each light field, the depth whose refocused ROI is sharpest (sub-step refined, optionally
    smoothed in inverse depth over time).

    ``follow``: the ROI moves with the object, found in each light field (refocused at the previous depth) by
    matching the previous refocused ROI. Then, with ``compensate_motion`` (used only with ``follow``: the
    velocity comes from the followed ROI), a second pass refocuses with the
    object's image velocity (from the ROI track) taken out of every view (``motion_shifts``): views spread
    over a scan period otherwise smear a fast object, and its motion biases the depth (it correlates with the
    scan's position over the period). Returns (depths chosen, refocused images, ROIs, image velocities px/s).
    """
    lightfields, depths, roi = _check_track(lightfields, depths, roi, measure, smooth)
    rois, inverse, images = [], [], []
    for lf in lightfields:                       # pass 1: where the object is, and its depth without motion
        if follow and images:
            x0, y0, x1, y1 = roi
            roi = _follow(images[-1][y0:y1, x0:x1], refocus(lf, 1.0 / inverse[-1], on_motion="ignore"), roi)
        rois.append(roi)
        inv, flat = _best_depth(lf, depths, roi, measure, None)
        inverse.append(inv)
        if flat:
            warnings.warn(f"track_focus: light field {len(rois) - 1}: the ROI {tuple(roi)} looks the same at every "
                          "depth (no texture to focus on): its depth is not measured", TrackingWarning, stacklevel=2)
        images.append(refocus(lf, 1.0 / inverse[-1], on_motion="ignore") if follow else None)
    velocities = np.zeros((len(lightfields), 2))
    if follow and compensate_motion and len(lightfields) > 1:
        centres = np.array([[(r[0] + r[2]) / 2, (r[1] + r[3]) / 2] for r in rois], dtype=np.float64)
        times = np.array([lf.times.mean() for lf in lightfields])
        # the first ROI is the user's box, not a match: fit the matched ones (whole-pixel positions, so a
        # smooth fit, at most quadratic, beats differences) and evaluate its derivative at every period
        first = 1 if len(lightfields) > 2 else 0
        degree = min(2, len(lightfields) - first - 1)
        for i in (0, 1):
            fit = np.polynomial.Polynomial.fit(times[first:], centres[first:, i], degree)
            velocities[:, i] = fit.deriv()(times) if degree > 0 else 0.0
        inverse = [_best_depth(lf, depths, r, measure, v)[0] for lf, r, v in zip(lightfields, rois, velocities)]
    chosen, out, prev = [], [], None
    for lf, inv, v in zip(lightfields, inverse, velocities):
        if prev is not None and smooth > 0:
            inv = (1 - smooth) * inv + smooth * prev
        prev = inv
        z = 1.0 / inv if inv > 0 else math.inf
        chosen.append(z)
        out.append(refocus(lf, z, motion=v if follow and compensate_motion else None))
    return np.array(chosen), np.stack(out), rois, velocities
