"""Calibration from the data itself, against the geometry the simulation knows."""
import math
import os

import numpy as np
import pytest
from conftest import ROOT, TEST_VARIANT

import mitsuba_eventfield as ef
from mitsuba_eventfield.calibration import CalibrationError, fit_depth, fit_galvo, fit_tracks, track_point
from mitsuba_eventfield.optics import galvo as galvo_optics

GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")
LED = os.path.join(ROOT, "scenes", "led_depth", "led.xml")
W, H = 173, 130
FREQ = 250.0


def _exact_radius(optics, pixel, depth, amplitude_deg, phase_deg, width=W, height=H):
    """Radius (px, along x) of the circle traced by the scene point seen at ``pixel`` of the first view, at
    ``depth``: ray through the pixel at the first view's mirror angles, onto the plane z = depth, then projected
    through the mirrors at every angle of the scan (mitsuba_eventfield/optics/galvo.py)."""
    f = galvo_optics.focal_length_px(width, optics["fov_x_deg"])
    d1, s = optics["mirror_distance"], optics["mirror_separation"]
    curve = ef.make_curve("circle", frequency=FREQ, amplitude=amplitude_deg, phase=phase_deg)
    th0 = curve.angles(0.0)
    u, v = (pixel[0]) / width, (pixel[1]) / height
    d = galvo_optics.pinhole_direction(np, u, v, math.tan(math.radians(optics["fov_x_deg"]) / 2), width / height)
    o, d = galvo_optics.galvo_transform(np, (0.0, 0.0, 0.0), d, th0[0], th0[1], d1, s)
    t = (depth - o[2]) / d[2]
    p = (o[0] + t * d[0], o[1] + t * d[1], depth)
    ax, ay = curve.angles(np.linspace(0, 1 / FREQ, 720, endpoint=False))
    uu, _ = galvo_optics.project_point(np, p, ax, ay, d1, s, f, width, height)
    return np.ptp(uu) / 2


@pytest.mark.parametrize("seed", [1, 2])
def test_galvo_phase_and_radius_from_frames(seed, capsys):
    rng = np.random.default_rng(seed)
    phase, amp = float(rng.uniform(0, 360)), float(rng.uniform(0.3, 0.6))
    scene = ef.load_scene(GALVO, width=W, height=H, amplitude=amp, phase=phase)
    times = np.arange(16) / 16 / FREQ
    frames = ef.render_frames(scene, times)
    nominal = ef.make_curve("circle", frequency=FREQ, amplitude=amp)          # phase unknown to the fit
    patches = [(30, 40), (30, 90)]                                              # the wall, 2.5 m
    cal = fit_galvo(frames, times, nominal, patches)
    optics = scene.sensor.optics_metadata()
    exact = np.mean([_exact_radius(optics, (x + 0.5, y + 0.5), 2.5, amp, phase) for x, y in patches])
    err = (cal.phase_deg - phase + 180) % 360 - 180
    with capsys.disabled():
        print(f"\n[galvo calibration] phase {phase:.2f} deg -> {cal.phase_deg:.2f} +- {cal.std['phase_deg']:.2f} "
              f"(error {err:+.3f}); radius {exact:.3f} px -> {cal.radius_px()[0]:.3f} px; rms {cal.rms_px:.3f} px")
    assert abs(err) < 1.0
    assert abs(cal.radius_px()[0] - exact) < 0.1
    # frames starting a quarter period later: the first-frame phase moves by 90 deg, the clock phase does not
    late = fit_galvo(ef.render_frames(scene, times + 0.25 / FREQ), times + 0.25 / FREQ, nominal, patches)
    assert abs((late.phase_deg - phase - 90 + 180) % 360 - 180) < 1.0
    assert abs((late.clock_phase_deg - phase + 180) % 360 - 180) < 1.0


def test_galvo_calibration_from_event_reconstruction():
    phase = 137.0
    scene = ef.load_scene(GALVO, width=W, height=H, amplitude=0.5, phase=phase)
    ev = ef.render_events(scene, 1 / FREQ, steps=32, threshold=0.1)
    times = np.arange(16) / 16 / FREQ
    frames = ef.reconstruct.direct(ev, times, ef.render_frames(scene, [0.0])[0], 0.0)
    cal = fit_galvo(frames, times, ef.make_curve("circle", frequency=FREQ, amplitude=0.5), [(30, 40), (30, 90)])
    assert abs((cal.phase_deg - phase + 180) % 360 - 180) < 1.0


