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
    for e in r.errors:                          # measured: near 0.021-0.023, far 0.078-0.082, coverage 0.78
        assert e["near"] < 0.04 and e["far"] < 0.13 and e["coverage"] > 0.6 and e["near_pixels"] > 300
    # the runner recedes 2.5 cm per period; each map places it within 2% of Mitsuba
    est = [e["near_estimate_z"] for e in r.errors]
    true = [e["near_truth_z"] for e in r.errors]
    assert est[1] > est[0] and all(abs(a - b) / b < 0.02 for a, b in zip(est, true))


def test_field_correction_is_what_makes_the_wall_right(runner_capture):
    errs = {fc: np.mean([e["far"] for e in scanrate.run(RUNNER, captured=runner_capture, field_correction=fc).errors])
            for fc in ("off", "mean", "oriented")}
    # the wall fills the field: uncorrected, its off-axis parts read far too far (scale hypersensitivity);
    # measured 0.27 off, 0.080 mean, 0.086 oriented
    assert errs["off"] > 2.5 * errs["mean"] and abs(errs["oriented"] - errs["mean"]) < 0.02


def test_field_depth_model_on_axis_and_off_axis():
    lf = LightField(np.zeros((2, 101, 201)), np.zeros((2, 2)), np.zeros(2), (300.0, 300.0), (-60.0, -63.0), "galvo")
    # on axis the constant-shift depth is already right
    assert galvo_field_depth(lf, 1.5, 100, 50) == pytest.approx(1.5, rel=1e-3)
    # off axis (tx = 0.3): alpha = f (1 + tx^2) - f d / z for vertical edges -> the focal stack read it farther
    z, tx, d, f = 1.5, 90.0 / 300.0, 0.2, 300.0
    alpha = f * (1 + tx * tx) - f * d / z
    read = -60.0 / (alpha - 300.0)                                  # what the constant model makes of alpha
    assert read > 2 * z
    assert galvo_field_depth(lf, read, 190, 50, weight_x=1.0) == pytest.approx(z, rel=1e-6)
    # orientation weights: vertical stripes are all x gradient, horizontal ones all y
    stripes = np.tile((np.arange(40) // 4 % 2).astype(float), (30, 1))
    assert galvo_orientation_weight(stripes)[15, 20] == pytest.approx(1.0)
    assert galvo_orientation_weight(stripes.T)[20, 15] == pytest.approx(0.0)
    assert galvo_orientation_weight(np.ones((10, 10)))[5, 5] == 0.5


def test_scanrate_cli_outputs_and_errors(tmp_path):
    out = tmp_path / "sr"
    cmd = [sys.executable, "-m", "mitsuba_eventfield.cli", "scanrate-depth", RUNNER, "-o", str(out), "--periods", "1",
           "--views", "24", "-D", "width=64", "-D", "height=48"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["depth_maps_per_second"] == 100 and "depth_from_focus" in metrics["time_split_s"]
    assert len(metrics["errors"]) == 1 and "near" in metrics["summary"]
    channels, meta = read_exr(str(out / "depth_p000.exr"))
    assert set(channels) == {"depth", "confidence", "truth"} and meta["period_index"] == 0
    assert channels["depth"].shape == (48, 64) and (out / "scanrate_depth.png").exists()
    bad = subprocess.run([sys.executable, "-m", "mitsuba_eventfield.cli", "scanrate-depth", RUNNER, "-o",
                          str(tmp_path / "b"), "--near", "2", "--far", "1"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "near = 2.0, far = 1.0" in bad.stderr
    with pytest.raises(ValueError, match="field_correction"):
        scanrate.run(RUNNER, field_correction="magic")
