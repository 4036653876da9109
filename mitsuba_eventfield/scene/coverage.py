"""Which pixels each shape covers: the one home for that question (the designs comparison splits moving from
static regions with it, the static-pixel split of a render bounds what moving objects can reach with it)."""
from __future__ import annotations

import numpy as np

from .. import backend
from ..errors import EventFieldError
from . import instancing

mi, dr = backend.mi, backend.dr


def _aov():
    return mi.load_dict({"type": "aov", "aovs": "s:shape_index"})


def _index(timed, shape) -> float | None:
    """The value the shape-index AOV writes for ``shape``'s pixels; None for an instance of a scene file's own
    (below). For an instance the AOV writes the index of the shapegroup's own shape, which is not among the
    scene's shapes and which every instance of the group shares; an instance this package made of a moving
    shape (``scene/instancing.py``) is the only one of its group, so its group's shape stands for it."""
    if shape.class_name() == "Instance":
        shape = instancing.member(timed, shape.id())
        if shape is None:
            return None
    return float(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(shape))[0])


def unseen(timed, ids) -> list:
    """Those of ``ids`` whose pixels the shape-index AOV cannot show: not a shape of the scene (the sensor), or
    an instance of the scene file's own (``_index``). Its mask would be empty and its pixels taken as still, so
    the callers refuse it or do without the masks."""
    seen = {s.id() for s in timed.scene.shapes() if _index(timed, s) is not None}
    return sorted(i for i in ids if i not in seen)


def shape_masks(timed, t: float, sensor=None, view_time: float | None = None) -> dict:
    """{shape id: bool (H, W)}: the pixels each shape covers at time ``t``, from Mitsuba's ``shape_index`` AOV
    (one sample per pixel) through ``sensor`` (default: the scene's own), a scanning view at its phase of
    ``view_time`` when given."""
    timed.set_time(t, view_time)
    index = np.array(mi.render(timed.scene, sensor=timed.sensor if sensor is None else sensor, integrator=_aov(),
                               spp=1))[..., 0]
    indices = {s.id(): _index(timed, s) for s in timed.scene.shapes()}
    return {sid: index == value for sid, value in indices.items() if value is not None}


def covered_over_time(timed, times, ids, view_time: float | None = None) -> np.ndarray:
    """bool (H, W): the pixels any of the shapes ``ids`` covers at any of ``times``, as ``shape_masks`` sees them
    through the scene's sensor. The AOV render is frozen (``dr.freeze``) and replayed at each instant: about 3x
    faster than tracing it (3.4 against 10.4 ms at 346x260); one function, one sensor and film, so the sizes its
    recording holds stay right."""
    aov = _aov()
    index_image = backend.FrozenOrTraced(lambda scene, sensor: mi.render(scene, sensor=sensor, integrator=aov, spp=1))
    wanted = [_index(timed, s) for s in timed.scene.shapes() if s.id() in set(ids)]
    if None in wanted:
        raise EventFieldError(f"covered_over_time: objects {', '.join(unseen(timed, ids))}: not seen by the "
                              "shape-index AOV (an instance of the scene file's own, or not a shape)")
    covered = None
    for t in times:
        timed.set_time(float(t), view_time)
        image = index_image(timed.scene, timed.sensor)
        hit = np.isin(np.array(image)[..., 0], wanted)
        covered = hit if covered is None else covered | hit
    return covered
