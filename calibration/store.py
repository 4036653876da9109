"""Calibration files: JSON with a kind and a format version; written atomically; applied to light fields.

    {"format": "mitsuba-eventfield calibration", "version": 2,
     "galvo": {..., "optics": {...}, "quality": {...}}, "depth": {...}, "kaleidoscope": {...}}

Each part records the optics it was made for (``optics.optics_record``) and how well its fit is determined
(``quality``: residual, uncertainty, samples used). Version 1 files recorded no optics and are refused: nothing
could tell whether they belong to the data they are applied to.

``apply_to_lightfield`` makes refocus and depth from focus use the calibration instead of the nominal optics in
the event metadata, after ``optics.check_optics`` has compared the optics: the galvo calibration places each
view on the scan curve (its phase), the depth calibration replaces the disparity model (its inverse-depth fit,
halved for optical angles).
"""
from __future__ import annotations

import json
import os

import numpy as np

from mitsuba_eventfield.atomic import atomic_output, updating
from mitsuba_eventfield.errors import ConfigError, EventFieldError

from .depth import DepthCalibration
from .galvo import GalvoCalibration
from .kaleidoscope import KaleidoscopeCalibration
from .optics import KINDS_FOR_DESIGN, _plain, check_optics, optics_difference

FORMAT, VERSION = "mitsuba-eventfield calibration", 2
_KINDS = {"galvo": GalvoCalibration, "depth": DepthCalibration, "kaleidoscope": KaleidoscopeCalibration}


class CalibrationFile(dict):
    """{kind: calibration object} as loaded from ``path`` (named in every refusal)."""

    def __init__(self, parts: dict, path: str):
        super().__init__(parts)
        self.path = path


def _group(design: str) -> tuple:
    return KINDS_FOR_DESIGN.get(design, ())


def _check_same_setup(path: str, data: dict, kind: str, optics: dict) -> None:
    """One file may hold a galvo and a kaleidoscope calibration, but the parts acting on one design must come
    from one set-up: a depth model and a galvo phase of two set-ups would be refused together anyway, later."""
    for other in _group(optics["design"]):
        if other == kind or other not in data:
            continue
        diff = optics_difference(data[other].get("optics") or {}, optics)
        if diff:
            raise EventFieldError(f"{path}: already holds a {other} calibration made for other optics ({diff}, file vs "
                                  f"new): write this {kind} calibration to another file")


def save_calibration(path: str, optics: dict | None = None, **parts) -> str:
    """Write (or extend) a calibration file with ``galvo=``, ``depth=``, ``kaleidoscope=`` results, each made for
    ``optics`` (an ``optics_record``; default: the result's own ``optics``). Refuses a result with no optics.
    Read, extended and written under one lock (``atomic.updating``): two runs at once keep both parts."""
    with updating(path):
        return _save(path, optics, parts)


def _save(path: str, optics, parts: dict) -> str:
    data = load_calibration_dict(path) if os.path.exists(path) else {"format": FORMAT, "version": VERSION}
    for kind, obj in parts.items():
        if kind not in _KINDS:
            raise EventFieldError(f"{path}: unknown calibration kind {kind!r}; allowed: {', '.join(_KINDS)}")
        made_for = _plain(optics) if optics is not None else obj.optics
        diff = optics_difference(obj.optics, made_for) if obj.optics and made_for else None
        if diff:
            raise EventFieldError(f"{path}: the {kind} calibration was made for other optics than those it is saved "
                                  f"with ({diff})")
        if not made_for or kind not in _group(made_for.get("design")):
            raise EventFieldError(f"{path}: the {kind} calibration records no optics it was made for (got "
                                  f"{made_for or 'none'}): pass optics=optics_record(...) of its data")
        _check_same_setup(path, data, kind, made_for)
        obj.optics = made_for
        d = obj.as_dict()
        d.pop("kind", None)
        data[kind] = d
    with atomic_output(path, "calibration file") as tmp, open(tmp, "w") as f:
        json.dump(data, f, indent=2, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o))
    return path


