"""Two per-pixel laws of the pixel model, against their closed forms: a sensor's ON and OFF thresholds are each
drawn about their own nominal value (mismatch ~ N(C, sigma)), and the photoreceptor's low-pass cutoff of a dim
pixel never falls below ``cutoff_min_fraction`` of the bright cutoff (a dark pixel still follows its light)."""
import math

import drjit as dr
import numpy as np
import pytest

import mitsuba_eventfield  # noqa: F401  (configures Dr.Jit)
from mitsuba_eventfield.plugins import pixel_model as pm


def test_on_and_off_thresholds_are_drawn_about_their_own_nominal_values():
    """Asymmetric thresholds, ON 0.2 and OFF 0.3 with a 0.02 mismatch, over 100,000 pixels (the mean's standard
    error 6e-5). Measured: ON mean 0.2000, std 0.0200; OFF mean 0.3000, std 0.0200."""
    pm._sensor_draws.cache_clear()
    cfg = pm.PixelConfig(threshold_on=0.2, threshold_off=0.3, threshold_sigma=0.02)
    c = pm.sensor_constants(cfg, 100_000)
    on, off = c["c_on"].astype(np.float64), c["c_off"].astype(np.float64)
    print(f"ON {on.mean():.4f} +- {on.std():.4f}, OFF {off.mean():.4f} +- {off.std():.4f}")
    assert on.mean() == pytest.approx(0.2, abs=1e-3) and on.std() == pytest.approx(0.02, abs=1e-3)
    assert off.mean() == pytest.approx(0.3, abs=1e-3) and off.std() == pytest.approx(0.02, abs=1e-3)
    assert abs(np.corrcoef(on, off)[0, 1]) < 0.02                       # independent draws per pixel


def test_the_lowpass_cutoff_of_dim_pixels_has_a_floor():
    """Cutoff 300 Hz at the bright intensity 1, floor 1 % of it: a pixel at 1e-3 of bright and a black pixel
    both filter at 3 Hz, alpha = 1 - exp(-2 pi 3 Hz 1 ms) = 0.018673 over a 1 ms step (measured equal to 1e-7).
    Without the floor they would be 0.3 Hz (0.0019) and 0 (a black pixel that never follows a light turned
    on)."""
    from mitsuba import Float
    alpha = pm.lowpass_alpha(dr, Float([1e-3, 0.0]), 1e-3, 300.0, 1.0, 0.01).numpy()
    want = 1 - math.exp(-2 * math.pi * 3.0 * 1e-3)
    print(f"alpha {alpha}, closed form {want:.6f}")
    assert want == pytest.approx(0.018673, abs=1e-6)
    assert alpha == pytest.approx([want, want], rel=1e-5)


def test_the_lowpass_cutoff_stops_rising_at_the_bright_intensity():
    """``pixel_model.lowpass_cutoff``: proportional to the intensity up to ``bright_intensity``, then flat: a pixel
    ten times brighter than bright blends as one at bright (1 - exp(-2 pi 300 1e-3) = 0.84823)."""
    import math

    import drjit as dr
    import mitsuba as mi
    import numpy as np

    from mitsuba_eventfield.plugins import pixel_model as pm
    alpha = pm.lowpass_alpha(dr, mi.Float([10.0, 1.0]), 1e-3, 300.0, 1.0, 0.01).numpy()
    assert np.allclose(alpha, 1 - math.exp(-2 * math.pi * 0.3), rtol=1e-6)
    assert pm.lowpass_cutoff(np, np.array([0.0, 0.5, 4.0]), 300.0, 2.0, 0.01).tolist() == [3.0, 75.0, 300.0]
