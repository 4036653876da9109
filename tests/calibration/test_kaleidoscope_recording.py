"""A kaleidoscope camera recording, which carries no optics, refocused and read for depth through a calibration
made from a bare camera frame and the set-up's nominal optics (``calibrate kaleidoscope --optics``): before,
such a calibration's record lacked the views, and the light-field commands refused every recording.

Oracle: the same events with the render's own metadata (the sensor's optics, tested against geometry in
tests/plugins/test_kaleidoscope.py) give the same refocused image and depth map, value for value, and the grid
card of the scene sits 1 m away (scenes/moving_grid/grid_shapes.xml)."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, TEST_VARIANT

import mitsuba_eventfield as ef
from mitsuba_eventfield.images import read_exr, write_exr

SCENE = os.path.join(ROOT, "scenes", "moving_grid", "kaleidoscope.xml")
# the scene's sensor, as its XML gives it (aperture and relay aperture at their defaults)
NOMINAL = {"design": "kaleidoscope", "focal_length": 0.05, "focus_distance": 1.0, "tube_width": 0.012,
           "tube_height": 0.012, "tube_length": 0.06, "relay_distance": 0.03}
GRID_DEPTH = 1.0


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "mitsuba_eventfield.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=600)


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """The render (.h5, with optics), the same events as an AEDAT4 camera recording (no optics, no thresholds),
    the frame of the target with its metadata and stripped of it, and the nominal optics file. The recording is
    written through faery (a dependency, which the GPU image lacks: skipped there)."""
    pytest.importorskip("faery")
    d = tmp_path_factory.mktemp("kaleido_recording")
    ef.set_variant(TEST_VARIANT)
    events = ef.render_events(ef.load_scene(SCENE, views_px=120), 0.01, steps=20)
    ef.write_events(str(d / "rec.h5"), events)
    ef.write_events(str(d / "rec.aedat4"), events)
    r = _cli("frame", SCENE, "-o", d / "frame.exr", "-D", "views_px=120")
    assert r.returncode == 0, r.stderr
    write_exr(str(d / "bare.exr"), {"Y": read_exr(str(d / "frame.exr"))[0]["Y"]})
    (d / "nominal.json").write_text(json.dumps(NOMINAL))
    return d, events


def test_a_camera_recording_takes_its_views_from_the_calibration(capture):
    d, events = capture
    recording = ef.read_events(str(d / "rec.aedat4"))
    assert "optics" not in recording.meta and "pixel_model" not in recording.meta and recording.equals(events)
    r = _cli("calibrate", "kaleidoscope", d / "bare.exr", "--optics", d / "nominal.json", "-o", d / "bare.json")
    assert r.returncode == 0 and "3x3 views of 40x40 px" in r.stdout, r.stderr
    record = json.load(open(d / "bare.json"))["kaleidoscope"]["optics"]
    rendered = events.meta["optics"]
    assert record["views"] == rendered["views"] and record["n"] == 3
    for key in ("lens_to_image_plane", "image_plane_size", "aperture_radius", "focus_distance"):
        assert record[key] == pytest.approx(rendered[key], rel=1e-12), key
    outputs = {}
    for name, source, extra in (("recording", "rec.aedat4", ["--calibration", d / "bare.json", "--contrast", "0.2"]),
                                ("render", "rec.h5", [])):
        r = _cli("refocus", d / source, "--depth", "1.0", "-o", d / f"rf_{name}.png", *extra)
        assert r.returncode == 0, r.stderr
        r = _cli("depth", d / source, "--near", "0.5", "--far", "3", "-o", d / f"dp_{name}.png", *extra)
        assert r.returncode == 0, r.stderr
        outputs[name] = (read_exr(str(d / f"rf_{name}.exr"))[0]["Y"], read_exr(str(d / f"dp_{name}.exr"))[0])
    # the nominal optics alone, without a calibration, give the same light field
    r = _cli("refocus", d / "rec.aedat4", "--depth", "1.0", "-o", d / "rf_nominal.png", "--optics", d / "nominal.json",
             "--contrast", "0.2")
    assert r.returncode == 0, r.stderr
    assert np.array_equal(read_exr(str(d / "rf_nominal.exr"))[0]["Y"], outputs["render"][0])
    (image, depth), (image_ref, depth_ref) = outputs["recording"], outputs["render"]
    assert image.std() > 1 and np.array_equal(image, image_ref)
    assert np.array_equal(depth["depth"], depth_ref["depth"])
    confident = depth["confidence"] > 0.3
    assert confident.mean() > 0.2
    assert abs(np.median(depth["depth"][confident]) / GRID_DEPTH - 1) < 0.03


@pytest.mark.parametrize("change, message", [
    ({"design": "galvo"}, r"nominal\.json: design = 'galvo': this command takes kaleidoscope optics \(a JSON object "
                          r"with \"design\": \"kaleidoscope\" and focal_length, "),
    ({"relay_distanc": 0.03}, r"nominal\.json: relay_distanc: not a parameter of the kaleidoscope \(allowed: "),
    ({"relay_distance": 0.02}, r"nominal\.json: sensor 'kaleidoscope': \(relay_distance \+ tube_length\) / "
                               r"relay_distance = 4 must be an odd integer n .*relay_distance = 0\.03 for 3x3"),
    ({"tube_length": "6 cm"}, r"nominal\.json: tube_length = '6 cm': expected a finite number \(metres\)$"),
    ({"tube_width": 0.01}, r"nominal\.json: sensor 'kaleidoscope': film 120x120 and tube 0\.01x0\.012 differ in "
                           r"aspect ratio"),
])
def test_nominal_optics_are_checked(capture, tmp_path, change, message):
    import re
    d, _ = capture
    bad = tmp_path / "nominal.json"
    bad.write_text(json.dumps(dict(NOMINAL, **change)))
    r = _cli("calibrate", "kaleidoscope", d / "bare.exr", "--optics", bad, "-o", tmp_path / "k.json")
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and re.search(message, err[0]), err
    assert not (tmp_path / "k.json").exists()


def test_a_calibration_without_the_views_says_how_to_make_one(capture, tmp_path):
    d, _ = capture
    r = _cli("calibrate", "kaleidoscope", d / "bare.exr", "-o", tmp_path / "k.json")       # no --optics
    assert r.returncode == 0, r.stderr
    r = _cli("refocus", d / "rec.aedat4", "--calibration", tmp_path / "k.json", "--contrast", "0.2", "--depth", "1",
             "-o", tmp_path / "rf.png")
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and "optics record lacks views, lens_to_image_plane" in err[0] \
        and "eventfield calibrate kaleidoscope FRAME.exr --optics TUBE.json" in err[0], err


def test_optics_for_a_frame_that_carries_its_own_are_refused(capture, tmp_path):
    d, _ = capture
    r = _cli("calibrate", "kaleidoscope", d / "frame.exr", "--optics", d / "nominal.json", "-o", tmp_path / "k.json")
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and "carries its own (kaleidoscope) optics" in err[0], err
    assert not (tmp_path / "k.json").exists()


def test_microlens_set_ups_from_their_parameters():
    """The microlens layout's image plane is tube_width x tube_height (its set-up parameters must name them),
    and a count that is not a finite integer is one line, not an overflow."""
    from mitsuba_eventfield.plugins.kaleidoscope_sensor import optics_of
    ef.set_variant(TEST_VARIANT)
    optics = optics_of("microlens", {"views": 3, "tube_width": 0.009, "tube_height": 0.006}, 90, 60)
    assert optics["n"] == 3 and optics["image_plane_size"] == [0.009, 0.006] and len(optics["views"]) == 9
    for views in (float("inf"), 2.5):
        with pytest.raises(ValueError, match=r"^views = .*: expected an integer$"):
            optics_of("microlens", {"views": views}, 90, 60)


def test_reconstructing_a_recording(capture):
    """Frames from the recording equal the render's at the same instants (its first microsecond's events
    included: the stream starts there), and --fps places frames within the recording (they ran past its end)."""
    d, events = capture
    for name, source, extra in (("recording", "rec.aedat4", ["--contrast", "0.2"]), ("render", "rec.h5", [])):
        r = _cli("reconstruct", d / source, "-o", d / f"rc_{name}", "--times", "2.5,5,9.9", *extra)
        assert r.returncode == 0, r.stderr
    for k in range(3):
        a, b = (read_exr(str(d / f"rc_{name}" / f"frame_{k:04d}.exr"))[0]["Y"] for name in ("recording", "render"))
        assert a.std() > 0 and np.array_equal(a, b), k
    r = _cli("reconstruct", d / "rec.aedat4", "-o", d / "rc_fps", "--fps", "400", "--contrast", "0.2")
    assert r.returncode == 0, r.stderr
    times = [read_exr(str(d / "rc_fps" / f"frame_{k:04d}.exr"))[1]["time_s"] for k in range(3)]
    start = events.t[0] * 1e-6
    assert times == pytest.approx([start + 0.0025, start + 0.005, start + 0.0075], abs=1e-9)
    assert not (d / "rc_fps" / "frame_0003.exr").exists()


def test_a_start_frame_taken_during_the_recording(capture, tmp_path):
    """A frame camera beside the event camera takes its frame at some instant of the recording, not at its
    start: --start-time places it (the events up to it are in the frame). Scored against the rendered frame at
    9 ms (log intensity, where it is lit): with the frame's time the error is a few events' worth; taken as the
    stream's start, the events before it were counted twice."""
    d, _ = capture
    r = _cli("frame", SCENE, "-o", tmp_path / "f.exr", "--times", "5,9", "-D", "views_px=120")
    assert r.returncode == 0, r.stderr
    write_exr(str(tmp_path / "f5.exr"), {"Y": read_exr(str(tmp_path / "f_0000.exr"))[0]["Y"]})   # a camera's frame
    truth = np.log(np.maximum(read_exr(str(tmp_path / "f_0001.exr"))[0]["Y"], 1e-3))
    lit = truth > np.log(0.05)
    errors = {}
    for name, extra in (("placed", ["--start-time", "5"]), ("at the start", [])):
        out = tmp_path / name.replace(" ", "_")
        r = _cli("reconstruct", d / "rec.aedat4", "-o", out, "--contrast", "0.2", "--start-frame", tmp_path / "f5.exr",
                 "--times", "9", *extra)
        assert r.returncode == 0, r.stderr
        log_frame = np.log(read_exr(str(out / "frame_0000.exr"))[0]["Y"])     # the EXR holds exp(log intensity)
        errors[name] = float(np.mean(np.abs(log_frame - truth)[lit]))
    assert errors["placed"] < 0.12 and errors["placed"] < 0.5 * errors["at the start"], errors   # 0.074, 0.374
    r = _cli("reconstruct", d / "rec.aedat4", "-o", tmp_path / "bad", "--contrast", "0.2", "--start-frame",
             tmp_path / "f5.exr", "--start-time", "5", "--times", "4,9")
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and "4.000 ms is before --start-time 5.000 ms" in err[0], err
    r = _cli("reconstruct", d / "rec.aedat4", "-o", tmp_path / "hp", "--contrast", "0.2", "--method", "highpass",
             "--start-frame", tmp_path / "f5.exr", "--times", "9")                 # the frame was ignored
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and "--method highpass reconstructs from the events alone" in err[0]
    assert not (tmp_path / "hp").exists()


