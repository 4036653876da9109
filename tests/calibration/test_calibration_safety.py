"""Calibrations that refuse what is wrong: impossible fits, files made for other optics, old files, and
kaleidoscope calibration of a frame that has no tiles."""
import json
import os

import numpy as np
import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield import cli
from mitsuba_eventfield.apps import scanrate
from mitsuba_eventfield.calibration import (CalibrationError, PatchTrack, check_optics, fit_depth, fit_tracks,
                                            galvo_scale_limit, load_calibration, optics_difference, optics_record,
                                            register, same_optics, save_calibration)
from mitsuba_eventfield.images import write_exr
from mitsuba_eventfield.optics import galvo as galvo_optics

GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")
RUNNER = os.path.join(ROOT, "scenes", "runner", "runner.xml")
KALEIDO = os.path.join(ROOT, "scenes", "moving_grid", "kaleidoscope.xml")
W, H, FREQ = 64, 48, 250.0
Z = np.array([0.4, 0.7, 1.0, 1.6, 2.5])          # calibration depths (m)


def _exact_scales(pivot, width=W, fov=40.0):
    """Curve scales of an LED at the depths Z through a galvo with this pivot (S = 2 f (1 - pivot / z))."""
    return 2 * galvo_optics.focal_length_px(width, fov) * (1 - pivot / Z)


def cli_run(capsys, *args):
    """The CLI in this process: (exit status, stderr lines)."""
    code = cli.main([str(a) for a in args])
    return code, [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]


@pytest.fixture(scope="module")
def galvo_stream(tmp_path_factory):
    """One scan period of the static galvo scene at 64x48, and its optics record."""
    d = tmp_path_factory.mktemp("safety")
    scene = ef.load_scene(GALVO, width=W, height=H, amplitude=0.5)
    events = ef.render_events(scene, 1 / FREQ, steps=32, threshold=0.1)
    path = str(d / "g.h5")
    ef.write_events(path, events)
    return path, optics_record(events.meta["optics"], events.width, events.height)


def _depth_file(path, record):
    """A depth calibration from exact geometry, saved as made for ``record``."""
    save_calibration(str(path), record, depth=fit_depth(Z, _exact_scales(0.1)))
    return str(path)


# --- fits that the geometry cannot produce ------------------------------------------------------------------
@pytest.mark.parametrize("edit, message", [
    (lambda d: d.update(inverse=[d["inverse"][0], -d["inverse"][1]]), r"inverse: scales along x: the fit puts the "
                                                                      r"pivot at -0\.1 \(<= 0\)"),
    (lambda d: d.update(inverse_y=[-1.0, 5.0]), r"inverse_y: scales along y: the fitted scale at infinity is -1"),
    (lambda d: d.update(inverse=["a", 1]), r"inverse = \('a', 1\): expected \(p, q\), two numbers"),
    (lambda d: d.update(depths=[0.5]), r"depths = \[0\.5\]: expected three or more depths > 0"),
])
def test_a_hand_edited_depth_model_is_refused_as_the_fit_would(galvo_stream, tmp_path, edit, message):
    """A depth calibration file is read by the fit's own rules: a pivot behind the camera (which inverts depth
    maps: one was loaded and made a map of 0.76 m), a negative scale at infinity, a malformed model, too few
    depths; one line naming the file."""
    from conftest import refused_when_edited
    _, record = galvo_stream
    refused_when_edited(_depth_file(tmp_path / "d.json", record), "depth", edit, message)


def test_led_depths_in_another_unit_are_warned_about():
    """LED captures at depths given in centimetres for optics in metres fit cleanly (the model is the same up
    to scale) to a pivot 100 times the optics' mirror distance: warned, naming the unit; in metres, quiet."""
    import warnings
    from types import SimpleNamespace

    from mitsuba_eventfield.calibration import fit_depth_from_tracks
    geometry = galvo_optics.GalvoGeometry(W, H, galvo_optics.focal_length_px(W, 40.0), 0.1, 0.1)
    scales = _exact_scales(0.1)
    fits = [SimpleNamespace(patches=[(W / 2, H / 2)], scale_px_per_rad=(s, s)) for s in scales]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert fit_depth_from_tracks(Z, fits, geometry).pivot == pytest.approx(0.1)
    with pytest.warns(UserWarning, match=r"the fitted pivot, 10, is 100 times the optics' mirror distance 0\.1: are "
                                         r"the capture depths in the optics' unit \(metres\)\?"):
        fit_depth_from_tracks(100 * Z, fits, geometry)


