"""The light field of data made with a calibrated or nominal set-up, in Python as the commands make it.

A camera recording carries no optics: :func:`with_optics` gives it the set-up's nominal optics (a JSON file or a
dict, the commands' ``--optics``) or those of the calibration made for the set-up (``--calibration``), and
:func:`calibrated_lightfield` makes the light field with every part of a calibration applied (a galvo's phase
and depth model through the events, so the solvers use the calibrated views; a kaleidoscope's registration and
flat field on the light field). The commands call both (``cli.inputs.give_optics``, ``cli.lightfield``), so a
script and a command given the same files get the same light field. Contrast thresholds, which a recording
lacks too, are ``from_events``' ``c_on`` / ``c_off``.

    import mitsuba_eventfield as ef
    from mitsuba_eventfield import calibration
    cal = calibration.load_calibration("kcal.json")
    rec = calibration.with_optics(ef.read_events("capture.aedat4"), calibration=cal)
    lf = calibration.calibrated_lightfield(rec, cal, c_on=0.2, c_off=0.2)
"""
from __future__ import annotations

import os

from mitsuba_eventfield.errors import ConfigError, EventFieldError

class CommandedPhaseWarning(UserWarning):
    """A galvo recording's views placed at the commanded scan phase: no calibration measured the mirror's."""


PYTHON_NAMES = {"optics": "optics=", "calibration": "calibration=", "file": "FILE.json or a dict"}
COMMAND_NAMES = {"optics": "--optics", "calibration": "--calibration", "file": "FILE.json"}


def with_optics(events, optics=None, calibration=None, *, design: str | None = None, where: str = "the events",
                names: dict = PYTHON_NAMES, takes_calibration: bool = True):
    """``events`` (a camera recording, which carries no optics) with the set-up's optics in its metadata: the
    nominal ones of ``optics`` (a JSON file's path or a dict: ``design`` galvo with fov_x_deg, mirror_distance,
    mirror_separation and the scan record, or kaleidoscope / microlens with the sensor's parameters in metres;
    ``design``: the one the caller takes, None for any) or those recorded by ``calibration`` (a loaded
    calibration file or its path). A stream that carries its own optics is returned as it is, and refuses
    ``optics`` (it would be ignored); one with neither is refused, saying what to pass. ``names``: how the
    caller spells the two (the commands pass ``COMMAND_NAMES``); ``takes_calibration``: whether the refusal
    offers a calibration (``eventfield calibrate`` makes one)."""
    from mitsuba_eventfield.events.stream import EventStream

    from .nominal import nominal_optics, recording_optics
    if not isinstance(events, EventStream):
        raise ConfigError(f"with_optics: events: expected an EventStream (ef.read_events), got "
                          f"{type(events).__name__}")
    if optics is not None and calibration is not None:        # one would be ignored
        raise EventFieldError(f"{names['optics']} and {names['calibration']}: give one (a calibration records the "
                              "optics it was made for)")
    if events.meta.get("optics"):
        if optics is not None:
            shown = os.fspath(optics) if isinstance(optics, (str, os.PathLike)) else "(a dict)"
            raise EventFieldError(f"{names['optics']} {shown}: {where} carries its own "
                                  f"({events.meta['optics'].get('design')}) optics; {names['optics']} is for a "
                                  "camera recording without them")
        return events
    if optics is not None:
        if not isinstance(optics, (str, os.PathLike, dict)):
            raise ConfigError(f"{names['optics']} {type(optics).__name__}: expected {names['file']}")
        record = nominal_optics(optics if isinstance(optics, dict) else os.fspath(optics), events.width,
                                events.height, design=design)
    elif calibration is not None:
        calibration = _loaded(calibration, names["calibration"])        # read once: a path is loaded here
        record = recording_optics(calibration, events, where)
    else:
        raise EventFieldError(f"{where}: the recording carries no optics (no light-field metadata): pass "
                              f"{optics_options(names, design, takes_calibration)}")
    crop = (events.meta.get("crop") or {}).get("window")
    if crop is not None and record.get("design") == "galvo":     # its field of view and axis: the whole film's
        raise EventFieldError(f"{where}: cut to the window {','.join(map(str, crop))} of its sensor: a window is "
                              "for a kaleidoscope's tube image on part of the sensor; galvo optics describe the "
                              "whole film")
    if record.get("design") == "galvo" and (calibration is None or "galvo" not in calibration):
        import warnings
        warnings.warn(f"{where}: the views sit at the commanded scan phase, which no galvo calibration measured: a "
                      "mirror that lags its command misplaces them (a quarter period of the 100 Hz circle read "
                      "offaxis_cards' 0.5 / 1.2 m cards at 1.11 / 1.09 m); eventfield calibrate galvo measures it",
                      CommandedPhaseWarning, stacklevel=2)
    return EventStream(events.x, events.y, events.t, events.p, events.width, events.height,
                       dict(events.meta, optics=record))


