"""The galvo sensor against Mitsuba's own cameras and against the mirror geometry."""
import math
import re

import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.optics import galvo as galvo_optics


def _mi():
    import mitsuba as mi
    return mi


def _textured_scene(sensor, width=64, height=48, spp=4):
    mi = _mi()
    T = mi.ScalarTransform4f
    return mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 2},
        "sensor": dict(sensor, fov=40, to_world=T().look_at(origin=[0, 0.3, -2], target=[0, 0, 1], up=[0, 1, 0]),
                       film={"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}},
                       sampler={"type": "independent", "sample_count": spp}),
        "env": {"type": "constant", "radiance": 0.3},
        "floor": {"type": "rectangle", "to_world": T().translate([0, -0.5, 0]).rotate([1, 0, 0], -90).scale(3),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "checkerboard",
                                                              "to_uv": mi.ScalarTransform3f().scale(6)}}},
        "ball": {"type": "sphere", "center": [0.3, 0, 0.5], "radius": 0.3,
                 "emitter": {"type": "area", "radiance": {"type": "checkerboard",
                                                          "to_uv": mi.ScalarTransform3f().scale(8)}}}})


@pytest.mark.parametrize("lens", ["pinhole", "thinlens"])
def test_zero_amplitude_reproduces_builtin_camera(lens):
    mi = _mi()
    builtin = {"type": "perspective"} if lens == "pinhole" else {"type": "thinlens", "aperture_radius": 0.05,
                                                                 "focus_distance": 2.3}
    galvo = {"type": "galvo", "amplitude": 0.0}
    if lens == "thinlens":
        galvo.update(aperture_radius=0.05, focus_distance=2.3)
    a = np.array(mi.render(_textured_scene(builtin), seed=1))
    b = np.array(mi.render(_textured_scene(galvo), seed=1))
    assert a.mean() > 0.1
    assert np.abs(a - b).max() < 1e-5


# --- a small bright point traces the scan curve; its size follows the mirror geometry -----------------
W = 128
FOV = 20.0
D1, SEP = 0.1, 0.03              # X mirror pivot 10 cm in front of the camera, Y mirror 3 cm further
A_DEG, FREQ = 2.0, 100.0


def _point_scene(z):
    mi = _mi()
    return ef.load_scene(mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": {"type": "galvo", "fov": FOV, "curve": "circle", "frequency": FREQ, "amplitude": A_DEG,
                   "mirror_distance": D1, "mirror_separation": SEP,
                   "film": {"type": "hdrfilm", "width": W, "height": W, "rfilter": {"type": "box"}},
                   "sampler": {"type": "stratified", "sample_count": 64, "jitter": False}},
        "led": {"type": "sphere", "center": [0, 0, z], "radius": 0.006 * z,
                "emitter": {"type": "area", "radiance": 1.0}}}))


def _centroids(timed, times):
    mi = _mi()
    out = []
    ys, xs = np.mgrid[0:W, 0:W] + 0.5
    for t in times:
        timed.set_time(t)
        img = np.array(mi.render(timed.scene, seed=0))[..., 0]
        out.append(((img * xs).sum() / img.sum(), (img * ys).sum() / img.sum()))
    return np.array(out)


def _semi_axes(t, xy):
    """Fit x, y = c + a cos(wt) + b sin(wt) (w known); return the amplitude along x and y."""
    w = 2 * math.pi * FREQ
    basis = np.c_[np.ones_like(t), np.cos(w * t), np.sin(w * t)]
    coef, *_ = np.linalg.lstsq(basis, xy, rcond=None)
    return np.hypot(coef[1], coef[2])


def test_point_traces_ellipse_sized_by_mirror_geometry(capsys):
    f = galvo_optics.focal_length_px(W, FOV)
    times = np.arange(12) / (12 * FREQ)
    measured = {}
    for z in (0.4, 0.8, 1.6):
        rx, ry = _semi_axes(times, _centroids(_point_scene(z), times))
        # first-order geometry (docs/design.md, "Physics"): r = 2 f A (1 - pivot / z), pivot d1 for x, d1 + s for y
        px = 2 * f * math.radians(A_DEG) * (1 - D1 / z)
        py = 2 * f * math.radians(A_DEG) * (1 - (D1 + SEP) / z)
        # exact geometry: project the point through the rotated mirrors
        curve = ef.make_curve("circle", frequency=FREQ, amplitude=A_DEG)
        ax, ay = curve.angles(np.linspace(0, 1 / FREQ, 400, endpoint=False))
        u, v = galvo_optics.project_point(np, (0.0, 0.0, z), ax, ay, D1, SEP, f, W, W)
        ex, ey = np.ptp(u) / 2, np.ptp(v) / 2
        with capsys.disabled():
            print(f"\n[galvo point z={z}] rx {rx:.3f} px (first order {px:.3f}, exact {ex:.3f}); "
                  f"ry {ry:.3f} px (first order {py:.3f}, exact {ey:.3f})")
        assert rx == pytest.approx(px, rel=0.01) and ry == pytest.approx(py, rel=0.01)
        assert rx == pytest.approx(ex, rel=0.005) and ry == pytest.approx(ey, rel=0.005)
        measured[z] = (rx, ry)
    # the trace grows with depth (pivot in front of the camera), and y (farther pivot) is the smaller axis
    assert measured[0.4][0] < measured[0.8][0] < measured[1.6][0]
    assert all(ry < rx for rx, ry in measured.values())


