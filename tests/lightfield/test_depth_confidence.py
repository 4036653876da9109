"""What a depth map's confidence promises, against geometry and Mitsuba's depth output: refocused values stay
within the views' (no Lanczos rings), the depth resolution a galvo gives each pixel against ray-traced mirrors,
and a scene whose wall the optics cannot resolve reports the card it can and not the wall
(focus/depth.py's module docstring; docs/design.md, "Where methods fail")."""
import math
import os

import cv2
import numpy as np
import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield.evaluation import truth
from mitsuba_eventfield.focus.depth import RESOLVABLE_PX, depth_resolution_px
from mitsuba_eventfield.focus.refocus import RING_MARGIN
from mitsuba_eventfield.lightfield.model import Disparity, LightField
from mitsuba_eventfield.optics import galvo as galvo_optics

W, H, FOV, D1, SEP = 96, 72, 40.0, 0.2, 0.01
GALVO_STATIC = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")


def _galvo_lf(stack, amplitude_deg=2.0):
    """A galvo light field of ``stack`` (K, H, W) on a circle of mechanical ``amplitude_deg``, exact geometry."""
    k = len(stack)
    phase = 2 * np.pi * np.arange(k) / k
    amp = math.radians(amplitude_deg)
    angles = np.stack([amp * np.cos(phase), amp * np.sin(phase)], axis=-1)
    g = galvo_optics.GalvoGeometry(W, H, galvo_optics.focal_length_px(W, FOV), D1, D1 + SEP)
    return LightField(stack, 2 * angles, np.zeros(k), Disparity(*g.paraxial_disparity()), "galvo", {}, g), angles, g


def test_refocus_stays_within_the_views_next_to_black_letters():
    """Black blocks (0.013) on a bright wall (6.4), the contrast of scenes/galvo_static, on a plane at 0.9 m (each
    view the reference moved by its exact homography). Every refocused pixel is an average of the views'
    intensities, so it lies within their range; the refocus's resampling may pass it by ``RING_MARGIN`` (for
    peaks between samples). Averaged plain Lanczos warps ring below zero there: the oracle that the check has
    something to catch."""
    ref = np.full((H, W), 6.4, np.float32)
    for y0, x0 in ((10, 10), (30, 50), (50, 20)):
        ref[y0:y0 + 12, x0:x0 + 8] = 0.013
    flat, _, _ = _galvo_lf(np.stack([ref] * 16))
    stack = np.stack([cv2.warpPerspective(ref, m, (W, H), flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_REFLECT_101)
                      for m in flat.alignments(0.9)])
    lf, _, _ = _galvo_lf(stack)
    for depth in (0.45, 0.9, 3.0):
        img = ef.refocus(lf, depth, on_motion="ignore")
        assert img.min() >= 0.013 / RING_MARGIN * (1 - 1e-5) and img.max() <= 6.4 * RING_MARGIN * (1 + 1e-5), depth
        plain = np.mean([cv2.warpPerspective(v, m, (W, H), flags=cv2.INTER_LANCZOS4 | cv2.WARP_INVERSE_MAP,
                                             borderMode=cv2.BORDER_REFLECT_101)
                         for v, m in zip(stack, lf.alignments(depth))], axis=0)
        assert plain.min() < 0 and plain.max() > 6.45, depth      # measured -0.09 .. -0.17 and 6.51 .. 6.67
    sharp = ef.refocus(lf, 0.9, on_motion="ignore")
    assert sharp[14:18, 12:16].max() < 0.02 and sharp[34:38, 52:56].max() < 0.02   # in focus: black (0.013)


@pytest.mark.parametrize("depth", [0.45, 1.0, 2.5])
def test_depth_resolution_matches_ray_traced_mirrors(depth):
    """``depth_resolution_px``: how far (RMS over the views, about their mean) a point moves when its depth grows
    by 10 %. Oracle: the point on each pixel's ray at ``depth`` and at 1.1 ``depth`` traced through the rotated
    mirrors (``optics.galvo.project_point``), not the homographies; the function interpolates a slope taken over
    the range searched (0.3-4 m), so it is held to 3 %."""
    lf, angles, g = _galvo_lf(np.ones((24, H, W), np.float32))
    res = depth_resolution_px(lf, np.full((H, W), depth), 0.3, 4.0)
    for i, j in ((36, 48), (5, 5), (60, 90), (10, 80)):
        u, v = j + 0.5, i + 0.5                               # array index -> continuous pixel coordinates

        def seen(z):
            p = ((W / 2 - u) / g.focal_px * z, (H / 2 - v) / g.focal_px * z, z)
            x, y = galvo_optics.project_point(np, p, angles[:, 0], angles[:, 1], D1, SEP, g.focal_px, W, H)
            return np.stack([x, y], axis=-1)
        move = seen(depth) - seen(1.1 * depth)
        move -= move.mean(axis=0)
        want = float(np.sqrt(np.mean(np.sum(move ** 2, axis=1))))
        assert res[i, j] == pytest.approx(want, rel=0.03), (i, j)


