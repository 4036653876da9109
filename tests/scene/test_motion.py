"""Motion files: poses against closed-form geometry, validation errors that name file and key."""
import math
import warnings

import numpy as np
import pytest
from conftest import DEMO

import mitsuba_eventfield as ef


def test_velocity_and_spin_poses():
    m = ef.parse_motion({"objects": {
        "a": {"velocity": [1.0, 2.0, 0.0]},
        "b": {"spin": {"rpm": 60, "axis": [0, 0, 1], "center": [1, 0, 0]}, "velocity": [0, 0, 3]}}})
    pa = m.objects["a"].matrix(0.5) @ [0, 0, 0, 1]
    assert np.allclose(pa[:3], [0.5, 1.0, 0.0])
    # 60 rpm: a quarter turn in 0.25 s about the axis through (1,0,0); the point (2,0,0) goes to (1,1,0)
    pb = m.objects["b"].matrix(0.25) @ [2, 0, 0, 1]
    assert np.allclose(pb[:3], [1.0, 1.0, 0.75])


def test_poses_over_an_array_of_times_match_one_by_one():
    """``matrices`` (closed form over all times) against ``matrix`` at each time, for velocity, a spin about an
    unnormalised axis, and keyframes combined with both; the spin also against the closed form above."""
    m = ef.parse_motion({"objects": {"o": {
        "velocity": [0.3, -1.0, 2.0], "spin": {"rpm": 137, "axis": [1, 2, 2], "center": [0.5, 0, -1]},
        "keyframes": [{"t": 0.0, "translate": [0, 0, 0]}, {"t": 0.2, "translate": [1, 0, 0], "rotate": [10, 0, 30]}]}}})
    obj = m.objects["o"]
    times = np.linspace(-0.1, 0.4, 41)
    assert np.allclose(obj.matrices(times), np.stack([obj.matrix(t) for t in times]), atol=1e-12)
    spin = ef.parse_motion({"objects": {"b": {"spin": {"rpm": 60, "axis": [0, 0, 1], "center": [1, 0, 0]}}}})
    assert np.allclose((spin.objects["b"].matrices([0.25])[0] @ [2, 0, 0, 1])[:3], [1.0, 1.0, 0.0])


@pytest.mark.parametrize("interp", ["linear", "cubic", "step"])
def test_keyframes(interp):
    m = ef.parse_motion({"objects": {"k": {"interpolation": interp, "keyframes": [
        {"t": 0.0, "translate": [0, 0, 0]}, {"t": 1.0, "translate": [2, 0, 0], "rotate": [0, 0, 90]},
        {"t": 2.0, "translate": [2, 2, 0], "rotate": [0, 0, 90]}]}}})
    o = m.objects["k"]
    at = lambda t: (o.matrix(t) @ [1, 0, 0, 1])[:3]  # noqa: E731
    assert np.allclose(at(1.0), [2, 1, 0])            # keyframes are hit exactly
    assert np.allclose(at(5.0), [2, 3, 0])            # held after the last one
    assert np.allclose(at(-1.0), [1, 0, 0])           # and before the first
    mid = at(0.5)
    if interp == "step":
        assert np.allclose(mid, [1, 0, 0])
    elif interp == "linear":                          # half translation, 45 degree slerp
        assert np.allclose(mid, [1 + math.cos(math.pi / 4), math.sin(math.pi / 4), 0])
    else:
        assert not np.allclose(mid, [1 + math.cos(math.pi / 4), math.sin(math.pi / 4), 0])


@pytest.mark.parametrize("raw, message", [
    ({"objects": {"a": {"velocity": [1, 2]}}}, "objects.a.velocity"),
    ({"objects": {"a": {"spin": {"rpm": "fast"}}}}, "objects.a.spin.rpm"),
    ({"objects": {"a": {"spin": {"rpm": 5, "axis": [0, 0, 0]}}}}, "objects.a.spin.axis"),
    ({"objects": {"a": {"keyframes": [{"t": 1}, {"t": 0}]}}}, "strictly increasing"),
    ({"objects": {"a": {"keyframes": [{"t": 0}], "interpolation": "bezier"}}}, "'linear', 'cubic', 'step'"),
    ({"objects": {"a": {"velocty": [0, 0, 1]}}}, "unknown key objects.a.velocty"),
    ({"objects": {"a": {}}}, "declares no motion"),
    ({"duration": -1}, "duration"),
])
def test_validation_errors_name_the_key(raw, message):
    with pytest.raises(ef.ConfigError, match="demo.motion.toml.*" + message.replace("(", r"\(")):
        ef.parse_motion(raw, source="demo.motion.toml")


