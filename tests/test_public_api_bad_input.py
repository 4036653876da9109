"""The public Python functions against bad arguments: each raises ``EventFieldError`` (``ConfigError`` where
the value is wrong, which is also a ``ValueError``) with one line that names the field, never an unrelated
exception from deep inside."""
import math
import os
import shutil
import tempfile

import numpy as np
import pytest
from conftest import DEMO, ROOT, TEST_VARIANT

import mitsuba_eventfield as ef
from mitsuba_eventfield.lightfield.model import Disparity

OUT = os.path.join(tempfile.gettempdir(), f"ef_bad_input_{os.getpid()}")   # cases write here: must stay empty
EVENTS = ef.EventStream([1, 2], [1, 2], [10, 20], [1, -1], 8, 6)
GALVO = {"design": "galvo", "scan": ef.scan.curve_to_dict(ef.make_curve("circle", frequency=100, amplitude=0.5))}
KALEIDOSCOPE = {"design": "kaleidoscope", "n": 1, "views": [{"tile": [0, 0, 4, 4], "flip_x": False, "flip_y": False,
                                                             "i": 0, "j": 0, "subaperture": [0.0, 0.0]}]}
LF = ef.LightField(np.ones((2, 8, 8)), np.zeros((2, 2)), np.zeros(2), Disparity((0.0, 0.0), (1.0, 1.0)))


@pytest.fixture(scope="module")
def scene():
    return ef.load_scene(DEMO, width=16, height=12)


def _quiet_log_text():
    """quiet_mitsuba_log("no"): text is not a bool (and "no" would switch the quiet log on); restores the log."""
    try:
        return ef.quiet_mitsuba_log("no")
    finally:
        ef.quiet_mitsuba_log(False)


