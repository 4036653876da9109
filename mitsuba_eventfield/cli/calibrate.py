"""``calibrate galvo | depth | kaleidoscope``: calibrations from the data itself (``calibration/``)."""
from __future__ import annotations

import math
import sys
import warnings

import numpy as np

from ..calibration.nominal import nominal_optics
from ..calibration.targets import warn_off_seams
from ..errors import EventFieldError
from ..events.stuck_pixels import without_stuck_pixels
from ..validate import MAX_VIEWS, cut_window, number_list
from .args import num
from .inputs import (CROP_HELP, crop_option, film_hint, galvo_frames, galvo_scan, give_optics, luminance_channel,
                     nonempty, start_log, with_contrast)

OPTICS_HELP = ("JSON of the set-up's nominal galvo optics (design, fov_x_deg, mirror_distance, mirror_separation, "
               "scan), for a camera recording that carries none")


def add_parsers(sub) -> None:
    cal = sub.add_parser("calibrate", help="calibration from the data itself: galvo | depth | kaleidoscope")
    csub = cal.add_subparsers(dest="kind", required=True)
    cg = csub.add_parser("galvo", help="phase and curve size of the scan from a capture of a static scene")
    cg.add_argument("file", help="event file (galvo)")
    cg.add_argument("--patch", action="append", required=True, metavar="X,Y", help="textured patch centre (repeatable)")
    cg.add_argument("--views", type=num(4, MAX_VIEWS, integer=True), default=24,     # 3 unknowns: 4 frames
                    help="frames reconstructed over the scan period (default 24)")
    cg.add_argument("--period", type=num(0, integer=True), default=0, help="scan period index (default 0)")
    cg.add_argument("--start-frame", help="EXR of the linear frame at the stream start (else: galvo solver)")
    cg.add_argument("--optics", help=OPTICS_HELP)
    cg.add_argument("--contrast", help="contrast threshold ON[,OFF] of a recording that carries none (e.g. 0.2)")
    cg.add_argument("-o", "--output", required=True, help="calibration JSON (created or extended)")
    cd = csub.add_parser("depth", help="curve size against known depths from LED captures")
    cd.add_argument("captures", nargs="+", metavar="FILE:DEPTH", help="event file of the LED at DEPTH (scene units)")
    cd.add_argument("--views", type=num(5, MAX_VIEWS, integer=True), default=24,
                    help="instants of the scan period the LED is tracked at (default 24)")
    cd.add_argument("--optics", help=OPTICS_HELP)
    cd.add_argument("--contrast", help="contrast threshold ON[,OFF] of recordings that carry none (e.g. 0.2)")
    cd.add_argument("-o", "--output", required=True, help="calibration JSON (created or extended)")
    ck = csub.add_parser("kaleidoscope", help="tile seams, flips, view registration, flat-field from frames")
    ck.add_argument("frame", help="EXR (linear) of a flat textured target, at the focus distance unless "
                    "--target-depth says where")
    ck.add_argument("--target-depth", type=num(0, lo_open=True), default=None, metavar="Z",
                    help="the target's depth (scene units), when it is not at the focus distance: its parallax is "
                    "taken out of the registration")
    ck.add_argument("--flat", help="EXR (linear) of a uniform white target, for the flat-field")
    ck.add_argument("--crop", metavar="X,Y,W,H", help=CROP_HELP + "; the recordings then take the same --crop")
    from ..plugins.kaleido_optics import SETUP_PARAMETERS      # pure (no Mitsuba): --help stays quick
    ck.add_argument("--optics", help="JSON of the set-up's nominal kaleidoscope optics, for a camera frame that "
                                     "carries none: \"design\": \"kaleidoscope\" and the sensor's parameters "
                                     f"({', '.join(SETUP_PARAMETERS['kaleidoscope'])}; each optional, defaults as "
                                     "the sensor's), in metres as in a scene; recordings of the set-up then take "
                                     "their views from the calibration")
    ck.add_argument("-o", "--output", required=True, help="calibration JSON (created or extended)")


def _capture(path: str, a):
    """A capture's events, with the nominal optics of ``--optics`` and the thresholds of ``--contrast`` where it
    carries none (a camera recording: refused in one line without them)."""
    from ..events.io import read_events
    ev = read_events(path)
    ev = give_optics(ev, path, a.optics, design="galvo", takes_calibration=False)
    return nonempty(without_stuck_pixels(with_contrast(ev, a.contrast, path), path), path)