def test_negative_pivot_fit_refused():
    assert fit_depth(Z, _exact_scales(0.1)).pivot == pytest.approx(0.1)
    # scales that shrink with depth: the fit puts the pivot behind the camera (-0.10 m for a nominal 0.1 m)
    with pytest.raises(CalibrationError, match="pivot at -0.1 .*inverted"):
        fit_depth(Z, _exact_scales(-0.1))
    # also on the y scales alone
    with pytest.raises(CalibrationError, match="scales along y: the fit puts the pivot at -0.11"):
        fit_depth(Z, _exact_scales(0.1), scales_y=_exact_scales(-0.11))


def test_inverted_model_refused():
    # a pivot beyond the nearest calibration depth: the scale changes sign inside the calibrated range
    with pytest.raises(CalibrationError, match="beyond the nearest calibration depth 0.4"):
        fit_depth(Z, _exact_scales(0.6))
    # a negative scale at infinity
    with pytest.raises(CalibrationError, match="scale at infinity"):
        fit_depth(Z, -_exact_scales(0.1))
    # non-finite or too few depths
    with pytest.raises(CalibrationError, match="finite"):
        fit_depth([0.4, 0.7, np.inf], [100.0, 120.0, 130.0])
    with pytest.raises(CalibrationError, match="at least 3 distinct depths"):
        fit_depth([0.4, 0.7], [100.0, 120.0])
    # two captures' depths swapped: a positive pivot in front of the nearest depth, but not pinned by the data
    # (0.061 +- 0.046 here; the right labels 0.0996 +- 0.0007); it was written, and depth maps with it had no
    # confident pixel
    noisy = _exact_scales(0.1) + np.random.default_rng(0).normal(0, 0.5, len(Z))
    assert fit_depth(Z, noisy).std["pivot"] < 0.01
    with pytest.raises(CalibrationError, match=r"scales along x: the fit does not pin the pivot \(0\.06\d* \+- "
                                               r"0\.046, rms 10\.5 px/rad\): check that each capture is given its own"):
        fit_depth(Z[[1, 0, 2, 3, 4]], noisy)
    with pytest.raises(CalibrationError, match="scales along y: the fit does not pin the pivot"):
        fit_depth(Z, noisy, scales_y=noisy[[1, 0, 2, 3, 4]])


def test_depth_fit_records_its_quality(tmp_path, galvo_stream):
    _, record = galvo_stream
    rng = np.random.default_rng(3)
    dc = fit_depth(Z, _exact_scales(0.1) + rng.normal(0, 0.5, len(Z)))
    assert 0 < dc.std["pivot"] < 0.01 and dc.quality["samples"] == 5
    data = json.loads(open(_depth_file(tmp_path / "c.json", record)).read())
    assert data["version"] == 2 and data["depth"]["optics"] == record
    assert data["depth"]["quality"]["samples"] == 5 and "pivot_std" in data["depth"]["quality"]


def test_galvo_fit_with_absurd_radius_refused(galvo_stream):
    _, record = galvo_stream
    curve = ef.make_curve("circle", frequency=FREQ, amplitude=0.5)
    times = np.arange(16) / 16 / FREQ

    def track(scale):
        ax, ay = curve.angles(times + 0.3 / FREQ)
        a0 = curve.angles(0.3 / FREQ)
        return PatchTrack((30, 20), np.stack([scale * (ax - a0[0]), scale * (ay - a0[1])], -1), np.ones(16))
    f = galvo_optics.focal_length_px(W, 40.0)
    limit = galvo_scale_limit(record)
    assert 2 * f < limit < 4 * f
    assert fit_tracks([track(2 * f)], times, curve, scale_limit=limit).scale_px_per_rad[0] == pytest.approx(2 * f)
    with pytest.raises(CalibrationError, match="absurd curve size"):
        fit_tracks([track(20 * f)], times, curve, scale_limit=limit)