def test_the_python_path_of_a_recording(capture, tmp_path):
    """A script gets the light field the commands get (``calibration.recording``, which the commands call): the
    recording with its calibration's optics or the nominal ones as a dict, against the render with its own
    metadata, view for view; the calibration's kaleidoscope part is applied (and said); what is missing or
    would be ignored is refused in Python's spelling."""
    from mitsuba_eventfield import calibration
    d, events = capture
    r = _cli("calibrate", "kaleidoscope", d / "bare.exr", "--optics", d / "nominal.json", "-o", tmp_path / "k.json")
    assert r.returncode == 0, r.stderr
    cal = calibration.load_calibration(str(tmp_path / "k.json"))
    recording = ef.read_events(str(d / "rec.aedat4"))
    reference = ef.lightfield.from_events(events)
    from_cal = calibration.calibrated_lightfield(calibration.with_optics(recording, calibration=cal), cal,
                                                 c_on=0.2, c_off=0.2)
    from_path = calibration.calibrated_lightfield(calibration.with_optics(recording, calibration=str(tmp_path /
                                                                                                      "k.json")),
                                                  str(tmp_path / "k.json"), c_on=0.2, c_off=0.2)
    nominal = ef.lightfield.from_events(calibration.with_optics(recording, optics=NOMINAL), c_on=0.2, c_off=0.2)
    assert reference.views.std() > 0.01
    for lf in (from_cal, from_path, nominal):
        assert np.array_equal(lf.views, reference.views) and np.array_equal(lf.positions, reference.positions)
    assert from_cal.meta["calibrated"] == ["kaleidoscope"] and not nominal.meta.get("calibrated")
    # with a start frame: the recording starts at its first event, whose microsecond's events are integrated
    # as the render's (which starts at 0) are; they were taken as already in the frame
    log_start = np.log(np.maximum(read_exr(str(d / "bare.exr"))[0]["Y"], 1e-3))
    assert recording.start_us == recording.t[0] > 0 and np.count_nonzero(recording.t == recording.t[0]) > 0
    framed = [ef.lightfield.from_events(s, log_start=log_start, **kw) for s, kw in (
        (calibration.with_optics(recording, optics=NOMINAL), dict(c_on=0.2, c_off=0.2)), (events, {}))]
    assert np.array_equal(framed[0].views, framed[1].views)
    assert "optics" not in recording.meta                     # the caller's stream is left as it was
    with pytest.raises(ef.EventFieldError, match=r"^the events: the recording carries no optics .*: pass "
                                                 r"calibration= \(a calibration file made for its set-up\) or optics= "
                                                 r"FILE\.json or a dict \(the set-up's nominal light-field optics\)$"):
        calibration.with_optics(recording)
    with pytest.raises(ef.EventFieldError, match=r"carries its own \(kaleidoscope\) optics; optics= is for a camera"):
        calibration.with_optics(events, optics=NOMINAL)
    with pytest.raises(ef.EventFieldError, match=r"^optics= and calibration=: give one"):
        calibration.with_optics(recording, optics=NOMINAL, calibration=cal)
    with pytest.raises(ef.ConfigError, match=r"^calibrated_lightfield: events: expected an EventStream .* got "
                                             r"LightField$"):
        calibration.calibrated_lightfield(reference, cal)
    with pytest.raises(ef.EventFieldError, match=r"^optics: tube_width = 'wide': expected a finite number"):
        calibration.with_optics(recording, optics=dict(NOMINAL, tube_width="wide"))
    other = json.load(open(tmp_path / "k.json"))
    other["kaleidoscope"]["optics"]["focus_distance"] = 2.0                  # made for another set-up
    (tmp_path / "other.json").write_text(json.dumps(other))
    with pytest.raises(ef.EventFieldError, match=r"other\.json: .*focus_distance"):       # before any work
        calibration.calibrated_lightfield(calibration.with_optics(recording, calibration=cal),
                                          str(tmp_path / "other.json"), c_on=0.2, c_off=0.2)


