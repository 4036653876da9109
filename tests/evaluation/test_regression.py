"""Regression images: the bundled scenes render as blessed (eventfield regression --bless re-blesses)."""
import os
import shutil

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
