"""The optics of data that carries none (a camera recording, a camera frame): a set-up's nominal optics from a
JSON file, and the optics a recording takes from the calibration made for its set-up. The light-field commands
and ``eventfield calibrate`` both read them from here."""
from __future__ import annotations

from mitsuba_eventfield.errors import ConfigError, EventFieldError

# what from_events needs of each design's optics, beyond what a calibration's optics record always holds
LIGHTFIELD_FIELDS = {"galvo": ("scan", "fov_x_deg", "mirror_distance", "mirror_separation"),
                     "kaleidoscope": ("n", "views", "lens_to_image_plane", "image_plane_size", "focus_distance"),
                     "microlens": ("n", "views", "lens_to_image_plane", "image_plane_size", "focus_distance")}


def nominal_optics(path, width: int, height: int, design: str | None = "galvo") -> dict:
    """A set-up's nominal optics from a JSON file (``--optics``) or a dict of its fields (Python's ``optics=``), for a
    camera recording or frame that carries none, as a render records them in ``meta["optics"]``; ``design`` is the one
    the command takes (None: the file's own, any light-field design). Galvo: the fields a render records (fov_x_deg,
    mirror_distance, mirror_separation, scan), each checked, and no others. Kaleidoscope (or microlens): the sensor
    plugin's own parameters (focal_length, focus_distance, tube_width, ...), from which the sensor itself, on this
    ``width`` x ``height`` film, gives the views, tiles and sub-apertures (``kaleidoscope_sensor.optics_of``).
    Calibrating needs them to start from; the calibration then records them for the light-field commands."""
    from mitsuba_eventfield.validate import json_file
    if isinstance(path, dict):                  # Python's optics= as a record: checked as a file's would be
        optics, path = dict(path), "optics"
    else:
        optics = json_file(path, "optics file")
    found = optics.get("design") if isinstance(optics, dict) else None
    if design is None:
        if found not in LIGHTFIELD_FIELDS:
            raise EventFieldError(f"{path}: design = {found!r}: expected a JSON object whose \"design\" is one of "
                                  f"{', '.join(LIGHTFIELD_FIELDS)}")
        design = found
    if design == "galvo":
        fields = LIGHTFIELD_FIELDS["galvo"]
    else:
        from mitsuba_eventfield.backend import ensure_variant
        from mitsuba_eventfield.plugins.kaleido_optics import SETUP_PARAMETERS
        from mitsuba_eventfield.plugins.kaleidoscope_sensor import optics_of
        fields = SETUP_PARAMETERS[design]
    if found != design:
        raise EventFieldError(f"{path}: design = {found!r}: this command takes {design} optics (a JSON object with "
                              f"\"design\": \"{design}\" and {', '.join(fields)}"
                              f"{'' if design == 'galvo' else ', each optional'})")
    if design == "galvo":
        return _galvo_nominal(path, optics)
    ensure_variant()                                  # the sensor plugin is registered with the variant
    try:
        return optics_of(design, {k: v for k, v in optics.items() if k != "design"}, width, height)
    except ValueError as e:
        raise EventFieldError(f"{path}: {e}") from None


# what a scan record of a rig's nominal optics must give, per curve (``optics.scan.make_curve``'s parameters
# that set its rate and size): their defaults are for curves built in code, and a record without them took
# them silently (a 2 deg circle without its frequency read as 250 Hz: depths 0.94 / 0.73 m for 0.5 / 1.2)
SCAN_SIZE_AND_RATE = {"circle": ("frequency", "amplitude"), "line": ("frequency", "amplitude"),
                      "lissajous": ("freq_x", "freq_y", "amplitude_x", "amplitude_y"),
                      "raster": ("frequency", "lines", "amplitude_x", "amplitude_y"),
                      "moore": ("frequency", "order", "amplitude")}