def test_missing_target_id_lists_movable_ids():
    with pytest.raises(ef.EventFieldError, match=r"no movable object with id 'ghost'.*ball.*cube"):
        ef.load_scene(DEMO, motion={"objects": {"ghost": {"velocity": [1, 0, 0]}}}, width=16, height=12)


def test_mesh_and_shape_updates_follow_the_pose(monkeypatch):
    import drjit as dr
    import mitsuba as mi

    from mitsuba_eventfield.scene import instancing
    monkeypatch.setenv(instancing.ENV, "0")     # the mesh form (CUDA loads moving shapes as instances)
    timed = ef.load_scene(DEMO, width=16, height=12)
    # a step writes and updates the moving parameters alone (3 of the demo's 40); what follows reads them back
    # through the full set and ray-casts the scene, so the objects and their parents saw the update
    assert sorted(timed._moving.keys()) == ["ball.to_world", "cube.vertex_normals", "cube.vertex_positions"]
    assert len(timed.params.keys()) > 30
    v0 = np.array(timed.params["cube.vertex_positions"]).reshape(-1, 3)
    bbox0 = np.array(timed.scene.bbox().max)
    timed.set_time(0.05)
    v1 = np.array(timed.params["cube.vertex_positions"]).reshape(-1, 3)
    expected = (timed.motion.objects["cube"].matrix(0.05) @ np.c_[v0, np.ones(len(v0))].T).T[:, :3]
    assert np.allclose(v1, expected, atol=1e-5)
    # half a turn at 300 rpm after 0.1 s: the cube maps onto itself mirrored through its axis
    timed.set_time(0.1)
    v2 = np.array(timed.params["cube.vertex_positions"]).reshape(-1, 3)
    c = np.array([0.8, 0.25, 0.0])
    assert np.allclose(v2[:, [0, 2]] - c[[0, 2]], -(v0[:, [0, 2]] - c[[0, 2]]), atol=1e-5)
    # the ball (an analytic sphere) moved 0.4 m along x: check it through a ray cast
    ray = mi.Ray3f(mi.Point3f(-0.5, 0.3, 5.0), mi.Vector3f(0, 0, -1))
    hit = timed.scene.ray_intersect(ray)
    assert abs(hit.p.z[0] - (0.6 + 0.3)) < 1e-3     # ball centre now at x=-0.5, z=0.6, radius 0.3
    timed.set_time(0.0)
    hit0 = timed.scene.ray_intersect(ray)
    assert not (abs(hit0.p.z[0] - 0.9) < 1e-3)
    del bbox0, dr


