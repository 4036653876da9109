"""The steps a render takes unasked (issue 18: defaults chosen by measurement, ``stepping.default_steps``):
steps sized by the image motion known before rendering (uniform, or placed by the motion without a scan),
checked against the analytic scene's exact events, rendered image shifts, the galvo phase grid, the scene's own
motion and the explicit stepping they stand for."""
import math

import cv2
import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.evaluation import analytic as an
from mitsuba_eventfield.evaluation import bench
from mitsuba_eventfield.scene import bundled_scene
from mitsuba_eventfield.simulate import image_motion
from mitsuba_eventfield.simulate.stepping import UNKNOWN_MOTION_STEPS

DEMO = bundled_scene("demo/demo.xml")


def _chosen(ev, placed: bool = False):
    """Why the default chose its steps; ``placed``: the steps are placed by the image motion (not uniform)."""
    st = ev.meta["stepping"]
    assert (st["mode"], st.get("criterion")) == (("adaptive", "image motion") if placed else ("uniform", None))
    assert st["chosen"]["steps"] == ev.meta["render"]["steps"]
    return st["chosen"]


def test_kaleidoscope_views_move_as_pinholes_at_their_subapertures():
    """The grid's image motion the stepping predicts for every kaleidoscope view against the shift measured
    by phase correlation between two rendered frames 20 ms apart (centre and corner view, 64 px tiles)."""
    timed = ef.load_scene(bundled_scene("moving_grid/kaleidoscope.xml"), views_px=192)
    timed.set_time(0.0)
    predicted = image_motion.object_displacements(timed, np.linspace(0.0, 0.02, 21)).sum()
    frames = ef.render_frames(timed, [0.0, 0.02], spp=16, log=False).astype(np.float32)
    for row, col in ((1, 1), (0, 0), (2, 1)):
        tile = np.s_[row * 64:(row + 1) * 64, col * 64:(col + 1) * 64]
        (dx, dy), _ = cv2.phaseCorrelate(frames[0][tile], frames[1][tile])
        assert math.hypot(dx, dy) == pytest.approx(predicted, rel=0.05), (row, col)
    assert predicted == pytest.approx(2.8, rel=0.05)        # 0.5 m/s at 1 m through a 13 deg view of 64 px
    # the suite's 20 px views at 4 spp (noise 0.46 C, 2 px a step): the grid's 0.9 px take one step, no floor
    small = ef.render_events(ef.load_scene(bundled_scene("moving_grid/kaleidoscope.xml"), views_px=60), 0.02)
    assert small.meta["render"]["steps"] == 1 and _chosen(small)["by"] == "image motion"


def test_low_noise_scene_takes_half_pixel_steps_and_meets_its_exact_events(tmp_path):
    """The analytic scene (4 spp noise 0.035 C): 0.5 px a step, which its speed makes 100 steps, and the
    events' count error against the closed form within 1 % (at 1 px a step it is 3.8 %)."""
    velocity = bench.analytic_velocity()
    path = bench.write_analytic_scene(str(tmp_path), velocity)
    ev = ef.render_events(ef.load_scene(path, height=48))     # 48 rows of the same sinusoid: the bench's film
    chosen = _chosen(ev)
    assert chosen["by"] == "image motion" and chosen["px_per_step"] == 0.5
    assert chosen["noise_over_threshold"] < 0.25
    assert ev.meta["render"]["steps"] == 100
    assert ev.meta["render"]["image_motion_px_per_step"]["objects"] <= 0.5 + 1e-6
    truth = an.truth_events(velocity, bench.ANALYTIC_DURATION, bench.ANALYTIC_C)
    assert bench.analytic_score(ev, truth)["count_error"] < 0.01
    assert ev.meta["render"]["timing_limit"] is not None      # the probe's noise map serves the limit note too
    # the probe's first frame, staged as the first step's, is the frame the loop would have rendered: the
    # events are bit for bit those of asking for the same 100 steps
    same = ef.render_events(ef.load_scene(path, height=48), steps=100)
    for a in "xytp":
        assert np.array_equal(getattr(ev, a), getattr(same, a))


