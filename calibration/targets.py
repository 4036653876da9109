"""What a kaleidoscope calibration's frames must be, checked on the frames themselves: the registration target
flat (one shift per view wherever it is registered), the flat-field target uniform (no texture inside the
views). Each failure is a warning naming what it does to the calibration: the frames may be a rig's best."""
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
# seams); a textured frame given as the flat field would imprint its texture in every view's gain. Measured: log
# intensity less its Gaussian blur (sigma 4 px), std inside the views (a fifth of the tile left out at each side),
# the worst view: rendered flat fields 0.000-0.016 (relay apertures none, 2 and 1.5 mm) and 0.010-0.019 with 1 %
# camera noise; the textured card of the registration tests 0.072-0.104 (at 1 and 1.5 m). Warned above 0.04.
MAX_FLAT_TEXTURE = 0.04
FLAT_TEXTURE_SIGMA_PX = 4.0


def flat_texture(views) -> float:
    """The largest std (log units) of the unflipped ``views``' fine detail inside their borders."""
    from scipy.ndimage import gaussian_filter
    worst = 0.0
    for view in views:
        b = max(1, min(view.shape) // 5)
        v = np.log(np.maximum(np.asarray(view, np.float64), 1e-6))[b:-b, b:-b]
        worst = max(worst, float((v - gaussian_filter(v, FLAT_TEXTURE_SIGMA_PX)).std()) if v.size else 0.0)
    return worst


def warn_flat_texture(views) -> float:
    """``flat_texture`` of a flat-field frame's views, with a warning above ``MAX_FLAT_TEXTURE``."""
    texture = flat_texture(views)
    if texture > MAX_FLAT_TEXTURE:
        warnings.warn(f"kaleidoscope flat field: the frame has detail inside its views ({texture:.3f} in log, a "
                      f"uniform target's vignetting: under {MAX_FLAT_TEXTURE:g}): a textured frame, not a uniform "
                      "white target? its texture is divided into every view", stacklevel=3)
    return texture
