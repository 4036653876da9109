"""HDR light field: the event field against two 8-bit exposures, scored in the log domain against the render."""
import os
import subprocess
import sys

import numpy as np
from conftest import ROOT

from mitsuba_eventfield.apps import hdr
from mitsuba_eventfield.atomic import MANIFEST

SCENE = os.path.join(ROOT, "scenes", "hdr_leds", "hdr_leds.xml")


def test_ldr_model_quantises_and_clips():
    lin = np.array([0.0, 0.001, 0.5, 1.0, 3.0])
    codes = hdr.ldr_codes(lin, exposure=1.0)
    assert codes.tolist() == [0, 0, 128, 255, 255]
    back = hdr.ldr_to_linear(codes, 1.0)
    assert back[0] == 0.5 / 255 and abs(back[2] - 0.5) <= 0.5 / 255 and back[4] == 1.0   # clipped: 3 reads as 1


def test_event_field_keeps_both_ends_of_the_range(capsys):
    r = hdr.compare(SCENE, {"width": 80, "height": 60}, depth=1.45, steps_per_period=48)
    with capsys.disabled():
        print("\n[HDR light field, 80x60]\n" + r.report())
    assert r.dynamic_range >= 1e4                                   # the scene is HDR as the issue asks
    assert r.regions["bright"].sum() > 50 and r.regions["dark"].sum() > 500
    ev, short, long = (r.errors[k] for k in ("events", "ldr_short", "ldr_long"))
    # each exposure fails where it clips or underflows; the events hold both ends to within ~2 thresholds (C = 0.2)
    assert short["dark"] > 0.8 and long["bright"] > 0.8
    assert ev["worst_region"] < 0.4 < 0.5 * min(short["worst_region"], long["worst_region"])
    assert ev["all"] < min(short["all"], long["all"])


def test_hdr_cli_outputs_and_bad_depth(tmp_path):
    env = dict(os.environ)
    cmd = [sys.executable, "-m", "mitsuba_eventfield.cli", "hdr", SCENE, "-o", str(tmp_path / "h"),
           "-D", "width=48", "-D", "height=36", "--steps", "32"]
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
    assert r.returncode == 0, r.stderr
    assert sorted(n for n in os.listdir(tmp_path / "h") if n != MANIFEST) == ["events.exr", "hdr.png", "ldr_long.exr", "ldr_short.exr",
                                                   "metrics.json", "truth.exr"]
    bad = subprocess.run(cmd[:-2] + ["--depth", "-1"], capture_output=True, text=True, env=env, timeout=600)
    assert bad.returncode == 2 and "argument --depth: '-1': allowed range is (0, inf]" in bad.stderr