def load_calibration_dict(path: str) -> dict:
    from mitsuba_eventfield.validate import json_file
    data = json_file(path, "calibration file")
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise EventFieldError(f"{path}: not a version {VERSION} {FORMAT!r} file")
    if data.get("version") == 1:
        raise EventFieldError(f"{path}: a version 1 calibration file, which records no optics, so it cannot be "
                              "checked against the data: re-run eventfield calibrate into a new file")
    if data.get("version") != VERSION:
        raise EventFieldError(f"{path}: not a version {VERSION} {FORMAT!r} file (version {data.get('version')!r})")
    return data


def load_calibration(path: str) -> CalibrationFile:
    """{kind: calibration object} for every kind in the file; each part must record its optics."""
    data = load_calibration_dict(path)
    out = {}
    for kind, cls in _KINDS.items():
        if kind not in data:
            continue
        fields = dict(data[kind]) if isinstance(data[kind], dict) else {}
        fields.pop("quality", None)                       # derived from the other fields, for readers
        if not isinstance(fields.get("optics"), dict) or not fields["optics"].get("design"):
            raise EventFieldError(f"{path}: the {kind} calibration records no optics, so it cannot be checked "
                                  "against the data: re-run eventfield calibrate")
        for key in ("scale_px_per_rad", "tile", "inverse", "linear", "inverse_y"):
            if key in fields and isinstance(fields[key], list):
                fields[key] = tuple(fields[key])
        try:
            out[kind] = cls(**fields)
        except TypeError as e:
            raise EventFieldError(f"{path}: the {kind} calibration is not readable ({e}): re-run eventfield "
                                  "calibrate") from None
        except ConfigError as e:           # a field's value, checked by the calibration's own class
            raise EventFieldError(f"{path}: {e}") from None
    return CalibrationFile(out, path)


def calibrated_optics(calibration: dict, optics: dict, width: int, height: int) -> dict:
    """A galvo stream's optics metadata (``events.meta["optics"]`` or its ``optics_record``) with the galvo and
    depth parts of ``calibration`` in it, so that whatever reads the optics reads the calibrated views: the
    events-only solvers' equations, the light field's positions and geometry, the depths searched. A galvo
    calibration's curve with its phase as the record's ``time_offset`` (the view at capture time t is where the
    curve is at tau0 + t - t_first: ``GalvoCalibration.view_angles``); a depth calibration's pivots and angle
    gains as ``calibrated_geometry`` (``DepthCalibration.geometry``, read by ``GalvoGeometry.from_optics``);
    ``calibrated`` lists the parts, ``commanded_scan`` keeps the record's own scan; ``width`` x ``height``: the
    film (the gains are per focal length in pixels). The caller checks the calibration against the data first
    (``check_optics``)."""
    from mitsuba_eventfield.optics.galvo import GalvoGeometry
    if optics.get("calibrated"):
        raise EventFieldError(f"the optics are already calibrated ({', '.join(optics['calibrated'])}): apply a "
                              "calibration once, to the data's own optics")
    out, kinds = dict(optics), [k for k in ("galvo", "depth") if k in calibration]
    if "galvo" in kinds:
        g = calibration["galvo"]
        # added to a record's own offset (a table keeps its shift there: optics.scan.curve_to_dict)
        out["scan"] = dict(g.curve, time_offset=float(g.curve.get("time_offset", 0.0)) + float(g.tau0 - g.t_first))
        # what the controller was told: ``event_angles(actual=False)`` (the fitted curve is what the mirror did)
        out["commanded_scan"] = dict(optics["scan"])
    if "depth" in kinds:
        nominal = GalvoGeometry.from_optics(optics, width, height)
        geometry = calibration["depth"].geometry(nominal)
        out["calibrated_geometry"] = {k: float(getattr(geometry, k))
                                      for k in ("pivot_x", "pivot_y", "gain_x", "gain_y")}
    out["calibrated"] = kinds
    return out


def calibrated_events(events, calibration: dict, optics: dict):
    """``events`` with its optics metadata calibrated (``calibrated_optics``), for reconstructions that read the
    views' geometry while they solve (``focus.galvo_periods``, the ``galvo`` method); ``optics``: the
    ``optics_record`` of ``events``, against which the calibration is checked first. Other designs are returned
    as they are (their calibration acts on the light field: ``apply_to_lightfield``)."""
    from mitsuba_eventfield.events.stream import EventStream

    from .galvo import check_capture
    kinds = check_optics(calibration, optics)
    if optics.get("design") != "galvo" or not set(kinds) & {"galvo", "depth"}:
        return events
    if "galvo" in kinds:
        check_capture(calibration["galvo"], events)
    meta = dict(events.meta, optics=calibrated_optics(calibration, events.meta["optics"], events.width,
                                                      events.height))
    return EventStream(events.x, events.y, events.t, events.p, events.width, events.height, meta)