def test_the_probe_frames_are_the_first_step_and_the_accuracy_limit_frame(tmp_path, monkeypatch):
    """A default render renders no more frames than asking for its steps: the loop renders its steps 1..N,
    and neither the first frame (the probe's, at the render's seed) nor the accuracy-limit note's other seed."""
    from mitsuba_eventfield.simulate.frames import FrameRenderer
    path = bench.write_analytic_scene(str(tmp_path), bench.analytic_velocity())
    real, calls = FrameRenderer.render, []

    def counted(self, timed, seed, once=False, step=None):
        calls.append((step, once))
        return real(self, timed, seed, once, step)
    monkeypatch.setattr(FrameRenderer, "render", counted)
    ef.render_events(ef.load_scene(path), steps=100)
    explicit, calls[:] = list(calls), []
    ev = ef.render_events(ef.load_scene(path))
    assert ev.meta["render"]["steps"] == 100 and ev.meta["render"]["timing_limit"] is not None
    assert len(explicit) == 102 and (0, False) in explicit and any(once for _, once in explicit)
    assert len(calls) == 100 and (0, False) not in calls and not any(once for _, once in calls)


def test_noisy_scene_takes_two_pixel_steps_until_samples_quiet_the_noise():
    """The demo at 4 spp (noise 0.40 C): 2 px a step, said in a note (not a coarse-step warning); at 64 spp the
    noise is small and the steps are four times as many. The demo's objects slow down, so the steps are placed
    by their motion: as many as the path the objects' image travels (projected here 20,000 times, independently
    of the 1024 samples the stepping takes) needs at each bound, fewer than uniform steps at the fastest speed."""
    timed = ef.load_scene(DEMO, width=48, height=36)
    noisy = ef.render_events(timed, 0.05, spp=4)
    quiet = ef.render_events(timed, 0.05, spp=64)
    a, b = _chosen(noisy, placed=True), _chosen(quiet, placed=True)
    assert a["px_per_step"] == 2.0 and a["noise_over_threshold"] >= 0.25
    assert "waived_for_noise" not in a               # the ideal pixel has no low-pass floor to waive
    assert b["px_per_step"] == 0.5 and b["noise_over_threshold"] < 0.25
    timed.set_time(0.0)
    path = image_motion.object_displacements(timed, np.linspace(0.0, 0.05, 20_001)).sum()
    for ev, bound in ((noisy, 2.0), (quiet, 0.5)):
        steps, chosen = ev.meta["render"]["steps"], ev.meta["stepping"]["chosen"]
        assert steps == pytest.approx(path / bound, abs=1.0)
        assert steps <= 0.9 * chosen["steps_for_motion"]               # uniform steps at the fastest speed
        assert ev.meta["render"]["image_motion_px_per_step"]["objects"] <= bound * 1.02
    assert quiet.meta["render"]["steps"] == pytest.approx(4 * noisy.meta["render"]["steps"], abs=3)
    notes = noisy.meta["render"]["notes"]
    assert any("as many as the image motion at the 2 px a step the default allows where Monte-Carlo noise" in n
               for n in notes)
    assert not any("steps coarser than the image motion" in n for n in notes)
    assert quiet.meta["render"]["timing_limit"] is not None            # placed steps get the accuracy-limit note


def _motion_bound(chosen) -> float:
    """The px-a-step bound the motion's step count used, from the noise the stepping measured (independently of
    ``chosen["px_per_step"]``, which records it)."""
    from mitsuba_eventfield.simulate import stepping
    noisy = (chosen["noise_over_threshold"] or 0) >= stepping.NOISE_LIMITED
    bound = stepping.NOISY_PX_PER_STEP if noisy else stepping.FINE_PX_PER_STEP
    assert chosen["px_per_step"] == bound
    return bound


