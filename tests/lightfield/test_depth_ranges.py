"""Depth from focus measures planes beyond the range searched (``focus.depth._outer_planes``); every one of them
must be a depth the light field refocuses at (``LightField.depth_range``)."""
import math

import numpy as np
from lf_scenes import texture

import mitsuba_eventfield as ef
from mitsuba_eventfield.lightfield.model import Disparity, LightField
from mitsuba_eventfield.optics.galvo import GalvoGeometry


def test_planes_beyond_the_range_stay_where_a_calibrated_galvo_refocuses():
    """A depth calibration gave the runner pivots of 0.199 m (x) and 0.211 m (y). Searched from 0.4 m, the
    plane at half that depth passed the x disparity's sign test and was then refused by refocus (depths from the
    farther pivot on): ``scanrate-depth --calibration`` stopped with "depth = 0.2: ... in [0.211157, ...]"."""
    geometry = GalvoGeometry(48, 48, 60.0, 0.199, 0.211157)
    angle = np.linspace(0, 2 * math.pi, 8, endpoint=False)
    positions = 0.02 * np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    views = np.repeat(texture(3, size=48)[None], 8, axis=0)
    lf = LightField(views, positions, np.zeros(8), Disparity(*geometry.paraxial_disparity()), "galvo", {}, geometry)
    assert math.isclose(lf.depth_range()[0], 0.211157)
    dm = ef.depth_from_focus(lf, 0.4, 4.0, 8, "tenengrad")       # through refocus, which checks each depth
    assert dm.depth.shape == (48, 48) and np.all(np.isfinite(dm.depth))