def _galvo(a) -> None:
    from .. import calibration as cal
    ev = _capture(a.file, a)
    patches = []
    for p in a.patch:
        xy = number_list(p, "--patch", lo=0)
        if len(xy) != 2 or xy[0] >= ev.width or xy[1] >= ev.height:
            raise EventFieldError(f"--patch {p!r}: expected X,Y inside the {ev.width}x{ev.height} frame")
        patches.append(tuple(xy))
    nominal = ev.meta.get("optics", {})

    def frames_at(dt):              # the events-only solver's frames under the scan moved dt seconds ahead
        scan = dict(nominal["scan"], time_offset=nominal["scan"].get("time_offset", 0.0) + dt)
        ev.meta["optics"] = dict(nominal, scan=scan)
        try:
            return galvo_frames(ev, a.period, a.views)[:2]
        finally:
            ev.meta["optics"] = nominal
    try:            # every refusal names the recording (the fit's own knew none)
        nominal_curve = galvo_scan(ev)             # (a stream of another design: refused first)
        optics = cal.optics_record(nominal, ev.width, ev.height, where=a.file)
        kw = {"scale_limit": cal.galvo_scale_limit(optics)}
        if a.start_frame:           # views from a frame: no scan phase assumed
            frames, times, curve = galvo_frames(ev, a.period, a.views, start_log(a.start_frame, ev))
            result = cal.fit_galvo(frames, times, curve, patches, **kw)
        else:                       # a camera's clock starts anywhere in the scan: the phase found, consistently
            result = cal.fit_galvo_consistent(frames_at, nominal_curve, patches, **kw)
    except EventFieldError as e:
        raise EventFieldError(e if str(e).startswith(a.file) else f"{a.file}: {e}") from None
    result.capture = cal.capture_of(ev)
    note = cal.scale_note(result, optics)
    if note:
        print(f"eventfield: warning: {a.file}: {note}", file=sys.stderr)
    cal.save_calibration(a.output, optics, galvo=result)
    print(f"galvo: phase {result.phase_deg:.2f} +- {result.std['phase_deg']:.2f} deg at the first frame "
          f"({result.clock_phase_deg:.2f} deg at t = 0), curve radius "
          f"{result.radius_px()[0]:.3f} x {result.radius_px()[1]:.3f} px, rms {result.rms_px:.3f} px "
          f"({result.frames_used} matches) -> {a.output}")


def _depth(a) -> None:
    from .. import calibration as cal
    from ..optics.galvo import GalvoGeometry
    depths, fits, records = [], [], {}
    for item in a.captures:
        path, _, depth = item.rpartition(":")
        try:
            depth = float(depth)
        except ValueError:
            raise EventFieldError(f"{item!r}: expected FILE:DEPTH") from None
        if not (math.isfinite(depth) and depth > 0):
            raise EventFieldError(f"{item!r}: depth = {depth:g}: must be a finite number > 0 (scene units)")
        ev = _capture(path, a)
        records[path] = cal.optics_record(ev.meta.get("optics"), ev.width, ev.height, where=path)
        if records[path]["design"] != "galvo":      # (a kaleidoscope capture failed on a missing galvo field)
            raise EventFieldError(f"{path}: {records[path]['design']} optics: a depth calibration fits a galvo's "
                                  "scan scale, and needs galvo captures")
        try:
            fit = cal.fit_led(ev, samples=a.views, scale_limit=cal.galvo_scale_limit(records[path]))   # events alone
        except EventFieldError as e:
            raise EventFieldError(f"{path}: {e}") from None
        depths.append(depth)
        fits.append(fit)
    optics = cal.same_optics(records)          # one set-up for all the captures
    result = cal.fit_depth_from_tracks(depths, fits, GalvoGeometry.from_optics(optics, optics["width"],
                                                                               optics["height"]))
    cal.save_calibration(a.output, optics, depth=result)
    print(f"depth: inverse model rms {result.rms_inverse:.3f} px/rad (pivot {result.pivot:.4g}), linear "
          f"model rms {result.rms_linear:.3f} px/rad; best: {result.best} -> {a.output}")


