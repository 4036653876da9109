"""The light-field commands as a user runs them: render, frame, reconstruct, refocus, depth."""
import os
import re
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT

from mitsuba_eventfield.output_folders import MANIFEST

GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")


def run(*args):
    return subprocess.run([sys.executable, "-m", "mitsuba_eventfield.cli", *args], capture_output=True, text=True,
                          timeout=600)


@pytest.fixture(scope="module")
def galvo_capture(tmp_path_factory):
    d = tmp_path_factory.mktemp("galvo")
    small = ["-D", "width=120", "-D", "height=90"]
    r = run("render", GALVO, "-o", str(d / "g.h5"), "--duration", "0.004", "--steps", "32", "--quiet", *small)
    assert r.returncode == 0, r.stderr
    r = run("frame", GALVO, "-o", str(d / "start.exr"), *small)
    assert r.returncode == 0, r.stderr
    r = run("frame", GALVO, "-o", str(d / "small.exr"), "-D", "width=60", "-D", "height=45")  # wrong size
    assert r.returncode == 0, r.stderr
    from mitsuba_eventfield.images import write_exr
    write_exr(str(d / "depth_only.exr"), {"Z": np.ones((45, 60))})                                # no Y or R
    return d


def test_reconstruct_refocus_depth_outputs(galvo_capture):
    from mitsuba_eventfield.images import read_exr
    d = galvo_capture
    r = run("reconstruct", str(d / "g.h5"), "-o", str(d / "rec"), "--times", "1,2,3", "--start-frame",
            str(d / "start.exr"))
    assert r.returncode == 0, r.stderr
    assert sorted(n for n in os.listdir(d / "rec") if n != MANIFEST) == [f"frame_000{k}.{e}" for k in range(3) for e in ("exr", "png")]
    frame, meta = read_exr(str(d / "rec" / "frame_0001.exr"))
    assert frame["Y"].shape == (90, 120) and np.all(np.isfinite(frame["Y"])) and meta["method"] == "direct"
    r = run("refocus", str(d / "g.h5"), "-o", str(d / "rf.png"), "--depth", "0.5,2.5", "--start-frame",
            str(d / "start.exr"), "--views", "16")
    assert r.returncode == 0, r.stderr
    near, _ = read_exr(str(d / "rf_0.5.exr"))
    far, meta = read_exr(str(d / "rf_2.5.exr"))
    assert meta["depth"] == 2.5 and meta["optics"]["design"] == "galvo"
    # a start frame is information beyond the events: the output and the printed line say it was used
    assert meta["inputs"].startswith("events + a start frame (extra information") and "start frame" in r.stdout
    assert not np.allclose(near["Y"], far["Y"])
    r = run("depth", str(d / "g.h5"), "-o", str(d / "depth.png"), "--near", "0.3", "--far", "4", "--planes", "16",
            "--start-frame", str(d / "start.exr"), "--views", "16", "--measure", "tenengrad")
    assert r.returncode == 0, r.stderr
    dm, meta = read_exr(str(d / "depth.exr"))
    assert set(dm) == {"depth", "confidence", "reason"} and meta["planes"] == 16
    conf = dm["confidence"] > 0.3
    # the card (0.5 m, image centre-right area) is confident and near; the wall (2.5 m) is not confident: at
    # 120 x 90 its points move 0.011 px in the views for 10 % more depth, beyond what they resolve (focus/depth.py)
    card, wall = np.s_[38:55, 62:85], np.s_[5:25, 5:40]
    assert conf[card].mean() > 0.2 and abs(np.median(dm["depth"][card][conf[card]]) / 0.5 - 1) < 0.25
    assert conf[wall].mean() < 0.05
    # the output says why: past about 0.55 m (where 10 % moves the views 0.05 px; the card at 0.5 m reads 0.055 px)
    farthest = re.search(r"beyond the depth resolution: past a depth of about ([0-9.]+)", r.stdout)
    assert farthest and 0.45 < float(farthest.group(1)) < 0.7, r.stdout
    assert os.path.getsize(d / "depth.png") > 0
    # views from the high-pass filter hold each view's changes only: on this capture its depth map read the text
    # wall at 0.43 m, confidently; the command says so
    r = run("depth", str(d / "g.h5"), "-o", str(d / "depth_hp.png"), "--near", "0.3", "--far", "4", "--planes", "16",
            "--views", "16", "--method", "highpass")
    assert r.returncode == 0 and "--method highpass keeps each view's changes" in r.stderr, (r.stdout, r.stderr)
    # and direct with no start frame integrates onto a flat image (a new user: 1213 of 1430 confident pixels more
    # than 10 % off, without a word); the count the command prints leaves out pixels that failed a check, and
    # the threshold it counted with is in the EXR
    r = run("depth", str(d / "g.h5"), "-o", str(d / "depth_dr.png"), "--near", "0.3", "--far", "4", "--planes", "16",
            "--views", "16", "--method", "direct", "--min-confidence", "0")
    assert r.returncode == 0 and "--method direct without --start-frame integrates" in r.stderr, (r.stdout, r.stderr)
    channels, meta = read_exr(str(d / "depth_dr.exr"))
    counted = re.search(r"median depth of confident pixels [0-9.]+ m \(([0-9]+) pixels", r.stdout)
    assert counted and int(counted.group(1)) == int((channels["confidence"] > 0).sum()) < channels["depth"].size
    assert meta["min_confidence"] == 0


