"""A galvo calibration reaches everything that reads a stream's optics (``calibration.calibrated_optics``): the
events-only solvers' equations too, not only the light field they return. Checked against the same stream with
its true metadata, on the bundled offaxis_cards (two cards at 0.5 and 1.2 m), scored against Mitsuba's depth."""
import copy
import math
import os

import numpy as np
import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield.calibration import (GalvoCalibration, apply_to_lightfield, calibrated_optics, fit_depth,
                                            optics_record, save_calibration)
from mitsuba_eventfield.cli.main import main as cli
from mitsuba_eventfield.evaluation import truth
from mitsuba_eventfield.images import read_exr
from mitsuba_eventfield.lightfield.model import LightField, galvo_paraxial_disparity
from mitsuba_eventfield.optics.galvo import GalvoGeometry, focal_length_px
from mitsuba_eventfield.optics.scan import curve_from_dict

CARDS = os.path.join(ROOT, "scenes", "offaxis_cards", "offaxis_cards.xml")
W, H = 96, 72
LAG_S = 0.0025          # the mirror a quarter period (90 degrees of the 100 Hz circle) behind its command


def _lagging(events, lag):
    """The stream as a rig whose controller reports the command while the mirror lags by ``lag`` seconds: its
    metadata's scan runs ``lag`` ahead of the views, and the galvo calibration that says so."""
    scan = events.meta["optics"]["scan"]
    stated = dict(scan, phase=(scan["phase"] + 360.0 * scan["frequency"] * lag) % 360.0)
    meta = copy.deepcopy(events.meta)
    meta["optics"]["scan"] = stated
    recording = ef.EventStream(events.x, events.y, events.t, events.p, events.width, events.height, meta)
    record = optics_record(meta["optics"], W, H)
    # the first frame of the calibration's captures 3 ms into the clock, where the mirror was at curve time 3 ms
    # less the lag (t_first != 0 tells tau0 - t_first from its sign errors)
    galvo = GalvoCalibration(curve=stated, t_first=0.003, tau0=0.003 - lag, phase_deg=0.0,
                             scale_px_per_rad=(1.0, 1.0), optics=record)
    return recording, record, galvo


@pytest.fixture(scope="module")
def cards(tmp_path_factory):
    scene = ef.load_scene(CARDS, width=W, height=H)
    events = ef.render_events(scene, 0.01, steps=120)
    z = truth.truth_depth(scene, 0.0)
    return events, z, tmp_path_factory.mktemp("calibrated")


def test_calibrated_optics_place_the_views_where_the_calibration_does(cards):
    """The scan record's ``time_offset`` gives the calibration's view angles, ``calibrated_geometry`` its
    pivots and gains; a light field made from the calibrated optics equals the same light field calibrated
    afterwards (``apply_to_lightfield``)."""
    events, _, _ = cards
    recording, record, galvo = _lagging(events, LAG_S)
    f = focal_length_px(W, 40.0)
    z = np.array([0.4, 0.6, 1.0, 2.0])
    depth = fit_depth(z, 0.98 * 2 * f * (1 - 0.15 / z), 2 * f * (1 - 0.17 / z))
    depth.optics = record
    cal = {"galvo": galvo, "depth": depth}
    placed = calibrated_optics(cal, recording.meta["optics"], W, H)
    t = np.linspace(0.0, 0.02, 57)
    assert np.allclose(curve_from_dict(placed["scan"]).angles(t), galvo.view_angles(t), atol=1e-12)
    geometry = GalvoGeometry.from_optics(placed, W, H)
    want = depth.geometry(GalvoGeometry.from_optics(recording.meta["optics"], W, H))
    fields = ("focal_px", "pivot_x", "pivot_y", "gain_x", "gain_y")
    assert [getattr(geometry, k) for k in fields] == pytest.approx([getattr(want, k) for k in fields], rel=1e-12)
    assert (geometry.pivot_x, geometry.pivot_y, geometry.gain_x, geometry.gain_y) == pytest.approx(
        (0.15, 0.17, 0.98, 1.0), rel=1e-6)                      # the fits' own: S = 2 f g (1 - pivot / z) per axis
    assert placed["calibrated"] == ["galvo", "depth"]
    # the events' angles: the calibration's views as what the mirror did, the record's own scan as commanded
    stream = ef.EventStream(*(np.zeros(3, d) for d in (np.uint16, np.uint16)), np.array([0, 2500, 7000]),
                            np.ones(3, np.int8), W, H, {"optics": placed})
    assert np.allclose(np.stack(stream.scan_angles()), np.stack(galvo.view_angles(stream.t * 1e-6)), atol=1e-12)
    command = {k: v for k, v in recording.meta["optics"]["scan"].items() if k not in ("bandwidth_hz", "damping")}
    commanded = curve_from_dict(command).angles(stream.t * 1e-6)
    assert np.allclose(np.stack(stream.scan_angles(actual=False)), np.stack(commanded), atol=1e-12)
    times = (np.arange(8) + 0.5) / 800
    frames = np.zeros((8, H, W))
    before = apply_to_lightfield(ef.from_galvo(frames, times, recording.meta["optics"]), cal, record)
    made = ef.from_galvo(frames, times, placed)
    assert np.allclose(made.positions, before.positions, atol=1e-12) and made.galvo == before.galvo
    assert made.meta["calibrated"] == ["depth", "galvo"] == before.meta["calibrated"]
    # without its geometry (a shift-invariant galvo light field) the depth calibration is the paraxial model of
    # the calibrated pivots and gains, not reported applied while the nominal model stays
    bare = ef.from_galvo(frames, times, recording.meta["optics"])
    bare = LightField(bare.views, bare.positions, bare.times, bare.disparity, "galvo", bare.meta)
    flat = apply_to_lightfield(bare, cal, record)
    assert flat.galvo is None and flat.meta["calibrated"] == ["depth", "galvo"]
    assert flat.alpha(0.5) == pytest.approx(galvo_paraxial_disparity(geometry).alpha(0.5), rel=1e-12)
    assert flat.alpha(0.5) != pytest.approx(bare.alpha(0.5), rel=1e-3)
    with pytest.raises(ef.EventFieldError, match="already calibrated"):
        calibrated_optics(cal, placed, W, H)
    with pytest.raises(ef.EventFieldError, match="already calibrated"):       # nor checked, nor fitted to
        optics_record(placed, W, H)


