"""What limits timing accuracy, measured against the analytic scene's exact events (evaluation/analytic.py):
with a noise-free sampler the error falls as the square of the step; with Monte-Carlo noise it stops falling at
a floor that only more samples lower. The same measurements as benchmarks/bench_accuracy.py, at two step counts."""
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.evaluation import analytic as an

C, DURATION = 0.1, 0.01
SPEED = 0.5 * an.PIX / (DURATION / 100)


def _median_error_us(sampler, steps):
    import mitsuba as mi
    timed = ef.load_scene(mi.load_dict(an.scene_dict(mi, SPEED, sampler)),
                          motion={"objects": {"plane": {"velocity": [SPEED, 0.0, 0.0]}}})
    ev = ef.render_events(timed, DURATION, steps=steps, threshold=C, spp=sampler["sample_count"])
    return an.score(ev, an.truth_events(SPEED, DURATION, C))["timing_median_us"]


def test_noise_free_sampler_is_limited_by_the_steps():
    sampler = {"type": "stratified", "sample_count": 16, "jitter": False}
    coarse, fine = _median_error_us(sampler, 80), _median_error_us(sampler, 320)
    assert fine < 1.0 and coarse / fine > 4          # measured 1.22 and 0.215 us: 5.7x for 4x the steps


@pytest.mark.parametrize("spp", [4, 16])
def test_monte_carlo_noise_sets_a_floor_that_steps_do_not_lower(spp):
    sampler = {"type": "independent", "sample_count": spp}
    coarse, fine = _median_error_us(sampler, 80), _median_error_us(sampler, 320)
    assert fine > 5.0 and coarse / fine < 1.5        # measured 11.3 -> 10.9 us (4 spp), 8.5 -> 8.0 us (16 spp)
