"""mitsuba-eventfield: render and process event fields (event cameras behind light-field optics).

    import mitsuba_eventfield as ef
    scene = ef.load_scene("scenes/demo/demo.xml")          # + scenes/demo/demo.motion.toml
    events = ef.render_events(scene, duration=0.02, steps=40, spp=4)
    ef.write_events("demo.h5", events)

Importing this package configures Dr.Jit's libLLVM (see ``_llvm``) before Mitsuba loads; import it before
``mitsuba``/``drjit`` in your own scripts.
"""
from . import _llvm

_llvm.configure()

from ._version import __version__  # noqa: E402
from .backend import choose_variant, set_variant  # noqa: E402
from .errors import ConfigError, EventFieldError  # noqa: E402
from .eventio import H5EventWriter, read_events, write_events  # noqa: E402
from .events import EventStream  # noqa: E402
from .motion import Motion, load_motion, parse_motion  # noqa: E402
from .preview import event_frame_rgb, write_preview  # noqa: E402
from .render import RenderSummary, render_events, render_frames  # noqa: E402
from . import auto, depth, hdr, lightfield, reconstruct  # noqa: E402
from .sweep import SweepTable, sweep  # noqa: E402
from .scene import TimedScene, load_scene  # noqa: E402
from . import scan  # noqa: E402
from . import slomorf  # noqa: E402  (ef.slomorf.slomorf: slow-motion refocus)
from . import highspeed, quality, scanrate, truth  # noqa: E402  (the other applications, their scoring)
from .scan import ScanCurve, curve_from_dict, event_angles, make_curve  # noqa: E402
from .views import ViewStack, extract_views, split_events, view_of_pixel  # noqa: E402
from .lightfield import LightField, from_galvo, from_spatial, galvo_lightfields, galvo_view_times  # noqa: E402
from .refocus import depth_planes, focal_stack, refocus, track_focus  # noqa: E402
from .depth import DepthMap, depth_from_focus, focus_measure  # noqa: E402

__all__ = ["__version__", "choose_variant", "set_variant", "EventFieldError", "ConfigError", "EventStream",
           "H5EventWriter", "read_events", "write_events", "Motion", "load_motion", "parse_motion",
           "event_frame_rgb", "write_preview", "RenderSummary", "render_events", "render_frames", "reconstruct", "TimedScene", "load_scene", "scan",
           "ScanCurve", "make_curve", "curve_from_dict", "event_angles", "ViewStack", "extract_views", "split_events",
           "view_of_pixel", "LightField", "from_galvo", "from_spatial", "galvo_lightfields", "galvo_view_times",
           "SweepTable", "sweep", "depth_planes", "focal_stack", "refocus", "track_focus", "DepthMap", "depth_from_focus", "focus_measure"]
