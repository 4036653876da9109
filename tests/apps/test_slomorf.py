"""SloMoRF: event interpolation of 120 fps RGB frames and refocus, scored against the renderer's ground truth.

Bounds come from measurements at this size (scenes/falling, 150 px film = 50 px views, 25 ms, factor 8; numbers
in the comments), with headroom, and each is one a broken method would miss.
"""
import json
import os
import subprocess
import sys

import cv2
import numpy as np
import pytest
from conftest import ROOT, TEST_VARIANT

from mitsuba_eventfield import backend
from mitsuba_eventfield.apps import slomorf
from mitsuba_eventfield.output_folders import MANIFEST

SCENE = os.path.join(ROOT, "scenes", "falling", "falling.xml")
DART = os.path.join(ROOT, "scenes", "dart", "kaleidoscope.xml")


@pytest.fixture(scope="module")
def result():
    return slomorf.slomorf(SCENE, {"views_px": 150}, duration=0.025, factor=8)


def test_interpolate_takes_colour_from_the_side_that_did_not_change():
    red, blue = np.zeros((1, 2, 3)), np.zeros((1, 2, 3))
    red[..., 0], blue[..., 2] = 0.5, 0.25
    change = np.full((1, 2), np.log(0.5))           # the pixel halved in luminance ...
    before, after = np.array([[3.0, 0.0]]), np.array([[0.0, 3.0]])   # ... before t (pixel 0) or after t (pixel 1)
    out = slomorf.interpolate(red, blue, np.where(before > 0, change, 0), np.where(after > 0, change, 0),
                              before, after, w_b=0.5, fusion="events")
    np.testing.assert_allclose(out[0, 0], blue[0, 0])                 # already changed: the next frame's colour
    np.testing.assert_allclose(out[0, 1], red[0, 1])                  # not yet changed: the previous frame's
    timed = slomorf.interpolate(red, blue, np.where(before > 0, change, 0), np.where(after > 0, change, 0),
                                w_b=0.5, fusion="time")
    assert not np.allclose(timed[0, 0], blue[0, 0])                   # the time fusion mixes both colours


def test_events_beat_linear_blending_against_the_truth(result, capsys):
    with capsys.disabled():
        print("\n[SloMoRF, 150 px film, 25 ms, 8x]\n" + result.report())
    m = result.metrics
    ev, ev_time, lin = (m["frames"][k] for k in ("events", "events_time", "linear"))
    assert m["interpolated_frames"] == 21 and result.is_key.sum() == 4
    # measured: PSNR 26.1 / 24.0 dB, moving pixels 16.5 / 14.4 dB, SSIM 0.963 / 0.913, worst frame 23.7 / 21.5
    # dB (events / linear)
    assert ev["psnr"] > lin["psnr"] + 1.4 and ev["psnr_moving"] > lin["psnr_moving"] + 1.4
    assert ev["ssim"] > lin["ssim"] + 0.03 and ev["psnr_worst"] > lin["psnr_worst"] + 1.4
    assert ev["psnr"] > 25.0 and ev["psnr_moving"] > 15.5 and ev["ssim"] > 0.95
    # the event-count fusion beats time-distance weights (measured +0.34 dB)
    assert ev["psnr"] > ev_time["psnr"] + 0.15
    # the motion is large enough for linear blending to fail visibly: moving pixels measured 14.4 dB
    assert lin["psnr_moving"] < 15.5


def test_the_report_says_when_the_duration_was_cut_to_whole_frame_intervals(result):
    """25 ms at 120 fps is three whole frame intervals: nothing cut, nothing said. A duration the frames do not
    divide was cut silently (20 ms at 60 fps simulated 16.667 ms): the report's first line now says so."""
    assert result.meta["duration_s"] == pytest.approx(0.025) and "duration_asked_s" not in result.meta
    assert result.report().splitlines()[0] == "25.000 ms simulated"
    cut = slomorf.slomorf(SCENE, {"views_px": 60}, fps=120, factor=2, duration=0.02, depths=(0.8,))
    assert cut.meta["duration_s"] == pytest.approx(2 / 120) and cut.meta["duration_asked_s"] == 0.02
    assert cut.report().splitlines()[0] == "16.667 ms simulated (20 ms asked, cut to whole 120 fps frame intervals)"