@pytest.fixture(scope="module")
def galvo_static():
    """One 250 Hz scan period of scenes/galvo_static at 120 x 90 (its default 32 steps), Mitsuba's depth, and a
    16-spp frame at the period's start (scoring only)."""
    scene = ef.load_scene(GALVO_STATIC, width=120, height=90)
    events = ef.render_events(scene, 0.004)
    return events, truth.truth_depth(scene, 0.0), ef.render_frames(scene, [0.0], spp=16)[0]


def test_a_wall_the_optics_cannot_resolve_is_not_confident(galvo_static):
    """At 120 x 90 a point at 2.5 m and one at 2.75 m move 0.010 px apart in the views (RMS): the text wall's
    depth is beyond what the views can tell, and before the resolution check 31 % of the image was confident,
    75 % of it more than 10 % off (the wall read at the far end of the range), and 39 % of it moved by more
    than 10 % when the period's window moved by 3 us. Now only the card's text (0.5 m) is confident, and right,
    and stays put."""
    events, z, frame = galvo_static
    events = ef.EventStream(events.x, events.y, events.t, events.p, events.width, events.height, dict(events.meta))
    maps = []
    for shift_us in (0, 3):
        events.meta["t_start_us"] = shift_us
        lf = ef.lightfield.from_events(events, period=0, views=32, method="galvo")
        maps.append(ef.depth_from_focus(lf, 0.3, 4.0, 32, "variance"))
    dm = maps[0]
    wall, card = z > 2.0, z < 1.0
    assert np.median(dm.resolution_px[wall]) < 0.25 * RESOLVABLE_PX             # measured 0.010
    sure = dm.confidence > 0.3
    assert sure[wall].mean() < 0.01                                          # measured 0
    text = card & truth.textured(frame, 0.1)                                 # the text on the card
    assert sure[text].mean() > 0.15                                          # measured 0.20
    err = np.abs(dm.depth[sure] / z[sure] - 1)
    assert np.median(err) < 0.06 and (err > 0.1).mean() < 0.05               # measured 2.9 %, 0.019
    both = sure & (maps[1].confidence > 0.3)
    moved = np.abs(maps[1].depth[both] / dm.depth[both] - 1)
    assert both.sum() > 0.8 * sure.sum() and (moved > 0.1).mean() < 0.02      # measured 0.005


def test_the_events_only_solver_maps_unresolved_pixels_at_their_own_depth(galvo_static):
    """The period solver (focus.galvo_periods) maps each pixel's views at its depth from focus. A depth the
    optics cannot resolve still aligns the views to within RESOLVABLE_PX, so the solver takes it
    (``DepthMap.focus_confidence``); when it took only the confident depths and filled the rest with their
    median, galvo_static's wall was mapped at the card's 0.47 m and the start image's log error on the textured
    pixels rose from 0.20 to 0.26 (against a 16-spp render, scoring only)."""
    from mitsuba_eventfield.evaluation.failure_scene import log_error
    from mitsuba_eventfield.focus.galvo_periods import reconstruct_periods
    events, z, frame = galvo_static
    _, rec = next(reconstruct_periods(events, views=32, periods=[0]))
    wall = z > 2.0
    assert np.median(rec.depth[wall]) > 1.5                               # measured 2.42 m
    assert (rec.confidence[wall] > 0.5).mean() < 0.01                     # the map's confidence stays honest
    assert log_error(rec.log_start, frame, truth.textured(frame, 0.05)) < 0.23     # measured 0.204


