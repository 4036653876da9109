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


def test_scores_against_their_definitions():
    """``fit_gain``: the factor that takes the estimate to the truth (an estimate at twice the truth: 0.5, whatever
    the pixels that are not positive); ``psnr``: 10 log10(1 / mse) of images scaled by the white level (a
    uniform error of 1/255 of white: 48.13 dB); ``ssim``: codes rounded (an estimate less than half a code
    from the truth at every pixel is the same 8-bit image: 1.0, where truncating moved every pixel a code)."""
    from mitsuba_eventfield.evaluation.quality import fit_gain, psnr, ssim
    rng = np.random.default_rng(5)
    truth = rng.uniform(0.1, 1.0, (32, 32))
    estimate = 2.0 * truth
    estimate[0, :4] = 0.0                                       # not positive: left out of the fit
    assert fit_gain(estimate, truth) == pytest.approx(0.5, rel=1e-12)
    white = 1.0
    assert psnr(np.clip(truth + 1 / 255, 0, None), truth, white) == pytest.approx(20 * np.log10(255), abs=0.05)
    codes = np.rint(truth * 255) / 255                          # exactly on the codes
    assert ssim(codes * (1 - 0.3 / 255), codes, white) == 1.0