def _led_scale(depth, phase=0.0):
    scene = ef.load_scene(LED, depth=depth, radius=0.006 * depth, phase=phase)
    times = np.arange(24) / 24 / FREQ
    frames = ef.render_frames(scene, times, log=False)
    cal = fit_tracks([track_point(frames)], times, ef.make_curve("circle", frequency=FREQ, amplitude=0.5))
    return cal, scene.sensor.optics_metadata()


def test_depth_calibration_recovers_the_geometry(capsys):
    inches = np.array([15, 25, 35, 50, 65, 80, 100])
    depths = inches * 0.0254
    scales, optics = [], None
    for z in depths:
        cal, optics = _led_scale(float(z))
        scales.append(cal.scale_px_per_rad[0])
    dc = fit_depth(depths, scales)
    f = galvo_optics.focal_length_px(346, optics["fov_x_deg"])
    with capsys.disabled():
        print(f"\n[depth calibration 15-100 in] scale residual rms: inverse {dc.rms_inverse:.3f}, linear (paper) "
              f"{dc.rms_linear:.3f} px/rad; depth rms: inverse {dc.depth_rms_inverse * 1000:.1f} mm, linear "
              f"{dc.depth_rms_linear * 1000:.1f} mm; pivot {dc.pivot * 100:.2f} cm (set {optics['mirror_distance'] * 100:.1f} "
              f"cm); S_inf {dc.inverse[0]:.1f} px/rad (2f = {2 * f:.1f})")
    # On exact projections the inverse model recovers the pivot to 1e-4 (checked when this was written); here the
    # rendered LED centroids carry ~0.05 px of noise (5.5 px/rad in scale), which sets these bounds.
    assert dc.best == "inverse" and dc.rms_inverse < dc.rms_linear / 5
    assert abs(dc.pivot - optics["mirror_distance"]) / optics["mirror_distance"] < 0.05
    assert abs(dc.inverse[0] - 2 * f) / (2 * f) < 0.02
    z = dc.depth(scales)
    near = depths < 1.0                                     # depth is well determined where dS/dz is large
    assert np.allclose(z[near], depths[near], rtol=0.08)


def test_refusals_with_reasons():
    scene = ef.load_scene(GALVO, width=W, height=H, amplitude=0.5)
    times = np.arange(16) / 16 / FREQ
    frames = ef.render_frames(scene, times)
    curve = ef.make_curve("circle", frequency=FREQ, amplitude=0.5)
    with pytest.raises(CalibrationError, match="at least 4 are needed"):
        fit_galvo(frames[:3], times[:3], curve, [(30, 40)])
    flat = np.zeros_like(frames)
    with pytest.raises(CalibrationError, match="textureless"):
        fit_galvo(flat, times, curve, [(30, 40)])
    rng = np.random.default_rng(0)
    noisy = frames + rng.normal(0, 3.0, frames.shape)                     # noise far above the contrast
    with pytest.raises(CalibrationError, match="too uncertain|too\\s+noisy|only .* frames match|positive curve"):
        fit_galvo(noisy, times, curve, [(30, 40)])
    with pytest.raises(CalibrationError, match="at least 3 distinct depths"):
        fit_depth([0.5, 0.5, 1.0], [1, 2, 3])


# --- kaleidoscope -------------------------------------------------------------------------------------------
def _mosaic(offsets, n=3, tile=64, seed=4):
    """A kaleidoscope-like mosaic: view (i, j) is a band-limited texture shifted by offsets[(i, j)], odd tiles
    mirrored, so neighbouring tiles are mirror images across their seam."""
    from lf_scenes import texture
    from scipy.ndimage import fourier_shift
    base = texture(seed, size=tile + 32, blob=2).astype(np.float64)
    half = (n - 1) // 2
    mosaic = np.zeros((n * tile, n * tile))
    for (i, j), (dx, dy) in offsets.items():
        shifted = np.fft.ifft2(fourier_shift(np.fft.fft2(base), (dy, dx))).real[16:16 + tile, 16:16 + tile]
        t = shifted[:, ::-1] if i % 2 else shifted
        t = t[::-1] if j % 2 else t
        r, c = j + half, i + half
        mosaic[r * tile:(r + 1) * tile, c * tile:(c + 1) * tile] = t
    return np.log(mosaic)