def test_galvo_default_steps_keep_the_phase_grid_and_reuse_periods():
    """Under a periodic scan the default is a whole number of steps per period, so a static scene's later
    periods are fed from the first (reused) and the bound holds for scan and blades together; and at least a
    rendered instant for each of a period's light-field views (at 48x36 the motion alone asks for fewer)."""
    from mitsuba_eventfield.optics.galvo import VIEWS_PER_PERIOD
    timed = ef.load_scene(bundled_scene("galvo_static/galvo_static.xml"), width=48, height=36)
    period = timed.scan_period
    ev = ef.render_events(timed, 3 * period)
    steps = ev.meta["render"]["steps"]
    chosen = _chosen(ev)
    per_period = max(math.ceil(chosen["steps_for_motion"] / 3), VIEWS_PER_PERIOD)   # whole steps a period
    assert steps == 3 * per_period and 3 < chosen["steps_for_motion"] < 3 * VIEWS_PER_PERIOD
    assert chosen["by"] == "light-field views" and chosen["steps_for_lightfield_views"] == 3 * VIEWS_PER_PERIOD
    bound = _motion_bound(chosen)
    assert chosen["steps_for_motion"] == math.ceil(chosen["largest_image_speed_px_per_s"] * 3 * period
                                                   / bound * (1 - 1e-9))
    assert ev.meta["render"]["image_motion_px_per_step"]["scan"] <= bound * 1.05
    assert ev.meta["render"]["reused_steps"] + ev.meta["render"]["copied_steps"] >= 2 * steps // 3
    fan = ef.load_scene(bundled_scene("fan/fan.xml"), width=48, height=36)
    ev = ef.render_events(fan, 2 * fan.scan_period)
    chosen, motion = _chosen(ev), ev.meta["render"]["image_motion_px_per_step"]
    assert ev.meta["render"]["steps"] % 2 == 0
    assert motion["scan"] + motion["objects"] <= _motion_bound(chosen) * 1.05


def test_unknown_motion_takes_the_fixed_default(tmp_path):
    """A moving sensor: nothing projects its motion, so neither the default nor adaptive stepping pretends to
    know it (the default takes 100 steps, adaptive falls back to the log change)."""
    timed = ef.load_scene(DEMO, motion={"objects": {"camera": {"velocity": [0.5, 0, 0]}}}, width=32, height=24)
    times = np.linspace(0.0, 0.01, 5)
    assert image_motion.image_displacements(timed, times) is None
    assert image_motion.motion_schedule(timed, 0.0, 0.01) is None
    ev = ef.render_events(timed, 0.01)
    assert ev.meta["render"]["steps"] == UNKNOWN_MOTION_STEPS
    assert "not known" in _chosen(ev)["by"]


def test_low_pass_pixel_bounds_the_default_step_unless_noise_hides_it():
    """davis346's 300 Hz photoreceptor: no default step longer than 1 / (pi 300 Hz), 1.06 ms, where the render is
    quiet (64 spp); at 4 spp (noise 0.4 C) the motion's 2 px steps, the low-pass floor waived and said so."""
    timed = ef.load_scene(DEMO, width=32, height=24)
    quiet = ef.render_events(timed, 0.02, preset="davis346", spp=64)
    assert quiet.meta["render"]["steps"] == math.ceil(0.02 * math.pi * 300) == 19
    assert _chosen(quiet)["by"] == "low-pass pixel" and "waived_for_noise" not in _chosen(quiet)
    noisy = ef.render_events(timed, 0.02, preset="davis346")
    chosen = _chosen(noisy)               # 2 steps: placing them by the motion would save none
    assert chosen["waived_for_noise"] == ["low-pass pixel"] and chosen["steps_for_lowpass_pixel"] == 19
    assert chosen["by"] == "image motion" and chosen["px_per_step"] == 2.0 and noisy.meta["render"]["steps"] < 19


