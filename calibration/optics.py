"""The optics a calibration was made for, and the comparison that refuses one made for other optics.

A calibration measures one set-up: the galvo's phase and curve size hold for one scan curve, lens and film, the
depth model for one pair of mirror pivots, the kaleidoscope's registration for one tube and film. Applied to
another set-up it is silently wrong (reported on the runner: 34-71 % depth error instead of 2-4 %), so every
part records the nominal optics of the data it was fitted to (``optics_record``), and whatever applies a
calibration compares them with the optics of its own data (``check_optics``).

Compared, within ``REL_TOL``: film width and height (exactly), and

* galvo: the field of view, both mirror pivots, and the scan curve (kind, frequencies, amplitudes, offsets,
  table sizes, mirror bandwidth). Not its phase: that is what the galvo calibration measures. For a Lissajous
  figure the two phases minus a common time shift (its shape) are compared. Not ``max_angle_deg`` either (the
  mirror's safety limit, not optics), nor aperture and focus (blur only);
* kaleidoscope: the view count n, and the main lens (focal length, focus, aperture) and tube (size, relay
  distance and aperture) where both records know them (a calibration made from a bare EXR frame without
  ``--optics`` knows only its size and the tiles it found).
"""
from __future__ import annotations

import json
import math

import numpy as np

from mitsuba_eventfield.errors import EventFieldError

REL_TOL = 1e-3                  # 0.1 %: galvo depth is ~z / pivot = 10x as sensitive to the scales (1 % of depth)
PHASE_TOL_DEG = 0.1             # Lissajous shape (relative phase after the best common time shift)
GALVO_KEYS = ("fov_x_deg", "mirror_distance", "mirror_separation")
SPATIAL_KEYS = ("focal_length", "focus_distance", "tube", "relay_distance", "aperture_radius", "relay_aperture")
# carried, not compared (they follow from n and the keys above): the views a camera recording of the set-up,
# which carries no optics, takes its light field from (``calibration.nominal.recording_optics``)
SPATIAL_CARRIED = ("views", "lens_to_image_plane", "image_plane_size")
SCAN_NOT_COMPARED = ("phase", "phase_x", "phase_y", "max_angle_deg")
# the calibration kinds that act on each design's light fields
KINDS_FOR_DESIGN = {"galvo": ("galvo", "depth"), "kaleidoscope": ("kaleidoscope",), "microlens": ("kaleidoscope",)}


def _plain(value):
    """JSON-plain copy (NumPy scalars and arrays to Python numbers and lists)."""
    return json.loads(json.dumps(value, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))


def optics_record(optics: dict, width: int, height: int, where: str = "the data") -> dict:
    """What a calibration of data with sensor metadata ``optics`` (``events.meta["optics"]``) and a
    ``width`` x ``height`` film was made for: the fields ``check_optics`` compares."""
    design = (optics or {}).get("design")
    if design not in KINDS_FOR_DESIGN:
        raise EventFieldError(f"{where}: its metadata describes no light-field optics (optics.design is {design!r}; "
                              "expected galvo, kaleidoscope or microlens): a calibration cannot be checked against it")
    if optics.get("calibrated"):      # calibrated_optics: fitting or checking against it would mix the two
        raise EventFieldError(f"{where}: its optics are already calibrated ({', '.join(optics['calibrated'])}): a "
                              "calibration is made for and checked against the recording's own optics")
    record = {"design": design, "width": int(width), "height": int(height)}
    keys = ("scan",) + GALVO_KEYS if design == "galvo" else ("n",) + SPATIAL_KEYS + SPATIAL_CARRIED
    record.update({k: _plain(optics[k]) for k in keys if optics.get(k) is not None})
    missing = [k for k in ("scan",) + GALVO_KEYS if k not in record] if design == "galvo" else []
    if missing:
        raise EventFieldError(f"{where}: galvo optics without {', '.join(missing)} in its metadata")
    return record


def _same(a, b) -> bool:
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return math.isclose(a, b, rel_tol=REL_TOL, abs_tol=1e-12)
    return a == b


def _lissajous_shape_differs(a: dict, b: dict) -> bool:
    """Whether the phases of two Lissajous scans differ by more than a common time shift tau, which moves
    phase_x by 360 fx tau and phase_y by 360 fy tau: tau from phase_x (one per x cycle of the figure's period),
    then what is left of phase_y."""
    from mitsuba_eventfield.optics.scan import curve_from_dict
    fx, fy = a["freq_x"], a["freq_y"]
    period = curve_from_dict(a).period
    cycles = np.arange(max(1, min(10_000, round(fx * period))) if period else 1)
    tau = ((b["phase_x"] - a["phase_x"]) / 360 + cycles) / fx
    left = (b["phase_y"] - a["phase_y"] - 360 * fy * tau + 180) % 360 - 180
    return float(np.min(np.abs(left))) > PHASE_TOL_DEG