def test_kaleidoscope_registration_recovers_offsets(capsys):
    from mitsuba_eventfield.calibration.kaleidoscope import register
    rng = np.random.default_rng(7)
    offsets = {(i, j): ((0.0, 0.0) if (i, j) == (0, 0) else tuple(rng.uniform(-1.5, 1.5, 2)))
               for i in (-1, 0, 1) for j in (-1, 0, 1)}
    cal = register(_mosaic(offsets))
    errs = [math.hypot(v["offset"][0] - offsets[(v["i"], v["j"])][0], v["offset"][1] - offsets[(v["i"], v["j"])][1])
            for v in cal.views]
    with capsys.disabled():
        print(f"\n[kaleidoscope registration] n = {cal.n}, max offset error {max(errs):.3f} px (offsets up to 1.5 px)")
    assert cal.n == 3 and cal.tile == (64, 64)
    assert max(errs) < 0.1


def test_kaleidoscope_tiles_found_on_a_render_and_flat_field():
    import mitsuba as mi
    from lf_scenes import kaleido_sensor, two_planes

    from mitsuba_eventfield.calibration.kaleidoscope import find_tiles, flat_field, register
    ef.set_variant(TEST_VARIANT)
    target = two_planes(mi, kaleido_sensor(film=240, spp=4), blank_strip=False)   # a calibration target ...
    target.pop("near")
    target["far"]["to_world"] = mi.ScalarTransform4f().translate([0, 0, 1.0]).rotate([0, 1, 0], 180).scale(0.5)
    frame = np.log(np.array(mi.render(mi.load_dict(target)))[..., 0])              # ... at the focus distance
    tiles = find_tiles(frame)
    assert tiles["x"]["n"] == tiles["y"]["n"] == 3 and tiles["x"]["seams"] == [80, 160]
    cal = register(frame, tiles)
    flat_scene = dict(two_planes(mi, kaleido_sensor(film=240, spp=4, relay_aperture=0.002)))
    flat_scene["far"]["emitter"]["radiance"] = 1.0                                   # uniform white target
    flat_scene.pop("near")
    gains = flat_field(cal, np.array(mi.render(mi.load_dict(flat_scene)))[..., 0])
    assert gains.shape == (9, 80, 80) and abs(gains[4].mean() - 1) < 1e-6
    assert gains[:, :, 0].mean() < gains[:, :, 40].mean()       # the relay pupil vignettes at the seams
    with pytest.raises(CalibrationError, match="uniform"):
        find_tiles(np.ones((96, 96)))


def test_depth_calibration_keeps_each_axis_pivot(tmp_path):
    """The y mirror sits further from the lens than the x mirror: each axis gets its own disparity model."""
    from mitsuba_eventfield.calibration import load_calibration, optics_record, save_calibration
    f, z = 100.0, np.array([0.4, 0.7, 1.0, 1.6, 2.5])
    dc = fit_depth(z, 2 * f * (1 - 0.10 / z), scales_y=2 * f * (1 - 0.11 / z))
    optics = {"design": "galvo", "fov_x_deg": 40.0, "mirror_distance": 0.1, "mirror_separation": 0.01,
              "scan": {"curve": "circle", "frequency": FREQ, "amplitude": 0.5, "phase": 0.0}}
    save_calibration(str(tmp_path / "c.json"), optics_record(optics, W, H), depth=dc)
    nominal = galvo_optics.GalvoGeometry(W, H, f, 0.3, 0.5)                       # pivots that the calibration replaces
    g = load_calibration(str(tmp_path / "c.json"))["depth"].geometry(nominal)
    assert np.allclose([g.pivot_x, g.pivot_y, g.gain_x, g.gain_y], [0.10, 0.11, 1.0, 1.0])
    g1 = fit_depth(z, 2 * f * (1 - 0.10 / z)).geometry(nominal)
    assert g1.pivot_y == g1.pivot_x                                      # x only: both axes share it
    # a mirror that turns 3 % less than commanded: the scale at infinity is 3 % smaller, the gain says so
    g2 = fit_depth(z, 0.97 * 2 * f * (1 - 0.10 / z)).geometry(nominal)
    assert g2.gain_x == pytest.approx(0.97) and g2.pivot_x == pytest.approx(0.10)
    with pytest.raises(CalibrationError, match="scales_y: 2 values for 5 depths"):
        fit_depth(z, 2 * f * (1 - 0.10 / z), scales_y=[1.0, 2.0])