CASES = {
    "render_events duration": (lambda s: ef.render_events(s, -1.0, steps=4), "duration"),
    "render_events steps": (lambda s: ef.render_events(s, 0.01, steps=0), "steps"),
    "render_events spp": (lambda s: ef.render_events(s, 0.01, steps=2, spp=float("nan")), "spp"),
    # named as given (it named threshold_on, which the caller did not write)
    "render_events threshold": (lambda s: ef.render_events(s, 0.01, steps=2, threshold=-1),
                                "render: threshold = -1: allowed range is (0, 10]"),
    "render_events pixel": (lambda s: ef.render_events(s, 0.01, steps=2, pixel={"bogus": 1}), "bogus"),
    "render_events threshold twice": (lambda s: ef.render_events(s, 0.01, steps=2, threshold=0.3,
                                                                 pixel={"threshold_on": 0.15}), "given twice"),
    "events_from_frames threshold twice": (lambda s: ef.events_from_frames(
        np.ones((3, 4, 4)), [0.0, 0.001, 0.002], threshold=0.3, pixel={"threshold_off": 0.1}), "given twice"),
    "sweep xml reserved": (lambda s: ef.sweep(DEMO, {"xml.motion": [None]}), "load_scene"),
    "sweep render name": (lambda s: ef.sweep(DEMO, {"render.stepz": [8]}), "stepz"),
    "render_events pixel preset": (lambda s: ef.render_events(s, 0.01, steps=2, pixel="davis346"), "preset="),
    "render_events output": (lambda s: ef.render_events(s, 0.01, steps=2, output="/tmp/x.foo"), ".foo"),
    "render_events buffer": (lambda s: ef.render_events(s, 0.01, steps=2, event_buffer_mb=0), "event_buffer_mb"),
    "render_events checkpoint": (lambda s: ef.render_events(s, 0.01, steps=2, checkpoint_s=5), "HDF5 output"),
    "render_frames times": (lambda s: ef.render_frames(s, [math.nan]), "times"),
    "render_frames spp": (lambda s: ef.render_frames(s, [0.0], spp=0), "spp"),
    "read_events": (lambda s: ef.read_events("/nonexistent/e.h5"), "no such event file"),
    "time_window reversed": (lambda s: EVENTS.time_window(5000, 1000), "t1_us = 1000 is before t0_us = 5000"),
    "read_events folder": (lambda s: ef.read_events(ROOT), "a folder, not an event file (image frames become "
                                                           "events through 'eventfield convert')"),
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
    # the rest of the facade (``ef.__all__``); test_every_facade_callable_has_a_case keeps the table complete
    "choose_variant unknown": (lambda s: ef.choose_variant("nope_variant"), "nope_variant"),
    "choose_variant type": (lambda s: ef.choose_variant(5), "variant"),
    "set_variant type": (lambda s: ef.set_variant(5), "variant"),
    "quiet_mitsuba_log type": (lambda s: _quiet_log_text(), "enable"),
    "EventStream width": (lambda s: ef.EventStream([1], [1], [1], [1], "8", 6), "width"),
    "EventStream NaN time": (lambda s: ef.EventStream([1], [1], [math.nan], [1], 8, 6), "t contains NaN"),
    "EventStream shape": (lambda s: ef.EventStream([[1]], [[1]], [[1]], [[1]], 8, 6), "1-D"),
    "H5EventWriter chunk": (lambda s: ef.H5EventWriter(os.path.join(OUT, "w.h5"), 8, 6, chunk=0), "chunk"),
    "H5EventWriter compression": (lambda s: ef.H5EventWriter(os.path.join(OUT, "w.h5"), 8, 6, compression="zip"),
                                  "compression"),
    "H5EventWriter width": (lambda s: ef.H5EventWriter(os.path.join(OUT, "w.h5"), -8, 6), "width"),
    "H5EventWriter threads": (lambda s: ef.H5EventWriter(os.path.join(OUT, "w.h5"), 8, 6, threads=-1), "threads"),
    "read_events path type": (lambda s: ef.read_events(None), "path"),
    "stuck_pixels not a stream": (lambda s: ef.stuck_pixels(None, 0.2, 0.2), "expected an EventStream"),
    "stuck_pixels threshold": (lambda s: ef.stuck_pixels(EVENTS, 0.0, 0.2), "threshold_on"),
    "without_stuck_pixels no thresholds": (lambda s: ef.without_stuck_pixels(ef.EventStream.empty(4, 4), "rec.raw"),
                                           "rec.raw: no contrast thresholds"),
    "write_events not a stream": (lambda s: ef.write_events(os.path.join(OUT, "e.h5"), None), "events"),
    "Motion duration": (lambda s: ef.Motion(duration=-1.0), "duration"),
    "load_motion": (lambda s: ef.load_motion("/nonexistent/m.toml"), "not found"),
    "parse_motion type": (lambda s: ef.parse_motion(5), "motion"),
    "event_frame_rgb saturation": (lambda s: ef.event_frame_rgb(EVENTS, saturation=-1), "saturation"),
    "event_frame_rgb window": (lambda s: ef.event_frame_rgb(EVENTS, t0_us=100, t1_us=5), "t1_us"),
    "event_frame_rgb events": (lambda s: ef.event_frame_rgb(None), "events"),
    "write_preview events": (lambda s: ef.write_preview(os.path.join(OUT, "p.png"), None), "events"),
    "write_preview t0": (lambda s: ef.write_preview(os.path.join(OUT, "p.png"), EVENTS, t0_us=math.nan), "t0_us"),
    "render_frames empty times": (lambda s: ef.render_frames(s, []), "times"),
    "events_from_frames fps": (lambda s: ef.events_from_frames(np.ones((3, 4, 4)), fps=-1), "fps"),
    "events_from_frames on_device": (lambda s: ef.events_from_frames(
        np.ones((3, 4, 4)), fps=10, output=os.path.join(OUT, "c.h5"), on_device=True), "on_device"),
    "render_events on_device": (lambda s: ef.render_events(s, 0.01, steps=2, output=os.path.join(OUT, "r.h5"),
                                                           on_device=True), "on_device"),
    "TimedScene scene": (lambda s: ef.TimedScene(None), "scene"),
    "load_scene motion": (lambda s: ef.load_scene(DEMO, motion=5, width=16, height=12), "motion"),
    "curve_from_dict curve": (lambda s: ef.curve_from_dict({"curve": "zigzag"}), "zigzag"),
    "curve_from_dict type": (lambda s: ef.curve_from_dict(None), "scan"),
    "event_angles no galvo": (lambda s: ef.event_angles(EVENTS), "galvo"),
    "ViewStack shapes": (lambda s: ef.ViewStack(np.ones((2, 3, 3)), np.ones((3, 2)), np.ones((2, 2))), "ij"),
    "extract_views optics": (lambda s: ef.extract_views(np.ones((12, 16)), {"design": "galvo"}), "kaleidoscope"),
    "extract_views frame": (lambda s: ef.extract_views(np.ones(4), KALEIDOSCOPE), "frame"),
    "extract_views margin": (lambda s: ef.extract_views(np.ones((4, 4)), KALEIDOSCOPE, margin=9), "margin"),
    "extract_views smaller frame": (lambda s: ef.extract_views(np.ones((3, 4)), KALEIDOSCOPE), "cover 4x4"),
    "extract_views larger frame": (lambda s: ef.extract_views(np.ones((4, 6)), KALEIDOSCOPE), "cover 4x4"),
    "extract_views views cut": (lambda s: ef.extract_views(np.ones((4, 4)), dict(KALEIDOSCOPE, n=2)), "n x n"),
    "ViewStack.view missing": (lambda s: ef.extract_views(np.ones((4, 4)), KALEIDOSCOPE).view(1, 0), "no view"),
    "view_of_pixel outside": (lambda s: ef.view_of_pixel([5, -1], [1, 1], KALEIDOSCOPE), "outside the film (4x4)"),
    "split_events no layout": (lambda s: ef.split_events(EVENTS), "kaleidoscope"),
    "view_of_pixel optics": (lambda s: ef.view_of_pixel(1, 1, None), "optics"),
    "LightField lengths": (lambda s: ef.LightField(np.ones((2, 3, 3)), np.ones((3, 2)), np.ones(2), LF.disparity),
                           "one length"),
    "LightField NaN": (lambda s: ef.LightField(np.full((1, 3, 3), np.nan), np.zeros((1, 2)), [0.0], LF.disparity),
                       "NaN"),
    "from_galvo optics": (lambda s: ef.from_galvo(np.zeros((2, 4, 4)), [0.0, 1e-3], {}), "galvo"),
    "from_galvo times": (lambda s: ef.from_galvo(np.zeros((2, 4, 4)), [0.0], GALVO), "one time per frame"),
    "from_spatial frame": (lambda s: ef.from_spatial(np.ones(4), KALEIDOSCOPE), "frame"),
    "galvo_lightfields no galvo": (lambda s: ef.galvo_lightfields(EVENTS), "galvo"),
    "galvo_lightfields views": (lambda s: ef.galvo_lightfields(
        ef.EventStream([1], [1], [10], [1], 8, 6, {"optics": GALVO}), views=0), "views"),
    "galvo_view_times views": (lambda s: ef.galvo_view_times(GALVO, 0.0, 0), "views"),
    "galvo_view_times start": (lambda s: ef.galvo_view_times(GALVO, math.nan, 4), "t_period_start"),
    "sweep scene": (lambda s: ef.sweep("/nonexistent/s.xml", {"render.spp": [1]}), "not a scene file"),
    "sweep over type": (lambda s: ef.sweep(DEMO, "render.spp"), "over"),
    "sweep over empty": (lambda s: ef.sweep(DEMO, {}), "over"),
    "sweep processes": (lambda s: ef.sweep(DEMO, {"render.spp": [1]}, processes=0), "processes"),
    "sweep base key": (lambda s: ef.sweep(DEMO, {"render.spp": [1]}, base={"spp": 4}), "base"),
    "load_motion type": (lambda s: ef.load_motion(5), "path"),
    "depth_planes count": (lambda s: ef.depth_planes(1.0, 2.0, 2.5), "count"),
    "focal_stack depths": (lambda s: ef.focal_stack(LF, []), "depths"),
    "refocus depth type": (lambda s: ef.refocus(LF, "1"), "depth"),
    "refocus motion": (lambda s: ef.refocus(LF, 1.0, motion="x"), "motion"),
    "track_focus roi": (lambda s: ef.track_focus([LF], [1.0, 2.0], (0, 0, 100, 100)), "roi"),
    "track_focus depths": (lambda s: ef.track_focus([LF], [], (0, 0, 4, 4)), "depths"),
    "depth_from_focus window": (lambda s: ef.depth_from_focus(LF, 1.0, 2.0, planes=3, window=0), "window"),
    "focus_measure window": (lambda s: ef.focus_measure(np.ones((8, 8)), window=0), "window"),
    "focus_measure image": (lambda s: ef.focus_measure(np.ones(4)), "img"),
}

