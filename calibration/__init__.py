"""Calibration from the data itself (installed as ``mitsuba_eventfield.calibration``).

* ``galvo``: where each frame sits on the scan curve (phase) and the curve's size, from patch or LED tracks;
* ``led``: an LED's track and curve size from its events alone (no start image), for the depth calibration;
* ``depth``: curve size against known depths, the paper's linear model and the geometric inverse-depth model;
* ``kaleidoscope``: tile seams, flips, sub-pixel view registration, flat-field;
* ``optics``: the optics a calibration was made for, and the check that refuses one made for other optics;
* ``nominal``: the optics of data that carries none (a nominal optics file; a recording's from its calibration);
* ``store``: save / load calibration files (JSON) and apply them to light fields;
* ``recording``: a camera recording's optics (nominal, or its calibration's) and a calibrated light field, in
  Python as the commands make them.
"""
from .depth import DepthCalibration, fit_depth, fit_depth_from_tracks  # noqa: F401
from .galvo import (CalibrationError, GalvoCalibration, PatchTrack, capture_of, fit_galvo, fit_galvo_consistent,
                    fit_tracks,
                    galvo_scale_limit, scale_note, track_patch, track_point)
from .led import fit_led, fit_point_track, track_led  # noqa: F401,E402
from .kaleidoscope import KaleidoscopeCalibration, find_tiles, flat_field, known_tiles, register  # noqa: F401,E402
from .optics import check_optics, kaleidoscope_record, optics_difference, optics_record, same_optics
from .store import save_calibration  # noqa: F401,E402
from .store import CalibrationFile, apply_to_lightfield, calibrated_events, calibrated_optics, load_calibration
from .recording import calibrated_lightfield, with_optics  # noqa: F401,E402