def _galvo_nominal(path: str, optics: dict) -> dict:
    from mitsuba_eventfield.optics.galvo import OPTICS_RECORD_KEYS, checked_optics
    from mitsuba_eventfield.optics.scan import curve_from_dict
    missing = [k for k in LIGHTFIELD_FIELDS["galvo"] if k not in optics]
    if missing:
        raise EventFieldError(f"{path}: galvo optics without {', '.join(missing)}")
    unknown = sorted(set(optics) - set(OPTICS_RECORD_KEYS))
    if unknown:            # a misspelt optional field would have been left out silently
        raise EventFieldError(f"{path}: {', '.join(unknown)}: not a field of galvo optics (allowed: "
                              f"{', '.join(OPTICS_RECORD_KEYS)})")
    try:
        keys = ("fov_x_deg", "mirror_distance", "mirror_separation")
        optics.update(zip(keys, checked_optics(*(optics[k] for k in keys), path)))
        if not isinstance(optics["scan"], dict):
            raise EventFieldError(f"{path}: scan = {optics['scan']!r}: expected a scan curve record")
        missing = [k for k in SCAN_SIZE_AND_RATE.get(optics["scan"].get("curve"), ()) if k not in optics["scan"]]
        if missing:        # a default (250 Hz, 1 deg) is no rig's: refused as a missing field is
            raise EventFieldError(f"{path}: scan: a {optics['scan']['curve']} record without {', '.join(missing)} "
                                  f"(it needs {', '.join(SCAN_SIZE_AND_RATE[optics['scan']['curve']])})")
        curve_from_dict(optics["scan"], where=f"{path}: scan")
    except ConfigError as e:
        raise EventFieldError(str(e)) from None
    return optics


def recording_optics(calibration, ev, where) -> dict:
    """The optics of a recording (which carries none) from the calibration made for its set-up: the optics record
    its parts share, checked against the recording's film size and for what the light field needs."""
    records = [getattr(part, "optics", None) or {} for part in calibration.values()]
    designs = sorted({r.get("design") for r in records if r.get("design")})
    source = getattr(calibration, "path", "calibration")
    if len(designs) != 1:
        raise EventFieldError(f"{source}: cannot give optics to {where}, which carries none: the calibration is for "
                              f"{' and '.join(map(str, designs)) or 'no'} optics, it must be for one design")
    record = next(r for r in records if r.get("design") == designs[0])
    check_crop(calibration, ev, where, source)
    if (record.get("width"), record.get("height")) != (ev.width, ev.height):
        raise EventFieldError(f"{source}: made for a {record.get('width')}x{record.get('height')} film, the "
                              f"recording {where} is {ev.width}x{ev.height}")
    missing = [k for k in LIGHTFIELD_FIELDS[designs[0]] if record.get(k) is None]
    if missing:
        hint = "" if designs[0] == "galvo" else \
            "; calibrate from the camera frame with the tube's nominal optics: eventfield calibrate kaleidoscope " \
            "FRAME.exr --optics TUBE.json"
        raise EventFieldError(f"{source}: its {designs[0]} optics record lacks {', '.join(missing)}, which the light "
                              f"field of {where} (a recording without optics) needs{hint}")
    return {k: v for k, v in record.items() if k not in ("width", "height")}


def check_crop(calibration, ev, where, source) -> None:
    """A calibration made from a window of a larger sensor (``calibrate kaleidoscope --crop``) takes recordings
    cut to that window: one of the whole sensor is told the window, one cut elsewhere is refused (its views
    would be other pixels' than the calibration registered)."""
    crops = [part.crop for part in calibration.values() if getattr(part, "crop", None)]
    if not crops:
        return
    window, sensor = crops[0]["window"], crops[0]["sensor"]
    crop = ev.meta.get("crop") or {}
    given, whole = crop.get("window"), crop.get("sensor") or [ev.width, ev.height]
    shown = ",".join(map(str, window))
    if given is None and [ev.width, ev.height] == list(window[2:]):
        return                             # cut before it came here, where no record says from where
    if list(whole) != list(sensor):        # a window of another sensor holds other pixels, whatever its place
        raise EventFieldError(f"{source}: made on a {sensor[0]}x{sensor[1]} sensor (the window {shown}); {where} "
                              f"was recorded on a {whole[0]}x{whole[1]} one")
    if given is None:
        raise EventFieldError(f"{source}: made from the window {shown} of the {sensor[0]}x{sensor[1]} sensor: cut "
                              f"{where} to it (--crop {shown}; in Python, events.crop(*window))")
    if list(given) != list(window):
        raise EventFieldError(f"{source}: made from the window {shown} of the sensor; {where} is cut to "
                              f"{','.join(map(str, given))}")
