"""SSIM (evaluation/quality.py): OpenCV contrib's, and the same computation with core OpenCV where the contrib
modules are missing (the project's GPU image has opencv-python-headless only), equal to the bit; and the
score's known values (identical images 1, a constant offset's exact value)."""
import cv2
import numpy as np
import pytest

from mitsuba_eventfield.evaluation import quality


def _pair(shape, seed=0):
    rng = np.random.default_rng(seed)
    a = (rng.random(shape) * 255).astype(np.uint8)
    return a, cv2.GaussianBlur(a, (5, 5), 1.0)


@pytest.mark.parametrize("shape", [(60, 80), (48, 64, 3)])
def test_core_opencv_ssim_equals_contribs_to_the_bit(shape, monkeypatch):
    if not hasattr(cv2, "quality"):
        pytest.skip("OpenCV's contrib modules are not installed: nothing to compare the core computation with")
    a, b = _pair(shape)
    contrib = quality.ssim_map(a, b)
    score = cv2.quality.QualitySSIM_compute(a, b)[0]
    monkeypatch.delattr(cv2, "quality")
    core = quality.ssim_map(a, b)
    assert core.dtype == np.float32 and core.shape == shape and np.array_equal(core, contrib)
    channels = 1 if len(shape) == 2 else shape[-1]
    assert quality.ssim(a.astype(float), b.astype(float), white=255.0) == pytest.approx(
        np.mean(score[:channels]), abs=1e-7)


def test_ssim_known_values_without_contrib(monkeypatch):
    monkeypatch.delattr(cv2, "quality", raising=False)
    a, b = _pair((40, 50), seed=1)
    assert quality.ssim(a.astype(float), a.astype(float), white=255.0) == pytest.approx(1.0, abs=1e-6)
    # a constant offset d leaves every variance and covariance alone: SSIM is the luminance term alone,
    # (2 mu (mu + d) + C1) / (mu^2 + (mu + d)^2 + C1), on a flat image mu everywhere
    # (dark codes, where C1 weighs: without it the value would be 0.8; float32 blurs of a constant leave
    # variances of ~1e-6, against C2 = 58.5)
    flat, d = np.full((40, 50), 5, np.uint8), 5
    expected = (2 * 5 * 10 + 6.5025) / (5 ** 2 + 10 ** 2 + 6.5025)
    assert float(quality.ssim_map(flat, flat + d).mean()) == pytest.approx(expected, rel=1e-5)
    assert 0.2 < quality.ssim(b.astype(float), a.astype(float), white=255.0) < 0.9
