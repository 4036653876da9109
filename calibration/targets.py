"""What a kaleidoscope calibration's frames must be, checked on the frames themselves: the registration target
flat (one shift per view wherever it is registered), the flat-field target uniform (no texture inside the
views). A target that is not flat is warned about (the frame may be a rig's best, and the calibration still
holds most of the misalignment); a textured flat field is refused (it is worse than none)."""
from __future__ import annotations

import warnings

import numpy as np

# A flat target is one shift per view wherever it is registered; a target whose depth varies (or views rotated or
# distorted against each other) shifts its parts by different amounts, and the one shift fitted is their parallax
# averaged, read as misalignment. So each view is registered again in quarters (those with texture, after the
# shift found) and the quarters' offsets compared. Measured (rendered frames, 5 % noise added alike): a flat card
# filling the views 0.00 px (120, 240 px views) and 0.11-0.14 px (48 px); scenes/falling's posts, block and wall
# (0.55, 0.8, 1.4 m, focus 1 m) 0.40-0.56 px. Warned above 0.25 px.
MAX_QUARTER_SPREAD_PX = 0.25
QUARTER_TEXTURE = 0.05          # std of a quarter's log intensity for it to take part (a blank one registers noise)


def quarter_spread(centre: np.ndarray, view: np.ndarray, offset) -> float:
    """Largest distance (px) between the offsets of ``view``'s textured quarters, once moved by ``offset``,
    against the centre view's (both inside the registration margin); 0 with fewer than two textured quarters."""
    from scipy.ndimage import shift
    from skimage.registration import phase_cross_correlation
    moved = shift(view, (-offset[1], -offset[0]), order=3, mode="nearest")
    bh, bw = centre.shape[0] // 2, centre.shape[1] // 2
    window = np.outer(np.hanning(bh), np.hanning(bw))
    found = []
    for y in (0, bh):
        for x in (0, bw):
            c, m = centre[y:y + bh, x:x + bw], moved[y:y + bh, x:x + bw]
            if c.std() < QUARTER_TEXTURE:
                continue
            shift_yx = phase_cross_correlation((c - c.mean()) * window, (m - m.mean()) * window,
                                               upsample_factor=20, normalization=None)[0]
            found.append(np.asarray(shift_yx, np.float64))
    return max((float(np.hypot(*(a - b))) for a in found for b in found), default=0.0)


def warn_not_flat(views) -> None:
    """A warning when a registered view's quarters disagree by more than ``MAX_QUARTER_SPREAD_PX``."""
    worst = max(views, key=lambda v: v["quarter_spread_px"])
    if worst["quarter_spread_px"] > MAX_QUARTER_SPREAD_PX:
        warnings.warn(f"kaleidoscope calibration: view ({worst['i']}, {worst['j']})'s quarters register "
                      f"{worst['quarter_spread_px']:.2f} px apart (a flat target: under {MAX_QUARTER_SPREAD_PX:g}): "
                      "the target is not flat (its parallax is read as misalignment, and depths from this "
                      "calibration are biased) or the views are rotated or distorted against each other; calibrate "
                      "with a flat textured target filling the views", stacklevel=3)


# A uniform white target's views vary only by the vignetting, which is smooth inside them (sharp only at the
# seams); a textured frame given as the flat field would divide its texture into every view's gain, worse than no
# flat field. Measured: log intensity blurred by 1 px less its 4 px blur (detail of 2-10 px: white camera noise
# mostly lies below it), std inside the views (a fifth of the tile left out at each side), the worst view:
# rendered flat fields 0.000-0.026 (relay apertures none and 2 mm, 16 and 128 spp, up to 5 % camera noise; the
# unblurred residual read 0.057 at 5 % noise), the textured card of the registration tests 0.064-0.089 (at 1 and
# 1.5 m). Refused above 0.04.
MAX_FLAT_TEXTURE = 0.04
FLAT_TEXTURE_BAND_PX = (1.0, 4.0)