def test_kaleidoscope_refocus_stays_within_the_views_next_to_black_blocks():
    """The shift-invariant refocus (exact Fourier shifts, focus/refocus.py) rings at a sharp edge as Lanczos
    does: 3 x 3 views of black blocks (0.013) on 6.4, refocused half a pixel off their alignment, had pixels
    clipped to 0. Now every pixel lies within the views' range, widened by ``RING_MARGIN``; the test's own
    Fourier sum (the same phase ramps, unclipped) shows the rings it removes."""
    from mitsuba_eventfield.lightfield.model import Disparity as D
    ref = np.full((64, 64), 6.4, np.float32)
    ref[20:32, 20:28] = 0.013
    ref[40:50, 36:44] = 0.013
    pos = np.array([(i, j) for i in (-1, 0, 1) for j in (-1, 0, 1)], float)
    views = np.stack([np.roll(ref, (2 * int(p[1]), 2 * int(p[0])), axis=(0, 1)) for p in pos])   # aligned at 2
    lf = ef.LightField(views, pos, np.zeros(len(pos)), D((0.0, 0.0), (1.0, 1.0)))
    for alpha in (0.7, 1.5, 2.0):
        img = ef.refocus(lf, alpha=(alpha, alpha), on_motion="ignore")
        assert img.min() >= 0.013 / RING_MARGIN * (1 - 1e-5) and img.max() <= 6.4 * RING_MARGIN * (1 + 1e-5), alpha
    fy, fx = np.fft.fftfreq(64)[:, None], np.fft.fftfreq(64)[None, :]
    spectra = np.fft.fft2(views)
    plain = np.real(np.fft.ifft2(np.mean([s * np.exp(2j * np.pi * (fx * 1.5 * p[0] + fy * 1.5 * p[1]))
                                          for s, p in zip(spectra, pos)], axis=0)))
    assert plain.min() < 0                                  # the unclipped sum rings below zero
    sharp = ef.refocus(lf, alpha=(2.0, 2.0), on_motion="ignore")
    assert sharp[24:28, 22:26].max() < 0.02                 # aligned: the block is black


def test_the_map_says_why_textured_pixels_are_not_confident(galvo_static):
    """``DepthMap.notes``: searched from 0.6 m, the card (0.5 m) is sharpest nearer than the range; at 120 x 90
    the depth resolution ends at about 0.55 m (the card's own pixels resolve 0.055 px for 10 %), and the text wall
    lies past it. Searched over 0.3-4 m, no pixel is said to lie outside the range."""
    events, z, _ = galvo_static
    lf = ef.lightfield.from_events(events, period=0, views=32, method="galvo")
    inside = ef.depth_from_focus(lf, 0.3, 4.0, 32, "variance").notes()
    assert len(inside) == 1 and "beyond the depth resolution: past a depth of about 0.5" in inside[0], inside
    narrow = ef.depth_from_focus(lf, 0.6, 4.0, 32, "variance").notes()
    assert any("sharpest nearer than 0.6" in line for line in narrow), narrow


def test_each_pixel_names_the_check_it_fails(galvo_static):
    """``DepthMap.reasons``: one code a pixel, the first check it fails (``REASONS``), consistent with the
    confidence (0 wherever a check fails) and with the notes. On galvo_static at 120 x 90 against Mitsuba's depth:
    the text wall (2.5 m) past the depth resolution is code 5 where textured; searched from 0.6 m the card's
    textured pixels (0.5 m) are sharpest nearer than the range, code 3."""
    from mitsuba_eventfield.focus.depth import REASON_META, REASONS
    events, z, _ = galvo_static
    lf = ef.lightfield.from_events(events, period=0, views=32, method="galvo")
    wall, card = z > 2.0, z < 1.0
    for near in (0.3, 0.6):
        dm = ef.depth_from_focus(lf, near, 4.0, 32, "variance")
        reasons = dm.reasons()
        assert reasons.dtype == np.uint8 and set(np.unique(reasons)) <= set(REASONS)
        assert np.all(dm.confidence[reasons > 0] == 0)
        passed = reasons == 0
        assert np.array_equal(dm.confidence[passed], dm.focus_confidence[passed])
        assert np.all(dm.evidence[passed] >= 0.3) and not dm.at_limit[passed].any()
        textured_wall = wall & ((reasons >= 3) | (reasons == 0))    # evidence and texture of its own
        assert textured_wall.sum() > 500
        if near == 0.3:
            assert (reasons[textured_wall] == 5).mean() > 0.9                # measured 1.00
            # the card's text; at 120 x 90 its 0.5 m is near the resolution (0.055 px for 10 %), and where its
            # focus curve does not tell 0.5 from 0.54 m it is unresolved (code 5)
            assert (reasons[card] == 0).mean() > 0.05                        # measured 0.08
            # sharpest beyond the range: only a few wall pixels at the card's occluding edge (measured 4, 3-4 px
            # from it), where the focus window holds both depths
            beyond = (reasons == 3) | (reasons == 4)
            from_card = cv2.distanceTransform((~card).astype(np.uint8), cv2.DIST_L2, 5)
            assert beyond.sum() < 20 and np.all(from_card[beyond] <= 5)
        else:
            # the rest (measured 0.12) sharpest inside the range, at >= 0.6 m, where 10 % moves its views less
            # than RESOLVABLE_PX: code 5
            textured_card = card & (reasons >= 3)
            assert (reasons[textured_card] == 3).mean() > 0.5               # measured 0.88
        notes = dm.notes()                                          # the notes count these codes
        assert any(line.startswith(f"{(reasons == 5).mean():.0%} of the pixels are textured but beyond the depth "
                                   "resolution") for line in notes), notes
        assert any("sharpest nearer than 0.6" in line for line in notes) == (near == 0.6)
        channels = dm.channels()
        assert list(channels) == ["depth", "confidence", "reason"]
        assert np.array_equal(channels["reason"], reasons.astype(np.float32))
    assert REASON_META["reason_codes"]["5"].startswith("beyond the depth resolution")