def test_refocus_of_interpolated_frames_against_refocused_truth(result):
    rf = result.metrics["refocus"]
    ev, lin = rf["events"], rf["linear"]
    # measured: 33.6 / 32.6 dB, SSIM 0.977 / 0.947; at the block's depth 0.8: 27.4 / 25.3 dB
    assert ev["psnr"] > lin["psnr"] + 0.6 and ev["ssim"] > lin["ssim"] + 0.015
    assert ev["psnr"] > 32.0 and ev["ssim"] > 0.965
    block = result.depths.index(0.8)
    assert ev["per_depth"][block]["psnr"] > lin["per_depth"][block]["psnr"] + 1.3
    for e, li in zip(ev["per_depth"], lin["per_depth"]):
        assert e["psnr"] > li["psnr"]


def test_each_depth_brings_its_own_object_into_focus(result):
    """Pixels whose true depth (Mitsuba's depth AOV) is the post's, the block's or the wall's are sharpest in
    the image refocused at that depth, by a clear factor (measured Tenengrad ratios 6.2, 2.6, 3.8)."""
    fc = result.metrics["focus_check"]
    assert fc["all_sharpest_at_own_depth"]
    for region in fc["regions"]:
        assert region["pixels"] > 1000
        assert region["ratio_to_next_best"] > 1.8, region
    assert result.failed_checks() == []
    result.metrics["focus_check"]["regions"][1]["sharpest_at_own_depth"] = False     # as a failed check reads
    try:
        assert result.failed_checks() == [f"slomorf: focus check failed at {fc['regions'][1]['depth']:g}: its "
                                          f"region ({fc['regions'][1]['pixels']} px) is sharper refocused at "
                                          "another depth"]
    finally:
        result.metrics["focus_check"]["regions"][1]["sharpest_at_own_depth"] = True


def test_variant_is_restored(result):
    assert backend.mi.variant() == TEST_VARIANT        # conftest's; the RGB frames used the RGB variant


def test_outputs_are_complete(result, tmp_path):
    out = tmp_path / "s"
    written = slomorf.write_outputs(result, str(out))
    n = len(result.times)
    assert len(written["frames"]) == n and len(written["refocus"]) == n * len(result.depths)
    cap = cv2.VideoCapture(written["mp4"])
    assert cap.isOpened()
    frames = 0
    while cap.read()[0]:
        frames += 1
    cap.release()
    assert frames == n
    from PIL import Image
    with Image.open(written["gif"]) as gif:
        assert gif.n_frames == n
    with Image.open(written["frames"][1]) as png:
        meta = json.loads(png.text["eventfield_meta"])
        assert meta["frame"] == "interpolated (events)" and meta["fps"] == 120.0 and meta["optics"]["n"] == 3
    with open(written["metrics"]) as f:
        m = json.load(f)
    assert set(m["time_split_s"]) == {"render_events", "render_rgb_frames", "render_truth_for_scoring",
                                      "interpolate", "refocus", "refocus_for_scoring", "score", "write"}
    assert m["metrics"]["frames"]["events"]["psnr"] == result.metrics["frames"]["events"]["psnr"]
    assert m["factor"] == 8 and m["score_domain"].startswith("8-bit") and "pixel_model" in m
    assert m["paper"][0]["figure"] == "Fig. 8" and "--depths 0.55,0.8,1.4" in m["paper"][0]["command"]
    assert not [p for p in out.rglob("*") if p.name.startswith(".")]          # no temporary files left


