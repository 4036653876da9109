"""Scene and motion: a Mitsuba scene with its motion file, posed at any instant (``TimedScene``)."""
from .bundled import bundled_scene, scenes_dir  # noqa: F401
from .motion import Motion, load_motion, parse_motion  # noqa: F401
from .timed import TimedScene, load_scene  # noqa: F401