def _ray_traced_scales(point, d1, s, f, width, height, delta=1e-6):
    """Pixels per mechanical radian of each mirror for a camera-frame point, by ray geometry alone
    (``project_point``, not the homographies): central differences of its image position."""
    def at(tx, ty):
        return np.array(galvo_optics.project_point(np, point, tx, ty, d1, s, f, width, height))
    sx = (at(delta, 0.0) - at(-delta, 0.0))[0] / (2 * delta)
    sy = (at(0.0, delta) - at(0.0, -delta))[1] / (2 * delta)
    return abs(sx), abs(sy), at(0.0, 0.0)


def test_scan_scale_off_axis_is_the_ray_traced_one_and_the_depth_fit_uses_it():
    """An LED off the axis moves by 2 f (k - pivot / z) per radian, k = 1 + t^2 (``GalvoGeometry.scan_scale``):
    fitted as if on the axis (k = 1) its gain came out (1 + t^2) high and its pivot as much short."""
    f = galvo_optics.focal_length_px(W, 40.0)
    d1, sep = 0.1, 0.01
    geometry = galvo_optics.GalvoGeometry(W, H, f, d1, d1 + sep)
    z = np.array([0.4, 0.7, 1.0, 1.6, 2.5])
    sx, sy, pixels = [], [], []
    for depth in z:                                 # the LED on one off-axis ray: t = (0.3, -0.2) at every depth
        a, b, centre = _ray_traced_scales((0.3 * depth, -0.2 * depth, depth), d1, sep, f, W, H)
        assert geometry.scan_scale(depth, *centre) == pytest.approx((a, b), rel=1e-6)
        sx, sy, pixels = sx + [a], sy + [b], pixels + [centre]
    assert geometry.field_factors(*pixels[0]) == pytest.approx((1.09, 1.04))
    # an LED on the axis (the film's centre, W x H not square): the default reference pixel, k = 1 on both axes
    a, b, centre = _ray_traced_scales((0.0, 0.0, 1.0), d1, sep, f, W, H)
    assert centre == pytest.approx((W / 2, H / 2)) and W != H
    assert geometry.field_factors() == (1.0, 1.0) and geometry.scan_scale(1.0) == pytest.approx((a, b), rel=1e-6)
    factors = [geometry.field_factors(*c) for c in pixels]
    for gain in (1.0, 0.97):                        # a mirror turning 3 % less than commanded
        fitted = fit_depth(z, gain * np.array(sx), gain * np.array(sy), field_factors=factors).geometry(geometry)
        assert (fitted.pivot_x, fitted.pivot_y) == pytest.approx((d1, d1 + sep), rel=1e-6)
        assert (fitted.gain_x, fitted.gain_y) == pytest.approx((gain, gain), rel=1e-6)
    # the paper's linear model, fitted to the scales as measured, is judged against the inverse model where the
    # LEDs were (against the on-axis one its valid range came out empty: nan to nan)
    lo, hi = fit_depth(z, sx, sy, field_factors=factors).linear_valid_range()
    assert lo < 0.7 < hi and (lo, hi) == pytest.approx(fit_depth(z, sx, sy).linear_valid_range(), rel=0.05)
    on_axis = fit_depth(z, sx, sy).geometry(geometry)           # what the fit did before: 9 % and 4 % off
    assert on_axis.gain_x == pytest.approx(1.09, rel=1e-3) and on_axis.pivot_x == pytest.approx(d1 / 1.09, rel=1e-3)
    with pytest.raises(CalibrationError, match=r"field_factors: shape \(2, 2\) for 5 depths"):
        fit_depth(z, sx, sy, field_factors=factors[:2])


