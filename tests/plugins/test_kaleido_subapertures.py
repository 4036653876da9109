"""Where a kaleidoscope's views look from: each view (i, j) is a perspective view through its own sub-aperture
of the main lens, a_ij = (-1)^(i+1) (r - i W) D / (R + L) per axis (plugins/kaleido_optics.py: D the lens to
tube entrance distance, 1 / f = 1 / D + 1 / S, R the relay distance, L the tube length). The two axes obey one
law, so for a square tube the sub-apertures are transposes of each other, and a scene symmetric under x <-> y
renders to a film equal to its transpose; the sensor's view records and the derived geometry agree on the
sub-aperture pitch."""
import numpy as np
import pytest

from mitsuba_eventfield.plugins import kaleido_optics
from mitsuba_eventfield.plugins.kaleidoscope_sensor import optics_of

W_TUBE, L_TUBE, RELAY, FOCAL, FOCUS = 0.012, 0.06, 0.03, 0.05, 1.0


def test_the_subapertures_of_a_square_tube_are_transposes_of_each_other():
    """subaperture(i, j) at relay pupil point (rx, ry) is subaperture(j, i) at (ry, rx) with its components
    swapped, for every cell of a 5x5 kaleidoscope and pupil points off the axis; the diagonal cells' components
    are equal (cell (1, 1) from the pupil centre: (-7.02, -7.02) mm at the defaults' magnification 0.585)."""
    d = 1.0 / (1.0 / FOCAL - 1.0 / FOCUS)
    scale = d / (RELAY + L_TUBE)
    for rx, ry in ((0.0, 0.0), (1e-3, -2.5e-3), (-4e-3, 3e-3)):
        for i in range(-2, 3):
            for j in range(-2, 3):
                a = kaleido_optics.subaperture(i, j, rx, ry, W_TUBE, W_TUBE, scale, np)
                b = kaleido_optics.subaperture(j, i, ry, rx, W_TUBE, W_TUBE, scale, np)
                assert (float(a[0]), float(a[1])) == pytest.approx((float(b[1]), float(b[0])), abs=1e-15)
    one = kaleido_optics.subaperture(1, 1, 0.0, 0.0, W_TUBE, W_TUBE, scale, np)
    assert float(one[0]) == pytest.approx(float(one[1]), abs=1e-15)
    assert float(one[0]) == pytest.approx(-W_TUBE * scale, rel=1e-12)      # (-1)^(1+1) (0 - W) D / (R + L)


def test_a_transpose_symmetric_scene_renders_to_a_transposed_film():
    """A checkerboard emitter at 3 m (out of focus: the views' parallax is ~2 px) centred on the diagonal
    x = y, so the scene is its own transpose; 96x96 film (3x3 views of 32x32), 16 spp. The film equals its
    transpose in every tile to within pixel-sampling noise: measured mean |film - film^T| / mean 0.035-0.046
    per tile (0.018-0.023 at 64 spp); the y sub-apertures mirrored put the off-centre tiles 0.27-0.44 apart."""
    import mitsuba as mi
    n, z = 96, 3.0
    plane = mi.ScalarTransform4f().translate([0.15 * z, 0.15 * z, z]).rotate([1, 0, 0], 180).scale(2 * z)
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": {"type": "kaleidoscope", "sampler": {"type": "independent", "sample_count": 16},
                   "film": {"type": "hdrfilm", "width": n, "height": n, "rfilter": {"type": "box"},
                            "pixel_format": "luminance"}},
        "plane": {"type": "rectangle", "to_world": plane,
                  "emitter": {"type": "area", "radiance": {"type": "checkerboard", "color0": 0.1, "color1": 1.0,
                                                           "to_uv": mi.ScalarTransform3f().scale(11 * z)}}}})
    film = np.array(mi.render(scene, seed=0))[..., 0]
    diff = np.abs(film - film.T)
    tiles = [float(diff[r * 32:(r + 1) * 32, c * 32:(c + 1) * 32].mean() / film.mean())
             for r in range(3) for c in range(3)]
    print("mean |film - film^T| / mean per tile:", np.round(tiles, 3))
    assert max(tiles) < 0.1


def test_the_subaperture_pitch_is_the_spacing_of_the_sensors_views():
    """``kaleido_geometry``'s pitch (what the sensor checks its aperture and sub-aperture overlap against) is
    the spacing of the views' sub-apertures that the sensor records for light fields, on both axes of a 96x72
    film (tube 12 x 9 mm): W D / (R + L) = 7.018 mm and H D / (R + L) = 5.263 mm at D = 52.63 mm."""
    optics = optics_of("kaleidoscope", {}, 96, 72)
    w_tube, h_tube = optics["image_plane_size"]
    geo = kaleido_optics.kaleido_geometry(w_tube, h_tube, L_TUBE, RELAY, FOCAL, FOCUS, optics["aperture_radius"], 0.0)
    at = {(v["i"], v["j"]): np.array(v["subaperture"]) for v in optics["views"]}
    assert len(at) == 9 and geo["n"] == 3
    for (i, j), a in at.items():
        if (i + 1, j) in at:
            assert abs(at[(i + 1, j)][0] - a[0]) == pytest.approx(geo["subaperture_pitch"][0], rel=1e-9)
        if (i, j + 1) in at:
            assert abs(at[(i, j + 1)][1] - a[1]) == pytest.approx(geo["subaperture_pitch"][1], rel=1e-9)
    d = 1.0 / (1.0 / FOCAL - 1.0 / FOCUS)
    assert geo["subaperture_pitch"] == pytest.approx((w_tube * d / (RELAY + L_TUBE), h_tube * d / (RELAY + L_TUBE)),
                                                     rel=1e-12)
    print(f"pitch {np.array(geo['subaperture_pitch']) * 1e3} mm")
