"""Post-capture refocus by shift-and-add, focal stacks, and focus tracking over time.

Refocusing at depth z shifts every view back by its disparity at z (``LightField.shifts``) and averages in
linear intensity, which is what a lens with the synthetic aperture would integrate. Shifts are exact
(Fourier phase ramps on reflect-padded views), so no resampling blur biases focus measures.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from .lightfield import LightField


def _shift(img, dx, dy):
    """img sampled at (x + dx, y + dy) with Lanczos interpolation (little blur), zero outside."""
    m = np.float32([[1, 0, dx], [0, 1, dy]])
    return cv2.warpAffine(img, m, (img.shape[1], img.shape[0]), flags=cv2.INTER_LANCZOS4 | cv2.WARP_INVERSE_MAP,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def _coverage(h, w, dx, dy):
    """Where the shifted view has data: x + dx in [0, w-1] and y + dy in [0, h-1]."""
    xs, ys = np.arange(w) + dx, np.arange(h) + dy
    return np.outer((ys >= 0) & (ys <= h - 1), (xs >= 0) & (xs <= w - 1)).astype(np.float32)


def shifted_views(lf: LightField, depth):
    """Generator of (aligned view, coverage) for every view, aligned for a point at ``depth``."""
    h, w = lf.shape
    for view, (dx, dy) in zip(lf.views, lf.shifts(depth)):
        v = view.astype(np.float32)
        yield _shift(v, dx, dy), _coverage(h, w, dx, dy)


class _Spectra:
    """Fourier transforms of a light field's (padded) views, computed once per light field.

    Shift-and-add in the Fourier domain is exact for band-limited views: a sub-pixel shift is a phase ramp,
    with none of the blur of bilinear resampling. (Bilinear blur is worst at half-pixel shifts, so it pulls
    focus measures towards depths where every shift is a whole pixel; measured: 7% depth bias.) The sum of
    shifted views is one inverse FFT per depth.
    """

    def __init__(self, lf: LightField, pad: int):
        self.pad = pad
        v = lf.views if lf.views.ndim == 4 else lf.views[..., None]
        padded = np.pad(v, ((0, 0), (pad, pad), (pad, pad), (0, 0)), mode="reflect")
        self.hp, self.wp = padded.shape[1:3]
        self.spec = np.fft.rfft2(padded, axes=(1, 2)).astype(np.complex64)   # (K, Hp, Wp//2+1, C)
        self.ky = np.fft.fftfreq(self.hp)[:, None]
        self.kx = np.fft.rfftfreq(self.wp)[None, :]
        self.channels = lf.views.ndim == 4

    def shifted_sum(self, shifts) -> np.ndarray:
        # the phase ramp is separable: exp(2 pi i (ky dy + kx dx)) = col(ky) row(kx), so no per-pixel exp
        col = np.exp(2j * np.pi * self.ky[:, 0][None, :] * shifts[:, 1, None]).astype(np.complex64)  # (K, Hp)
        row = np.exp(2j * np.pi * self.kx[0][None, :] * shifts[:, 0, None]).astype(np.complex64)     # (K, Wp')
        total = np.zeros(self.spec.shape[1:], np.complex64)
        for k in range(len(shifts)):       # measured fastest: ~8x an einsum over (K, H, W) here
            total += np.outer(col[k], row[k])[..., None] * self.spec[k]
        img = np.fft.irfft2(total, s=(self.hp, self.wp), axes=(0, 1))
        p = self.pad
        img = img[p:self.hp - p, p:self.wp - p]
        return img if self.channels else img[..., 0]


def _spectra(lf: LightField, max_shift: float) -> _Spectra:
    pad = int(np.ceil(max_shift)) + 4
    cached = lf.cache.get("spectra")
    if cached is None or cached.pad < pad:
        cached = _Spectra(lf, max(pad, 16))
        lf.cache["spectra"] = cached
    return cached


def refocus(lf: LightField, depth: float | None = None, alpha=None) -> np.ndarray:
    """The light field refocused at ``depth`` (scene units; math.inf allowed) or at the disparity slope
    ``alpha`` (pixels per unit of view position, see ``LightField``): (H, W[, C]) linear intensity."""
    if alpha is None and not (depth is not None and depth > 0):
        raise ValueError(f"depth = {depth!r}: must be > 0 (math.inf for infinity), or give alpha")
    shifts = lf.shifts(depth, alpha)
    spectra = _spectra(lf, np.abs(shifts).max())
    return np.maximum(spectra.shifted_sum(shifts) / len(lf.views), 0.0)


def depth_planes(near: float, far: float, count: int) -> np.ndarray:
    """``count`` depths from near to far, uniform in inverse depth (uniform in disparity)."""
    if not (0 < near < far) or count < 2:
        raise ValueError(f"depth planes: need 0 < near ({near}) < far ({far}) and count ({count}) >= 2")
    return 1.0 / np.linspace(1.0 / near, 1.0 / far, count)


def focal_stack(lf: LightField, depths) -> np.ndarray:
    """(D, H, W[, C]) refocused images, one per depth."""
    return np.stack([refocus(lf, float(z)) for z in depths])


def track_focus(lightfields, depths, roi, measure: str = "tenengrad", smooth: float = 0.0):
    """Refocus a sequence of light fields on the object inside ``roi`` = (x0, y0, x1, y1) as it moves in
    depth: for each light field, the depth whose refocused ROI is sharpest (sub-step refined, optionally
    smoothed in inverse depth over time). Returns (depths chosen, refocused images)."""
    from .depth import focus_measure, refine_peak
    x0, y0, x1, y1 = roi
    chosen, images, prev = [], [], None
    depths = np.asarray(depths, dtype=np.float64)
    for lf in lightfields:
        stack = focal_stack(lf, depths)
        scores = np.array([focus_measure(s if s.ndim == 2 else s.mean(-1), measure)[y0:y1, x0:x1].mean()
                           for s in stack])
        k = int(np.argmax(scores))
        inv = refine_peak(1.0 / depths, scores, k)
        if prev is not None and smooth > 0:
            inv = (1 - smooth) * inv + smooth * prev
        prev = inv
        z = 1.0 / inv if inv > 0 else math.inf
        chosen.append(z)
        images.append(refocus(lf, z))
    return np.array(chosen), np.stack(images)