# Cases known to fail, with where (strict xfail: a fix turns them into XPASS failures and the entry must then be
# removed). None now: the eleven found when the table was completed were fixed (backend, scene, optics, render,
# sweep), and load_motion(5) no longer reads and closes file descriptor 5.
KNOWN_FAILURES = {}

# Facade callables with no bad-input case, and why: each takes no input a user could get wrong.
EXEMPT = {
    "EventFieldError": "exception class: any message is valid",
    "ConfigError": "exception class: any message is valid",
    "RenderSummary": "result record that render_events fills in and returns; never built from user input",
    "SweepTable": "result record that sweep returns; never built from user input",
    "DepthMap": "result record that depth_from_focus returns; never built from user input",
    "DeviceEventStream": "result record that events_from_frames / render_events return with on_device; never "
                         "built from user input",
    "ScanCurve": "abstract base of the scan curves (its methods raise NotImplementedError); curves come from "
                 "make_curve / curve_from_dict, which have cases",
}


PARAMS = [pytest.param(name, marks=pytest.mark.xfail(strict=True, reason=KNOWN_FAILURES[name]))
          if name in KNOWN_FAILURES else name for name in CASES]


@pytest.fixture(scope="module", autouse=True)
def out_dir():
    os.makedirs(OUT, exist_ok=True)
    yield OUT
    shutil.rmtree(OUT)


