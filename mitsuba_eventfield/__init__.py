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

from . import lightfield  # noqa: E402
# The package follows the pipeline: scene (scene + motion) -> optics (galvo geometry, scan curves) -> simulate
# (time stepping; the sensor and integrator plugins) -> events (stream, files, previews) -> lightfield
# (reconstruction, views) -> focus (refocus, depth) -> apps (the paper's applications) -> evaluation (truth,
# scores, benchmarks, regression images); calibration/ and device/ beside them, cli/ on top. This facade
# re-exports the names a user needs; each lives in one module.
from ._version import __version__  # noqa: E402
from .apps import scanrate  # noqa: E402
from .apps import scan_frequency  # noqa: E402
from .apps import designs  # noqa: E402
from .apps import hdr, highspeed, slomorf  # noqa: E402
from .backend import choose_variant, quiet_mitsuba_log, set_variant  # noqa: E402
from .errors import ConfigError, EventFieldError  # noqa: E402
from .evaluation import quality, truth  # noqa: E402
from .evaluation.sweep import SweepTable, sweep  # noqa: E402
from .events.io import H5EventWriter, read_events, write_events  # noqa: E402
from .events.preview import event_frame_rgb, write_preview  # noqa: E402
from .events.stream import EventStream  # noqa: E402
from .events.stuck_pixels import stuck_pixels, without_stuck_pixels  # noqa: E402
from .focus import depth, galvo_periods  # noqa: E402,F401  (galvo_periods: from_events' "periods" method)
from .focus.depth import DepthMap, depth_from_focus, focus_measure  # noqa: E402
from .focus.refocus import depth_planes, focal_stack, refocus  # noqa: E402
from .focus.tracking import track_focus  # noqa: E402
from .lightfield import reconstruct  # noqa: E402
from .lightfield.model import LightField, from_galvo, from_spatial, galvo_view_times  # noqa: E402
from .lightfield.streams import galvo_lightfields  # noqa: E402
from .lightfield.views import ViewStack, extract_views, split_events, view_of_pixel  # noqa: E402
from .optics import scan  # noqa: E402
from .optics.scan import ScanCurve, curve_from_dict, event_angles, make_curve  # noqa: E402
from .scene import Motion, TimedScene, load_motion, load_scene, parse_motion  # noqa: E402
from .simulate import auto  # noqa: E402
from .simulate.convert import events_from_frames  # noqa: E402
from .simulate.device_stream import DeviceEventStream  # noqa: E402
from .simulate.render import RenderSummary, render_events, render_frames  # noqa: E402

__all__ = ["__version__", "choose_variant", "set_variant", "quiet_mitsuba_log", "EventFieldError", "ConfigError", "EventStream",
           "DeviceEventStream",
           "H5EventWriter", "read_events", "write_events", "stuck_pixels", "without_stuck_pixels", "Motion",
           "load_motion", "parse_motion",
           "event_frame_rgb", "write_preview", "RenderSummary", "render_events", "render_frames", "events_from_frames", "reconstruct",
           "TimedScene", "load_scene", "scan", "ScanCurve", "make_curve", "curve_from_dict", "event_angles",
           "ViewStack", "extract_views", "split_events", "view_of_pixel", "LightField", "from_galvo",
           "from_spatial", "galvo_lightfields", "galvo_view_times", "SweepTable", "sweep", "depth_planes",
           "focal_stack", "refocus", "track_focus", "DepthMap", "depth_from_focus", "focus_measure", "auto",
           "lightfield", "depth", "quality", "truth", "hdr", "highspeed", "slomorf", "scanrate", "scan_frequency", "designs"]
