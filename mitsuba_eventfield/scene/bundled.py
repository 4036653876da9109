"""The scenes shipped with the package (``scenes/`` in the source tree, installed as the package data
``mitsuba_eventfield.scenes``), found the same way from a checkout, an editable install or a wheel."""
from __future__ import annotations

import os
from importlib import resources

from ..errors import EventFieldError


def scenes_dir() -> str:
    """The folder holding the bundled scenes."""
    return str(resources.files("mitsuba_eventfield.scenes"))


def bundled_scene(name: str) -> str:
    """Path of a bundled scene file, e.g. ``bundled_scene("fan/fan.xml")``."""
    path = os.path.join(scenes_dir(), *name.split("/"))
    if not os.path.isfile(path):
        available = sorted(os.path.relpath(os.path.join(d, f), scenes_dir())
                           for d, _, files in os.walk(scenes_dir()) for f in files if f.endswith(".xml"))
        raise EventFieldError(f"no bundled scene {name!r}; available: {', '.join(available)}")
    return path
