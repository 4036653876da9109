"""Calibration from the data itself (installed as ``mitsuba_eventfield.calibration``).

* ``galvo``: where each frame sits on the scan curve (phase) and the curve's size, from patch or LED tracks;
* ``depth``: curve size against known depths, the paper's linear model and the geometric inverse-depth model;
* ``kaleidoscope``: tile seams, flips, sub-pixel view registration, flat-field;
* ``store``: save / load calibration files (JSON) and apply them to light fields.
"""
from .depth import DepthCalibration, fit_depth  # noqa: F401
from .galvo import CalibrationError, GalvoCalibration, PatchTrack, fit_galvo, fit_tracks, track_patch, track_point  # noqa: F401
from .kaleidoscope import KaleidoscopeCalibration, find_tiles, flat_field, register  # noqa: F401,E402
from .store import apply_to_lightfield, load_calibration, save_calibration  # noqa: F401,E402