@pytest.mark.parametrize("shapes", [2, 6])
def test_many_moving_meshes_move_in_one_kernel_per_step(shapes):
    """Rigid motion of many meshes is one Dr.Jit kernel per step whatever their number, and later steps
    compile nothing (a literal per shape or per time would recompile every step)."""
    import drjit as dr
    import mitsuba as mi
    scene = mi.load_dict({"type": "scene", "sensor": {"type": "perspective"},
                          **{f"c{i}": {"type": "cube", "id": f"c{i}"} for i in range(shapes)}})
    motion = {"objects": {f"c{i}": {"velocity": [0.1 * i, 0, 0], "spin": {"rpm": 60.0 * i, "axis": [0, 1, 0], "center": [0, 0, 0]}} for i in range(shapes)}}
    timed = ef.load_scene(scene, motion=motion)
    for t in (0.001, 0.0015):          # two warm-up steps: a first step's own kernels are not the steady state's
        timed.set_time(t)
    dr.eval()
    dr.kernel_history()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        for k in range(2, 6):
            timed.set_time(0.001 * k)
        history = [h for h in dr.kernel_history() if h.get("type") == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    # per step: our one kernel for every mesh's vertices and normals, plus Mitsuba's own update of each mesh
    # (parameters_changed); moving the meshes one by one took two per mesh (12 against 7 for six meshes)
    assert len(history) == 4 * (1 + shapes) and all(h.get("cache_hit") for h in history)
    v = np.array(timed.params[f"c{shapes - 1}.vertex_positions"]).reshape(-1, 3)
    assert abs(v[:, 0].mean() - 0.1 * (shapes - 1) * 0.005) < 1e-5       # the last cube moved with its velocity


def test_a_step_moves_meshes_and_shapes_without_copying_entries_to_or_from_the_device():
    """A step of three moving meshes and a moving rectangle copies no matrix entry to or from the device one by
    one: each single-entry copy is a sync on a GPU (the fan's step made 66 of them with matrices from NumPy and
    the rectangle's read back for Mitsuba's host-side copy). What remains are Mitsuba's bounding-box reads of
    each mesh (6 of 128 bytes); the meshes' matrices go to the device in one array.
    Vertices against the motion's own matrices applied in NumPy, the rectangle by a ray."""
    import drjit as dr
    import mitsuba as mi
    scene = mi.load_dict({"type": "scene", "sensor": {"type": "perspective"},
                          **{f"m{i}": {"type": "cube", "id": f"m{i}"} for i in range(3)},
                          "r": {"type": "rectangle", "id": "r",
                                "to_world": mi.ScalarTransform4f().translate([5, 0, 0])}})
    motion = {"objects": {
        "m0": {"velocity": [0.3, 0, 0], "spin": {"rpm": 600, "axis": [0, 1, 1], "center": [1, 0, 0]}},
        "m1": {"velocity": [0, -2, 0]},
        "m2": {"spin": {"rpm": 60, "axis": [1, 0, 0], "center": [0, 0, 0]}},
        "r": {"velocity": [0, 0, 40], "spin": {"rpm": 900, "axis": [0, 0, 1], "center": [5, 0, 0]}}}}
    timed = ef.load_scene(scene, motion=motion)
    base = {k: np.array(timed.params[f"{k}.vertex_positions"]).reshape(-1, 3).astype(np.float64)
            for k in ("m0", "m1", "m2")}
    timed.set_time(0.01)
    dr.sync_thread()
    dr.kernel_history()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        timed.set_time(0.02)
        dr.sync_thread()
        history = dr.kernel_history()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    copies = [h["size"] for h in history if h.get("type") == dr.KernelType.Memcpy]
    assert not [c for c in copies if c <= 64] and len(copies) <= 6 * 3, copies
    for k in ("m0", "m1", "m2"):
        m = timed.motion.objects[k].matrix(0.02)
        expect = base[k] @ m[:3, :3].T + m[:3, 3]
        got = np.array(timed.params[f"{k}.vertex_positions"]).reshape(-1, 3)
        assert np.abs(got - expect).max() < 1e-5
    # the rectangle (z = 0 at rest, away from the cubes) now at z = 0.8, turned about its centre; a ray along z
    hit = timed.scene.ray_intersect(mi.Ray3f(mi.Point3f(5.1, 0.2, 5.0), mi.Vector3f(0, 0, -1)))
    assert abs(hit.p.z[0] - 0.8) < 1e-5


def test_moving_emitting_shapes_compile_nothing_after_the_first_frames():
    """A moving shape that emits keeps values of its transform as literals in its emitter's sampling: from a
    literal (scalar-built) to_world an unfrozen render compiled a new kernel every frame (5 of 5). Its
    transform is made opaque; a plain moving shape keeps the literal (no read-back: the test above)."""
    import drjit as dr
    import mitsuba as mi
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path"},
        "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 16, "height": 12}},
        "lamp": {"type": "rectangle", "id": "lamp", "emitter": {"type": "area", "radiance": 1.0},
                 "to_world": mi.ScalarTransform4f().translate([0, 0, 3])},
        "ball": {"type": "sphere", "id": "ball", "emitter": {"type": "area", "radiance": 2.0},
                 "to_world": mi.ScalarTransform4f().translate([1, 0, 4])},
        "card": {"type": "rectangle", "id": "card", "to_world": mi.ScalarTransform4f().translate([-1, 0, 5])}})
    timed = ef.load_scene(scene, motion={"objects": {"lamp": {"velocity": [0.5, 0, 0]},
                                                     "ball": {"velocity": [0, 0.5, 0]},
                                                     "card": {"velocity": [0, -0.5, 0]}}})
    first = ef.render_frames(timed, [0.0, 0.01], log=False)
    dr.kernel_history()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        later = ef.render_frames(timed, list(np.linspace(0.02, 0.1, 5)), log=False)
        history = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert history and all(k["cache_hit"] for k in history)
    assert np.abs(later[-1] - first[0]).max() > 0.1          # the lamp and the ball did move in the image