# --- edges: a circular scan sees every orientation, an x-only scan misses horizontal edges ----------------
def _square_scene(curve, **curve_params):
    mi = _mi()
    T = mi.ScalarTransform4f
    tex = np.full((64, 64), 0.05, np.float32)
    tex[16:48, 16:48] = 0.8                                 # bright square, dark surround
    return ef.load_scene(mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": dict({"type": "galvo", "fov": 30, "curve": curve, "mirror_distance": 0.03,
                        "film": {"type": "hdrfilm", "width": 64, "height": 64, "rfilter": {"type": "box"}},
                        "sampler": {"type": "independent", "sample_count": 4}}, **curve_params),
        "card": {"type": "rectangle", "to_world": T().translate([0, 0, 1.0]).rotate([0, 1, 0], 180).scale(0.4),
                 "emitter": {"type": "area", "radiance": {"type": "bitmap", "bitmap": mi.Bitmap(tex[..., None]),
                                                          "raw": True, "filter_type": "nearest"}}}}), motion=None)


def _edge_counts(ev):
    counts = ev.counts()
    # square edges in the image: card half-size 0.4 at z=1 -> [-0.2, 0.2]; image half-width tan(15 deg)
    half = math.tan(math.radians(15))
    lo, hi = [int(round(32 + 32 * v / half)) for v in (-0.2, 0.2)]
    mid = slice(28, 36)                                     # middle of the edge, away from the corners
    horizontal = counts[lo - 2:lo + 3, mid].sum() + counts[hi - 2:hi + 3, mid].sum()
    vertical = counts[mid, lo - 2:lo + 3].sum() + counts[mid, hi - 2:hi + 3].sum()
    return horizontal, vertical


def test_circle_scan_fires_on_all_edges_x_scan_misses_horizontal():
    ev_c = ef.render_events(_square_scene("circle", frequency=250.0, amplitude=0.5), 0.004, steps=40)
    ev_x = ef.render_events(_square_scene("line", frequency=250.0, amplitude=0.5, axis="x"), 0.004, steps=40)
    hc, vc = _edge_counts(ev_c)
    hx, vx = _edge_counts(ev_x)
    assert hc > 200 and vc > 200 and 0.8 < hc / vc < 1.25
    # An x-only scan moves horizontal edges along themselves: no events to first order. A yaw bends off-axis
    # horizontal lines at second order (~0.004 px here), which can flip a single sub-pixel sample sitting on a
    # hard texel edge: allow 0.5% of the vertical-edge count, not more.
    assert vx > 200 and hx <= 0.005 * vx


# --- period reuse, metadata, recompilation, errors ----------------------------------------------------------
def test_static_period_reuse_equals_full_render():
    timed = _square_scene("circle", frequency=250.0, amplitude=0.5)
    reused = ef.render_events(timed, 0.012, steps=60)           # 3 periods of 20 steps
    full = ef.render_events(timed, 0.012, steps=60, reuse=False)
    assert len(full) > 100 and reused.equals(full)
    r = reused.meta["render"]
    # period 1 is rendered, period 2 reuses its frames, and the pixel state then repeats, so period 3 is copied
    assert r["reused_steps"] == 21 and r["copied_steps"] == 20
    assert any("reused" in n for n in r["notes"]) and any("repeated" in n for n in r["notes"])
    assert full.meta["render"]["reused_steps"] == full.meta["render"]["copied_steps"] == 0
    # two periods: the state repeats after the second, with no period left to copy; said anyway ("the events of
    # the later periods are exact copies") until 2026-11-27
    two = ef.render_events(timed, 0.008, steps=40).meta["render"]
    assert two["copied_steps"] == 0 and not any("repeated" in n for n in two["notes"])