@pytest.mark.parametrize("kw, words", [
    ({"factor": 1}, ["factor = 1", "2..64"]),
    ({"factor": 2.5}, ["factor = 2.5", "integer"]),
    ({"depths": (0.8, 0.0)}, ["depths", "> 0"]),
    ({"depths": (-1.0,)}, ["depths", "> 0"]),
    ({"fps": 0.5}, ["fps = 0.5", "1..10000"]),
    ({"fps": 2e4}, ["fps = 20000.0", "1..10000"]),
    ({"duration": 0.001}, ["duration = 0.001", "0.00833333"]),
])
def test_bad_input_is_refused_before_rendering(kw, words):
    with pytest.raises(ValueError) as err:
        slomorf.slomorf(SCENE, {"views_px": 90}, **kw)
    for w in words:
        assert w in str(err.value)


def test_a_depth_with_nothing_on_it_is_refused_before_rendering(monkeypatch):
    """scenes/falling lies between 0.55 and 1.4 m: a refocus depth of 0.2 m (the default depths on another
    scene, a typo) has no pixel in its focus band, whose scores came out NaN after every render; the dart's
    scene lacks the falling scene's post at 0.55 m. Refused from Mitsuba's depth before any event."""
    def no_render(*a, **k):
        raise AssertionError("rendered before the depths were checked")
    monkeypatch.setattr(slomorf, "render_events", no_render)
    with pytest.raises(ValueError, match=r"plane '--depths 0.2' at 0.2: no part of .*falling.xml lies within 0.1"):
        slomorf.slomorf(SCENE, {"views_px": 90}, duration=0.025, depths=(0.8, 0.2))
    with pytest.raises(ValueError, match=r"plane '--depths 0.55' at 0.55: no part of .*kaleidoscope.xml"):
        slomorf.slomorf(DART, {"width": 99, "height": 66}, duration=0.0084)


