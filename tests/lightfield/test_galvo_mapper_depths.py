"""The events-only solver's view mapping (``galvo_solve._Mapper``) against the exact homography at each pixel's
own depth: a depth map of three regions, 0.5 / 1.2 / 0.8 m (offaxis_cards' optics: fov 40 deg, X and Y mirror
pivots 0.2 and 0.21 m, at 96x72), mapped from the rest view to the view at mechanical angles (2, 1) deg. The
mapper interpolates six planes linearly in inverse depth; 0.5 and 1.2 m are its end planes and 0.8 m lies
between two (1.25 1/m between 1.067 and 1.3). Measured: worst 8e-15 px at the planes, 1.3e-5 px at 0.8 m (the
image position is nearly linear in inverse depth over a plane's step); the interpolation weights swapped put
the regions' worst pixels 0.29-0.50 px off."""
import math

import numpy as np

from mitsuba_eventfield.lightfield.galvo_solve import _Mapper
from mitsuba_eventfield.optics.galvo import GalvoGeometry

W, H = 96, 72
OPTICS = {"fov_x_deg": 40.0, "mirror_distance": 0.2, "mirror_separation": 0.01}


def test_each_pixel_is_mapped_at_its_own_depth():
    g = GalvoGeometry.from_optics(OPTICS, W, H)
    depth = np.full((H, W), 0.8)
    depth[:, :32] = 0.5
    depth[:, 32:64] = 1.2
    a_from, a_to = (0.0, 0.0), (math.radians(2.0), math.radians(1.0))
    sx, sy = _Mapper(g, 1.0 / depth)(a_from, a_to)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    worst = {}
    for z in (0.5, 1.2, 0.8):
        m = g.view_to_view(a_from, a_to, z)
        den = m[2, 0] * xx + m[2, 1] * yy + m[2, 2]
        ex, ey = (m[0, 0] * xx + m[0, 1] * yy + m[0, 2]) / den, (m[1, 0] * xx + m[1, 1] * yy + m[1, 2]) / den
        at = depth == z
        worst[z] = float(np.hypot(sx - ex, sy - ey)[at].max())
        assert np.hypot(ex - xx, ey - yy)[at].min() > 5.0          # the views do move these pixels
    print("worst error per depth (px):", {z: f"{e:.1e}" for z, e in worst.items()})
    assert max(worst.values()) < 1e-3
