"""A kaleidoscope calibration applied to light fields (``calibration.apply_to_lightfield``): the registration of a
misaligned tube, measured on a target, puts refocus and depth back where a perfect tube has them; a target off the
focus plane gives the thin-lens parallax and nothing else; the flat field divides out the relay's vignetting in
views whose levels a frame gave, and leaves views made from events alone as they are.

Ground truth: the rendered scene's own geometry (two textured planes at NEAR and FAR, lf_scenes), the same
scene through a tube with no misalignment (integer shifts of whole tiles are exact) and without the relay pupil
(no vignetting), and the thin-lens disparity model (``Disparity.for_spatial``) the registration is not given."""
import numpy as np
import pytest
from conftest import TEST_VARIANT
from lf_scenes import FAR, NEAR, kaleido_sensor, two_planes

import mitsuba_eventfield as ef
from mitsuba_eventfield.calibration import (apply_to_lightfield, flat_field, known_tiles, load_calibration,
                                            optics_record, register, save_calibration)

N, TILE = 3, 80
NEAR_REGION, FAR_REGION = np.s_[10:70, 5:35], np.s_[10:70, 42:54]
# whole-pixel misalignments of each view (dx, dy) in its own unflipped coordinates, centre view fixed
MISALIGNED = {(-1, -1): (2, -2), (-1, 0): (-2, -1), (-1, 1): (-2, 2), (0, -1): (2, 0), (0, 0): (0, 0),
              (0, 1): (-2, -2), (1, -1): (-1, 0), (1, 0): (1, 0), (1, 1): (-1, -2)}


@pytest.fixture(scope="module")
def renders():
    ef.set_variant(TEST_VARIANT)
    import mitsuba as mi

    def render(scene):
        return np.array(mi.render(mi.load_dict(scene)))[..., 0]
    scene = mi.load_dict(two_planes(mi, kaleido_sensor(spp=128)))
    optics = scene.sensors()[0].optics_metadata()
    targets = {}
    for depth in (1.0, FAR):           # the far card alone, at the focus distance and where it is
        target = two_planes(mi, kaleido_sensor(spp=16), blank_strip=False)
        target.pop("near")
        target["far"]["to_world"] = mi.ScalarTransform4f().translate([0, 0, depth]).rotate([0, 1, 0], 180).scale(0.5)
        targets[depth] = render(target)
    vignetted = render(two_planes(mi, kaleido_sensor(spp=128, relay_aperture=0.002)))
    flat = dict(two_planes(mi, kaleido_sensor(spp=128, relay_aperture=0.002)))
    flat["far"]["emitter"]["radiance"] = 1.0                                  # a uniform white target
    flat.pop("near")
    return np.array(mi.render(scene))[..., 0], optics, targets, vignetted, render(flat)


def _misalign(frame: np.ndarray) -> np.ndarray:
    """The film of a tube whose views sit ``MISALIGNED`` pixels off (each tile's content moved in its own
    unflipped coordinates; what leaves one edge enters the other, outside the regions scored)."""
    out = frame.copy()
    for row in range(N):
        for col in range(N):
            i, j = col - 1, row - 1
            tile = out[row * TILE:(row + 1) * TILE, col * TILE:(col + 1) * TILE]
            flip = (slice(None, None, -1 if j % 2 else 1), slice(None, None, -1 if i % 2 else 1))
            dx, dy = MISALIGNED[(i, j)]
            tile[:] = np.roll(tile[flip], (dy, dx), axis=(0, 1))[flip]
    return out


def _depths(lf) -> tuple:
    dm = ef.depth_from_focus(lf, 0.4, 3.0, 32, "variance")
    return float(np.median(dm.depth[NEAR_REGION])), float(np.median(dm.depth[FAR_REGION]))