CROP = (25, 10, 120, 120)           # where the tube's 120x120 image lies on a 160x140 sensor
WINDOW = ",".join(map(str, CROP))


@pytest.fixture(scope="module")
def larger_sensor(capture, tmp_path_factory):
    """The render's events and bare frame placed at CROP on a 160x140 sensor (grey around the tube image), as a
    camera whose sensor is larger than the tube's image records them, and the calibration made with the
    window (``calibrate kaleidoscope --crop``)."""
    d, events = capture
    t = tmp_path_factory.mktemp("larger_sensor")
    x0, y0, w, h = CROP
    ef.write_events(str(t / "big.aedat4"), ef.EventStream(events.x + x0, events.y + y0, events.t, events.p, 160, 140,
                                                          {}))
    frame = np.full((140, 160), 0.3, np.float32)
    frame[y0:y0 + h, x0:x0 + w] = read_exr(str(d / "bare.exr"))[0]["Y"]
    write_exr(str(t / "big.exr"), {"Y": frame})
    r = _cli("calibrate", "kaleidoscope", t / "big.exr", "--optics", d / "nominal.json", "--crop", WINDOW,
             "-o", t / "big.json")
    assert r.returncode == 0 and "3x3 views of 40x40 px" in r.stdout and "eventfield: warning" not in r.stderr, \
        r.stderr
    return d, events, t


