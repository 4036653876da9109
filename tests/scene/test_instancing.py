"""Moving shapes loaded as Mitsuba instances (scene/instancing.py; on by default on CUDA only): which shapes the
rewrite wraps, that the render moves them as the mesh form does (the same events but for the transforms' float
rounding), and that the shape-index coverage still finds an instanced object."""
import os
import xml.etree.ElementTree as ET

import pytest
from conftest import DEMO, ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield.scene import instancing
from mitsuba_eventfield.scene.coverage import shape_masks, unseen

FAN = os.path.join(ROOT, "scenes", "fan", "fan.xml")

SCENE = """<scene version="3.0.0">
    <shape type="sphere" id="ball"><float name="radius" value="0.1"/></shape>
    <shape type="rectangle" id="lamp"><emitter type="area"/></shape>
    <shape type="cube" id="still"/>
    <shape type="instance" id="copy"><ref id="somewhere"/></shape>
</scene>"""


def test_the_rewrite_wraps_moving_shapes_without_emitters():
    text, wrapped = instancing.rewrite(SCENE, ["ball", "lamp", "copy", "missing"])
    assert wrapped == ["ball"]                            # an emitter, an instance, an unknown id: left alone
    assert '<shape type="shapegroup" id="ball__group"><shape type="sphere" id="ball__shape">' in text
    assert '<shape type="instance" id="ball"><ref id="ball__group" /></shape>' in text
    assert 'id="lamp"' in text and 'id="still"' in text and 'id="copy"' in text
    assert instancing.rewrite(SCENE, ["lamp", "still_not"]) == (None, [])
    # each group and its instance take the shape's place: a shape may refer to what is defined above it
    text, wrapped = instancing.rewrite(SCENE, ["ball", "still"])
    order = [el.get("id") for el in ET.fromstring(text)]
    assert wrapped == ["ball", "still"]
    assert order == ["ball__group", "ball", "lamp", "still__group", "still", "copy"]
    assert instancing.rewrite("<scene", ["ball"]) == (None, [])      # Mitsuba's loader reports bad XML


def test_on_by_default_on_cuda_only(monkeypatch):
    import mitsuba as mi
    monkeypatch.delenv(instancing.ENV, raising=False)
    cuda = mi.variant().startswith("cuda")
    assert instancing.wanted() == cuda
    assert ef.load_scene(DEMO, width=32, height=24).instanced == (["ball", "cube"] if cuda else [])
    assert ef.load_scene(DEMO, motion=None, width=32, height=24).instanced == []      # nothing moves


@pytest.mark.parametrize("scene", [DEMO, FAN], ids=["demo", "fan"])
def test_instances_render_the_mesh_forms_events(monkeypatch, scene):
    """The demo's ball and cube, the fan's blades and label: moved by their instances' ``to_world``, the same
    events as moving the shapes themselves, up to the transforms' float rounding (measured: 0 and 2 of 2,421
    and 126,177 events on this film; the H100 gave 26 of 966 k on the demo)."""
    runs = {}
    for forced in ("0", "1"):
        monkeypatch.setenv(instancing.ENV, forced)
        timed = ef.load_scene(scene, width=64, height=48)
        runs[forced] = (timed.instanced, ef.render_events(timed, 0.008, steps=32))
    (plain_ids, plain), (ids, inst) = runs["0"], runs["1"]
    assert plain_ids == [] and ids == sorted(n for n, o in ef.load_scene(scene).motion.objects.items())
    assert len(plain) > 2000 and abs(len(inst) - len(plain)) <= 1e-3 * len(plain)
    assert inst.meta["scene"]["instanced"] == ids and "instanced" not in plain.meta["scene"]


def test_coverage_finds_an_instanced_object(monkeypatch):
    masks = {}
    for forced in ("0", "1"):
        monkeypatch.setenv(instancing.ENV, forced)
        timed = ef.load_scene(DEMO, width=64, height=48)
        masks[forced] = shape_masks(timed, 0.05)
        assert unseen(timed, ["ball", "cube", "wall"]) == []
    for sid in ("ball", "cube"):
        plain, inst = masks["0"][sid], masks["1"][sid]
        assert plain.sum() > 30 and (plain & inst).sum() >= 0.97 * (plain | inst).sum()