@pytest.mark.parametrize("args, message", [
    (["refocus", "{d}/g.h5", "-o", "{d}/x.png", "--depth", "-1"], "--depth = '-1': allowed range is (0, inf]"),
    (["depth", "{d}/g.h5", "-o", "{d}/x.png", "--near", "2", "--far", "1"], "need 0 < near < far"),
    (["depth", "{d}/g.h5", "-o", "{d}/x.png", "--near", "1", "--far", "2", "--measure", "blur"], "--measure 'blur'"),
    (["reconstruct", "{d}/g.h5", "-o", "{d}/rec2", "--method", "e2vid"], "unknown reconstruction method 'e2vid'"),
    (["depth", "{d}/g.h5", "-o", "{d}/x.png", "--near", "1", "--far", "2", "--method", "foo"],
     "--method 'foo': allowed: complementary, direct, galvo, highpass, periods"),
    (["reconstruct", "{d}/g.h5", "-o", "{d}/rec3", "--method", "complementary"], "needs --start-frame"),
    (["refocus", "{d}/g.h5", "-o", "{d}/x.png", "--depth", "1", "--start-frame", "{d}/small.exr"],
     "small.exr: a frame of 60x45; the stream's sensor is 120x90"),
    (["refocus", "{d}/g.h5", "-o", "{d}/x.png", "--depth", "1", "--period", "9"],
     "scan period 9 is not in the stream: allowed 0..0"),
    (["calibrate", "galvo", "{d}/g.h5", "--patch", "30,30", "--period", "-1", "-o", "{d}/x.json"],
     "argument --period: '-1': allowed range is [0, inf)"),
    (["calibrate", "kaleidoscope", "{d}/depth_only.exr", "-o", "{d}/x.json"],
     "depth_only.exr: needs a Y channel, or R, G and B (linear, for their luminance); it has Z"),
])
def test_bad_input(galvo_capture, args, message):
    d = galvo_capture
    r = run(*[a.format(d=d) for a in args])
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and message in lines[0], r.stderr
    assert not any(os.path.exists(d / f"x.{ext}") for ext in ("png", "exr", "json"))