def optics_options(names: dict = PYTHON_NAMES, design: str | None = None, takes_calibration: bool = True) -> str:
    """What a recording without optics is told to pass (the one wording of every such refusal)."""
    return (f"{names['calibration']} (a calibration file made for its set-up) or " if takes_calibration else "") + \
        f"{names['optics']} {names['file']} (the set-up's nominal {design or 'light-field'} optics)"


def calibrated_lightfield(events, calibration, *, where: str = "the events", nearest: float | None = None,
                          **from_events_kw):
    """The light field of ``events`` (``lightfield.streams.from_events`` and its keywords) with every part of
    ``calibration`` (a loaded file or its path; None: none) applied: a calibration made for other optics, or
    for another window of the sensor, than the stream's is refused before any reconstruction; a galvo stream's
    phase and depth model go into its optics first (``calibrated_events``: the events-only solvers then use
    the calibrated views and pivots), the rest (a kaleidoscope's registration and flat field) onto the light
    field (``apply_to_lightfield``). ``nearest``: a nearer depth the caller needs (the commands' --near), which
    the per-period solver then searches too when no ``depth_range`` is given (from the calibrated pivots:
    ``galvo_periods.default_depth_range``). The light field's ``meta["calibrated"]`` lists the parts applied;
    ``where``: what the refusals call the events."""
    from mitsuba_eventfield.events.stream import EventStream
    from mitsuba_eventfield.focus.galvo_periods import default_depth_range
    from mitsuba_eventfield.lightfield.streams import PERIODS, default_method, from_events

    from .store import apply_to_lightfield
    if not isinstance(events, EventStream):
        raise ConfigError(f"calibrated_lightfield: events: expected an EventStream (ef.read_events, then "
                          f"with_optics for a recording), got {type(events).__name__}")
    loaded = None if calibration is None else _loaded(calibration, "calibrated_lightfield: calibration")
    placed, record = (events, None) if loaded is None else calibrated_stream(events, loaded, where)[:2]
    optics = placed.meta.get("optics") or {}
    method = from_events_kw.get("method") or default_method(optics.get("design"),
                                                            from_events_kw.get("log_start") is not None)
    if method == PERIODS and nearest is not None and from_events_kw.get("depth_range") is None:
        from_events_kw["depth_range"] = default_depth_range(optics, nearest)
    lf = from_events(placed, **from_events_kw)
    if loaded is None or lf.meta.get("calibrated"):      # none, or applied through the events
        return lf
    try:
        return apply_to_lightfield(lf, loaded, record)
    except ConfigError as e:                             # a calibration's own refusal names no file
        raise EventFieldError(f"{getattr(loaded, 'path', 'calibration')}: {e}") from None


def calibrated_stream(events, calibration, where: str = "the events") -> tuple:
    """(``events`` with a galvo calibration's phase and depth model in its optics, the stream's optics record,
    the parts so applied): a calibration made for other optics, or another window of the sensor, is refused
    first. The one place where a calibration reaches a stream (``calibrated_lightfield``; ``reconstruct``'s
    galvo solve)."""
    from .nominal import check_crop
    from .optics import check_optics, optics_record
    from .store import calibrated_events
    loaded = _loaded(calibration, "calibration")
    record = optics_record(events.meta.get("optics", {}), events.width, events.height, where=where)
    kinds = check_optics(loaded, record)
    check_crop(loaded, events, where, getattr(loaded, "path", "calibration"))
    applied = sorted(set(kinds) & {"galvo", "depth"}) if record.get("design") == "galvo" else []
    return calibrated_events(events, loaded, record), record, applied


def _loaded(calibration, name: str):
    """A calibration given as a loaded file (or a dict of its parts) or a path (str or path-like)."""
    from .store import load_calibration
    if isinstance(calibration, (str, os.PathLike)):
        return load_calibration(os.fspath(calibration))
    if not isinstance(calibration, dict):
        raise ConfigError(f"{name}: expected a calibration file's path or calibration.load_calibration(...), got "
                          f"{type(calibration).__name__}")
    return calibration
