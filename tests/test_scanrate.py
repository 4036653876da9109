"""Depth at the scan rate (issue 10, part 3): a metric depth map per 100 Hz scan period of the runner, scored
against Mitsuba's depth AOV."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT
from mitsuba_eventfield import highspeed, scanrate
from mitsuba_eventfield.images import read_exr
from mitsuba_eventfield.lightfield import LightField, galvo_field_depth, galvo_orientation_weight

RUNNER = os.path.join(ROOT, "scenes", "runner", "runner.xml")


@pytest.fixture(scope="module")
def runner_capture():
    return highspeed.capture(RUNNER, {"width": 128, "height": 96}, periods=2)


def test_runner_depth_every_period(runner_capture, capsys):
    r = scanrate.run(RUNNER, captured=runner_capture)
    with capsys.disabled():
        print("\n[depth at the scan rate, runner, 128x96]\n" + r.report())
    assert len(r.depth_maps) == 2 and r.meta["depth_maps_per_second"] == 100
    for e in r.errors:                          # measured: near 0.020, far 0.042, coverage 0.86
        assert e["near"] < 0.035 and e["far"] < 0.07 and e["coverage"] > 0.75 and e["near_pixels"] > 300
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


def test_field_correction_is_what_makes_the_wall_right(runner_capture):
    errs = {fc: np.mean([e["far"] for e in scanrate.run(RUNNER, captured=runner_capture, field_correction=fc).errors])
            for fc in ("off", "mean", "oriented")}
    # the wall fills the field: uncorrected, its off-axis parts read far too far (scale hypersensitivity);
    # the x and y scales differ off the diagonal, so weighting them by edge orientation beats their mean.
    # Measured 0.271 off, 0.078 mean, 0.042 oriented.
    assert errs["off"] > 2.5 * errs["mean"] and errs["oriented"] < 0.75 * errs["mean"]


@pytest.mark.parametrize("weight_x", [1.0, 0.0])
def test_field_depth_model_against_the_ray_traced_galvo(weight_x):
    # the exact two-mirror optics (plugins/galvo_optics.project_point, the geometric oracle) for an off-axis
    # point: fit the shift slope a constant-shift focal stack would find along x (vertical edges) or y
    from mitsuba_eventfield.plugins import galvo_optics as go
    w, h, d1, s = 201, 151, 0.2, 0.01
    f = go.focal_length_px(w, 40.0)
    lf = LightField(np.zeros((2, h, w)), np.zeros((2, 2)), np.zeros(2), (f, f), (-f * d1, -f * (d1 + s)), "galvo")
    z = 1.6
    for tx, ty in ((0.3, -0.2), (-0.25, 0.1)):
        p = (-tx * z, -ty * z, z)            # Mitsuba's image x runs to camera -x: pixel left of centre for +x
        x0, y0 = go.project_point(np, p, 0.0, 0.0, d1, s, f, w, h)
        phase = np.linspace(0, 2 * np.pi, 64, endpoint=False)
        amp = np.radians(2.0)
        ax, ay = amp * np.cos(phase), amp * np.sin(phase)
        xs, ys = go.project_point(np, p, ax, ay, d1, s, f, w, h)
        u = np.stack([2 * ax, 2 * ay], axis=-1)               # view positions: optical angles
        # a point shifts by alpha * position (LightField); fit each axis on its own (the cross term, f tx ty,
        # goes into the other coefficient). Measured: 266.8 and 251.4 px/rad here, the model 266.5 and 250.9
        slope_x = np.linalg.lstsq(u, xs - x0, rcond=None)[0][0]
        slope_y = np.linalg.lstsq(u, ys - y0, rcond=None)[0][1]
        slope = slope_x if weight_x == 1.0 else slope_y
        B = lf.B[0] if weight_x == 1.0 else lf.B[1]
        read = B / (slope - f)                                  # what the constant model makes of that slope
        corrected = galvo_field_depth(lf, read, x0 - 0.5, y0 - 0.5, weight_x=weight_x)
        assert read > 1.08 * z                                  # 6-17 degrees off axis: 9-60% too far
        # left: ~1% from the model's first-order terms (0.1% of the slope, times the hypersensitivity z / pivot)
        assert corrected == pytest.approx(z, rel=0.015) and abs(corrected - z) < 0.2 * abs(read - z)


def test_field_depth_on_axis_and_orientation_weights():
    lf = LightField(np.zeros((2, 101, 201)), np.zeros((2, 2)), np.zeros(2), (300.0, 300.0), (-60.0, -63.0), "galvo")
    assert galvo_field_depth(lf, 1.5, 100, 50) == pytest.approx(1.5, rel=1e-3)    # on axis nothing changes
    # vertical stripes are all x gradient, horizontal ones all y, flat has no preference
    stripes = np.tile((np.arange(40) // 4 % 2).astype(float), (30, 1))
    assert galvo_orientation_weight(stripes)[15, 20] == pytest.approx(1.0)
    assert galvo_orientation_weight(stripes.T)[20, 15] == pytest.approx(0.0)
    assert galvo_orientation_weight(np.ones((10, 10)))[5, 5] == 0.5


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
    assert set(channels) == {"depth", "confidence", "truth"} and meta["period_index"] == 0
    assert channels["depth"].shape == (48, 64) and (out / "scanrate_depth.png").exists()
    bad = subprocess.run([sys.executable, "-m", "mitsuba_eventfield.cli", "scanrate-depth", RUNNER, "-o",
                          str(tmp_path / "b"), "--near", "2", "--far", "1"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "near = 2.0, far = 1.0" in bad.stderr
    with pytest.raises(ValueError, match="field_correction"):
        scanrate.run(RUNNER, field_correction="magic")
