"""Depth at the scan rate (issue 10, part 3): a metric depth map per 100 Hz scan period of the runner, scored
against Mitsuba's depth AOV."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield.apps import highspeed, scanrate
from mitsuba_eventfield.images import read_exr

RUNNER = os.path.join(ROOT, "scenes", "runner", "runner.xml")


@pytest.fixture(scope="module")
def runner_capture():
    return highspeed.capture(RUNNER, {"width": 128, "height": 96}, periods=2)


def test_runner_depth_every_period(runner_capture, capsys):
    r = scanrate.run(RUNNER, captured=runner_capture)
    with capsys.disabled():
        print("\n[depth at the scan rate, runner, 128x96]\n" + r.report())
    assert len(r.depth_maps) == 2 and r.meta["depth_maps_per_second"] == 100
    # measured: near 0.018, far 0.011, coverage 0.47, the near tail (90th percentile) 0.05. Before the own-texture
    # and resolution checks (focus/depth.py) 0.86 of the textured pixels were confident and the far error was
    # 0.042; while own texture was measured around a pixel (not on its most uniform side), coverage 0.66 (the
    # plain sides of the letters' and the runner's edges) and the near tail 0.13 (the wall beside the runner)
    for e in r.errors:
        assert e["near"] < 0.035 and e["far"] < 0.03 and e["coverage"] > 0.4 and e["near_pixels"] > 200
        assert e["near_p90"] < 0.08
    # the runner recedes 2.5 cm per period; each map places it within 2% of Mitsuba
    est = [e["near_estimate_z"] for e in r.errors]
    true = [e["near_truth_z"] for e in r.errors]
    assert est[1] > est[0] and all(abs(a - b) / b < 0.02 for a, b in zip(est, true))


def test_depth_maps_with_the_calibration_from_led_captures(runner_capture):
    # the paper's one calibration step: an LED at known depths through the same galvo gives the disparity model
    cal = scanrate.calibrate_depth(RUNNER, {"width": 128, "height": 96})
    d = cal["depth"]                                    # measured: pivot 0.2026 (x), S_inf 353.9 (2f = 351.7)
    assert d.best == "inverse" and abs(d.pivot - 0.2) / 0.2 < 0.03
    r = scanrate.run(RUNNER, captured=runner_capture, calibration=cal)
    assert r.meta["calibrated"] == ["depth"]
    for e in r.errors:                                  # measured: near 0.018-0.020, far 0.043-0.046
        assert e["near"] < 0.035 and e["far"] < 0.07


def test_the_led_calibration_renders_within_a_pixel_a_step():
    """Four steps a view, and more where the scan moves the LED more than a pixel a step: at the runner's
    160x120 (its default film) the 96 steps of 24 views moved it 1.11 px, and the calibration's own renders
    warned its user."""
    from mitsuba_eventfield.apps.scanrate import LED_SCENE, _led_steps
    from mitsuba_eventfield.scene.bundled import bundled_scene
    from mitsuba_eventfield.simulate.image_motion import scan_px_per_step
    for size, expected in (((160, 120), 107), ((128, 96), 96)):
        target = ef.load_scene(RUNNER, width=size[0], height=size[1])
        o = target.sensor.optics_metadata()
        led = ef.load_scene(bundled_scene(LED_SCENE), width=size[0], height=size[1], depth=1.0, fov=o["fov_x_deg"],
                            mirror_distance=o["mirror_distance"], mirror_separation=o["mirror_separation"],
                            frequency=o["scan"]["frequency"], amplitude=o["scan"]["amplitude"])
        period = 1.0 / o["scan"]["frequency"]
        steps = _led_steps(led, period, 24)
        assert steps == expected and scan_px_per_step(led, period, steps) <= 1.0
        assert steps == 96 or scan_px_per_step(led, period, steps - 1) > 1.0       # the fewest that keep it


def test_scanrate_cli_outputs_and_errors(tmp_path):
    out = tmp_path / "sr"
    cmd = [sys.executable, "-m", "mitsuba_eventfield.cli", "scanrate-depth", RUNNER, "-o", str(out), "--periods", "1",
           "--views", "24", "-D", "width=64", "-D", "height=48", "--calibrate"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["depth_maps_per_second"] == 100 and "depth_from_focus" in metrics["time_split_s"]
    assert len(metrics["errors"]) == 1 and "near" in metrics["summary"] and metrics["calibrated"] == ["depth"]
    assert len(json.loads((out / "calibration.json").read_text())["depth"]["depths"]) == 6
    channels, meta = read_exr(str(out / "depth_p000.exr"))
    assert set(channels) == {"depth", "confidence", "reason", "truth"} and meta["period_index"] == 0
    assert channels["depth"].shape == (48, 64) and (out / "scanrate_depth.png").exists()
    bad = subprocess.run([sys.executable, "-m", "mitsuba_eventfield.cli", "scanrate-depth", RUNNER, "-o",
                          str(tmp_path / "b"), "--near", "2", "--far", "1"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "near = 2.0, far = 1.0" in bad.stderr


def test_periods_with_no_confident_pixel_report_none_not_nan():
    """A period with no confident pixel in a region has no error there: the report said "nan (p90 nan)" with
    NumPy's All-NaN warnings, and metrics held NaN medians."""
    import warnings

    import numpy as np

    from mitsuba_eventfield.apps.scanrate import ScanRateDepth
    empty = {"near": float("nan"), "near_p90": float("nan"), "near_pixels": 0, "far": float("nan"),
             "far_p90": float("nan"), "far_pixels": 0, "coverage": 0.0, "near_truth_z": float("nan"),
             "near_estimate_z": float("nan")}
    some = dict(empty, far=0.02, far_p90=0.05, far_pixels=40, coverage=0.3)
    r = ScanRateDepth([None, None], [None, None], [None, None], [empty, some], np.array([0.002, 0.006]), 0.004,
                      {"min_confidence": 0.5, "split_depth": 1.0, "time_split_s": {"render": 1.0}})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s = r.summary()
        text = r.report()
    assert s["near"] == {"median": None, "worst": None} and s["far"] == {"median": 0.02, "worst": 0.02}
    assert s["coverage"] == {"median": 0.15, "worst": 0.0}
    assert "nan" not in text and text.count("no confident pixel") == 3


def test_capture_steps_cover_the_objects_motion_too(runner_capture):
    """The capture's steps keep the scan's and the moving objects' image motion together under a pixel a step,
    as the render's check adds them (sized from the scan alone, the runner at 80x60 went 1.05 px a step and
    the render's warning told the application's user to pass --steps)."""
    from mitsuba_eventfield.simulate.image_motion import largest_px_per_step
    motion = runner_capture.events.meta["render"]["image_motion_px_per_step"]
    assert motion["objects"] > 0 and largest_px_per_step(runner_capture.events.meta) <= 1.0 + 1e-9
    assert not [n for n in runner_capture.events.meta["render"]["notes"] if "steps coarser" in n]
