"""Image quality against a ground truth: PSNR and SSIM on one documented scale.

Both images are divided by a white level (default: the truth's 99.9th percentile, so a few specular or LED
pixels do not set the scale) and clipped to [0, 1]; PSNR is then 10 log10(1 / MSE) and SSIM is OpenCV's
(Wang et al. 2004, Gaussian 11x11 window, on 8-bit codes), averaged over channels.
"""
from __future__ import annotations

import numpy as np


def fit_gain(estimate: np.ndarray, truth: np.ndarray) -> float:
    """The one factor that best brings ``estimate`` to ``truth`` (median of their log ratio over pixels
    where both are positive): for scoring reconstructions from events, which fix log brightness only up to
    one constant (an event camera records changes, not levels). Fitted once per capture, never per image, so
    it cannot hide errors of shape; the method itself never sees it."""
    e, t = np.asarray(estimate, np.float64), np.asarray(truth, np.float64)
    ok = (e > 0) & (t > 0)
    if not ok.any():
        raise ValueError("no pixel is positive in both images: no gain to fit")
    return float(np.exp(np.median(np.log(t[ok]) - np.log(e[ok]))))


def gain_aligned(estimate, reference) -> np.ndarray:
    """``estimate`` times :func:`fit_gain` to ``reference`` (as it is where no pixel is positive in both)."""
    est = np.asarray(estimate, np.float64)
    try:
        return est * fit_gain(est, reference)
    except ValueError:
        return est


def white_level(truth: np.ndarray) -> float:
    level = float(np.percentile(np.asarray(truth, np.float64), 99.9))
    if not level > 0:
        raise ValueError("the ground truth is black: no white level to score against")
    return level


def _unit(img, white):
    return np.clip(np.asarray(img, np.float64) / white, 0.0, 1.0)


def psnr(estimate: np.ndarray, truth: np.ndarray, white: float | None = None) -> float:
    """dB; inf for identical images."""
    if np.shape(estimate) != np.shape(truth):
        raise ValueError(f"shapes differ: estimate {np.shape(estimate)}, truth {np.shape(truth)}")
    white = white_level(truth) if white is None else white
    mse = float(np.mean((_unit(estimate, white) - _unit(truth, white)) ** 2))
    return float("inf") if mse == 0 else float(10 * np.log10(1.0 / mse))


# OpenCV's SSIM constants for 8-bit codes: (0.01 * 255)^2 and (0.03 * 255)^2
_SSIM_C1, _SSIM_C2 = 6.5025, 58.5225


def ssim_map(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The per-pixel SSIM of two 8-bit images (float32, the images' shape): OpenCV contrib's
    ``cv2.quality.QualitySSIM_compute``. Where the contrib modules are missing (``opencv-python-headless``
    installed beside or instead of the contrib build, as on the project's GPU image), the same computation
    with core OpenCV's Gaussian blur, in the same float32 order: equal to contrib's to the bit
    (tests/evaluation/test_quality.py)."""
    import cv2
    if hasattr(cv2, "quality"):
        return np.asarray(cv2.quality.QualitySSIM_compute(a, b)[1], np.float32).reshape(np.shape(a))
    i1, i2 = np.asarray(a, np.float32), np.asarray(b, np.float32)

    def blur(x):
        return cv2.GaussianBlur(x, (11, 11), 1.5)
    mu1, mu2 = blur(i1), blur(i2)
    s1, s2, s12 = blur(i1 * i1) - mu1 * mu1, blur(i2 * i2) - mu2 * mu2, blur(i1 * i2) - mu1 * mu2
    return ((2 * mu1 * mu2 + _SSIM_C1) * (2 * s12 + _SSIM_C2)
            / ((mu1 * mu1 + mu2 * mu2 + _SSIM_C1) * (s1 + s2 + _SSIM_C2)))


def ssim(estimate: np.ndarray, truth: np.ndarray, white: float | None = None) -> float:
    if np.shape(estimate) != np.shape(truth):
        raise ValueError(f"shapes differ: estimate {np.shape(estimate)}, truth {np.shape(truth)}")
    white = white_level(truth) if white is None else white
    a = np.rint(_unit(estimate, white) * 255).astype(np.uint8)
    b = np.rint(_unit(truth, white) * 255).astype(np.uint8)
    # the mean over each channel's map, then over channels (every channel has as many pixels)
    return float(np.mean(ssim_map(a, b), dtype=np.float64))


def scores(estimate: np.ndarray, truth: np.ndarray, white: float | None = None) -> dict:
    white = white_level(truth) if white is None else white
    return {"psnr_db": psnr(estimate, truth, white), "ssim": ssim(estimate, truth, white)}