def test_registration_of_a_misaligned_tube_restores_refocus_and_depth(renders, tmp_path, capsys):
    scene, optics, targets, _, _ = renders
    cal = register(np.log(_misalign(targets[1.0])), known_tiles(N, N * TILE, N * TILE))
    for v in cal.views:
        assert np.allclose(v["offset"], MISALIGNED[(v["i"], v["j"])], atol=0.02), v
    record = optics_record(optics, N * TILE, N * TILE)
    path = save_calibration(str(tmp_path / "k.json"), record, kaleidoscope=cal)
    calibration = load_calibration(path)                      # through the file, as the CLI takes it
    perfect = ef.from_spatial(scene, optics, log=False)
    misaligned = ef.from_spatial(_misalign(scene), optics, log=False)
    fixed = apply_to_lightfield(misaligned, calibration, record)
    assert fixed.meta["calibrated"] == ["kaleidoscope"]
    depths = {name: _depths(lf) for name, lf in (("perfect", perfect), ("misaligned", misaligned),
                                                 ("calibrated", fixed))}
    sharp, sharp_fixed = ef.refocus(perfect, NEAR)[NEAR_REGION], ef.refocus(fixed, NEAR)[NEAR_REGION]
    rms = float(np.sqrt(np.mean((sharp_fixed - sharp) ** 2)))
    with capsys.disabled():
        print(f"\n[kaleidoscope registration applied] near / far card (truth {NEAR} / {FAR} m): "
              + ", ".join(f"{k} {a:.3f} / {b:.3f}" for k, (a, b) in depths.items())
              + f"; refocus at the near card vs the perfect tube: rms {rms:.4f}")
    for z, measured in zip((NEAR, FAR), depths["calibrated"]):
        assert abs(measured - z) / z < 0.01
    assert abs(depths["misaligned"][1] - FAR) / FAR > 0.05            # what the calibration is for
    assert rms < 0.003


def test_a_target_off_the_focus_plane_gives_only_its_parallax(renders):
    """Registered on the card at 1.5 m, the views are displaced by its thin-lens parallax (up to 0.8 px here);
    taken out with ``target_depth``, what is left for a perfect tube is nothing."""
    scene, optics, targets, _, _ = renders
    lf = ef.from_spatial(scene, optics, log=False)
    cal = register(np.log(targets[FAR]), known_tiles(N, N * TILE, N * TILE))
    measured = np.array([v["offset"] for v in cal.views])
    assert 0.5 < np.abs(measured).max()
    cal.target_depth = FAR
    assert np.abs(cal.misalignment(lf.meta["ij"], lf.positions, lf.disparity)).max() < 0.01


def test_flat_field_divides_frame_levels_and_leaves_event_levels(renders):
    scene, optics, targets, vignetted, flat = renders
    record = optics_record(optics, N * TILE, N * TILE)
    cal = register(np.log(targets[1.0]), known_tiles(N, N * TILE, N * TILE))
    flat_field(cal, flat)
    cal.optics = record
    truth = ef.from_spatial(scene, optics, log=False).views[:, 5:75, 5:75]     # no relay pupil: no vignetting
    lf = ef.from_spatial(vignetted, optics, log=False)
    fixed = apply_to_lightfield(lf, {"kaleidoscope": cal}, record)
    assert fixed.meta["calibrated"] == ["flat_field", "kaleidoscope"]
    before, after = lf.views[:, 5:75, 5:75] / truth, fixed.views[:, 5:75, 5:75] / truth
    assert np.percentile(before, 5) < 0.8                              # the relay vignettes at the seams
    assert 0.98 < np.percentile(after, 1) and np.percentile(after, 99) < 1.02
    # the same film as levels integrated from events: log changes carry no gain, so nothing is divided
    from_events = ef.from_spatial(vignetted, optics, log=False, levels="events")
    kept = apply_to_lightfield(from_events, {"kaleidoscope": cal}, record)
    assert kept.meta["calibrated"] == ["kaleidoscope"] and np.array_equal(kept.views, from_events.views)
    assert kept.view_offsets is not None and np.abs(kept.view_offsets).max() < 0.05


def test_view_offsets_belong_to_spatial_light_fields_and_follow_subsets(renders):
    scene, optics, _, _, _ = renders
    lf = ef.from_spatial(scene, optics, log=False)
    offsets = np.arange(18, dtype=float).reshape(9, 2) / 10
    moved = ef.LightField(lf.views, lf.positions, lf.times, lf.disparity, lf.kind, lf.meta, None, offsets)
    assert np.allclose(moved.shifts(NEAR) - lf.shifts(NEAR), offsets)
    assert np.allclose(moved.alignments(NEAR)[:, :2, 2], moved.shifts(NEAR))
    assert np.allclose(moved.subset([2, 5]).view_offsets, offsets[[2, 5]])
    with pytest.raises(ef.ConfigError, match="view_offsets of shape"):
        ef.LightField(lf.views, lf.positions, lf.times, lf.disparity, lf.kind, lf.meta, None, offsets[:3])