def test_a_scan_table_keeps_its_own_time_offset_under_a_calibration():
    """A tabulated scan (raster) keeps a time shift in its record; a calibration's phase adds to it (a review
    found it replaced: 0.015 rad off) and the views equal ``GalvoCalibration.view_angles``."""
    from mitsuba_eventfield.optics.scan import curve_to_dict, make_curve, shifted
    table = curve_to_dict(shifted(make_curve("raster", frequency=100.0, lines=4), 0.0011))
    assert table["time_offset"] == pytest.approx(0.0011)
    optics = {"design": "galvo", "scan": table, "fov_x_deg": 40.0, "mirror_distance": 0.2, "mirror_separation": 0.01}
    galvo = GalvoCalibration(curve=table, t_first=0.002, tau0=0.0057, phase_deg=0.0, scale_px_per_rad=(1.0, 1.0),
                             optics=optics_record(optics, W, H))
    placed = calibrated_optics({"galvo": galvo}, optics, W, H)
    t = np.linspace(0.0, 0.03, 301)
    assert np.allclose(curve_from_dict(placed["scan"]).angles(t), galvo.view_angles(t), atol=1e-12)


def _card_depths(path, z):
    channels, meta = read_exr(path)
    sure = channels["confidence"] >= 0.5
    out = []
    for card in ((z < 0.8), (z > 0.8) & (z < 2.0)):
        assert (card & sure).sum() > 0.9 * card.sum()
        out.append(float(np.median(channels["depth"][card & sure])))
    return out, meta


def test_the_events_only_solver_reads_a_lagging_mirrors_calibration(cards, capsys):
    """``eventfield depth`` of a recording whose mirror lags its command by a quarter period, with the galvo
    calibration that measured the lag: the per-period solver now solves with the calibrated views and the map
    equals the one from the true metadata (measured: 0.499 / 1.196 m both). When the calibration only placed
    the finished light field, the solve used the commanded phase: 0.504 / 1.214 m. Without it, 1.11 / 1.09 m."""
    events, z, tmp = cards
    recording, record, galvo = _lagging(events, LAG_S)
    ef.write_events(str(tmp / "true.h5"), events)
    ef.write_events(str(tmp / "lagging.h5"), recording)
    save_calibration(str(tmp / "cal.json"), record, galvo=galvo)
    common = ["--near", "0.3", "--far", "3"]
    assert cli(["depth", str(tmp / "true.h5"), "-o", str(tmp / "true.png"), *common]) == 0
    capsys.readouterr()
    assert cli(["depth", str(tmp / "lagging.h5"), "--calibration", str(tmp / "cal.json"), "-o",
                str(tmp / "cal.png"), *common]) == 0
    assert "; calibration applied: galvo" in capsys.readouterr().out          # the console says so too
    (true_near, true_far), _ = _card_depths(str(tmp / "true.exr"), z)
    (near, far), meta = _card_depths(str(tmp / "cal.exr"), z)
    assert abs(near / true_near - 1) < 0.002 and abs(far / true_far - 1) < 0.002
    assert abs(near / 0.5 - 1) < 0.01 and abs(far / 1.2 - 1) < 0.01
    assert meta["calibration"]["applied"] == ["galvo"]