@pytest.mark.parametrize("name", PARAMS)
def test_bad_argument_is_one_named_error(scene, name):
    call, field = CASES[name]
    with pytest.raises(ef.EventFieldError) as err:
        call(scene)
    message = str(err.value)
    assert field in message and "\n" not in message and "Traceback" not in message, message
    assert not os.listdir(OUT), f"refused call left {os.listdir(OUT)} behind"
    ef.set_variant(TEST_VARIANT)                  # set_variant's refusal must leave the variant usable


def test_every_facade_callable_has_a_case():
    """Every callable ``ef.__all__`` exports has a case above (a case is named after its function), or an
    entry in EXEMPT saying why it needs none; EXEMPT and KNOWN_FAILURES name only what exists."""
    callables = {n for n in ef.__all__ if callable(getattr(ef, n))}
    covered = {name.split()[0] for name in CASES}
    missing = sorted(callables - covered - set(EXEMPT))
    assert not missing, f"facade functions without a bad-input case (add one to CASES, or to EXEMPT): {missing}"
    stale = sorted(set(EXEMPT) & covered | set(EXEMPT) - callables)
    assert not stale, f"EXEMPT entries that have a case or are not facade callables: {stale}"
    assert set(KNOWN_FAILURES) <= set(CASES), sorted(set(KNOWN_FAILURES) - set(CASES))


def test_a_range_is_closed_at_infinity_only_where_infinity_is_taken():
    """An error's range says whether inf itself is allowed: ``number`` refuses it (open end), a light field's
    depth takes it (closed end). An ideal mirror has no frequency ceiling (a real galvo's range ends at its
    limit: tests/optics/test_scan.py)."""
    with pytest.raises(ef.ConfigError, match=r"allowed range is \(0, inf\)$"):
        ef.make_curve("circle", frequency=0.0, amplitude=0.5, galvo_model="ideal")
    with pytest.raises(ef.ConfigError, match=r"\(0, inf\)"):
        ef.make_curve("circle", frequency=math.inf, amplitude=0.5, galvo_model="ideal")
    for call in (lambda z: LF.check_depth(z), lambda z: ef.focal_stack(LF, [z])):
        with pytest.raises(ef.ConfigError, match=r"allowed range is \(0, inf\]$"):
            call(-1.0)
    assert LF.check_depth(math.inf) == math.inf and np.isfinite(ef.focal_stack(LF, [math.inf])).all()
