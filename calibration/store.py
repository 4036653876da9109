"""Calibration files: JSON with a kind and a format version; written atomically; applied to light fields.

    {"format": "mitsuba-eventfield calibration", "version": 1, "galvo": {...}, "depth": {...},
     "kaleidoscope": {...}}

``apply_to_lightfield`` makes refocus and depth from focus use the calibration instead of the nominal optics in
the event metadata: the galvo calibration places each view on the scan curve (its phase), the depth
calibration replaces the disparity model (its inverse-depth fit, halved for optical angles).
"""
from __future__ import annotations

import json
import os

import numpy as np

from mitsuba_eventfield.atomic import atomic_output
from mitsuba_eventfield.errors import EventFieldError

from .depth import DepthCalibration
from .galvo import GalvoCalibration
from .kaleidoscope import KaleidoscopeCalibration

FORMAT, VERSION = "mitsuba-eventfield calibration", 1
_KINDS = {"galvo": GalvoCalibration, "depth": DepthCalibration, "kaleidoscope": KaleidoscopeCalibration}


def save_calibration(path: str, **parts) -> str:
    """Write (or extend) a calibration file with ``galvo=``, ``depth=``, ``kaleidoscope=`` results."""
    data = load_calibration_dict(path) if os.path.exists(path) else {"format": FORMAT, "version": VERSION}
    for kind, obj in parts.items():
        if kind not in _KINDS:
            raise EventFieldError(f"{path}: unknown calibration kind {kind!r}; allowed: {', '.join(_KINDS)}")
        d = obj.as_dict()
        d.pop("kind", None)
        data[kind] = d
    with atomic_output(path, "calibration file") as tmp, open(tmp, "w") as f:
        json.dump(data, f, indent=2, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o))
    return path


def load_calibration_dict(path: str) -> dict:
    try:
        with open(path) as f:
            data = json.load(f)
    except FileNotFoundError:
        raise EventFieldError(f"{path}: calibration file not found") from None
    except json.JSONDecodeError as e:
        raise EventFieldError(f"{path}: not a calibration file (invalid JSON: {e})") from None
    if data.get("format") != FORMAT or data.get("version") != VERSION:
        raise EventFieldError(f"{path}: not a version {VERSION} {FORMAT!r} file")
    return data


def load_calibration(path: str) -> dict:
    """{kind: calibration object} for every kind in the file."""
    data = load_calibration_dict(path)
    out = {}
    for kind, cls in _KINDS.items():
        if kind in data:
            fields = dict(data[kind])
            for key in ("scale_px_per_rad", "tile", "inverse", "linear", "inverse_y"):
                if key in fields and isinstance(fields[key], list):
                    fields[key] = tuple(fields[key])
            out[kind] = cls(**fields)
    return out


def apply_to_lightfield(lf, calibration: dict):
    """A copy of ``lf`` placed and scaled by the calibration (galvo: view positions from the fitted phase;
    depth: the disparity model from the inverse-depth fit)."""
    from mitsuba_eventfield.lightfield import LightField
    positions, A, B = lf.positions.copy(), lf.A, lf.B
    if "galvo" in calibration and lf.kind == "galvo":
        ax, ay = calibration["galvo"].view_angles(lf.times)
        positions = np.stack([2 * np.asarray(ax), 2 * np.asarray(ay)], axis=-1)
    if "depth" in calibration:
        A, B = calibration["depth"].disparity_model()
    return LightField(lf.views, positions, lf.times, A, B, lf.kind, dict(lf.meta, calibrated=sorted(calibration)))
