"""Regression images: the bundled scenes render as blessed (eventfield regression --bless re-blesses)."""
import os
import shutil

import numpy as np
import pytest
from conftest import ROOT

from mitsuba_eventfield.evaluation import regression
from mitsuba_eventfield.scene import bundled_scene

REFERENCES = os.path.join(ROOT, "tests", "regression")


@pytest.mark.parametrize("case", regression.CASES, ids=[c.name for c in regression.CASES])
def test_matches_reference(case):
    problems = regression.compare(case, *regression.render_case(case), REFERENCES)
    assert problems == [], problems


def test_a_changed_sensor_parameter_is_caught(tmp_path):
    galvo = next(c for c in regression.CASES if c.name == "galvo_static")
    frame, net = regression.render_case(galvo, amplitude=0.55)                 # the scan 10% larger
    assert any("events differ" in p for p in regression.compare(galvo, frame, net, REFERENCES))
    # the demo camera's field of view one degree wider: a copy of the scene with one attribute changed
    demo = next(c for c in regression.CASES if c.name == "demo")
    src = os.path.dirname(bundled_scene("demo/demo.xml"))
    for f in os.listdir(src):
        shutil.copy(os.path.join(src, f), tmp_path / f)
    xml = (tmp_path / "demo.xml").read_text().replace('<float name="fov" value="40"/>', '<float name="fov" value="41"/>')
    (tmp_path / "demo.xml").write_text(xml)
    frame, net = regression.render_case(demo, scene_path=str(tmp_path / "demo.xml"))
    problems = regression.compare(demo, frame, net, REFERENCES)
    assert any("frame differs" in p for p in problems)


@pytest.mark.parametrize("name", ["galvo_static", "fan"])
def test_the_other_backend_tolerance_covers_last_bit_rounding_and_still_catches_a_change(name):
    """References are made on LLVM; CUDA's float32 sin/cos and ray intersections round differently. Shifting
    every instant of a galvo case by 1 ns to 0.1 us (0.0001-0.009 deg of its scan phase) stands in for that:
    a pixel near a threshold level at the last instant flips by one event, enough to move the galvo cases'
    per-pixel difference to ~0.08 (same-backend tolerance 0.05). The other-backend tolerances accept every
    such shift and still catch a scan 10 % larger."""
    case = next(c for c in regression.CASES if c.name == name)
    for shift in (1e-9, 1e-8, 1e-7):
        assert regression.compare(case, *regression.render_case(case, shift_s=shift), REFERENCES,
                                  other_backend=True) == [], shift
    bigger = regression.render_case(case, amplitude=0.55)
    assert any("events differ" in p for p in regression.compare(case, *bigger, REFERENCES, other_backend=True))


def test_the_references_say_which_backend_made_them(tmp_path):
    """Blessed references record their backend; comparing on the same backend keeps the strict tolerances."""
    case = next(c for c in regression.CASES if c.name == "demo")
    regression.bless(str(tmp_path), cases=[case])
    from mitsuba_eventfield.images import read_exr
    assert read_exr(str(tmp_path / "demo_frame.exr"))[1]["backend"] == regression._backend()
    frame, net = regression.render_case(case)

    def moved(k):       # k events moved from firing pixels to silent ones: the total stays, 2k / 1728 per pixel
        flat = net.ravel().copy()
        silent, firing = np.flatnonzero(flat == 0)[:k], np.flatnonzero(flat != 0)[:k]
        assert len(firing) == k
        flat[silent] += 1
        flat[firing] -= np.sign(flat[firing])
        return flat.reshape(net.shape)
    assert regression.compare(case, frame, moved(40), str(tmp_path)) == []                  # 0.046 < 0.05
    assert any("events differ" in p for p in regression.compare(case, frame, moved(100), str(tmp_path)))  # 0.116
    assert regression.compare(case, frame, moved(100), str(tmp_path), other_backend=True) == []     # < 0.16