def apply_to_lightfield(lf, calibration: dict, optics: dict):
    """A copy of ``lf`` placed and scaled by the calibration (galvo: view positions from the fitted phase;
    depth: the disparity model from the inverse-depth fit, both as ``calibrated_optics`` puts them; kaleidoscope:
    each view's misalignment as part of its shifts, and the flat field dividing views whose levels come from a
    frame). ``optics``: the ``optics_record`` of the data ``lf`` was made from; a calibration made for other
    optics is refused (``optics.check_optics``). A galvo light field solved from events alone is calibrated
    better through its events (``calibrated_events``): the solver then uses the calibrated views too."""
    from mitsuba_eventfield.lightfield.model import LightField, galvo_paraxial_disparity
    from mitsuba_eventfield.optics.galvo import GalvoGeometry
    from mitsuba_eventfield.optics.scan import curve_from_dict
    if not isinstance(optics, dict) or "design" not in optics:
        raise EventFieldError("apply_to_lightfield needs the optics record of the light field's data "
                              "(calibration.optics_record(events.meta['optics'], width, height))")
    if lf.meta.get("calibrated"):        # a flat field applied twice divided twice
        raise EventFieldError(f"the light field is already calibrated ({', '.join(lf.meta['calibrated'])}): apply "
                              "a calibration once, to the light field made from the data")
    kinds = check_optics(calibration, optics)
    views, positions, disparity, geometry = lf.views, lf.positions.copy(), lf.disparity, lf.galvo
    offsets, applied = lf.view_offsets, set(kinds)
    if lf.kind == "galvo" and set(kinds) & {"galvo", "depth"}:
        placed = calibrated_optics(calibration, optics, optics["width"], optics["height"])
        if "galvo" in kinds:
            curve = curve_from_dict(placed["scan"], where="galvo calibration")
            positions = np.stack(curve.optical_angles(np.asarray(lf.times, np.float64)), axis=-1)
        if "depth" in kinds:      # a light field without its geometry (shift-invariant) takes the paraxial model
            placed_geometry = GalvoGeometry.from_optics(placed, lf.shape[1], lf.shape[0])
            disparity = galvo_paraxial_disparity(placed_geometry)
            geometry = placed_geometry if geometry is not None else None
    if "kaleidoscope" in kinds:
        views, offsets, flat = _kaleidoscope_applied(lf, calibration["kaleidoscope"])
        applied |= {"flat_field"} if flat else set()
    return LightField(views, positions, lf.times, disparity, lf.kind, dict(lf.meta, calibrated=sorted(applied)),
                      geometry, offsets)


def _kaleidoscope_applied(lf, calibration) -> tuple:
    """(views, view_offsets, flat-fielded?) of a kaleidoscope light field under its calibration. The gains divide
    only views whose levels a frame gave (``meta['levels'] == 'frame'``): views integrated from events alone,
    or high-passed, hold log changes, the same under any gain, and dividing them would print the vignetting in
    reverse."""
    ij = lf.meta.get("ij")
    if lf.kind != "kaleidoscope" or ij is None or len(ij) != len(lf.views):
        raise EventFieldError(f"a kaleidoscope calibration applies to a kaleidoscope light field with its views' "
                              f"indices (meta['ij']); this one is {lf.kind!r}")
    offsets = calibration.misalignment(ij, lf.positions, lf.disparity)
    gains = calibration.view_gains(ij) if lf.meta.get("levels") == "frame" else None
    if gains is None:
        return lf.views, offsets, False
    if gains.shape != lf.views.shape[:3]:
        raise EventFieldError(f"the kaleidoscope calibration's views are {gains.shape[2]}x{gains.shape[1]} px, the "
                              f"light field's {lf.shape[1]}x{lf.shape[0]}")
    return lf.views / (gains if lf.views.ndim == 3 else gains[..., None]), offsets, True
