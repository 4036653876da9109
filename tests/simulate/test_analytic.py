"""The event integrator against the exact events of an analytic scene (evaluation/analytic.py)."""
import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.evaluation import analytic as an

C = 0.1
DURATION, STEPS = 0.01, 100
DT = DURATION / STEPS
SPEED = 0.5 * an.PIX / DT          # half a pixel per step


def _scene(mi):
    return ef.load_scene(mi.load_dict(an.scene_dict(mi, SPEED)),
                         motion={"objects": {"plane": {"velocity": [SPEED, 0.0, 0.0]}}})


def _truth():
    times = np.linspace(0, DURATION, STEPS * 200 + 1)
    return an.ideal_events(np.log(an.exact_intensity(times, SPEED)), times, C)


def test_rendered_frame_matches_analytic_radiance():
    import mitsuba as mi
    timed = _scene(mi)
    image = np.array(mi.render(timed.scene))[..., 0]
    expected = an.exact_intensity([0.0], SPEED)[0]
    assert np.max(np.abs(image - expected[None, :]) / expected[None, :]) < 2e-3


@pytest.mark.parametrize("adaptive", [False, "log-change", "motion"], ids=["uniform", "log-change", "motion"])
def test_events_match_exact_crossings(adaptive, capsys):
    import mitsuba as mi
    kwargs = {False: dict(steps=STEPS), "log-change": dict(adaptive="log-change", max_log_change=0.5, max_step=DT),
              "motion": dict(adaptive="motion", px_per_step=0.5)}[adaptive]
    ev = ef.render_events(_scene(mi), DURATION, threshold=C, **kwargs)
    truth = _truth()
    scored = an.score(ev, truth)
    count_diff, pol_ok, n_true = scored["count_diff"], scored["polarity_ok"], scored["exact_events"]
    med, p99 = scored["timing_median_us"] * 1e-6 / DT, scored["timing_p99_us"] * 1e-6 / DT
    with capsys.disabled():
        print(f"\n[analytic {adaptive or 'uniform'}] {len(ev)} events (exact {n_true}); "
              f"steps {ev.meta['render']['steps']}; max |count diff| {np.abs(count_diff).max()}; "
              f"timestamp error median {med:.4f} step, p99 {p99:.4f} step (step = {DT * 1e6:.0f} us)")
    assert n_true > 5000
    assert np.abs(count_diff).max() <= 1          # within one event per pixel
    assert pol_ok
    assert med < 0.02 and p99 < 0.1               # far below one step
    assert ev.is_sorted


def test_adaptive_step_count_follows_log_slope():
    """Steps are sized by the largest log slope: at least slope*T/(2 f C) (no step exceeds 2 f C, else it is
    re-rendered) and not many more than the controller's target slope*T/(0.9 f C)."""
    import mitsuba as mi
    f = 0.25
    ev = ef.render_events(_scene(mi), DURATION, threshold=C, adaptive="log-change", max_log_change=f)
    bs = an.B * np.sin(np.pi * an.PIX / an.LAM) / (np.pi * an.PIX / an.LAM)
    max_slope = bs / np.sqrt(an.A ** 2 - bs ** 2) * 2 * np.pi * SPEED / an.LAM   # d log I / dt, 1/s
    total = max_slope * DURATION
    steps = ev.meta["render"]["steps"]
    assert total / (2 * f * C) <= steps <= 1.3 * total / (0.9 * f * C)