# --- calibration files and the optics they were made for ----------------------------------------------------
def test_optics_comparison(galvo_stream):
    _, rec = galvo_stream
    other = lambda **kw: dict(rec, **kw)  # noqa: E731
    assert optics_difference(rec, other(scan=dict(rec["scan"], phase=123.0))) is None       # what is measured
    assert optics_difference(rec, other(fov_x_deg=rec["fov_x_deg"] * (1 + 1e-6))) is None   # float32 rounding
    assert optics_difference(rec, other(mirror_distance=0.2)) == "mirror_distance 0.1 vs 0.2"
    assert optics_difference(rec, other(scan=dict(rec["scan"], amplitude=0.6))) == "scan amplitude 0.5 vs 0.6"
    assert optics_difference(rec, other(scan=dict(rec["scan"], frequency=200.0))).startswith("scan frequency")
    assert optics_difference(rec, other(width=96)) == "width 64 vs 96"
    # a Lissajous figure: a common time shift is a phase; another relative phase is another figure
    liss = {"curve": "lissajous", "freq_x": 300.0, "freq_y": 200.0, "amplitude_x": 0.2, "amplitude_y": 0.2,
            "phase_x": 90.0, "phase_y": 0.0}
    tau = 0.37e-3
    shifted = dict(liss, phase_x=90.0 + 360 * 300 * tau, phase_y=360 * 200 * tau)
    assert optics_difference(other(scan=liss), other(scan=shifted)) is None
    assert "Lissajous" in optics_difference(other(scan=liss), other(scan=dict(liss, phase_y=30.0)))
    # a kaleidoscope calibration from a bare frame knows its size and n: the lens is compared where both know it
    bare = optics_record({"design": "kaleidoscope", "n": 3}, 120, 120)
    stream = optics_record({"design": "kaleidoscope", "n": 3, "focal_length": 0.05, "tube": [0.012] * 3}, 120, 120)
    assert optics_difference(bare, stream) is None
    assert optics_difference(bare, dict(stream, n=5)) == "n 3 vs 5"
    with pytest.raises(ef.EventFieldError, match="b.h5: made with other optics than a.h5: mirror_distance"):
        same_optics({"a.h5": rec, "b.h5": other(mirror_distance=0.2)})


@pytest.mark.parametrize("change, message", [
    ({"mirror_distance": 0.2}, "mirror_distance 0.2 vs 0.1"),
    ({"scan": {"amplitude": 1.0}}, "scan amplitude 1.0 vs 0.5"),
    ({"width": 128, "height": 96}, "width 128 vs 64"),
])
def test_refocus_and_depth_refuse_a_file_for_other_optics(galvo_stream, tmp_path, capsys, change, message):
    events, rec = galvo_stream
    made_for = dict(rec, **{k: v for k, v in change.items() if k != "scan"})
    made_for["scan"] = dict(rec["scan"], **change.get("scan", {}))
    cal = _depth_file(tmp_path / "other.json", made_for)
    for command in (["refocus", events, "-o", tmp_path / "rf.png", "--depth", "1", "--views", "8"],
                    ["depth", events, "-o", tmp_path / "d.png", "--near", "0.3", "--far", "4", "--views", "8",
                     "--planes", "4"]):
        code, err = cli_run(capsys, *command, "--calibration", cal)
        assert code == 2 and len(err) == 1, err
        assert cal in err[0] and "made for other optics" in err[0] and message in err[0], err
        assert not any(p.suffix in (".png", ".exr") for p in tmp_path.iterdir())
    # the same file made for this stream's optics is used
    code, err = cli_run(capsys, "depth", events, "-o", tmp_path / "ok.png", "--near", "0.3", "--far", "4",
                        "--views", "8", "--planes", "4", "--calibration", _depth_file(tmp_path / "same.json", rec))
    assert code == 0, err


def test_old_format_file_refused(galvo_stream, tmp_path, capsys):
    events, _ = galvo_stream
    dc = fit_depth(Z, _exact_scales(0.1))
    old = {k: v for k, v in dc.as_dict().items() if k not in ("kind", "std", "optics", "quality")}
    path = tmp_path / "v1.json"
    path.write_text(json.dumps({"format": "mitsuba-eventfield calibration", "version": 1, "depth": old}))
    with pytest.raises(ef.EventFieldError, match="version 1 .*records no optics.*re-run eventfield calibrate"):
        load_calibration(str(path))
    code, err = cli_run(capsys, "depth", events, "-o", tmp_path / "d.png", "--near", "0.3", "--far", "4",
                        "--views", "8", "--planes", "4", "--calibration", path)
    assert code == 2 and len(err) == 1 and "version 1" in err[0] and "re-run eventfield calibrate" in err[0], err
    # a version 2 file whose part lost its optics (edited by hand) is refused too
    path.write_text(json.dumps({"format": "mitsuba-eventfield calibration", "version": 2, "depth": old}))
    with pytest.raises(ef.EventFieldError, match="depth calibration records no optics"):
        load_calibration(str(path))