def test_a_wall_estimated_too_near_to_fail_the_resolution_check_is_not_confident():
    """galvo_static at 120 x 90 with a 4x scan amplitude: its 2.5 m wall is still unresolved (0.044 px for 10 %),
    but the check read the pixel's estimated depth, and wall pixels read too near passed it confidently: here
    88 more than 6 px from the card (at 346 x 260 and the default amplitude, the README's render, 699 at
    1.41-1.57 m, all of the wall's confident pixels away from the card). Their focus curves are within a few %
    of their peak from there to the far end of the range; the check now reads the farthest depth the curve
    does not tell from its peak (``indistinct_depth``). Left confident on the wall: the band beside the card's
    occluding edge, here up to 5 px, where the wall's letters are texture of its own, read nearer than the wall
    by the card's edge in the focus window (docs/design.md, "Where methods fail")."""
    scene = ef.load_scene(GALVO_STATIC, width=120, height=90, amplitude=2.0)
    events, z = ef.render_events(scene, 0.004), truth.truth_depth(scene, 0.0)
    dm = ef.depth_from_focus(ef.lightfield.from_events(events, views=32, method="galvo"), 0.4, 4.0, 32, "variance")
    sure, wall, card = dm.confidence >= 0.5, z > 2.0, z < 1.0
    from_card = cv2.distanceTransform((~card).astype(np.uint8), cv2.DIST_L2, 5)
    assert (sure & wall & (from_card > 6)).sum() == 0                         # was 88
    assert (sure & wall).sum() < 400                    # measured 321 (the card: 479, its text and its edge)
    assert np.median(np.abs(np.log(dm.depth[sure & card] / z[sure & card]))) < 0.03   # the card: 0.504 m
    assert np.median(dm.indistinct_depth[wall & (dm.reasons() == 5)]) > 2.0  # where the wall's curves stay flat


def test_a_peak_past_the_near_end_is_beyond_the_range(tmp_path):
    """galvo_static at 96 x 72 with its start frame, searched from 0.4 m (the README's flow, scaled down): 10 wall
    pixels (2.5 m) between the text lines peaked at the near end plane, their refined vertex beyond it, and read
    0.40 m confidently (a new user). A vertex more than ``PAST_END`` of the way to the outer plane past the end
    plane now flags the pixel as sharpest nearer than the range (code 3), as a sharper plane beyond it does; the
    ghosts closer to the end plane than that stay (a card exactly at an end plane lies there: its test is in
    tests/lightfield/test_lightfield.py)."""
    from mitsuba_eventfield.cli.main import main as cli
    from mitsuba_eventfield.images import read_exr
    size = ["-D", "width=96", "-D", "height=72"]
    assert cli(["render", GALVO_STATIC, "-o", str(tmp_path / "gs.h5"), "--duration", "0.004", *size]) == 0
    assert cli(["frame", GALVO_STATIC, "-o", str(tmp_path / "start.exr"), *size]) == 0
    assert cli(["depth", str(tmp_path / "gs.h5"), "-o", str(tmp_path / "d.png"), "--near", "0.4", "--far", "4",
                "--start-frame", str(tmp_path / "start.exr")]) == 0
    channels, _ = read_exr(str(tmp_path / "d.exr"))
    at_end = channels["depth"] < 0.405
    assert at_end.sum() > 10 and (at_end & (channels["confidence"] >= 0.2)).sum() <= 6      # measured 5 (was 10)
    assert (channels["reason"][at_end] == 3).sum() >= 5