def test_event_copy_equals_computation_over_many_periods():
    """Copying events once the pixel state repeats is exact, also with a start time inside a period."""
    timed = _square_scene("circle", frequency=250.0, amplitude=0.5)
    fast = ef.render_events(timed, 0.04, steps=400, t_start=0.0017)        # 10 periods
    assert fast.meta["render"]["copied_steps"] >= 300
    slow = ef.render_events(timed, 0.04, steps=400, t_start=0.0017, reuse=False)
    assert len(slow) > 1000 and fast.equals(slow)


def test_event_angles_recovered_from_metadata_alone(tmp_path):
    timed = _square_scene("circle", frequency=250.0, amplitude=0.5, phase=40.0)
    ev = ef.render_events(timed, 0.004, steps=20)
    path = str(tmp_path / "g.h5")
    ef.write_events(path, ev)
    back = ef.read_events(path)
    ax, ay = back.scan_angles()
    expected = ef.make_curve("circle", frequency=250.0, amplitude=0.5, phase=40.0).angles(back.t * 1e-6)
    assert np.allclose(ax, expected[0]) and np.allclose(ay, expected[1])
    assert np.allclose(np.hypot(ax, ay), math.radians(0.5))


def test_galvo_time_updates_do_not_recompile():
    import drjit as dr
    timed = _square_scene("circle", frequency=250.0, amplitude=0.5)
    # the warm-ups render the measured render's steps (its chunks of steps: the event passes are recorded per
    # chunk shape, plugins/event_batch.py) at other instants, twice (a freshly loaded scene's frozen render
    # records twice: simulate/frames.py): what must not recompile is the scan's new times
    for t_start in (0.0061, 0.0087):
        ef.render_events(timed, 0.004, steps=12, reuse=False, t_start=t_start)
    dr.kernel_history()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        ef.render_events(timed, 0.004, steps=12, reuse=False, t_start=0.0123)
        history = dr.kernel_history()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    from conftest import steady_state_kernels
    steady, misses = steady_state_kernels(history, 12)
    assert len(steady) >= 9 and misses == []


@pytest.mark.parametrize("params, message", [
    ({"amplitude": 15.0}, "amplitude 15 deg at 250 Hz exceeds the galvo's derated limit of 2.074 deg"),
    ({"amplitude": 3.0, "max_angle": 2.0, "frequency": 30.0}, "exceeds the mechanical travel of +-2 deg"),
    ({"amplitude": 15.0, "galvo_model": "ideal"}, "exceeds the mechanical travel of +-10 deg"),
    ({"galvo_model": "gvs99"}, "galvo_model = 'gvs99': allowed gvs01x, ideal"),
    ({"frequency": 0.0}, "frequency (Hz) = 0.0: allowed range is (0, 1000]"),
    ({"frequency": -250.0}, "frequency (Hz) = -250.0"),
    ({"curve": "spiral"}, "unknown curve 'spiral'"),
])
def test_bad_galvo_parameters(params, message):
    mi = _mi()
    sensor = dict({"type": "galvo", "film": {"type": "hdrfilm", "width": 8, "height": 8}}, **params)
    with pytest.raises(Exception, match=re.escape(message)):
        mi.load_dict({"type": "scene", "sensor": sensor})


def test_galvo_camera_moves_through_motion_file():
    """The galvo's to_world is a motion target like any shape: a 0.3 m sideways move shifts a point at 2 m
    by f * 0.3 / 2 pixels."""
    mi = _mi()
    sc = mi.load_dict({"type": "scene", "integrator": {"type": "direct"},
                       "sensor": {"type": "galvo", "id": "cam", "amplitude": 0.0, "fov": 40,
                                  "film": {"type": "hdrfilm", "width": 32, "height": 32, "rfilter": {"type": "box"}},
                                  "sampler": {"type": "stratified", "sample_count": 16, "jitter": False}},
                       "led": {"type": "sphere", "center": [0, 0, 2], "radius": 0.05,
                               "emitter": {"type": "area", "radiance": 1.0}}})
    timed = ef.load_scene(sc, motion={"objects": {"cam": {"velocity": [1.0, 0, 0]}}})
    xs = np.mgrid[0:32, 0:32][1] + 0.5
    cx = []
    for t in (0.0, 0.3):
        timed.set_time(t)
        img = np.array(mi.render(sc))[..., 0]
        cx.append((img * xs).sum() / img.sum())
    assert cx[1] - cx[0] == pytest.approx(galvo_optics.focal_length_px(32, 40) * 0.3 / 2.0, rel=0.02)