def test_one_file_holds_one_setup_per_design(galvo_stream, tmp_path):
    _, rec = galvo_stream
    from mitsuba_eventfield.calibration import GalvoCalibration
    path = _depth_file(tmp_path / "c.json", rec)
    galvo = GalvoCalibration(curve=rec["scan"], t_first=0.0, tau0=0.0, phase_deg=0.0, scale_px_per_rad=(1.0, 1.0))
    with pytest.raises(ef.EventFieldError, match="already holds a depth calibration made for other optics "
                                                 r"\(fov_x_deg 40.0 vs 50.0"):
        save_calibration(path, dict(rec, fov_x_deg=50.0), galvo=galvo)
    save_calibration(path, rec, galvo=galvo)                    # the same set-up extends the file
    cal = load_calibration(path)
    assert sorted(cal) == ["depth", "galvo"] and check_optics(cal, rec) == ("galvo", "depth")
    with pytest.raises(ef.EventFieldError, match="holds no calibration for kaleidoscope optics"):
        check_optics(cal, optics_record({"design": "kaleidoscope", "n": 3}, 120, 120))


def test_scanrate_refuses_a_calibration_for_other_optics(tmp_path, capsys):
    defines = {"width": 64, "height": 48}
    scene = ef.load_scene(RUNNER, **defines)
    rec = optics_record(scene.sensor.optics_metadata(), 64, 48)
    other = dict(rec, scan=dict(rec["scan"], frequency=2 * rec["scan"]["frequency"]))     # another scan rate
    dc = fit_depth(Z, _exact_scales(0.2))
    dc.optics = other
    with pytest.raises(ef.EventFieldError, match="depth calibration was made for other optics: scan frequency"):
        scanrate.run(RUNNER, defines, periods=1, views=8, calibration={"depth": dc})
    path = _depth_file(tmp_path / "other.json", dict(rec, mirror_distance=rec["mirror_distance"] / 2))
    code, err = cli_run(capsys, "scanrate-depth", RUNNER, "-o", tmp_path / "sr", "--periods", "1", "--views", "8",
                        "-D", "width=64", "-D", "height=48", "--calibration", path)
    assert code == 2 and len(err) == 1 and path in err[0] and "mirror_distance" in err[0], err
    assert not (tmp_path / "sr").exists()


# --- kaleidoscope: no tiles, no calibration -----------------------------------------------------------------
def test_kaleidoscope_calibration_refuses_a_galvo_frame(tmp_path, capsys):
    galvo = ef.render_frames(ef.load_scene(GALVO, width=96, height=72), [0.0], log=False)[0]
    write_exr(str(tmp_path / "galvo.exr"), {"Y": galvo})
    out = tmp_path / "k.json"
    code, err = cli_run(capsys, "calibrate", "kaleidoscope", tmp_path / "galvo.exr", "-o", out)
    assert code == 2 and len(err) == 1 and "not a kaleidoscope frame" in err[0], err
    assert not out.exists()
    rng = np.random.default_rng(0)
    for frame in (rng.normal(size=(96, 96)), np.full((96, 96), 0.5)):      # noise, blank
        with pytest.raises(CalibrationError):
            register(frame)
    # a kaleidoscope frame of a bundled scene still calibrates, and records its optics and fit quality
    kaleido = ef.render_frames(ef.load_scene(KALEIDO, views_px=120), [0.0], log=False)[0]
    write_exr(str(tmp_path / "kaleido.exr"), {"Y": kaleido})
    code, err = cli_run(capsys, "calibrate", "kaleidoscope", tmp_path / "kaleido.exr", "-o", out)
    assert code == 0, err
    part = json.loads(out.read_text())["kaleidoscope"]
    assert part["n"] == 3 and part["optics"] == {"design": "kaleidoscope", "width": 120, "height": 120, "n": 3}
    assert part["quality"]["min_view_consistency"] > 0.8 and part["quality"]["samples"] == 9


