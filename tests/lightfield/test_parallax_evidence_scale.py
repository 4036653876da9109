"""``parallax_evidence`` is 1 exactly where the views change as much as the optics must make them: a 3x3
spatial light field (positions -1, 0, 1 per axis) of a log ramp of slope g = 0.03 per pixel along x, each view
the ramp shifted by alpha x its position, alpha = 1 px per unit at the depth of least parallax searched (alpha =
4 / z, depths 2, 3, 4 m). Then the log of a pixel over the views has std g alpha sqrt(2/3) (the x positions), and
the least RMS view displacement (both axes) is alpha sqrt(4/3): the std over the gradient x that displacement
is 1 / sqrt 2, which the /sqrt(2) of the law turns into 1 (measured 1.0000 at every pixel 4 or more from the
border, beyond the Sobel and the 7 px window; the border's reflected window reads up to 1.4)."""
import math

import numpy as np
import pytest

from mitsuba_eventfield.focus.depth import parallax_evidence, view_spread_px
from mitsuba_eventfield.lightfield.model import Disparity, LightField

H, W, SLOPE = 24, 32, 0.03


def test_views_that_move_as_the_optics_must_give_evidence_one():
    positions = np.array([(i, j) for j in (-1, 0, 1) for i in (-1, 0, 1)], np.float64)
    disparity = Disparity((0.0, 0.0), (4.0, 4.0))                 # alpha(z) = 4 / z: 1 px per unit at 4 m
    alpha = 1.0
    xx = np.arange(W, dtype=np.float64)[None, :].repeat(H, 0)
    views = np.stack([np.exp(SLOPE * (xx - alpha * px)) for px, _ in positions]).astype(np.float32)
    lf = LightField(views, positions, np.zeros(9), disparity, "kaleidoscope")
    depths = [2.0, 3.0, 4.0]
    spread = view_spread_px(lf, depths)
    assert spread == pytest.approx([2 * math.sqrt(4 / 3), 4 / 3 * math.sqrt(4 / 3), math.sqrt(4 / 3)], rel=1e-12)
    evidence = parallax_evidence(lf, depths)
    inside = evidence[4:-4, 4:-4]                  # beyond the Sobel and the 7 px window from the border
    print(f"evidence inside: {inside.min():.4f} .. {inside.max():.4f}")
    assert inside == pytest.approx(1.0, abs=2e-3)