def test_a_tube_image_on_part_of_a_larger_sensor(larger_sensor, tmp_path):
    """``--crop`` (``EventStream.crop``): calibrated and refocused with the window, the larger sensor's
    recording gives the render's own refocused image value for value, in Python too; a frame of the whole
    sensor is cut as the events were; the calibration and the outputs record the window."""
    d, events, t = larger_sensor
    assert json.load(open(t / "big.json"))["kaleidoscope"]["crop"] == {"window": list(CROP), "sensor": [160, 140]}
    r = _cli("refocus", t / "big.aedat4", "--calibration", t / "big.json", "--contrast", "0.2", "--crop", WINDOW,
             "--depth", "1.0", "-o", tmp_path / "rf.png")
    assert r.returncode == 0, r.stderr
    reference = ef.refocus(ef.lightfield.from_events(events), 1.0)
    image, meta = read_exr(str(tmp_path / "rf.exr"))
    assert reference.std() > 0.01 and np.allclose(image["Y"], reference, rtol=1e-6, atol=1e-7)
    assert meta["optics"]["design"] == "kaleidoscope" and meta["crop"] == {"window": list(CROP), "sensor": [160, 140]}
    from mitsuba_eventfield import calibration           # in Python: the same window, the same light field
    cut = ef.read_events(str(t / "big.aedat4")).crop(*CROP)
    assert cut.equals(events) and cut.meta["crop"] == {"window": list(CROP), "sensor": [160, 140]}
    lf = calibration.calibrated_lightfield(calibration.with_optics(cut, calibration=str(t / "big.json")),
                                           str(t / "big.json"), c_on=0.2, c_off=0.2)
    assert np.array_equal(lf.views, ef.lightfield.from_events(events).views)
    r = _cli("reconstruct", t / "big.aedat4", "--crop", WINDOW, "--contrast", "0.2", "--start-frame",
             t / "big.exr", "--times", "9", "-o", tmp_path / "rc")
    r0 = _cli("reconstruct", d / "rec.aedat4", "--contrast", "0.2", "--start-frame", d / "bare.exr", "--times", "9",
              "-o", tmp_path / "rc0")
    assert r.returncode == 0 and r0.returncode == 0, r.stderr + r0.stderr
    assert np.array_equal(*(read_exr(str(tmp_path / n / "frame_0000.exr"))[0]["Y"] for n in ("rc", "rc0")))