def test_cli_report_and_bad_factor(tmp_path):
    cmd = [sys.executable, "-m", "mitsuba_eventfield.cli", "slomorf", SCENE, "-o", str(tmp_path / "c"),
           "-D", "views_px=90", "--duration", "0.00834", "--factor", "2"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert "linear blend (baseline)" in r.stdout and "time split: render events" in r.stdout
    assert sorted(n for n in os.listdir(tmp_path / "c") if n != MANIFEST) == ["frames", "metrics.json", "refocus", "slomorf.gif", "slomorf.mp4",
                                                  "slomorf.png"]
    bad = subprocess.run(cmd[:-1] + ["1"], capture_output=True, text=True, timeout=600)
    assert bad.returncode == 2 and "argument --factor: '1': allowed range is [2, 64]" in bad.stderr


def test_the_algorithm_runs_on_events_and_keyframes_alone():
    """slow_motion_frames needs no scene and no truth: events of one pixel that brightens by e^(2 x 0.2) right
    after the first keyframe; elsewhere (no events) the films are the time-weighted blend."""
    from mitsuba_eventfield.apps.slomorf import slow_motion_frames
    from mitsuba_eventfield.events.stream import EventStream
    rng = np.random.default_rng(0)
    keys = rng.uniform(0.2, 0.8, (2, 4, 5, 3)).astype(np.float32)
    keys[1, 2, 3] = keys[0, 2, 3] * np.exp(0.4)                          # the pixel's brightening, seen at t_b
    times = np.arange(5) / 4 * 0.01                                       # 4 intervals between two keys
    is_key = np.array([True, False, False, False, True])
    meta = {"pixel_model": {"threshold_on": 0.2, "threshold_off": 0.2}, "t_start_us": 0}
    ev = EventStream(np.array([3, 3], np.uint16), np.array([2, 2], np.uint16), np.array([100, 200], np.int64),
                     np.array([1, 1], np.int8), 5, 4, meta)
    frames = slow_motion_frames(ev, keys, times, is_key, factor=4)
    for j in (1, 2, 3):
        w = j / 4
        np.testing.assert_allclose(frames["events"][j, 0, 0], (1 - w) * keys[0, 0, 0] + w * keys[1, 0, 0], rtol=1e-5)
        # the pixel fired both events before t_j: all of its change is already there
        np.testing.assert_allclose(frames["events"][j, 2, 3], keys[1, 2, 3], rtol=1e-4)
    assert np.array_equal(frames["linear"][0], keys[0]) and np.array_equal(frames["events"][4], keys[1])


@pytest.fixture(scope="module")
def dart():
    """The kaleidoscope dart (paper Fig. 9) at 8x: 960 fps from 120 fps, refocused on the dart and the wall."""
    return slomorf.slomorf(DART, {"width": 216, "height": 144}, factor=8, depths=(0.95, 1.8))


def test_kaleidoscope_dart_at_960_fps_against_the_truth(dart, capsys):
    """Measured at 216 x 144 (72 x 48 views), two RGB intervals: the numbers in the comments."""
    with capsys.disabled():
        print("\n[SloMoRF, kaleidoscope dart, 216x144 film, 8x]\n" + dart.report())
    m = dart.metrics
    assert dart.meta["output_fps"] == 960 and m["interpolated_frames"] == 14      # 7 between each pair of frames
    ev, lin = m["frames"]["events"], m["frames"]["linear"]
    # measured: PSNR 32.58 / 26.03 dB, moving pixels 21.70 / 15.15 dB, SSIM 0.987 / 0.934 (events / linear)
    assert ev["psnr"] > 31.5 and ev["psnr_moving"] > 20.5 and ev["ssim"] > 0.98
    assert ev["psnr"] > lin["psnr"] + 5 and ev["psnr_moving"] > lin["psnr_moving"] + 5
    assert ev["ssim"] > lin["ssim"] + 0.04
    rf_ev, rf_lin = m["refocus"]["events"], m["refocus"]["linear"]
    # refocused: 36.01 / 30.45 dB; at the dart's depth 0.95 m: 33.77 / 27.85 dB
    assert rf_ev["psnr"] > 35.0 and rf_ev["psnr"] > rf_lin["psnr"] + 4.5
    on_dart, on_dart_lin = rf_ev["per_depth"][0], rf_lin["per_depth"][0]
    assert on_dart["depth"] == 0.95 and on_dart["psnr"] > 32.5 and on_dart["psnr"] > on_dart_lin["psnr"] + 4.5


def test_dart_refocus_is_sharpest_on_the_dart_at_its_depth(dart):
    """Pixels whose Mitsuba depth is the dart's (within 10 % of 0.95 m in inverse depth, over the interpolated
    instants) are sharpest in the image refocused at 0.95 m; the wall's at 1.8 m (measured Tenengrad ratios
    2.70 over 1145 px and 4.25)."""
    fc = dart.metrics["focus_check"]
    on_dart, wall = fc["regions"]
    assert fc["all_sharpest_at_own_depth"] and on_dart["pixels"] > 800
    assert on_dart["ratio_to_next_best"] > 2.0 and wall["ratio_to_next_best"] > 3.0


def test_dart_paper_row_regenerates_the_run(dart):
    from mitsuba_eventfield.apps.slomorf_outputs import paper_rows
    from mitsuba_eventfield.cli.main import build_parser
    row = paper_rows(dart)[0]
    assert row["figure"] == "Fig. 9" and "960 fps from 120 fps" in row["measured"]
    assert f"{dart.metrics['frames']['events']['psnr']:.1f} dB with events" in row["measured"]
    args = build_parser().parse_args(row["command"].split()[1:])
    assert args.command == "slomorf" and args.scene == "scenes/dart/kaleidoscope.xml" and args.factor == 8
    assert args.depths == "0.95,1.8" and args.define == ["width=216", "height=144"]
    assert slomorf._check(args.fps, args.factor, (0.95,), args.duration)[0] == 120.0
    assert int(args.duration * args.fps + 1e-6) == 2          # the same two RGB intervals
