"""Which pixels each shape covers: the one home for that question (the designs comparison splits moving from
static regions with it, the static-pixel split of a render bounds what moving objects can reach with it)."""
from __future__ import annotations

import numpy as np

from .. import backend

mi, dr = backend.mi, backend.dr


def shape_masks(timed, t: float, sensor=None, view_time: float | None = None) -> dict:
    """{shape id: bool (H, W)}: the pixels each shape covers at time ``t``, from Mitsuba's ``shape_index`` AOV
    (one sample per pixel) through ``sensor`` (default: the scene's own), a scanning view at its phase of
    ``view_time`` when given."""
    timed.set_time(t, view_time)
    aov = mi.load_dict({"type": "aov", "aovs": "s:shape_index"})
    index = np.array(mi.render(timed.scene, sensor=timed.sensor if sensor is None else sensor, integrator=aov,
                               spp=1))[..., 0]
    return {s.id(): index == float(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(s))[0]) for s in timed.scene.shapes()}
