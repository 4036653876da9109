"""Depth from focus on light fields: focus measures over a focal stack, sub-step peak refinement, confidence.

Measures (``focus_measure``): ``sml`` (sum-modified-Laplacian), ``tenengrad`` (Sobel gradient energy), both
summed over a window; and ``variance`` (angular consistency: the spread of the aligned views at a pixel is
smallest at the right depth), which uses the views themselves rather than the refocused image. ``variance``
is the most robust on views reconstructed from events but resamples every view per plane (Lanczos): about
8x the cost of the others. (Summing shifted squared views in the Fourier domain instead was 4x faster but
10x less accurate: squaring doubles the bandwidth and the shift aliases.)

Confidence in [0, 1] is c / (c + c0) with c = peak - median of a pixel's focus curve and c0 = 5% of the
90th percentile of c over the image: a textureless pixel has a flat curve and gets ~0 instead of a confident
wrong depth.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .lightfield import LightField
from .refocus import depth_planes, refocus, shifted_views

MEASURES = ("sml", "tenengrad", "variance")


def focus_measure(img: np.ndarray, measure: str = "sml", window: int = 7) -> np.ndarray:
    """Per-pixel focus of one image (H, W), aggregated over a ``window`` x ``window`` box."""
    img = np.asarray(img, dtype=np.float32)
    if measure == "sml":
        kx = np.array([[0, 0, 0], [-1, 2, -1], [0, 0, 0]], np.float32)
        m = np.abs(cv2.filter2D(img, -1, kx)) + np.abs(cv2.filter2D(img, -1, kx.T))
    elif measure == "tenengrad":
        gx, gy = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3)
        m = gx * gx + gy * gy
    else:
        raise ValueError(f"unknown focus measure {measure!r}; allowed: {', '.join(MEASURES)}")
    return cv2.boxFilter(m, -1, (window, window), normalize=True, borderType=cv2.BORDER_REFLECT)


def refine_peak(x, scores, k):
    """Parabola through the peak and its neighbours: sub-step position of the maximum (in x units)."""
    if k <= 0 or k >= len(scores) - 1:
        return x[k]
    f0, f1, f2 = scores[k - 1], scores[k], scores[k + 1]
    den = f0 - 2 * f1 + f2
    off = 0.0 if den >= 0 else np.clip(0.5 * (f0 - f2) / den, -0.5, 0.5)
    step = x[k + 1] - x[k] if off > 0 else x[k] - x[k - 1]
    return x[k] + off * step


@dataclass
class DepthMap:
    depth: np.ndarray          # (H, W) scene units
    confidence: np.ndarray     # (H, W) in [0, 1]
    planes: np.ndarray         # depths searched
    measure: str


def _volume(lf: LightField, planes, measure, window):
    vol = []
    for z in planes:
        if measure == "variance":
            s1 = s2 = cov = None
            for v, c in shifted_views(lf, float(z)):
                g = v if v.ndim == 2 else v.mean(-1)
                g = np.log(np.maximum(g, 1e-6)) * c          # log: variance independent of brightness
                s1 = g if s1 is None else s1 + g
                s2 = g * g if s2 is None else s2 + g * g
                cov = c if cov is None else cov + c
            cov = np.maximum(cov, 1)
            var = np.maximum(s2 / cov - (s1 / cov) ** 2, 0)
            var = cv2.boxFilter(var.astype(np.float32), -1, (window, window), borderType=cv2.BORDER_REFLECT)
            vol.append(-var)                                    # focus = agreement = low variance
        else:
            img = refocus(lf, float(z))
            vol.append(focus_measure(img if img.ndim == 2 else img.mean(-1), measure, window))
    return np.stack(vol)


def depth_from_focus(lf: LightField, near: float, far: float, planes: int = 32, measure: str = "sml",
                     window: int = 7) -> DepthMap:
    """Per-pixel depth: the plane whose refocused image is sharpest, refined between planes."""
    if measure not in MEASURES:
        raise ValueError(f"unknown focus measure {measure!r}; allowed: {', '.join(MEASURES)}")
    zs = depth_planes(near, far, planes)
    inv = 1.0 / zs
    vol = _volume(lf, zs, measure, window)                     # (D, H, W)
    k = np.argmax(vol, axis=0)
    h, w = k.shape
    kk = np.clip(k, 1, len(zs) - 2)
    rows, cols = np.mgrid[0:h, 0:w]
    f0, f1, f2 = vol[kk - 1, rows, cols], vol[kk, rows, cols], vol[kk + 1, rows, cols]
    den = f0 - 2 * f1 + f2
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.where(den < 0, np.clip(0.5 * (f0 - f2) / den, -0.5, 0.5), 0.0)
    off = np.where((k == kk), off, 0.0)                        # no refinement at the ends of the range
    step = inv[1] - inv[0]                                     # uniform in inverse depth
    inv_depth = inv[k] + off * step
    depth = 1.0 / np.maximum(inv_depth, 1e-12)
    # confidence: how far the peak stands above the curve's median, against a floor set by the image's
    # well-textured pixels, so a flat (textureless) curve gets ~0 whatever its noise does
    contrast = vol.max(axis=0) - np.median(vol, axis=0)
    floor = 0.05 * float(np.percentile(contrast, 90)) + 1e-12
    conf = contrast / (contrast + floor)
    return DepthMap(depth, np.clip(np.nan_to_num(conf), 0, 1), zs, measure)
