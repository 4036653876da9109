"""Adaptive stepping by image motion (issue 18, part 3): steps placed before rendering where the known motion
(galvo scan, moving objects) happens; checked against the scan geometry computed independently, the analytic
scene, and the per-pixel log-change stepping it replaces on galvo scenes."""
import math
import os

import numpy as np
import pytest
from conftest import ROOT
from traced_galvo import traced_scan_path_px

import mitsuba_eventfield as ef
from mitsuba_eventfield.errors import EventFieldError
from mitsuba_eventfield.simulate.image_motion import motion_schedule, scan_px_per_step

GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")
FAN = os.path.join(ROOT, "scenes", "fan", "fan.xml")
GRID_K = os.path.join(ROOT, "scenes", "moving_grid", "kaleidoscope.xml")


def _lissajous_scene(tmp_path, **size):
    """scenes/galvo_static with a 100 x 150 Hz Lissajous scan: its image speed varies along the curve."""
    text = open(GALVO).read()
    text = text.replace('<string name="curve" value="circle"/>', '<string name="curve" value="lissajous"/>'
                        '<float name="freq_x" value="100"/><float name="freq_y" value="150"/>'
                        '<float name="amplitude_x" value="0.5"/><float name="amplitude_y" value="0.5"/>')
    for name in ("frequency", "amplitude", "phase"):
        text = text.replace(f'<float name="{name}" value="${name}"/>', "")
    for png in ("text.png", "letters.png"):
        text = text.replace(f'value="{png}"', f'value="{os.path.join(ROOT, "scenes", "galvo_static", png)}"')
    path = tmp_path / "lissajous.xml"
    path.write_text(text)
    return ef.load_scene(str(path), **size)


def _true_scan_motion(timed, t0, t1, samples=64):
    """Largest image displacement over [t0, t1] at the image centre and corners, traced through the rotated
    mirrors (``traced_galvo``): independent of the homographies the schedule is built from."""
    w, h = timed.film_size
    return traced_scan_path_px(timed.sensor.optics_metadata(), w, h, t0, t1, samples)


def test_lissajous_steps_are_short_where_the_scan_is_fast(tmp_path):
    timed = _lissajous_scene(tmp_path, width=64, height=48)
    period = timed.scan_period                                    # 20 ms
    instants = motion_schedule(timed, 0.0, period, px_per_step=0.5)
    steps = np.diff(instants)
    moved = np.array([_true_scan_motion(timed, a, b) for a, b in zip(instants[:-1], instants[1:])])
    assert moved.max() < 0.5 * 1.03                                # measured max 0.502 px (path sampled at 64/period)
    assert moved.mean() > 0.45                                     # no step wasted: measured 0.499
    assert steps.max() > 2 * steps.min()                           # measured 4.6x: short where the scan is fast
    # as many steps as the scan's path needs: about the count of uniform steps at the path's mean speed (the
    # schedule bounds the worst of five image points per interval, so a little more: measured 56 for 51.2)
    assert scan_px_per_step(timed, period, 1) / 0.5 <= len(steps) <= 1.15 * scan_px_per_step(timed, period, 1) / 0.5


def test_galvo_pays_no_more_than_uniform_steps_at_equal_accuracy(capsys):
    timed = ef.load_scene(GALVO, width=48, height=36)
    period = timed.scan_period
    ref = ef.render_events(timed, period / 2, steps=300, reuse=False)
    uniform_steps = int(math.ceil(scan_px_per_step(timed, period / 2, 1) / 0.25))
    uni = ef.render_events(timed, period / 2, steps=uniform_steps, reuse=False)
    mot = ef.render_events(timed, period / 2, adaptive=True, px_per_step=0.25, reuse=False)
    logc = ef.render_events(timed, period / 2, adaptive="log-change", max_log_change=0.5, reuse=False)
    n = {k: e.meta["render"]["steps"] for k, e in (("uniform", uni), ("motion", mot), ("log-change", logc))}
    err = {k: abs(len(e) / len(ref) - 1) for k, e in (("uniform", uni), ("motion", mot), ("log-change", logc))}
    with capsys.disabled():
        print(f"\n[galvo 48x36, half a period] steps {n}, |event count error| "
              + ", ".join(f"{k} {100 * v:.1f}%" for k, v in err.items()))
    assert mot.meta["stepping"]["criterion"] == "image motion"
    assert n["motion"] <= 2 * n["uniform"]                         # measured 17 vs 16 steps
    assert err["motion"] <= err["uniform"] + 0.01                  # equal accuracy: measured 11.5% vs 12.2%
    assert n["log-change"] > 20 * n["motion"]                      # the global log-change rule: measured 1801 (106x)


def test_moving_objects_add_to_the_scan():
    timed = ef.load_scene(FAN, width=64, height=48)
    with_fan = motion_schedule(timed, 0.0, timed.scan_period, px_per_step=1.0)
    scan_only = int(math.ceil(scan_px_per_step(timed, timed.scan_period, 1)))
    assert len(with_fan) - 1 > scan_only                           # the blades move on top of the scan


def test_unknown_motion_falls_back_or_refuses():
    timed = ef.load_scene(GRID_K, views_px=48, motion={"objects": {"camera": {"velocity": [0.1, 0, 0]}}})
    assert motion_schedule(timed, 0.0, 0.002) is None               # a moving sensor: its motion is not projected
    ev = ef.render_events(timed, 0.002, adaptive=True, min_step=1e-4, max_step=5e-4)
    assert ev.meta["stepping"]["criterion"] == "log change"
    with pytest.raises(EventFieldError, match="not known before rendering"):
        ef.render_events(timed, 0.002, adaptive="motion")
    with pytest.raises(EventFieldError, match="allowed values are False, True, 'motion', 'log-change'"):
        ef.render_events(timed, 0.002, adaptive="sometimes")


def test_schedules_of_many_scan_periods_do_not_alias_the_scan():
    """150,000 periods of a 250 Hz circle (10 min simulated): the schedule keeps at least 8 motion samples a
    period, so its steps per period are those of 1,000 periods within 2 % (8 chords of a circle are 2.6 % short
    of it). The 200,000-sample cap this replaced left 1.3 samples a period: they fell on nearly the same phases.
    Past 1,000,000 periods it is refused in one line."""
    timed = ef.load_scene(GALVO, width=48, height=36)
    period = timed.scan_period
    few = len(motion_schedule(timed, 0.0, 1000 * period, 1.0)) - 1
    many = len(motion_schedule(timed, 0.0, 150_000 * period, 1.0)) - 1
    assert many / 150_000 == pytest.approx(few / 1000, rel=0.02)
    with pytest.raises(EventFieldError, match=r"duration = .* scan periods.*at most 1000000 periods"):
        motion_schedule(timed, 0.0, 1_000_100 * period, 1.0)
