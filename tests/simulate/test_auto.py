"""Automatic modelling choices, each checked against the full computation."""
import os

from conftest import ROOT, TEST_VARIANT

import mitsuba_eventfield as ef

FAN = os.path.join(ROOT, "scenes", "fan", "fan.xml")
SMALL = {"width": 48, "height": 36}


def test_plan_choices_hold_against_the_full_computation(capsys):
    plan = ef.auto.plan(FAN, 0.004, defines=SMALL)
    with capsys.disabled():
        print("\n[auto plan, fan]\n" + plan.report())
    # colour: the fan scene is grey -> mono; the rgb render gives the same events
    assert plan.color is False
    ef.set_variant(color=True)
    rgb = ef.render_events(ef.load_scene(FAN, **SMALL), 0.004, steps=16, spp=4)
    ef.set_variant(TEST_VARIANT)
    mono = ef.render_events(ef.load_scene(FAN, **SMALL), 0.004, steps=16, spp=4)
    assert len(mono) > 100 and rgb.equals(mono)
    # spp: the chosen count meets the noise target on fresh seeds; half of it would not (unless at 1)
    timed = ef.load_scene(FAN, **SMALL)
    target = 0.5 * 0.2
    assert ef.auto.noise_std(timed, plan.spp, seeds=(10, 11, 12, 13)) <= target * 1.15
    if plan.spp > 1:
        assert ef.auto.noise_std(timed, plan.spp // 2, seeds=(10, 11, 12, 13)) > target * 0.85
    # steps: events with the chosen steps agree with 4x finer steps (the full computation)
    chosen = ef.render_events(timed, 0.004, steps=plan.steps, spp=plan.spp)
    finer = ef.render_events(timed, 0.004, steps=4 * plan.steps, spp=plan.spp)
    assert abs(len(chosen) - len(finer)) / len(finer) < 0.05
    assert plan.static is False


GALVO_STATIC = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")   # 250 Hz scan: 4 ms period


def test_auto_steps_of_a_moving_scene_are_whole_per_scan_period():
    """``--auto`` takes the default rule's steps, whole per scan period under a periodic scan, for a moving
    scene too (the fan, five 4 ms periods: 302 steps before, 60.4 a period) and never fewer than the motion
    needs (0.5 px a step)."""
    from mitsuba_eventfield.simulate.pixel_setup import event_integrator
    from mitsuba_eventfield.simulate.stepping import uniform_default_steps
    timed = ef.load_scene(FAN, width=96, height=72)
    assert not timed.is_static and timed.scan_period == 0.004
    steps, why = uniform_default_steps(timed, 0.02, 4, event_integrator(timed, None, None, None, None, None, None))
    assert steps % 5 == 0, steps
    assert steps * 0.5 >= why["largest_image_speed_px_per_s"] * 0.02 > (steps - 5) * 0.5


def test_static_scene_plan_rounds_steps_so_periods_are_reused():
    plan = ef.auto.plan(GALVO_STATIC, 0.012, defines=SMALL)
    assert plan.static and "reused" in plan.reasons["reuse"] and plan.steps % 3 == 0
    ev = ef.render_events(ef.load_scene(GALVO_STATIC, **SMALL), 0.012, steps=plan.steps, spp=plan.spp)
    r = ev.meta["render"]           # periods 2 and 3: frames from the cache, or whole events copied once state repeats
    assert r["reused_steps"] + r["copied_steps"] >= 2 * plan.steps // 3
    odd = ef.auto.plan(GALVO_STATIC, 0.005, defines=SMALL)             # 1.25 periods: nothing to reuse
    assert odd.static and "every step is rendered" in odd.reasons["reuse"]


def test_the_plan_takes_the_render_pixel_models_floors():
    """--auto --preset davis346 --pixel cutoff_hz=3000: the low-pass pixel needs steps no longer than two of its
    time constants (1885 over 0.2 s), whatever the image motion; the plan used the scene's own (ideal) pixel and
    chose 81."""
    plan = ef.auto.plan(os.path.join(ROOT, "scenes", "demo", "demo.xml"), 0.2, defines={"width": 36, "height": 24},
                        preset="davis346", pixel={"cutoff_hz": 3000.0})
    assert plan.steps >= 0.2 * 3.14159 * 3000 and "low-pass pixel" in plan.reasons["steps"], plan.reasons["steps"]
