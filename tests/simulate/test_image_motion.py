"""Image motion per step (the coarse-step note) against closed-form projections."""
import math
import re

import pytest
from conftest import ROOT
from traced_galvo import traced_scan_path_px

import mitsuba_eventfield as ef
from mitsuba_eventfield.simulate.image_motion import note_image_motion, object_px_per_step, scan_px_per_step
from mitsuba_eventfield.simulate.summary import RenderSummary


def _sliding_sphere(width=64, velocity=0.5):
    """A sphere of radius 0.1 at 2 m in front of a 45 deg pinhole, sliding sideways at ``velocity`` m/s."""
    import mitsuba as mi
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "eventfield", "threshold": 0.2},
        "sensor": {"type": "perspective", "fov": 45.0, "to_world": mi.ScalarTransform4f().look_at(
            origin=[0, 0, 0], target=[0, 0, 1], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": width, "height": width * 3 // 4}},
        "ball": {"type": "sphere", "id": "ball", "center": [0, 0, 2.0], "radius": 0.1,
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 1.0}}}})
    return ef.load_scene(scene, motion={"objects": {"ball": {"velocity": [velocity, 0, 0]}}})


def test_object_motion_matches_the_pinhole_projection():
    """The box corner nearest the camera (z = 1.9 m) moves fastest on the image: f v dt / 1.9 pixels a step."""
    timed = _sliding_sphere()
    focal = 64 / (2 * math.tan(math.radians(45.0) / 2))
    duration, steps = 0.02, 10
    expected = focal * 0.5 * (duration / steps) / 1.9
    assert object_px_per_step(timed, 0.0, duration, steps) == pytest.approx(expected, rel=0.02)
    # more steps than the motion is sampled at (256): still the path of one step, a thousandth of it here
    assert object_px_per_step(timed, 0.0, duration, 1000) == pytest.approx(expected * steps / 1000, rel=0.02)
    assert scan_px_per_step(timed, duration, steps) is None


def test_coarse_steps_are_noted_with_the_steps_that_suffice():
    timed = _sliding_sphere(velocity=20.0)               # 5 ms steps: 0.1 m, 77.25 px x 0.1 / 1.9 = 4.07 px
    coarse, fine = RenderSummary(), RenderSummary()
    note_image_motion(timed, 0.0, 0.02, 4, coarse)
    note_image_motion(timed, 0.0, 0.02, 64, fine)
    assert coarse.image_motion_px_per_step["objects"] == pytest.approx(4.07, rel=0.02)
    assert "steps coarser than the image motion" in coarse.notes[0]
    need = int(re.search(r"; (\d+) steps \(render --steps", coarse.notes[0])[1])
    assert need == 17 and fine.notes == [] and fine.image_motion_px_per_step["objects"] < 1


def test_galvo_scan_motion_in_the_render_metadata():
    """The fan's scan: the image path of one period (the same geometry the light fields use) over the steps of
    a period; recorded in every render's metadata, noted when over a pixel."""
    from mitsuba_eventfield.scene import bundled_scene
    timed = ef.load_scene(bundled_scene("fan/fan.xml"), width=48, height=36)
    ev = ef.render_events(timed, 0.004, steps=4)         # one 4 ms period in 4 steps: about 1.8 px each
    motion = ev.meta["render"]["image_motion_px_per_step"]
    path = traced_scan_path_px(timed.sensor.optics_metadata(), 48, 36)   # ray-traced, not the metadata's own
    assert motion["scan"] == pytest.approx(path / 4, rel=1e-3) and motion["scan"] > 1
    assert any("steps coarser than the image motion" in n for n in ev.meta["render"]["notes"])


def test_the_coarse_step_warning_says_the_scan_and_objects_add_up():
    """The fan at 96x72, 80 steps over 20 ms: the scan (0.90 px a step) and the blades (0.88 px) are each under
    a pixel; a point on a blade moves by both, 1.78 px, which is what the warning is about and must say."""
    from mitsuba_eventfield.scene import bundled_scene
    from mitsuba_eventfield.simulate.render import _new_summary
    from mitsuba_eventfield.simulate.stepping import stepping
    timed = ef.load_scene(bundled_scene("fan/fan.xml"), width=96, height=72)
    st = stepping(timed, 0.02, 80, False, 0.5, None, None, 4, 0, "fixed", 0.0, 1.0)
    notes = _new_summary(timed, st, None).notes
    scan = float(notes[0].split("per step the scan ")[1].split(" px")[0])
    assert scan < 1 and "together 1.78 px" in notes[0]


def test_a_moving_object_under_a_scan_moves_by_both():
    """A point on the grid sliding under the galvo's circle moves on the image by the scan's path and the
    grid's together (the circle's image speed is the same all round it, the slide's too): the largest image
    speed of the scene is the scan's alone (the scene without its motion) plus the grid's (its path per step),
    not the larger of the two (measured 2373 + 211 px/s)."""
    from mitsuba_eventfield.simulate.image_motion import largest_image_speed
    path, duration = f"{ROOT}/scenes/moving_grid/galvo.xml", 0.02
    moving, still = ef.load_scene(path, views_px=96), ef.load_scene(path, views_px=96, motion=None)
    scan = largest_image_speed(still, 0.0, duration)
    slide = object_px_per_step(moving, 0.0, duration, 100) * 100 / duration
    assert scan > 1000 and slide > 100
    assert largest_image_speed(moving, 0.0, duration) == pytest.approx(scan + slide, rel=1e-6)


def test_a_step_just_over_a_pixel_is_printed_as_more_than_one():
    """The coarse-step warning printed "the scan 1 px (more than 1 px ...); 129 steps" for 1.0004 px: pixels
    are written to as many digits as tell them from the bound."""
    from mitsuba_eventfield.simulate.image_motion import _px
    assert [_px(v) for v in (1.0004, 1.0, 3.871, 0.5)] == ["1.0004", "1", "3.87", "0.5"]