def test_a_calibration_on_part_of_a_sensor_says_what_is_wrong(larger_sensor, tmp_path):
    """A window one pixel off is warned about (its tiles are not the image's mirror seams: symmetry 1.00 a
    pixel to the left); the whole frame as the film, a window not of 3x3 tiles and an n from --optics that is
    not the tube's are refused in one line naming --crop or --optics, and write nothing."""
    import re
    d, _, t = larger_sensor
    r = _cli("calibrate", "kaleidoscope", t / "big.exr", "--optics", d / "nominal.json", "--crop", "26,10,120,120",
             "-o", tmp_path / "off.json")
    said = [line for line in r.stderr.splitlines() if line.startswith("eventfield: warning")]
    assert r.returncode == 0 and len(said) == 1 and f"{t / 'big.exr'}: the window 26,10,120,120: its 3x3 tiles' " \
        "edges are not the image's mirror seams (symmetry along x " in said[0] and " 1 px left)" in said[0], said
    (tmp_path / "n5.json").write_text(json.dumps(dict(NOMINAL, relay_distance=0.015)))     # a 5x5 tube
    for args, message in ((["--optics", d / "nominal.json"], r"film 160x140 .* \(the film: all 160x140 of .*big\.exr; "
                                                            r"where the tube's image covers part of the sensor, pass "
                                                            r"--crop X,Y,W,H\)$"),
                          (["--optics", d / "nominal.json", "--crop", "25,10,121,121"],
                           r"\(the film: the --crop window 25,10,121,121, 121x121\)$"),
                          (["--optics", tmp_path / "n5.json", "--crop", WINDOW],
                           r"big\.exr: not a kaleidoscope frame: .* \(its 5x5 views are those of --optics "
                           r".*n5\.json: the tube's\?\)$")):
        r = _cli("calibrate", "kaleidoscope", t / "big.exr", *args, "-o", tmp_path / "no.json")
        err = r.stderr.strip().splitlines()
        assert r.returncode == 2 and len(err) == 1 and re.search(message, err[0]), err
        assert not (tmp_path / "no.json").exists()


