"""The sensor's sampler: a scene that names none gets the chart's choice (multi-jittered), one that names one keeps
it, a caller can choose; the choice is in the event file's metadata, and it changes the events' accuracy the way
the chart measured (timestamps against the analytic scene's exact events)."""
import os

import numpy as np
import pytest
from conftest import DEMO, ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield.errors import EventFieldError
from mitsuba_eventfield.evaluation import analytic as an
from mitsuba_eventfield.evaluation import bench
from mitsuba_eventfield.scene import sampler as sm

RUNNER = os.path.join(ROOT, "scenes", "runner", "runner.xml")     # names a jitter-free stratified sampler


def _sampler(timed):
    return timed.sensor.sampler().class_name()


def test_a_scene_without_a_sampler_gets_the_default_and_one_with_a_sampler_keeps_it():
    demo = ef.load_scene(DEMO, width=24, height=18)
    assert _sampler(demo) == "MultijitterSampler" and "default" in demo.sampler_choice
    runner = ef.load_scene(RUNNER, width=24, height=18)
    assert _sampler(runner) == "StratifiedSampler" and runner.sampler_choice == "the scene's own"
    chosen = ef.load_scene(RUNNER, width=24, height=18, sampler={"type": "independent", "sample_count": 2})
    assert _sampler(chosen) == "IndependentSampler" and "chosen" in chosen.sampler_choice
    # the rewritten scene still finds its own files (the runner's meshes and textures) and its motion
    assert chosen.motion is not None and chosen.path == RUNNER


def test_the_default_is_what_the_metadata_says_and_equals_asking_for_it():
    ev = ef.render_events(ef.load_scene(DEMO, width=24, height=18), 0.02, steps=10)
    assert ev.meta["sampler"] == {"type": "MultijitterSampler",
                                  "chosen_by": "multijitter (default: the scene names none)"}
    asked = ef.render_events(ef.load_scene(DEMO, width=24, height=18, sampler={"type": "multijitter"}), 0.02, steps=10)
    assert len(ev) > 100 and np.array_equal(ev.t, asked.t) and np.array_equal(ev.x, asked.x)
    indep = ef.render_events(ef.load_scene(DEMO, width=24, height=18, sampler={"type": "independent"}), 0.02, steps=10)
    assert not (len(indep) == len(ev) and np.array_equal(indep.t, ev.t))


def test_the_default_sampler_times_events_better_than_mitsubas_own(tmp_path):
    """The reason for the default (bench_suite.md: median 12.4 -> 4.0 us at 4 spp, 100 steps): on the analytic
    scene, the default sampler's median timestamp error is at most half the independent sampler's."""
    path = bench.write_analytic_scene(str(tmp_path), bench.analytic_velocity())
    truth = an.truth_events(bench.analytic_velocity(), bench.ANALYTIC_DURATION, bench.ANALYTIC_C)
    errors = {}
    for name, sampler in (("default", None), ("independent", {"type": "independent"})):
        ev = ef.render_events(ef.load_scene(path, sampler=sampler, height=4), bench.ANALYTIC_DURATION, steps=100)
        errors[name] = bench.analytic_score(ev, truth)["timing_median_us"]
    print(errors)
    assert errors["default"] < 0.5 * errors["independent"]


def test_text_rewriting():
    text = '<scene><sensor type="perspective"><film type="hdrfilm"/></sensor></scene>'
    assert sm.names_sampler(text) is False
    new = sm.with_sampler(text, {"type": "multijitter", "sample_count": 16, "jitter": False})
    assert '<sampler type="multijitter"><integer name="sample_count" value="16"/>' in new
    assert '<boolean name="jitter" value="false"/>' in new and sm.names_sampler(new) is True
    assert sm.with_sampler(new, {"type": "independent"}).count("<sampler") == 1
    assert sm.names_sampler("<scene><include filename='cam.xml'/></scene>") is None     # loaded as it is
    assert sm.choose("<scene/>", None) == (None, "the scene's own")


def test_choosing_a_sampler_for_a_scene_without_a_sensor_is_refused(tmp_path):
    path = tmp_path / "nosensor.xml"
    path.write_text('<scene version="3.0.0"><shape type="sphere"/></scene>')
    with pytest.raises(EventFieldError, match="nosensor.xml"):
        ef.load_scene(str(path), sampler={"type": "independent"})
