"""The accuracy-limit estimate's step term (``simulate/accuracy_limit.py``) for steps of unequal length: the second
divided difference of three frames, checked on log brightness that is exactly quadratic in time (where
linear interpolation's error bound dt^2 |L''| / (8 |L'|) is known in closed form)."""
import numpy as np
import pytest

from mitsuba_eventfield.simulate.accuracy_limit import AccuracyLimit


def _estimate(d1, d2, a=40.0, b=3.0, sigma=1e-3):
    """Frames of L(t) = a t^2 + b t + L0 (every pixel a different L0) at 0, d1, d1 + d2."""
    limit = AccuracyLimit((d1, d2), spp=4)
    l0 = np.linspace(-1.0, 1.0, 64).reshape(8, 8)
    limit.frames = [l0 + a * t * t + b * t for t in (0.0, d1, d1 + d2)]
    limit.sigma = np.full_like(l0, sigma)
    return limit.estimate()


@pytest.mark.parametrize("d1, d2", [(1e-3, 1e-3), (1e-3, 3e-3), (4e-3, 1e-3)])
def test_step_term_uses_the_second_divided_difference(d1, d2):
    est = _estimate(d1, d2)
    rate = 3.0 + 40.0 * d1                  # the first step's mean slope
    dt = (d1 + d2) / 2
    assert est["steps_us"] == pytest.approx(dt ** 2 * 80.0 / (8 * rate) * 1e6, rel=1e-6)
    assert est["noise_us"] == pytest.approx(1e-3 / rate * 1e6, rel=1e-6)


def test_equal_steps_reduce_to_the_uniform_formula():
    """Uniform steps: (l2 - 2 l1 + l0) / dt^2, the formula before placed steps."""
    dt = 2e-3
    est = _estimate(dt, dt)
    l0, l1, l2 = (40.0 * t * t + 3.0 * t for t in (0.0, dt, 2 * dt))
    rate = (l1 - l0) / dt
    assert est["steps_us"] == pytest.approx(dt ** 2 * ((l2 - 2 * l1 + l0) / dt ** 2) / (8 * rate) * 1e6, rel=1e-9)
    assert est["limit"] == ("steps" if est["steps_us"] > est["noise_us"] else "Monte-Carlo noise")
