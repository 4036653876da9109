"""The public Python functions against bad arguments: each raises ``EventFieldError`` (``ConfigError`` where
the value is wrong, which is also a ``ValueError``) with one line that names the field, never an unrelated
exception from deep inside."""
import math

import numpy as np
import pytest
from conftest import DEMO

import mitsuba_eventfield as ef


@pytest.fixture(scope="module")
def scene():
    return ef.load_scene(DEMO, width=16, height=12)


CASES = {
    "render_events duration": (lambda s: ef.render_events(s, -1.0, steps=4), "duration"),
    "render_events steps": (lambda s: ef.render_events(s, 0.01, steps=0), "steps"),
    "render_events spp": (lambda s: ef.render_events(s, 0.01, steps=2, spp=float("nan")), "spp"),
    "render_events threshold": (lambda s: ef.render_events(s, 0.01, steps=2, threshold=-1), "threshold_on"),
    "render_events pixel": (lambda s: ef.render_events(s, 0.01, steps=2, pixel={"bogus": 1}), "bogus"),
    "render_events output": (lambda s: ef.render_events(s, 0.01, steps=2, output="/tmp/x.foo"), ".foo"),
    "render_events buffer": (lambda s: ef.render_events(s, 0.01, steps=2, event_buffer_mb=0), "event_buffer_mb"),
    "render_events checkpoint": (lambda s: ef.render_events(s, 0.01, steps=2, checkpoint_s=5), "HDF5 output"),
    "render_frames times": (lambda s: ef.render_frames(s, [math.nan]), "times"),
    "render_frames spp": (lambda s: ef.render_frames(s, [0.0], spp=0), "spp"),
    "read_events": (lambda s: ef.read_events("/nonexistent/e.h5"), "no such event file"),
    "write_events": (lambda s: ef.write_events("/tmp/x.foo", ef.EventStream([1], [1], [1], [1], 4, 4)), ".foo"),
    "load_scene": (lambda s: ef.load_scene("/nonexistent/s.xml"), "not found"),
    "parse_motion": (lambda s: ef.parse_motion({"objects": {"a": {"velocity": [1, 2]}}}), "velocity"),
    "make_curve frequency": (lambda s: ef.make_curve("circle", frequency=-1, amplitude=0.5), "frequency"),
    "make_curve kind": (lambda s: ef.make_curve("zigzag", frequency=100, amplitude=0.5), "zigzag"),
    "EventStream lengths": (lambda s: ef.EventStream([1, 2], [1], [10], [1], 8, 6), "one length"),
    "EventStream range": (lambda s: ef.EventStream([100], [1], [10], [1], 8, 6), "exceed"),
    "events_from_frames": (lambda s: ef.events_from_frames(np.ones((3, 4)), [0, 1, 2]), "shape"),
    "set_variant": (lambda s: ef.set_variant("nope_variant"), "nope_variant"),
    "refocus no light field": (lambda s: ef.refocus(None, 1.0), "expected a LightField"),
    "depth_from_focus no light field": (lambda s: ef.depth_from_focus(None, 0.5, 2.0), "expected a LightField"),
    "depth_planes": (lambda s: ef.depth_planes(2.0, 1.0, 8), "near"),
    "render_events adaptive": (lambda s: ef.render_events(s, 0.01, adaptive="sometimes"), "adaptive"),
    "render_events px_per_step": (lambda s: ef.render_events(s, 0.01, adaptive=True, px_per_step=0), "px_per_step"),
    "designs.compare speeds": (lambda s: ef.designs.compare(speeds=(1, -2)), "speed"),
    "designs.grid_experiment texture": (lambda s: ef.designs.grid_experiment(texture="/nonexistent/g.png"),
                                        "g.png"),
    "scan_frequency.sweep": (lambda s: ef.scan_frequency.sweep(frequencies=(-5,)), "frequenc"),
    "hdr.lightfield depths": (lambda s: ef.hdr.lightfield(depths=(0.6, 0.0)), "depth"),
    "paper.generate only": (lambda s: __import__("mitsuba_eventfield.apps.paper", fromlist=["generate"]).generate(
        "/tmp/ef_paper_out", "/tmp/ef_paper.md", only=["nonsense"]), "nonsense"),
}


@pytest.mark.parametrize("name", CASES)
def test_bad_argument_is_one_named_error(scene, name):
    call, field = CASES[name]
    with pytest.raises(ef.EventFieldError) as err:
        call(scene)
    message = str(err.value)
    assert field in message and "\n" not in message and "Traceback" not in message, message
    ef.set_variant("llvm_ad_mono")                  # set_variant's refusal must leave the variant usable