def test_calibrate_commands(galvo_capture, tmp_path):
    import json
    d = galvo_capture
    cal = str(tmp_path / "cal.json")
    r = run("calibrate", "galvo", str(d / "g.h5"), "--patch", "30,30", "--patch", "30,60", "--start-frame",
            str(d / "start.exr"), "-o", cal)
    assert r.returncode == 0, r.stderr
    data = json.loads(open(cal).read())
    assert data["format"] == "mitsuba-eventfield calibration"
    from mitsuba_eventfield.calibration import load_calibration
    clock_phase = load_calibration(cal)["galvo"].clock_phase_deg          # the scene commands phase 0
    assert abs((clock_phase + 180) % 360 - 180) < 2, r.stdout
    r = run("depth", str(d / "g.h5"), "-o", str(tmp_path / "dc.png"), "--near", "0.3", "--far", "4", "--planes", "8",
            "--start-frame", str(d / "start.exr"), "--views", "16", "--calibration", cal)
    assert r.returncode == 0, r.stderr
    kframe = tmp_path / "k.exr"
    r = run("frame", os.path.join(ROOT, "scenes", "moving_grid", "kaleidoscope.xml"), "-o", str(kframe),
            "-D", "views_px=120")
    assert r.returncode == 0, r.stderr
    r = run("calibrate", "kaleidoscope", str(kframe), "-o", cal)
    assert r.returncode == 0 and "3x3 views of 40x40 px" in r.stdout, r.stderr + r.stdout
    data = json.loads(open(cal).read())
    assert {"galvo", "kaleidoscope"} <= set(data)                  # extended, not overwritten
    bad = run("calibrate", "galvo", str(d / "g.h5"), "--patch", "1,1", "-o", cal)
    assert bad.returncode == 2 and "does not fit in the 120x90 frames (allowed: x in [28, 91] and y in [28, 61])" \
        in bad.stderr, bad.stderr


def test_refocus_follows_moving_content_as_its_warning_says(tmp_path):
    """The moving-content warning's advice was Python's (refocus(..., motion=...)), which the command line could
    not take. It now names ``--follow=VX,VY`` too, and following that advice takes the warning away (the views'
    motion at that velocity taken out) and records the velocity; a malformed one is refused before the solve."""
    fan = os.path.join(ROOT, "scenes", "fan", "fan.xml")
    r = run("render", fan, "-o", str(tmp_path / "fan.h5"), "-D", "width=96", "-D", "height=72", "-D", "amplitude=2",
            "-D", "mirror_distance=0.2", "--duration", "0.008", "--quiet")
    assert r.returncode == 0, r.stderr
    r = run("refocus", str(tmp_path / "fan.h5"), "-o", str(tmp_path / "r.png"), "--depth", "0.6")
    advice = re.search(r"eventfield refocus (--follow=-?\d+,-?\d+)", r.stderr)
    assert r.returncode == 0 and advice, r.stderr
    r = run("refocus", str(tmp_path / "fan.h5"), "-o", str(tmp_path / "f.png"), "--depth", "0.6", advice.group(1))
    assert r.returncode == 0 and "content moves" not in r.stderr, r.stderr
    from mitsuba_eventfield.images import read_exr
    vx, vy = (float(v) for v in advice.group(1).split("=")[1].split(","))
    assert read_exr(str(tmp_path / "f.exr"))[1]["follow_px_s"] == [vx, vy]
    r = run("refocus", str(tmp_path / "fan.h5"), "-o", str(tmp_path / "g.png"), "--depth", "0.6", "--follow=1,2,3")
    assert r.returncode == 2 and "argument --follow: 1,2,3: expected VX,VY (pixels per second)" in r.stderr, r.stderr


def test_a_velocity_beyond_the_image_is_refused():
    """``refocus(..., motion=...)`` with content moved farther than the image over the views: one line (a
    --follow of 1e308 px/s warped views by 10^305 px, minutes of OpenCV past SIGTERM)."""
    import math

    from mitsuba_eventfield.errors import ConfigError
    from mitsuba_eventfield.focus.refocus import refocus
    from mitsuba_eventfield.lightfield.model import Disparity, LightField
    rng = np.random.default_rng(0)
    lf = LightField(rng.random((8, 32, 48)), np.zeros((8, 2)), np.linspace(0, 0.004, 8), Disparity((0.0, 0.0), (0.0, 0.0)))
    refocus(lf, math.inf, motion=(1000, 0))                                   # 2 px from the mean time: fine
    with pytest.raises(ConfigError, match=r"moves content 2e\+305 px .* farther than the 48-pixel image: allowed "
                                          r"\|v\| up to 2.4e\+04 px/s"):
        refocus(lf, math.inf, motion=(1e308, 1))
