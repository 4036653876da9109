"""Moving rigid shapes as Mitsuba instances, where that pays: on CUDA.

A moving shape is moved every step by a parameter update. For a mesh that is new vertex positions, and Mitsuba
then reads the mesh's bounding box back from the device and rebuilds its acceleration structure. The same shape
in a ``shapegroup``, placed by an ``instance`` whose ``to_world`` the motion sets, costs only the
instance-level rebuild. Measured on an H100 (benchmarks/results/motion_h100.md, the demo's ball and cube, 100
steps at 346x260): Mitsuba's update 0.77 -> 0.58 ms a step, and with the host staging each step while the GPU
renders (``backend.overlaps_steps``) the render 0.201 -> 0.141 s. On the CPU it lost twice (Embree pays the
instance's transform on every ray: docs/design.md, "Motion a step"), so there it is off.

The scene file is rewritten before loading: each moving ``<shape id="X">`` at the scene's top level that
carries no emitter (a shapegroup cannot hold one) and is not itself an instance or group becomes
``<shape type="shapegroup" id="X__group">`` holding it (renamed ``X__shape``), and
``<shape type="instance" id="X">`` referring to the group. The motion then binds ``X.to_world``, the
instance's. Shapes defined in included files are left as they are. ``EVENTFIELD_INSTANCES=1`` / ``0``
forces it on or off on any backend.

Mitsuba's shape-index AOV writes the index of the group's own shape for an instance's pixels. ``member``
gives that shape, so the pixel coverage (``scene/coverage.py``) still finds an instanced object.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

from .. import backend

ENV = "EVENTFIELD_INSTANCES"
_NOT_WRAPPED = ("instance", "shapegroup")


def group_id(sid: str) -> str:
    return f"{sid}__group"


def member_id(sid: str) -> str:
    return f"{sid}__shape"


def wanted() -> bool:
    """Whether moving shapes are loaded as instances: on CUDA (module docstring); ``EVENTFIELD_INSTANCES``
    forces it (``1``) or not (``0``)."""
    return backend.on_cuda_unless(ENV)


def rewrite(text: str, ids) -> tuple[str | None, list]:
    """(the scene text with the moving shapes ``ids`` as instances, the ids wrapped); (None, []) when none
    can be (module docstring)."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError:
        return None, []                  # Mitsuba's own loader reports the error, with its line
    wrapped, shift = [], 0           # shift: elements added before the current one (a group each)
    for i, el in enumerate(list(root)):
        sid = el.get("id")
        if el.tag != "shape" or sid not in ids or el.get("type") in _NOT_WRAPPED or el.find("emitter") is not None:
            continue
        group = ET.Element("shape", {"type": "shapegroup", "id": group_id(sid)})
        el.set("id", member_id(sid))
        root.remove(el)
        group.append(el)
        instance = ET.Element("shape", {"type": "instance", "id": sid})
        ET.SubElement(instance, "ref", {"id": group_id(sid)})
        root.insert(i + shift, group)      # in the shape's place: what it refers to stays defined before it
        root.insert(i + shift + 1, instance)
        shift += 1
        wrapped.append(sid)
    if not wrapped:
        return None, []
    return ET.tostring(root, encoding="unicode"), sorted(wrapped)


def member(timed, sid: str):
    """The group's own shape of the instance ``sid`` that ``rewrite`` made, or None (not one of them)."""
    if sid not in getattr(timed, "instanced", ()):
        return None
    prefix = f"{group_id(sid)}.{member_id(sid)}."
    for key, (_, _, node, _) in timed.params.properties.items():
        if key.startswith(prefix) and isinstance(node, backend.mi.Shape):
            return node
    return None