def test_shot_noise_keeps_its_rate_on_a_still_scene():
    """Shot noise fires at most one event a pixel a step: a still scene (one step by its motion) at 20 Hz over
    1 s takes steps of at most 0.1 events a pixel, and fires the Poisson rate (20 a pixel, within 5 %) instead of
    one event a pixel."""
    timed = ef.load_scene(DEMO, motion={"objects": {}}, width=16, height=12)
    ev = ef.render_events(timed, 1.0, pixel={"shot_noise_hz": 20.0, "shot_noise_bright_factor": 1.0})
    assert _chosen(ev)["by"] == "shot noise" and ev.meta["render"]["steps"] == 200
    assert len(ev) / (16 * 12) == pytest.approx(20.0, rel=0.05)


def test_long_galvo_renders_do_not_alias_the_scan():
    """The fastest image motion of 25,000 scan periods is that of one (the samples are not capped)."""
    timed = ef.load_scene(bundled_scene("galvo_static/galvo_static.xml"), width=48, height=36)
    one = image_motion.largest_image_speed(timed, 0.0, timed.scan_period)
    assert image_motion.largest_image_speed(timed, 0.0, 25_000 * timed.scan_period) == pytest.approx(one, rel=0.01)


def test_explicit_steps_are_untouched():
    ev = ef.render_events(ef.load_scene(DEMO, width=32, height=24), 0.01, steps=7)
    assert ev.meta["stepping"] == {"mode": "uniform", "steps": 7} and ev.meta["render"]["steps"] == 7


@pytest.mark.parametrize("bad", [-4, 2.5, 10**7])
def test_bad_spp_changing_is_refused_before_the_noise_probe_renders(bad):
    """The default steps' noise probe renders at spp_changing: it is checked first, one line, nothing rendered."""
    from mitsuba_eventfield.errors import EventFieldError
    with pytest.raises(EventFieldError, match="spp_changing"):
        ef.render_events(ef.load_scene(DEMO, width=32, height=24), 0.01, spp_changing=bad)


def test_placed_default_steps_are_the_adaptive_motion_steps_at_its_bound():
    """The demo's default (2 px, placed by the motion) renders the events of asking for that stepping
    (``adaptive="motion"``, 2 px, no step longer than the render, 1 us the shortest), bit for bit: the probe's
    first frame stands for the loop's, and both renders make the accuracy-limit note from the same frames."""
    timed = ef.load_scene(DEMO, width=48, height=36)
    default = ef.render_events(timed, 0.05)
    asked = ef.render_events(timed, 0.05, adaptive="motion", px_per_step=2.0, max_step=0.05, min_step=1e-6)
    assert _chosen(default, placed=True)["px_per_step"] == 2.0
    assert default.meta["render"]["steps"] == asked.meta["render"]["steps"] >= 3
    assert len(default) > 100
    for a in "xytp":
        assert np.array_equal(getattr(default, a), getattr(asked, a))
    assert default.meta["render"]["timing_limit"] == asked.meta["render"]["timing_limit"] is not None