def _scan_difference(a: dict, b: dict) -> str | None:
    for key in ["curve"] + sorted((set(a) | set(b)) - set(SCAN_NOT_COMPARED) - {"curve"}):
        if not _same(a.get(key), b.get(key)):
            return f"scan {key} {a.get(key)!r} vs {b.get(key)!r}"
    if a.get("curve") == "lissajous" and _lissajous_shape_differs(a, b):
        return (f"scan phase_x, phase_y ({a['phase_x']:g}, {a['phase_y']:g}) vs ({b['phase_x']:g}, {b['phase_y']:g}) "
                "(a different Lissajous figure, not a time shift)")
    return None


def optics_difference(made_for: dict, used_with: dict) -> str | None:
    """The first field in which two optics records differ, as ``"field A vs B"``; None for the same set-up."""
    for key in ("design", "width", "height"):
        if made_for.get(key) != used_with.get(key):
            return f"{key} {made_for.get(key)!r} vs {used_with.get(key)!r}"
    if made_for["design"] == "galvo":
        for key in GALVO_KEYS:
            if not _same(made_for.get(key), used_with.get(key)):
                return f"{key} {made_for.get(key)!r} vs {used_with.get(key)!r}"
        return _scan_difference(made_for.get("scan") or {}, used_with.get("scan") or {})
    for key in ("n",) + SPATIAL_KEYS:       # where both know it
        if key in made_for and key in used_with and not _same(made_for[key], used_with[key]):
            return f"{key} {made_for[key]!r} vs {used_with[key]!r}"
    return None


def check_optics(calibration: dict, optics: dict, source: str | None = None) -> tuple:
    """Refuse (EventFieldError, one line naming the file, the field and both values) a calibration any of whose
    parts acting on ``optics`` (an ``optics_record`` of the data) was made for other optics; returns those
    kinds. Parts for the other design are left alone (one file may hold a galvo and a kaleidoscope calibration),
    but a calibration with none for this design is refused: it would silently change nothing."""
    source = source or getattr(calibration, "path", None) or "calibration"
    kinds = tuple(k for k in KINDS_FOR_DESIGN[optics["design"]] if k in calibration)
    if not kinds:
        raise EventFieldError(f"{source}: holds no calibration for {optics['design']} optics (it has "
                              f"{', '.join(sorted(calibration)) or 'nothing'})")
    for kind in kinds:
        made_for = getattr(calibration[kind], "optics", None)
        if not made_for:
            raise EventFieldError(f"{source}: the {kind} calibration records no optics, so it cannot be checked "
                                  "against the data: re-run eventfield calibrate")
        diff = optics_difference(made_for, optics)
        if diff:
            raise EventFieldError(f"{source}: the {kind} calibration was made for other optics: {diff} (calibration "
                                  "vs data); re-run eventfield calibrate on data from this set-up")
    return kinds


def same_optics(records: dict) -> dict:
    """The one optics record of several captures ({name: optics_record}) that one calibration is fitted to;
    refuses captures from different set-ups, naming the first that differs."""
    (first, ref), *rest = records.items()
    for name, record in rest:
        diff = optics_difference(ref, record)
        if diff:
            raise EventFieldError(f"{name}: made with other optics than {first}: {diff}; one calibration needs "
                                  "captures from one set-up")
    return ref


def kaleidoscope_record(width: int, height: int, n: int, optics: dict | None = None,
                        where: str = "the frame") -> dict:
    """The optics record of a kaleidoscope calibration from a frame: its size and the tile count found, and the
    sensor's metadata (main lens, tube) when the frame carries it (an EXR written by eventfield)."""
    optics = dict(optics or {"design": "kaleidoscope"})
    if optics.get("design") != "kaleidoscope":
        raise EventFieldError(f"{where}: its metadata describes {optics.get('design')!r} optics: a kaleidoscope "
                              "calibration needs a kaleidoscope frame")
    if optics.get("n", n) != n:
        raise EventFieldError(f"{where}: {n}x{n} tiles found, but its metadata says n = {optics['n']}")
    return optics_record(dict(optics, n=n), width, height, where)
