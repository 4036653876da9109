"""The kaleidoscope and microlens sensors against real mirrors and against thin-lens geometry."""
import math

import numpy as np
import pytest

import mitsuba_eventfield as ef


def _mi():
    import mitsuba as mi
    return mi


def test_unfolded_tube_matches_real_mirrors_on_every_tile(capsys):
    mi = _mi()
    from mitsuba_eventfield.plugins.kaleidoscope_sensor import mirror_tube_shapes
    W, H, L, R = 1.0, 0.75, 2.0, 1.0               # scale-free; large units keep RayEpsilon negligible

    def scene(mode, mirrors):
        d = {"type": "scene", "integrator": {"type": "path", "max_depth": 8},
             "sensor": {"type": "kaleidoscope", "mode": mode, "tube_width": W, "tube_height": H, "tube_length": L,
                        "relay_distance": R, "film": {"type": "hdrfilm", "width": 192, "height": 144,
                                                      "rfilter": {"type": "box"}},
                        "sampler": {"type": "independent", "sample_count": 4}},
             "plane": {"type": "rectangle",
                       "to_world": mi.ScalarTransform4f().translate([0.3, 0.1, 3.0]).rotate([0, 1, 0], 180).scale(4),
                       "emitter": {"type": "area", "radiance": {"type": "checkerboard", "color0": 0.1, "color1": 1.0,
                                                                "to_uv": mi.ScalarTransform3f().scale(7)}}}}
        if mirrors:
            d.update(mirror_tube_shapes(W, H, L))
        return mi.load_dict(d)

    real = np.array(mi.render(scene("physical_tube", True), seed=0))[..., 0]
    unfolded = np.array(mi.render(scene("tube_only", False), seed=0))[..., 0]
    errors = []
    for r in range(3):
        for c in range(3):
            sl = np.s_[r * 48:(r + 1) * 48, c * 64:(c + 1) * 64]
            errors.append(np.abs(real[sl] - unfolded[sl]).mean() / unfolded[sl].mean())
    with capsys.disabled():
        print("\n[kaleidoscope] unfolded vs real mirrors, mean relative error per tile: "
              + " ".join(f"{e:.2e}" for e in errors))
    assert real.mean() > 0.3
    assert max(errors) < 5e-3          # isolated samples flip at checker edges by mirror RayEpsilon offsets


# --- a point at a known depth lands in every view where the thin-lens geometry puts it ----------------------
F, S = 0.05, 1.0                       # main lens focal length, focus distance


def _point_scene(layout, point, film=192, **extra):
    mi = _mi()
    sensor = dict({"type": "kaleidoscope", "layout": layout, "focal_length": F, "focus_distance": S,
                   "film": {"type": "hdrfilm", "width": film, "height": film, "rfilter": {"type": "box"}},
                   "sampler": {"type": "stratified", "sample_count": 64, "jitter": False}}, **extra)
    return mi.load_dict({"type": "scene", "integrator": {"type": "direct"}, "sensor": sensor,
                         "led": {"type": "sphere", "center": list(point), "radius": 0.002 * point[2] / 0.5,
                                 "emitter": {"type": "area", "radiance": 1.0}}})


def _predicted_view_position(optics, a, point, view_w, view_h):
    """Thin lens: the ray from P through sub-aperture a meets the image plane (distance D) at
    p = a (1 - D / z') + p0, p0 = -P D / z, 1/z' = 1/f - 1/z; views map p to pixels like the centre view."""
    D = optics["lens_to_image_plane"]
    W, H = optics["image_plane_size"]
    x, y, z = point
    zi = 1 / (1 / F - 1 / z)
    px = a[0] * (1 - D / zi) - x * D / z
    py = a[1] * (1 - D / zi) - y * D / z
    return (0.5 + px / W) * view_w, (0.5 + py / H) * view_h


def _centroid(img):
    ys, xs = np.mgrid[0:img.shape[0], 0:img.shape[1]] + 0.5
    return (img * xs).sum() / img.sum(), (img * ys).sum() / img.sum()


def test_views_show_point_at_predicted_disparity(capsys):
    mi = _mi()
    point = (0.02, 0.012, 0.5)                  # nearer than the focus plane: clear disparity
    sc = _point_scene("kaleidoscope", point)
    optics = sc.sensors()[0].optics_metadata()
    stack = ef.extract_views(np.array(mi.render(sc))[..., 0], optics)
    h, w = stack.images.shape[1:]
    errs, shifts = [], []
    for img, a in zip(stack.images, stack.positions):
        mx, my = _centroid(img)
        ex, ey = _predicted_view_position(optics, a, point, w, h)
        errs.append(math.hypot(mx - ex, my - ey))
        shifts.append((mx, ex))
    centre = _predicted_view_position(optics, (0, 0), point, w, h)
    spread = max(abs(e - centre[0]) for _, e in shifts)
    with capsys.disabled():
        print(f"\n[kaleidoscope] point at z={point[2]}: max position error {max(errs):.3f} px over 9 views "
              f"(disparity up to {spread:.2f} px)")
    assert spread > 1.0                          # the test is sensitive to the sign of the disparity
    assert max(errs) < 0.1