def test_a_light_field_knows_where_its_levels_come_from(renders):
    """The flat field divides only frame levels (``meta['levels']``): from_events labels each method."""
    from mitsuba_eventfield.lightfield.streams import from_events
    scene, optics, _, _, _ = renders
    t = np.arange(0, 2000, 20)
    ev = ef.EventStream(t % (N * TILE), (t // 7) % (N * TILE), t, np.where(t % 40, 1, -1), N * TILE, N * TILE,
                        {"optics": optics, "t_start_us": 0, "duration_us": 2000,
                         "pixel_model": {"threshold_on": 0.2, "threshold_off": 0.2}})
    start = np.log(scene)
    assert from_events(ev).meta["levels"] == "events"                                   # high-pass
    assert from_events(ev, method="direct").meta["levels"] == "events"                  # from a zero start
    assert from_events(ev, log_start=start).meta["levels"] == "frame"
    assert from_events(ev, method="complementary", log_start=start).meta["levels"] == "frame"
    with pytest.raises(ef.ConfigError, match="method 'highpass' reconstructs from the events alone"):
        from_events(ev, method="highpass", log_start=start)
    with pytest.raises(ef.ConfigError, match="'complementary' needs log_start"):
        from_events(ev, method="complementary")


def _negative_map() -> str:
    import base64
    return base64.b64encode(np.full((N * TILE, N * TILE), -1.0, "<f2").tobytes()).decode("ascii")


@pytest.mark.parametrize("edit, message", [
    (lambda k: k["views"][1].update(offset=["a", 0]), r"offset = \['a', 0\]: must be \[dx, dy\] in pixels"),
    (lambda k: k["views"][1].update(offset=[1e6, 0]), "must be within half a tile"),
    (lambda k: k["views"].pop(), "views must list the 9 views"),
    (lambda k: k.update(tile="x"), "tile = 'x': must be"),
    (lambda k: k.update(target_depth=-1), "target_depth = -1: must be a number > 0"),
    (lambda k: k["flat_map"].update(shape=[57600]), "flat_map must be a finite, non-negative 240x240 gain map"),
    (lambda k: k["flat_map"].update(base64=_negative_map()), "flat_map must be a finite, non-negative"),
    # the recorded layout, never read before: refused where it is not the sensor's (view (0, -1) is flipped in y)
    (lambda k: k["views"][1].update(flip_y=False), r"view \(0, -1\): flip_y = False: the 80x80 px tiles' layout "
                                                   r"has True \(the sensor's"),
    (lambda k: k["views"][1].update(flip_x=1), r"view \(0, -1\): flip_x = 1: .* has False"),
    (lambda k: k["views"][0].update(tile=[0, 0, 80, 79]), r"view \(-1, -1\): tile = \[0, 0, 80, 79\]"),
    (lambda k: k["views"][1].update(k["views"][0], offset=[0, 0]),
     r"views must list each of the 9 views of 3x3 tiles once"),
])
def test_a_hand_edited_calibration_is_refused_in_one_line(renders, tmp_path, edit, message):
    from conftest import refused_when_edited
    scene, optics, targets, _, flat = renders
    cal = register(np.log(targets[1.0]), known_tiles(N, N * TILE, N * TILE))
    flat_field(cal, flat)
    path = save_calibration(str(tmp_path / "k.json"), optics_record(optics, N * TILE, N * TILE), kaleidoscope=cal)
    refused_when_edited(path, "kaleidoscope", edit, message)


def test_old_or_twice_applied_calibrations_are_refused(renders, tmp_path):
    scene, optics, targets, _, flat = renders
    record = optics_record(optics, N * TILE, N * TILE)
    cal = register(np.log(targets[1.0]), known_tiles(N, N * TILE, N * TILE))
    cal.optics = record
    lf = ef.from_spatial(scene, optics, log=False)
    once = apply_to_lightfield(lf, {"kaleidoscope": cal}, record)
    with pytest.raises(ef.EventFieldError, match="already calibrated"):
        apply_to_lightfield(once, {"kaleidoscope": cal}, record)
    cal.registration = None              # a file from before the registration was refined
    with pytest.raises(ef.ConfigError, match="made by an earlier version"):
        apply_to_lightfield(lf, {"kaleidoscope": cal}, record)
    cal = register(np.log(targets[1.0]), known_tiles(N, N * TILE, N * TILE))
    cal.optics, cal.flat_gain = record, [1.0] * 9        # mean gains without the map: an older --flat file
    with pytest.raises(ef.ConfigError, match="mean gains but not its map"):
        apply_to_lightfield(lf, {"kaleidoscope": cal}, record)


def test_a_target_that_is_not_flat_is_warned_about(renders):
    """Registered in quarters, a flat target's views agree on one shift; the two planes (NEAR and FAR: depth
    varies across the views) do not, by about their parallax difference, and the calibration warns (its one
    shift per view would be that parallax averaged, read as misalignment). Oracle: the thin-lens disparity of
    the two planes (``Disparity.for_spatial``, which the registration is not given)."""
    import warnings
    frame, optics, targets, _, _ = renders
    with warnings.catch_warnings():
        warnings.simplefilter("error")                                   # a flat target: no warning
        flat = register(np.log(targets[FAR]), known_tiles(N, N * TILE, N * TILE))
    assert flat.quality["max_quarter_spread_px"] < 0.1
    with pytest.warns(UserWarning, match=r"quarters register .* px apart \(a flat target: under 0\.25\): the target is "
                                         r"not flat"):
        planes = register(np.log(frame), known_tiles(N, N * TILE, N * TILE))
    lf = ef.from_spatial(frame, optics)
    parallax = np.hypot(*(lf.shifts(NEAR) - lf.shifts(FAR)).T).max()      # px, the view farthest from the centre
    assert 0.8 * parallax < planes.quality["max_quarter_spread_px"] < 1.2 * parallax       # 3.32 and 3.48 px


def test_a_textured_frame_given_as_the_flat_field_is_refused(renders):
    """A uniform white target's views vary only by the relay's vignetting, smooth inside them, and camera noise
    is finer than the detail measured; the textured card given as the flat field would divide its texture into
    every view (``calibration.targets``), and is refused."""
    from mitsuba_eventfield.calibration import CalibrationError
    from mitsuba_eventfield.calibration.targets import flat_texture
    _, _, targets, _, flat = renders
    cal = register(np.log(targets[1.0]), known_tiles(N, N * TILE, N * TILE))
    noisy = flat * (1 + 0.05 * np.random.default_rng(2).standard_normal(flat.shape))     # 5 % camera noise
    for frame in (flat, noisy):                                     # vignetted, uniform: taken
        flat_field(cal, frame)
    with pytest.raises(CalibrationError, match=r"^the flat-field frame has detail inside its views \(0\.0[6-9]\d in "
                                               r"log; .* calibrate without a flat field$"):
        flat_field(cal, targets[1.0])
    parts = [np.ones((TILE, TILE))] * 9
    assert flat_texture(parts) == 0.0


def test_a_crop_window_off_the_images_seams_is_found(renders):
    """``targets.seam_shift``: the tube image (the far card at the focus distance, 240 px) placed at 60,40 on a
    dark, noisy 400x320 sensor; a window there meets the image's mirror seams, one 2 px right or 3 px up does
    not, and the seams are found where they are (the card's texture is not periodic)."""
    from mitsuba_eventfield.calibration.targets import seam_shift
    image = renders[2][1.0]
    dark = 1e-3 * (1 + 0.5 * np.random.default_rng(3).random((320, 400)))
    dark[40:40 + N * TILE, 60:60 + N * TILE] = image
    log = np.log(dark)
    for (x0, y0), shift in (((60, 40), (0, 0)), ((62, 40), (-2, 0)), ((60, 37), (0, 3))):
        assert seam_shift(log, (x0, y0, N * TILE, N * TILE), N)[0] == shift
