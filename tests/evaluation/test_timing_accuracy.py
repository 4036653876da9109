"""What limits timing accuracy, measured against the analytic scene's exact events (evaluation/analytic.py):
with a noise-free sampler the error falls as the square of the step; with Monte-Carlo noise it stops falling at
a floor that only more samples lower. The same measurements as benchmarks/bench_accuracy.py, at two step counts."""
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.evaluation import analytic as an

C, DURATION = 0.1, 0.01
SPEED = 0.5 * an.PIX / (DURATION / 100)


def _render(sampler, steps):
    import mitsuba as mi
    timed = ef.load_scene(mi.load_dict(an.scene_dict(mi, SPEED, sampler)),
                          motion={"objects": {"plane": {"velocity": [SPEED, 0.0, 0.0]}}})
    return ef.render_events(timed, DURATION, steps=steps, threshold=C, spp=sampler["sample_count"])


def _median_error_us(sampler, steps):
    return an.score(_render(sampler, steps), an.truth_events(SPEED, DURATION, C))["timing_median_us"]


def test_noise_free_sampler_is_limited_by_the_steps():
    sampler = {"type": "stratified", "sample_count": 16, "jitter": False}
    coarse, fine = _median_error_us(sampler, 80), _median_error_us(sampler, 320)
    assert fine < 1.0 and coarse / fine > 4          # measured 1.22 and 0.215 us: 5.7x for 4x the steps


@pytest.mark.parametrize("spp", [4, 16])
def test_monte_carlo_noise_sets_a_floor_that_steps_do_not_lower(spp):
    sampler = {"type": "independent", "sample_count": spp}
    coarse, fine = _median_error_us(sampler, 80), _median_error_us(sampler, 320)
    assert fine > 5.0 and coarse / fine < 1.5        # measured 11.3 -> 10.9 us (4 spp), 8.5 -> 8.0 us (16 spp)


@pytest.mark.parametrize("sampler, steps, limit", [
    ({"type": "stratified", "sample_count": 16, "jitter": False}, 80, "steps"),
    ({"type": "independent", "sample_count": 4}, 20, "steps"),
    ({"type": "independent", "sample_count": 4}, 80, "Monte-Carlo noise"),
], ids=["noise-free-80", "4spp-20", "4spp-80"])
def test_the_summary_names_the_limit(sampler, steps, limit):
    """The render's own estimate (simulate/accuracy_limit.py, from its first frames) names what the exact
    events show, and its size is within 3x of the measured median error."""
    ev = _render(sampler, steps)
    est = ev.meta["render"]["timing_limit"]
    measured = an.score(ev, an.truth_events(SPEED, DURATION, C))["timing_median_us"]
    assert est["limit"] == limit
    assert any(f"limited by {'the time step' if limit == 'steps' else limit}" in n for n in ev.meta["render"]["notes"])
    size = est["steps_us"] if limit == "steps" else est["noise_us"]
    assert measured / 3 < size < 3 * measured