def test_a_galvo_recording_in_python_as_on_the_command_line(cards):
    """``calibration.with_optics`` and ``calibrated_lightfield`` on a galvo camera recording (no optics) of the
    lagging rig: its light field takes the calibration's optics and its phase through the events, and its
    views sit where the true metadata puts them (the positions to 1e-9 rad; the views solved from the same
    events at those positions: equal to float32 rounding); the galvo part is said applied."""
    from mitsuba_eventfield import calibration
    events, _, tmp = cards
    recording, record, galvo = _lagging(events, LAG_S)
    save_calibration(str(tmp / "py_cal.json"), record, galvo=galvo)
    bare = ef.EventStream(events.x, events.y, events.t, events.p, W, H, {"t_start_us": events.start_us})
    cal = calibration.load_calibration(str(tmp / "py_cal.json"))
    lf = calibration.calibrated_lightfield(calibration.with_optics(bare, calibration=cal), cal, method="galvo",
                                           views=16, c_on=0.1, c_off=0.1)        # the render's threshold
    reference = ef.lightfield.from_events(events, method="galvo", views=16)
    assert lf.meta["calibrated"] == ["galvo"]
    assert np.allclose(lf.positions, reference.positions, atol=1e-9)
    assert np.allclose(lf.views, reference.views, rtol=1e-4, atol=1e-4)


def test_the_solvers_default_range_starts_from_the_calibrated_pivots(cards, monkeypatch):
    """A depth calibration moves the pivots (0.15 / 0.17 m here, nominal 0.2 / 0.21): the per-period solver's
    default range, and the nearer depth a command asks for (``nearest``), start from the calibrated ones, as
    the Python path's ``reconstruct_periods`` takes them (the command line searched from twice the nominal
    pivot, 0.42 m, before). A calibration given as a path-like is loaded; anything else is one line."""
    from pathlib import Path

    from mitsuba_eventfield import calibration
    from mitsuba_eventfield.lightfield import streams
    events, _, tmp = cards
    record = optics_record(events.meta["optics"], W, H)
    f = focal_length_px(W, 40.0)
    z = np.array([0.4, 0.6, 1.0, 2.0])
    depth = fit_depth(z, 2 * f * (1 - 0.15 / z), 2 * f * (1 - 0.17 / z))
    depth.optics = record
    save_calibration(str(tmp / "depth_cal.json"), record, depth=depth)
    asked = []
    monkeypatch.setattr(streams, "from_events", lambda ev, **kw: asked.append(kw["depth_range"]) or 1 / 0)
    for nearest, near in ((None, 0.34), (1.0, 0.34), (0.3, 0.3), (0.1, 0.17)):
        with pytest.raises(ZeroDivisionError):                # stopped where the solver would start
            calibration.calibrated_lightfield(events, Path(tmp / "depth_cal.json"), method="periods",
                                              nearest=nearest or math.inf)
        assert asked[-1] == pytest.approx((near, 1000.0), rel=1e-6), nearest
    for bad in (42, None.__class__):
        with pytest.raises(ef.ConfigError, match=r"^calibrated_lightfield: calibration: expected a calibration "
                                                 r"file's path or calibration\.load_calibration\(\.\.\.\), got "):
            calibration.calibrated_lightfield(events, bad)


def test_a_recordings_thresholds_reach_the_default_solver(cards):
    """``c_on`` / ``c_off`` given for a galvo recording (no pixel-model metadata) reach every pass of the
    default per-period solver: its light field equals the render's with the thresholds in its metadata (the
    solver's depth-from-focus pass read the metadata alone and refused the recording)."""
    from mitsuba_eventfield import calibration
    events, _, _ = cards
    optics = {k: events.meta["optics"][k] for k in ("design", "scan", "fov_x_deg", "mirror_distance",
                                                     "mirror_separation")}
    bare = ef.EventStream(events.x, events.y, events.t, events.p, W, H, {"t_start_us": events.start_us})
    recording = calibration.with_optics(bare, optics=optics)
    lf = ef.lightfield.from_events(recording, views=16, c_on=0.1, c_off=0.1)          # the render's threshold
    reference = ef.lightfield.from_events(events, views=16)
    assert lf.meta.get("inputs") == "events only" and np.allclose(lf.views, reference.views, rtol=1e-5, atol=1e-6)


