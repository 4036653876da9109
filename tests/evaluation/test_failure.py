"""Where the downstream methods fail (``evaluation.failure``): for each method one point inside its working
region returns an accurate result, and one outside is refused or flagged, never returned silently. Scored
against the renderer's own answers: the centre pinhole frame, Mitsuba's depth, the mirror geometry, a 16 spp
render. Small films (96 x 72), one scan period each."""
import warnings

import numpy as np
import pytest

from mitsuba_eventfield.errors import ConfigError
from mitsuba_eventfield.evaluation import failure
from mitsuba_eventfield.focus.depth import depth_from_focus
from mitsuba_eventfield.focus.refocus import MOTION_LIMIT_PX, MotionBlurWarning, refocus, view_motion


def test_refocus_sharp_when_still_flagged_when_the_card_moves():
    still = failure.refocus_point(0.0)
    assert still["status"] == "ok" and still["error"] > 35.0            # measured 37.9 dB
    assert still["measured_motion_px"] < 0.5 * MOTION_LIMIT_PX          # measured 0.23 px
    moving = failure.refocus_point(4.0)
    assert moving["status"] == "flagged"
    assert moving["error"] < still["error"] - 8                          # measured 24.9 dB: smeared by 4 px
    assert moving["measured_motion_px"] == pytest.approx(4.0, abs=0.5)   # measured 4.02 px
    # the flag names a velocity that follows the card (image -x), and a refusal is one line on request
    lf, truth, card = failure.refocus_case(4.0)
    vx, vy = view_motion(lf, 0.5)["velocity_px_s"]
    assert vx == pytest.approx(-4.0 / 0.01, rel=0.15) and abs(vy) < 0.1 * abs(vx)    # measured -357, 1
    with pytest.raises(ConfigError, match="moves 4.0 px") as e:
        refocus(lf, 0.5, on_motion="raise")
    assert "\n" not in str(e.value)
    with warnings.catch_warnings():
        warnings.simplefilter("error", MotionBlurWarning)
        refocus(lf, 0.5, motion=(vx, vy))              # the motion given: nothing to flag
        refocus(lf, 0.5, on_motion="ignore")


def test_depth_from_focus_flags_texture_below_the_threshold_and_depths_beyond_the_range():
    scored = failure.scored_pixels()
    good = failure.depth_point(0.5, scored)
    assert good["status"] == "ok" and good["confident_share"] > 0.85    # measured 0.94
    assert good["error"] < 0.03                                          # measured 0.018
    faint = failure.depth_point(0.05, scored)                           # texture 1 threshold deep: no events
    assert faint["events"] == 0 and faint["status"] == "flagged"
    assert faint["confident_share"] == 0.0                               # every pixel refused a depth
    assert faint["error_all_pixels"] > 0.3       # what the map holds is wrong (measured 0.65): rightly flagged
    # the card at 0.5 m searched from 0.6 m: its focus peaks at the nearest plane and rises beyond it
    lf, z, _ = failure.depth_case(0.5)
    card = scored & (z < 1.0)
    dm = depth_from_focus(lf, 0.6, 3.0, 24, "tenengrad")
    assert np.median(np.abs(dm.depth[card] / z[card] - 1)) > 0.15       # read as the nearest plane (20 % off)
    assert dm.at_limit[card].mean() > 0.95                               # measured 0.999
    assert dm.confident_share(mask=card) < 0.05                          # measured 0.001
    inside = depth_from_focus(lf, 0.3, 3.0, 24, "tenengrad")
    assert inside.at_limit[card].mean() < 0.01 and inside.confident_share(mask=card) > 0.95   # 0 and 1.0
    # searched from twice its depth: the curve peaks on a ghost inside the range (1.0 m and beyond, a 100 %
    # error), which a plane beyond the range (the card's own 0.5 m) outfocuses
    ghost = depth_from_focus(lf, 1.0, 3.0, 24, "tenengrad")
    assert np.median(np.abs(ghost.depth[card] / z[card] - 1)) > 0.5     # measured 1.18
    assert ghost.at_limit[card].mean() > 0.95                            # measured 0.999 (0.37 before)
    assert ghost.confident_share(mask=card) < 0.05                       # measured 0.001 (0.63 before)


def test_calibration_refuses_noisy_frames_instead_of_a_wrong_fit():
    clean = failure.calibration_point(0.0)
    for row in clean:
        assert row["status"] == "ok" and row["error"] < 0.02             # measured 1.3 % and 0.9 %
    noisy = [failure.calibration_point(400.0, seed=seed) for seed in range(5)]
    assert all([r["status"] for r in rows] == ["refused", "refused"] for rows in noisy)
    with_frame = [rows[1] for rows in noisy]     # frames from the events and a rendered start frame
    assert all(r["reason"].endswith("frames match the patches with correlation >= 0.6 (fewer than 50%)")
               for r in with_frame)
    # without the matched-share refusal most of them returned a fit beyond the sweep's 2 % tolerance, silently
    # (measured 3.5, 5.0, 1.4, 4.1, 3.1 %; the clean fits 1.3 and 0.9 %)
    unguarded = [r["unguarded_error"] for r in with_frame if r["unguarded_error"] is not None]
    assert sum(e > 0.02 for e in unguarded) >= 3, unguarded


def test_reconstruction_flags_a_card_nearer_than_the_range_searched():
    inside = failure.reconstruction_point(0.5)
    assert inside["status"] == "ok" and inside["outliers"] < 0.04        # measured 0.023
    assert inside["error"] < 0.02 and inside["card_depth_error"] < 0.02  # measured 0.016, 0.004
    near = failure.reconstruction_point(0.3)                             # searched from 0.42 m
    assert near["status"] == "flagged" and near["outliers"] > 0.08      # measured 0.104
    assert near["card_depth_error"] > 1.0                                 # its depth map is wrong (3.3)
    assert near["error"] > 1.3 * inside["error"]                          # and so is its image (0.029)


def test_a_row_returned_unflagged_without_a_measurable_error_is_silent():
    """``FailureSweep.silent``: the rows a method returned as fine ("ok") whose error is beyond the tolerance,
    and those whose error could not be measured (None, NaN: nothing to show it worked), for an error and for
    a score (higher is better); a flagged or refused row is never silent."""
    rows = [{"value": v, "error": e, "status": s} for v, e, s in (
        (1, 0.01, "ok"), (2, 0.5, "ok"), (3, None, "ok"), (4, float("nan"), "ok"), (5, 0.5, "flagged"),
        (6, None, "refused"))]
    sweep = failure.FailureSweep("m", "knob", "", "error", 0.1, False, rows)
    assert [r["value"] for r in sweep.silent] == [2, 3, 4] and sweep.as_dict()["silent"] == 3
    scores = failure.FailureSweep("m", "knob", "", "PSNR", 20.0, True, [dict(r) for r in rows])
    for r, psnr in zip(scores.rows, (30.0, 10.0, None, float("nan"), 10.0, None)):
        r["error"] = psnr
    assert [r["value"] for r in scores.silent] == [2, 3, 4]