def test_a_recording_cut_otherwise_than_its_calibration_is_refused(larger_sensor, tmp_path):
    """The calibration records the window: a recording of the whole sensor is told it, one cut elsewhere, or
    recorded on another sensor, is refused, and a window outside the sensor too; a stream with its own optics
    (they describe its whole film) refuses a crop. Each in one line, writing nothing."""
    import re
    d, events, t = larger_sensor
    x0, y0, _, _ = CROP
    ef.write_events(str(tmp_path / "other.aedat4"),                                       # another sensor
                    ef.EventStream(events.x + x0, events.y + y0, events.t, events.p, 240, 180, {}))
    for source, args, message in (
            ("big", [], r"big\.json: made from the window 25,10,120,120 of the 160x140 sensor: cut .*big\.aedat4 to "
                        r"it \(--crop 25,10,120,120; in Python, events\.crop\(\*window\)\)$"),
            ("big", ["--crop", "20,10,120,120"], r"big\.json: made from the window 25,10,120,120 of the sensor; "
                                                 r".*big\.aedat4 is cut to 20,10,120,120$"),
            ("big", ["--crop", "100,10,120,120"], r"^eventfield: error: --crop = 100,10,120,120: the window .* must "
                                                  r"lie inside the 160x140 sensor"),
            ("other", ["--crop", WINDOW], r"big\.json: made on a 160x140 sensor \(the window 25,10,120,120\); "
                                          r".*other\.aedat4 was recorded on a 240x180 one$")):
        path = t / "big.aedat4" if source == "big" else tmp_path / "other.aedat4"
        r = _cli("refocus", path, "--calibration", t / "big.json", "--contrast", "0.2", "--depth", "1", "-o",
                 tmp_path / "bad.png", *args)
        err = r.stderr.strip().splitlines()
        assert r.returncode == 2 and len(err) == 1 and re.search(message, err[0]), err
    r = _cli("refocus", d / "rec.h5", "--crop", "0,0,60,60", "--depth", "1", "-o", tmp_path / "bad.png")
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and "rec.h5: the stream carries kaleidoscope optics, which describe " \
        "its whole 120x120 film" in err[0], err
    assert not (tmp_path / "bad.png").exists()


def test_a_target_that_is_not_flat_is_named_in_the_warning(tmp_path):
    """scenes/falling (posts, block and wall at 0.55, 0.8 and 1.4 m) as the target: the calibration is written,
    with one warning line naming the frame, after the checks (the quarters' spread, 0.36-0.40 px at 120 px
    views, against a flat card's 0.00)."""
    falling = os.path.join(ROOT, "scenes", "falling", "falling.xml")
    r = _cli("frame", falling, "-o", tmp_path / "falling.exr", "-D", "views_px=120")
    assert r.returncode == 0, r.stderr
    r = _cli("calibrate", "kaleidoscope", tmp_path / "falling.exr", "-o", tmp_path / "k.json")
    err = [line for line in r.stderr.strip().splitlines() if "WARN" not in line]
    assert r.returncode == 0 and (tmp_path / "k.json").exists(), r.stderr
    assert len(err) == 1 and err[0].startswith(f"eventfield: warning: {tmp_path / 'falling.exr'}: kaleidoscope "
                                               "calibration: view (") and "the target is not flat" in err[0], err
    spread = json.load(open(tmp_path / "k.json"))["kaleidoscope"]["quality"]["max_quarter_spread_px"]
    assert 0.25 < spread < 0.6