def test_reconstruct_solves_a_recording_with_its_galvo_calibration(cards, capsys):
    """``reconstruct --method galvo --calibration``: a camera recording of the lagging rig (no optics) takes its
    optics and the measured lag from the calibration, and its frames equal those of the true metadata (to
    float32 rounding); the commanded phase (the lagging metadata, no calibration) gives other frames. Another
    method with a calibration is refused in one line (it reads no optics)."""
    from mitsuba_eventfield.images import read_exr
    events, _, tmp = cards
    recording, record, galvo = _lagging(events, LAG_S)
    save_calibration(str(tmp / "rc_cal.json"), record, galvo=galvo)
    bare = ef.EventStream(events.x, events.y, events.t, events.p, W, H, {"t_start_us": events.start_us})
    ef.write_events(str(tmp / "bare.h5"), bare)
    ef.write_events(str(tmp / "true_rc.h5"), events)
    ef.write_events(str(tmp / "lagging_rc.h5"), recording)
    common = ["--method", "galvo", "--times", "2"]
    assert cli(["reconstruct", str(tmp / "bare.h5"), "-o", str(tmp / "rc_cal"), "--calibration",
                str(tmp / "rc_cal.json"), "--contrast", "0.1", *common]) == 0
    out = capsys.readouterr().out
    assert "calibration applied: galvo" in out, out
    assert cli(["reconstruct", str(tmp / "true_rc.h5"), "-o", str(tmp / "rc_true"), *common]) == 0
    assert cli(["reconstruct", str(tmp / "lagging_rc.h5"), "-o", str(tmp / "rc_lag"), *common]) == 0
    (cal, meta), (true, _), (lag, _) = (read_exr(str(tmp / d / "frame_0000.exr")) for d in
                                        ("rc_cal", "rc_true", "rc_lag"))
    assert np.allclose(cal["Y"], true["Y"], rtol=1e-3, atol=1e-4)
    assert np.median(np.abs(np.log(lag["Y"] / true["Y"]))) > 10 * np.median(np.abs(np.log(cal["Y"] / true["Y"])))
    assert meta["calibration"]["applied"] == ["galvo"]
    capsys.readouterr()
    assert cli(["reconstruct", str(tmp / "bare.h5"), "-o", str(tmp / "rc_x"), "--calibration",
                str(tmp / "rc_cal.json"), "--contrast", "0.1", "--times", "2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "for --method galvo" in err[0] and "--method direct reads no optics" in err[0], err


def test_a_recording_at_the_commanded_phase_is_said_to_be(cards):
    """A galvo recording given nominal optics, or a calibration without a galvo part (depth only), has its views
    at the commanded scan phase, which a lagging mirror makes wrong without a word (1.11 / 1.09 m for 0.5 / 1.2
    above): ``with_optics`` says so (``CommandedPhaseWarning``); a calibration that measured the phase does
    not."""
    import warnings

    from mitsuba_eventfield import calibration
    from mitsuba_eventfield.calibration.recording import CommandedPhaseWarning
    events, _, tmp = cards
    recording, record, galvo = _lagging(events, LAG_S)
    bare = ef.EventStream(events.x, events.y, events.t, events.p, W, H, {"t_start_us": events.start_us})
    f = focal_length_px(W, 40.0)
    z = np.array([0.4, 0.6, 1.0, 2.0])
    depth = fit_depth(z, 2 * f * (1 - 0.15 / z))
    save_calibration(str(tmp / "phase.json"), record, galvo=galvo)
    save_calibration(str(tmp / "depth_only.json"), record, depth=depth)
    nominal = {k: recording.meta["optics"][k] for k in ("design", "scan", "fov_x_deg", "mirror_distance",
                                                        "mirror_separation")}
    for given in ({"optics": nominal}, {"calibration": str(tmp / "depth_only.json")}):
        with pytest.warns(CommandedPhaseWarning, match="commanded scan phase"):
            calibration.with_optics(bare, **given)
    with warnings.catch_warnings():
        warnings.simplefilter("error", CommandedPhaseWarning)
        calibration.with_optics(bare, calibration=str(tmp / "phase.json"))
        calibration.with_optics(events)                 # a render carries its own optics: nothing to say
