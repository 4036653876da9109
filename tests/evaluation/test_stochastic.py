"""Statistics for stochastic pixel models (issue 18, part 1): two seeds of one noisy model agree, a different
noise rate does not; scored on pure shot noise, whose distribution is known (Poisson: exponential intervals)."""
import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.errors import ConfigError
from mitsuba_eventfield.evaluation import stochastic

FRAMES = np.full((201, 24, 32), 0.5)          # a static grey scene: every event is shot noise
TIMES = np.linspace(0.0, 2.0, 201)


def _noise(rate_hz, seed):
    return ef.events_from_frames(FRAMES, TIMES, pixel={"shot_noise_hz": rate_hz, "seed": seed})


def test_two_seeds_agree_and_twice_the_noise_is_told_apart():
    a, b, double = _noise(5.0, 1), _noise(5.0, 2), _noise(10.0, 3)
    same, other = stochastic.compare(a, b), stochastic.compare(double, b)
    # 4802 noise events (768 pixels, 2 s): rates agree within Poisson noise (measured ratio 0.997, KS 0.031, p 0.04)
    assert abs(same["rate_ratio"] - 1) < 0.06 and abs(same["on_fraction_diff"]) < 0.03
    assert same["interval_ks"] < 0.05 and same["interval_ks_p"] > 0.01
    assert abs(other["rate_ratio"] - 2) < 0.15                       # measured 1.98 (KS 0.23)
    assert other["interval_ks"] > 0.2 and other["interval_ks_p"] < 1e-6
    # twice the Poisson rate halves the intervals (within a 2 s window the mean is T / (n + 1) for n events
    # per pixel; measured ratio 0.57)
    s, s2 = stochastic.statistics(a), stochastic.statistics(double)
    assert 0.4 < np.mean(s2["intervals"]) / np.mean(s["intervals"]) < 0.65
    assert s["rate_map"].shape == (24, 32)


def test_different_films_are_refused():
    a = _noise(5.0, 1)
    small = ef.events_from_frames(FRAMES[:, :12, :16], TIMES, pixel={"shot_noise_hz": 5.0})
    with pytest.raises(ConfigError, match="films differ"):
        stochastic.compare(a, small)