def flat_texture(views) -> float:
    """The largest std (log units) of the unflipped ``views``' detail of 2-10 px inside their borders."""
    from scipy.ndimage import gaussian_filter
    fine, coarse = FLAT_TEXTURE_BAND_PX
    worst = 0.0
    for view in views:
        b = max(1, min(view.shape) // 5)
        v = np.log(np.maximum(np.asarray(view, np.float64), 1e-6))[b:-b, b:-b]
        if v.size:
            worst = max(worst, float((gaussian_filter(v, fine) - gaussian_filter(v, coarse)).std()))
    return worst


def check_flat_texture(views) -> float:
    """``flat_texture`` of a flat-field frame's views; refused (CalibrationError) above ``MAX_FLAT_TEXTURE``."""
    from .galvo import CalibrationError
    texture = flat_texture(views)
    if texture > MAX_FLAT_TEXTURE:
        raise CalibrationError(f"the flat-field frame has detail inside its views ({texture:.3f} in log; a uniform "
                               f"target's vignetting, under {MAX_FLAT_TEXTURE:g}): a textured frame, whose texture "
                               "would be divided into every view; use a uniform white target's frame (several "
                               "averaged, if noisy), or calibrate without a flat field")
    return texture


# The seams between a kaleidoscope's tiles are lines of mirror symmetry (``kaleidoscope._symmetry_profile``); a
# window cut from a larger sensor (``--crop``) whose tiles' edges are not the image's seams cuts every view at
# another place, and the registration reads that as misalignment (a window 7 px off: offsets of 5 px, views
# agreeing to 0.999 once shifted, refocus with ghost edges). So the seams are looked for near the window's.
SEAM_SEARCH_PX = 8             # how far from the window's tile edges, per axis
SEAM_GAIN = 0.1                # a symmetry this much better elsewhere says the window is off


def seam_shift(frame: np.ndarray, window, n: int, half: int = 4) -> tuple:
    """((dx, dy), (at the window, best)): how far the mirror-symmetric seams of ``frame`` (the whole sensor, log)
    lie from the tile edges of ``window`` (x0, y0, w, h) cut into n x n tiles, and the mean seam symmetry there
    and at the best shift, per axis; (0, 0) where no shift is ``SEAM_GAIN`` more symmetric."""
    from .kaleidoscope import _symmetry_profile
    x0, y0, w, h = window
    shifts, scores = [], []
    # each axis's seams on the window's own rows or columns: the edge of a dark surround, along a whole
    # sensor's rows, outweighed every seam (windows 0, 2 and 5 px off all scored 0.93)
    for axis, start, size, strip in ((1, x0, w, frame[y0:y0 + h]), (0, y0, h, frame[:, x0:x0 + w])):
        prof = _symmetry_profile(strip, axis, half)
        edges = [start + k * size // n for k in range(1, n)]
        score = {s: float(np.mean([prof[c + s] for c in edges])) for s in range(-SEAM_SEARCH_PX, SEAM_SEARCH_PX + 1)
                 if all(half <= c + s <= len(prof) - 1 - half for c in edges)}
        top = max(score.values())          # the nearest of the best: a periodic target repeats its symmetry
        best = min((s for s, v in score.items() if v >= top - 0.02), key=abs)
        off = best if score[best] > score.get(0, -1.0) + SEAM_GAIN else 0
        shifts.append(off)
        scores.append((score.get(0, -1.0), score[best]))
    return tuple(shifts), tuple(scores)


def warn_off_seams(frame: np.ndarray, window, n: int) -> None:
    """A warning when the tiles of ``window`` (``--crop``) do not meet at the image's mirror seams
    (``seam_shift``)."""
    (dx, dy), (sx, sy) = seam_shift(frame, window, n)
    if dx or dy:
        worse = "; ".join(f"along {name} {at:.2f} at its edges, {best:.2f} {abs(d)} px {way[d > 0]}"
                          for name, d, (at, best), way in (("x", dx, sx, ("left", "right")),
                                                           ("y", dy, sy, ("up", "down"))) if d)
        warnings.warn(f"the window {','.join(map(str, window))}: its {n}x{n} tiles' edges are not the image's "
                      f"mirror seams (symmetry {worse}): the window is off (its views are cut elsewhere, "
                      "and read as misaligned), or the target is not at the focus distance", stacklevel=2)