def test_calibration_file_round_trip_and_use_in_refocus(tmp_path):
    """Galvo + depth calibration saved, loaded and applied: a light field whose metadata optics are wrong
    (mirror distance off by 2x) gets back the right depth from depth from focus."""
    from mitsuba_eventfield.calibration import apply_to_lightfield, load_calibration, optics_record, save_calibration
    from mitsuba_eventfield.calibration.depth import fit_depth

    # depth calibration from exact geometry of the LED scene's galvo (the test above checks the LED fit)
    f = galvo_optics.focal_length_px(W, 40.0)
    z = np.array([0.4, 0.7, 1.0, 1.6, 2.5])
    dc = fit_depth(z, 2 * f * (1 - 0.1 / z))
    scene = ef.load_scene(GALVO, width=W, height=H, amplitude=0.5, phase=70.0)
    times = np.arange(24) / 24 / FREQ
    frames = ef.render_frames(scene, times)
    gc = fit_galvo(frames, times, ef.make_curve("circle", frequency=FREQ, amplitude=0.5), [(30, 40), (30, 90)])
    optics = dict(scene.sensor.optics_metadata(), mirror_distance=0.2)          # wrong nominal geometry
    optics["scan"] = dict(optics["scan"], phase=0.0)                            # and unknown phase
    record = optics_record(optics, W, H)        # the calibration is made for (and checked against) these optics
    path = str(tmp_path / "cal.json")
    save_calibration(path, record, galvo=gc, depth=dc)
    cal = load_calibration(path)
    assert abs(cal["galvo"].phase_deg - gc.phase_deg) < 1e-9 and cal["depth"].best == dc.best
    lf = ef.from_galvo(frames, times, optics)
    wrong = ef.depth_from_focus(lf, 0.3, 5.0, 32, "tenengrad")
    right = ef.depth_from_focus(apply_to_lightfield(lf, cal, record), 0.3, 5.0, 32, "tenengrad")
    card, wall = np.s_[50:80, 95:140], np.s_[20:110, 10:40]
    good = right.confidence > 0.3
    assert abs(np.median(right.depth[card][good[card]]) - 0.5) < 0.05
    # at 173 px a 10 cm pivot separates 2.5 m from 5 m by 0.1 px of disparity: per pixel the wall is beyond what
    # the views resolve (not confident: focus/depth.py), and over the whole wall it is only "far"
    assert good[wall].mean() < 0.05 and np.median(right.resolution_px[wall]) < 0.05
    assert np.median(right.depth[wall]) > 1.0
    assert abs(np.median(wrong.depth[card][(wrong.confidence > 0.3)[card]]) - 0.5) > 0.1
    with pytest.raises(ef.EventFieldError, match="not a version 2"):
        (tmp_path / "bad.json").write_text('{"format": "x"}')
        load_calibration(str(tmp_path / "bad.json"))


def test_linear_depth_model_is_kept_only_with_a_warning_saying_where_it_breaks():
    f, z = 100.0, np.array([0.4, 0.7, 1.0, 1.6, 2.5])
    scale = lambda d: 2 * f * (1 - 0.10 / np.asarray(d))                # noqa: E731  exact geometry
    dc = fit_depth(z, scale(z))
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")                                 # the physical model does not warn
        assert dc.depth(scale(z)) == pytest.approx(z, rel=1e-9)
    lo, hi = dc.linear_valid_range()
    assert 0.1 < lo < hi < 10
    with pytest.warns(UserWarning, match=r"linear size-vs-depth model .* within 5% .* only for depths"):
        outside = dc.depth(scale([0.8 * lo, 1.3 * hi]), model="linear")
    assert np.all(np.abs(outside / [0.8 * lo, 1.3 * hi] - 1) > 0.05)   # it really is off there
    with pytest.warns(UserWarning):
        inside = dc.depth(scale([lo * 1.01, hi * 0.99]), model="linear")
    assert np.all(np.abs(inside / [lo * 1.01, hi * 0.99] - 1) <= 0.05)


def test_a_common_sub_pixel_bias_of_the_later_frames_is_not_a_phase_error():
    """Exact displacements of two patches on a 250 Hz circle, every frame after the first shifted by the same
    (0, 0.3) px (a template matches its own frame at a whole pixel, later frames carry the sub-pixel peak's
    bias): the phase was off by 1.4 degrees here (about 7 degrees a pixel along the first motion) before each
    patch had an offset of its own; now within 0.15 (frame 0, unbiased, is the one point off), scale 0.3 %."""
    from mitsuba_eventfield.calibration import PatchTrack
    curve = ef.make_curve("circle", frequency=250.0, amplitude=0.5)
    times = (np.arange(32) + 0.5) * curve.period / 32
    tau0, scale = 0.31e-3, (520.0, 480.0)
    ax, ay = curve.angles(tau0 + times - times[0])
    a0x, a0y = curve.angles(np.float64(tau0))
    exact = np.stack([scale[0] * (ax - a0x), scale[1] * (ay - a0y)], axis=-1)
    biased = exact + np.where(np.arange(32)[:, None] > 0, [0.0, 0.3], 0.0)
    tracks = [PatchTrack((30.0, 40.0), biased, np.ones(32)), PatchTrack((30.0, 90.0), biased.copy(), np.ones(32))]
    fit = fit_tracks(tracks, times, curve)
    true_phase = tau0 / curve.period * 360
    assert abs((fit.phase_deg - true_phase + 180) % 360 - 180) < 0.15
    assert fit.scale_px_per_rad == pytest.approx(scale, rel=3e-3)