def test_galvo_default_steps_give_each_light_field_view_an_instant():
    """The default's light-field floor: galvo_static at 120x90 over one 4 ms period took 11 steps at 2 px (its
    Monte-Carlo noise is 0.3 C), and the events-only light field's depth read the 0.5 m card and the 2.5 m wall
    both at 0.40 m, with a third of their pixels confident (before the refocus kept Lanczos samples within their
    neighbours' values). Scored against Mitsuba's depth output. Per pixel the wall's depth is beyond what the
    views resolve (2.5 m and 2.75 m differ by 0.010 px: focus/depth.py), so it is not confident, and its
    depth is scored as the median over the wall: 2.67 m at the default 32 steps, 1.84 m at 11."""
    from mitsuba_eventfield.evaluation import truth
    from mitsuba_eventfield.optics.galvo import VIEWS_PER_PERIOD
    timed = ef.load_scene(bundled_scene("galvo_static/galvo_static.xml"), width=120, height=90)
    ev = ef.render_events(timed, timed.scan_period)
    assert ev.meta["render"]["steps"] == VIEWS_PER_PERIOD and _chosen(ev)["by"] == "light-field views"
    # the one-depth solver, as these numbers were measured (the per-period solver, from_events' default since
    # 2026-11-27, reads the card at 0.464 m here: 7 % near at this film and one period)
    dm = ef.depth_from_focus(ef.lightfield.from_events(ev, method="galvo"), 0.3, 4.0, 32, "variance")
    z = truth.truth_depth(timed, 0.0)
    card, wall = z < 1, z > 2
    text = card & truth.textured(truth.centre_frame(timed, 0.0), 0.1)     # the text on the card
    sure = card & (dm.confidence > 0.3)
    assert (sure & text).sum() > 0.1 * text.sum()                         # measured 0.15
    assert abs(np.median(dm.depth[sure] / z[sure]) - 1) < 0.06           # measured 2.0 %
    assert (wall & (dm.confidence > 0.3)).sum() < 0.01 * wall.sum()       # measured 0
    assert abs(np.median(dm.depth[wall]) / 2.5 - 1) < 0.1                # measured 6.6 %


def test_the_noise_bound_is_recorded_when_the_light_field_views_decide(capsys):
    """galvo_static at 256 x 192 and 4 spp: the views' 32 steps a period beat the motion's 24 at the noise-limited
    2 px, leaving 1.33 px a step. The bound is recorded all the same, so neither the render's note nor the
    light-field commands warn "coarser than the image motion" on the file the default steps made (both did
    when only a deciding motion bound was recorded: the README's galvo_static render at 346 x 260)."""
    from mitsuba_eventfield.cli.lightfield import _warn_coarse_steps
    ev = ef.render_events(ef.load_scene(bundled_scene("galvo_static/galvo_static.xml"), width=256, height=192), 0.004)
    chosen = ev.meta["stepping"]["chosen"]
    assert chosen["by"] == "light-field views" and chosen["steps"] == 32 and chosen["steps_for_motion"] < 32
    assert chosen["px_per_step"] == 2.0 and chosen["noise_over_threshold"] >= 0.25
    assert 1.0 < ev.meta["render"]["image_motion_px_per_step"]["scan"] < 2.0
    assert not any("steps coarser" in n for n in ev.meta["render"]["notes"])
    assert any("as many as the light-field views, within the 2 px a step the default allows" in n
               for n in ev.meta["render"]["notes"])            # what set the steps, as stepping.chosen.by says
    _warn_coarse_steps("gs.h5", ev)
    assert capsys.readouterr().err == ""


def test_one_phase_grid_test_and_one_rounding_for_every_caller():
    """``stepping.whole_number`` is the one test of "a whole number of periods / steps" and ``whole_per_period``
    the one rounding: --auto's reuse rounded on its own, with a looser tolerance and no MAX_STEPS cap."""
    from types import SimpleNamespace

    from mitsuba_eventfield.simulate import auto
    from mitsuba_eventfield.simulate.stepping import MAX_STEPS, is_whole, whole_number, whole_per_period
    assert whole_number(0.02 / 0.004) == 5 and whole_number(4.9999999) == 5 and whole_number(4.9) == 0
    assert whole_number(0.4) == 0 and is_whole(0.0) and is_whole(-3.0000000001) and not is_whole(2.5)
    assert whole_per_period(10, 0.02, 0.004) == 10 and whole_per_period(11, 0.02, 0.004) == 15
    assert whole_per_period(11, 0.021, 0.004) == 11                              # not whole periods: as asked
    static = SimpleNamespace(is_static=True, scan_period=0.004)
    reasons = {"steps": "x"}
    assert auto._reuse(static, 0.02, 11, reasons) == 15 and "3 per scan period (15 in all)" in reasons["steps"]
    assert auto._reuse(static, 0.02, 10 * MAX_STEPS, {"steps": ""}) <= MAX_STEPS    # uncapped before