def _kaleidoscope_frame(a) -> tuple:
    """(the frame, cut to --crop; its optics metadata, or --optics'; the window; the whole sensor's frame)."""
    from ..images import read_exr
    frame = luminance_channel(a.frame)
    meta = read_exr(a.frame)[1].get("optics")
    window, whole = crop_option(a, frame.shape[1], frame.shape[0]), frame
    if window is not None:
        if isinstance(meta, dict) and meta.get("design"):
            raise EventFieldError(f"--crop {a.crop}: the frame {a.frame} carries its own ({meta['design']}) optics, "
                                  "which describe its whole film; --crop is for a camera frame")
        frame = cut_window(frame, window)
    if a.optics:
        if isinstance(meta, dict) and meta.get("design"):
            raise EventFieldError(f"--optics {a.optics}: the frame {a.frame} carries its own ({meta['design']}) "
                                  "optics; --optics is for a camera frame without them")
        try:
            meta = nominal_optics(a.optics, frame.shape[1], frame.shape[0], design="kaleidoscope")
        except EventFieldError as e:
            raise EventFieldError(film_hint(e, window, frame.shape[1], frame.shape[0], a.frame)) from None
    return frame, meta, window, whole


def _said(held, where: str) -> None:
    """Warnings held until a command's checks passed (a refused command says one line), named with ``where``."""
    for w in held:
        if issubclass(w.category, UserWarning):
            print(f"eventfield: warning: {where}: {w.message}", file=sys.stderr)
        else:                         # a library's own (deprecations): as it comes
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)


def _kaleidoscope(a) -> None:
    from .. import calibration as cal
    frame, meta, window, whole = _kaleidoscope_frame(a)
    sensor = whole.shape
    # the tiles of a frame whose metadata says n are known; a bare frame's are found by their seams
    n = meta.get("n") if isinstance(meta, dict) and meta.get("design") == "kaleidoscope" else None
    try:
        tiles = cal.known_tiles(n, frame.shape[1], frame.shape[0]) if isinstance(n, int) and n > 0 else None
        with warnings.catch_warnings(record=True) as said:      # named with the frame, after the refusals
            warnings.simplefilter("always", UserWarning)
            result = cal.register(np.log(np.maximum(frame, 1e-6)), tiles)
            if window is not None and a.target_depth is None:     # off the focus distance, parallax moves seams
                warn_off_seams(np.log(np.maximum(whole, 1e-6)), window, result.n)
    except cal.CalibrationError as e:      # n from --optics: the optics may be the thing that is wrong
        told = f" (its {n}x{n} views are those of --optics {a.optics}: the tube's?)" \
            if a.optics and n and str(e).startswith("not a kaleidoscope frame") else ""
        raise EventFieldError(f"{a.frame}: {e}{told}") from None
    result.target_depth = a.target_depth
    if window is not None:       # recorded, so a recording of the whole sensor is told the window to cut
        result.crop = {"window": list(window), "sensor": [sensor[1], sensor[0]]}
    optics = cal.kaleidoscope_record(frame.shape[1], frame.shape[0], result.n, meta, where=a.frame)
    if a.flat:
        flat = luminance_channel(a.flat)
        flat = cut_window(flat, window) if window is not None and flat.shape == sensor else flat   # whole sensor
        if flat.shape != frame.shape:
            raise EventFieldError(f"{a.flat}: flat frame is {flat.shape[1]}x{flat.shape[0]}, the frame "
                                  f"{a.frame} is {frame.shape[1]}x{frame.shape[0]}: they must match")
        try:
            cal.flat_field(result, flat)
        except cal.CalibrationError as e:        # (it named no file)
            raise EventFieldError(f"{a.flat}: {e}") from None
    cal.save_calibration(a.output, optics, kaleidoscope=result)
    _said(said, a.frame)
    worst = max(abs(c) for v in result.views for c in v["offset"])
    print(f"kaleidoscope: {result.n}x{result.n} views of {result.tile[0]}x{result.tile[1]} px, largest "
          f"offset {worst:.3f} px (target at {'the focus distance' if a.target_depth is None else a.target_depth})"
          f"{', flat field' if a.flat else ''} -> {a.output}")


def run_calibrate(a) -> int:
    try:
        {"galvo": _galvo, "depth": _depth, "kaleidoscope": _kaleidoscope}[a.kind](a)
    except ValueError as e:
        raise EventFieldError(str(e)) from None
    return 0


COMMANDS = {"calibrate": run_calibrate}