def test_patches_that_do_not_move_are_refused_in_words_not_scipys():
    """A static recording (or one of too few events) tracks no displacement: the fit's initial scale was below
    its own bound, and SciPy's "Initial guess is outside of provided bounds" was the whole message."""
    curve = ef.make_curve("circle", frequency=FREQ, amplitude=0.5)
    times = np.arange(16) / 16 / FREQ
    still = PatchTrack((30, 20), np.zeros((16, 2)) + 1e-12 * np.arange(32).reshape(16, 2), np.ones(16))
    with pytest.raises(CalibrationError, match=r"the patches move by at most 3e-11 px and not along the scan"):
        fit_tracks([still], times, curve)


def made_from(calibration) -> dict:
    """A GalvoCalibration's own fields (its as_dict adds kind and quality)."""
    import dataclasses
    return {f.name: getattr(calibration, f.name) for f in dataclasses.fields(calibration)}


def test_a_galvo_calibration_warns_when_applied_to_another_capture(galvo_stream):
    """A free-running galvo's phase holds for the capture it was fitted on; the file names that capture."""
    import warnings

    from mitsuba_eventfield.calibration import GalvoCalibration
    from mitsuba_eventfield.calibration.galvo import capture_of, check_capture
    from mitsuba_eventfield.optics.scan import curve_to_dict
    events = ef.read_events(galvo_stream[0])
    fitted = GalvoCalibration(curve=curve_to_dict(ef.make_curve("circle", frequency=FREQ, amplitude=0.5)),
                              t_first=0.0, tau0=0.0, phase_deg=0.0, scale_px_per_rad=(100.0, 100.0),
                              capture=capture_of(events))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_capture(fitted, events)                                   # its own capture: no word
        fitted.capture = {}
        check_capture(fitted, events)                                   # a file from before: nothing to check
        fitted.capture = capture_of(events)
    for bad in ({"events": 3}, "abc", {"events": 1.5, "t_first_us": 0, "t_last_us": 1}):     # hand-edited files
        with pytest.raises(ef.ConfigError, match="galvo calibration: capture = "):
            GalvoCalibration(**dict(made_from(fitted), capture=bad))
    later = events.time_window(int(events.t[0]) + 1000, None)
    with pytest.warns(UserWarning, match=r"fitted on another capture \(\d+ events, .* holds for that capture only"):
        check_capture(fitted, later)


def test_a_curve_larger_than_the_optics_show_is_noted(galvo_stream):
    """The recorded amplitude 1.6 deg where the mirror moved 2: the fitted scale is 1.25x 2 f (a driver's gain);
    the note says so, and says that only the phase is applied."""
    from mitsuba_eventfield.calibration import GalvoCalibration, scale_note
    from mitsuba_eventfield.optics.scan import curve_to_dict
    record = galvo_stream[1]
    f2 = 2 * galvo_optics.focal_length_px(record["width"], record["fov_x_deg"])
    made = dict(curve=curve_to_dict(ef.make_curve("circle", frequency=FREQ, amplitude=0.5)), t_first=0.0, tau0=0.0,
                phase_deg=0.0)
    assert scale_note(GalvoCalibration(**made, scale_px_per_rad=(0.9 * f2, 0.9 * f2)), record) is None
    note = scale_note(GalvoCalibration(**made, scale_px_per_rad=(1.25 * f2, 1.24 * f2)), record)
    assert "1.25x the largest these optics show" in note and "its scale is not" in note
    # patches near the film's edge show more (the keystone, 1 + t^2): 1.06x the on-axis bound is no driver's gain
    edge = dict(made, patches=[[2.0, record["height"] / 2]])
    k = galvo_optics.GalvoGeometry(record["width"], record["height"], f2 / 2, 0.0, 0.0).field_factors(2.0)[0]
    assert k > 1.1 and scale_note(GalvoCalibration(**edge, scale_px_per_rad=(1.06 * f2, f2)), record) is None
    assert "1.25x" in scale_note(GalvoCalibration(**edge, scale_px_per_rad=(1.25 * k * f2, f2)), record)