def test_a_render_past_the_keyframes_says_the_object_holds_its_pose():
    """Outside its keyframes an object holds its first or last pose (the motion file's rule): a render past
    them warns with the object and both spans; one inside them, or of a keyframed object that does not move,
    says nothing; velocity and spin alone never end."""
    from mitsuba_eventfield.scene.motion import MotionHeldWarning
    from mitsuba_eventfield.simulate.stepping import stepping
    m = ef.parse_motion({"objects": {
        "thrown": {"keyframes": [{"t": 0.01, "translate": [0, 0, 0]}, {"t": 0.05, "translate": [0, -0.1, 0]}]},
        "parked": {"keyframes": [{"t": 0.0, "translate": [1, 0, 0]}, {"t": 0.01, "translate": [1, 0, 0]}]},
        "rolling": {"velocity": [1, 0, 0], "spin": {"rpm": 60}}}})
    assert m.held_poses(0.01, 0.05) == []
    assert m.held_poses(0.0, 0.05) == [("thrown", 0.01, 0.05)]
    assert m.held_poses(0.02, 0.06) == [("thrown", 0.01, 0.05)]
    timed = ef.load_scene(DEMO)
    timed.motion = m
    with pytest.warns(MotionHeldWarning, match=r"'thrown' has keyframes from 0.01 to 0.05 s; the render runs "
                                               r"0.01 to 0.08 s"):
        stepping(timed, 0.07, 4, False, 0.1, None, None, 1, 0, "fixed", 0.01)
    with warnings.catch_warnings():
        warnings.simplefilter("error", MotionHeldWarning)
        stepping(timed, 0.04, 4, False, 0.1, None, None, 1, 0, "fixed", 0.01)


def test_a_ctrl_c_inside_a_load_or_a_frozen_call_stays_a_stop(monkeypatch):
    """A generation loop that catches EventFieldError per scene went on after the user's Ctrl-C: Mitsuba
    returned the interrupt raised in a plugin's constructor as its own error (the interrupt in its cause or only
    in its text), and Dr.Jit's traversal of a frozen function's arguments as a RuntimeError. Both are
    KeyboardInterrupt again."""
    from mitsuba_eventfield.plugins.frozen import FrozenOrTraced
    from mitsuba_eventfield.scene import timed

    def interrupted_load(*a, **k):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as stop:
            raise RuntimeError('failed to instantiate integrator plugin of type "eventfield":') from stop
    monkeypatch.setattr(timed.sampler_module, "load_text", interrupted_load)
    with pytest.raises(KeyboardInterrupt):
        ef.load_scene(DEMO)
    monkeypatch.setattr(timed.sampler_module, "load_text", lambda *a, **k: (_ for _ in ()).throw(
        RuntimeError("plugin raised\nTraceback (most recent call last):\nKeyboardInterrupt")))
    with pytest.raises(KeyboardInterrupt):
        ef.load_scene(DEMO)
    frozen = FrozenOrTraced(lambda x: x)

    def interrupted_call(*a):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as stop:
            raise RuntimeError("FlatVariables::assign(): error encountered while processing an argument") from stop
    frozen.frozen = interrupted_call
    with pytest.raises(KeyboardInterrupt):
        frozen(1)