@pytest.mark.parametrize("views", [3, 2, 4])
def test_microlens_views_follow_the_same_geometry(views):
    """Each view's image of a point moves as its metadata's sub-aperture says, for odd and even view counts
    (an even count's metadata was half a cell off: views = 2 put its sub-apertures at 0 and -7.3 mm where the
    rays pass at +-4.2, a 0.9 px error in each view's position)."""
    mi = _mi()
    point = (0.0, 0.0, 0.4)
    sc = _point_scene("microlens", point, film=240, views=views, aperture_radius=0.01, tube_width=0.012,
                      tube_height=0.012)
    optics = sc.sensors()[0].optics_metadata()
    stack = ef.extract_views(np.array(mi.render(sc))[..., 0], optics)
    h, w = stack.images.shape[1:]
    assert np.allclose(stack.positions.mean(axis=0), 0.0, atol=1e-12)     # symmetric about the axis
    # lenslet-sized pixels bias every view's centroid alike: compare displacements from the views' mean
    measured = np.array([_centroid(img) for img in stack.images])
    predicted = np.array([_predicted_view_position(optics, a, point, w, h) for a in stack.positions])
    err = (measured - measured.mean(axis=0)) - (predicted - predicted.mean(axis=0))
    assert np.abs(err).max() < 0.3
    assert np.abs(predicted[:, 0] - predicted[:, 0].mean()).max() > 1.0    # disparity: the sign is tested


# --- events: static scenes are silent; motion parallel to an edge fires nothing ------------------------
def _stripes_scene(sensor, orientation, velocity):
    mi = _mi()
    tex = np.full((64, 64), 0.1, np.float32)
    if orientation == "horizontal":
        tex[::8] = 0.9
    else:
        tex[:, ::8] = 0.9
    return ef.load_scene(mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": dict(sensor, film={"type": "hdrfilm", "width": 96, "height": 96, "rfilter": {"type": "box"}},
                       sampler={"type": "independent", "sample_count": 4}),
        "card": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, 1.0]).rotate([0, 1, 0], 180)
                 .scale(1.0),
                 "emitter": {"type": "area", "radiance": {"type": "bitmap", "bitmap": mi.Bitmap(tex[..., None]),
                                                          "raw": True, "filter_type": "nearest"}}}}),
        motion={"objects": {"card": {"velocity": [velocity, 0.0, 0.0]}}} if velocity else None)


KALEIDO = {"type": "kaleidoscope", "focal_length": F, "focus_distance": S}
GALVO = {"type": "galvo", "fov": 12, "curve": "circle", "frequency": 250.0, "amplitude": 0.1}


def test_kaleidoscope_static_scene_is_silent_and_parallel_edges_fire_nothing():
    static = ef.render_events(_stripes_scene(KALEIDO, "vertical", 0.0), 0.004, steps=8)
    assert len(static) == 0
    across = ef.render_events(_stripes_scene(KALEIDO, "vertical", 2.0), 0.004, steps=20)
    along = ef.render_events(_stripes_scene(KALEIDO, "horizontal", 2.0), 0.004, steps=20)
    assert len(across) > 500
    assert len(along) <= 0.002 * len(across)
    # the galvo's circular scan sees the horizontal stripes even when they only move along themselves
    galvo_along = ef.render_events(_stripes_scene(GALVO, "horizontal", 2.0), 0.004, steps=40)
    assert len(galvo_along) > 500


def test_split_events_into_views(tmp_path):
    timed = _stripes_scene(KALEIDO, "vertical", 2.0)
    ev = ef.render_events(timed, 0.002, steps=10)
    path = str(tmp_path / "k.h5")
    ef.write_events(path, ev)
    back = ef.read_events(path)
    views = ef.split_events(back)
    assert len(views) == 9 and sum(len(v) for v in views) == len(ev)
    for v in views:
        assert v.width == 32 and v.height == 32 and (len(v) == 0 or v.x.max() < 32)
    # the centre view's events are the centre tile's, unchanged
    c = views[4]
    sel = (ev.x >= 32) & (ev.x < 64) & (ev.y >= 32) & (ev.y < 64)
    assert np.array_equal(np.sort(c.x.astype(int) + 32), np.sort(ev.x[sel].astype(int)))


def test_each_views_events_are_that_views_pixels():
    """``split_events`` against ``extract_views`` on the same pixels: one event at every pixel of the film, its
    time the pixel's index; each view's events must sit, unflipped, where ``extract_views`` puts the image of
    pixel indices (the centre view alone, unflipped, could not tell a flip or a view order wrong)."""
    timed = _stripes_scene(KALEIDO, "vertical", 2.0)
    optics = timed.sensor.optics_metadata()
    w, h = (int(v) for v in timed.sensor.film().size())
    yy, xx = np.mgrid[0:h, 0:w]
    ids = (yy * w + xx).ravel()
    ev = ef.EventStream(xx.ravel(), yy.ravel(), ids, np.ones(ids.size, np.int8), w, h, {"optics": optics})
    images = ef.extract_views(ids.reshape(h, w), optics).images
    views = ef.split_events(ev)
    assert len(views) == len(images) == 9
    for k, (v, image) in enumerate(zip(views, images)):
        assert len(v) == image.size and np.array_equal(image[v.y, v.x], v.t), k


@pytest.mark.parametrize("params, message", [
    ({"relay_distance": 0.025}, "must be an odd integer n"),
    ({"aperture_radius": 0.003}, "the main lens cuts the outer views"),
    ({"relay_aperture": 0.008}, "sub-apertures .* overlap"),
    ({"tube_width": -0.01}, "tube_width = -0.01: must be a finite length > 0"),
    ({"film": {"type": "hdrfilm", "width": 100, "height": 100}}, "not a multiple of 3 views"),
    ({"film": {"type": "hdrfilm", "width": 96, "height": 48}, "tube_height": 0.012}, "aspect ratio"),
    ({"layout": "hexagonal"}, "layout = 'hexagonal'"),
])
def test_bad_geometry_is_refused(params, message):
    mi = _mi()
    sensor = dict({"type": "kaleidoscope", "film": {"type": "hdrfilm", "width": 96, "height": 96}}, **params)
    with pytest.raises(Exception, match=message):
        mi.load_dict({"type": "scene", "sensor": sensor})
