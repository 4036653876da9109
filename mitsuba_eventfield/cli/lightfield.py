"""Commands that turn event files into images: ``reconstruct``, ``refocus``, ``depth``."""
from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import warnings

import numpy as np

from ..errors import ConfigError, EventFieldError
from ..focus.depth import DEFAULT_MEASURE
from ..lightfield.galvo_solve import solver_progress
from ..lightfield.reconstruct import MAX_CUTOFF_HZ
from ..lightfield.model import radiance_of_levels, warn_levels_beyond
from ..lightfield.streams import MIN_VIEWS
from ..optics.galvo import VIEWS_PER_PERIOD as DEFAULT_VIEWS
from ..validate import MAX_PLANES, MAX_VIEWS, number_list
from .args import check_files, num, save_image, times_ms, velocity
from .inputs import CROP_HELP, give_optics, read_input, reconstruct_optics, start_log


CONTRAST_HELP = ("ON[,OFF]: contrast thresholds (log intensity per event) of a recording that carries none "
                 "(default: the file's pixel-model metadata)")


OPTICS_HELP = ("a JSON file of the set-up's nominal optics, for a recording that carries none and no calibration: "
               "\"design\" galvo (fov_x_deg, mirror_distance, mirror_separation, scan, as a render's "
               "meta['optics']) or kaleidoscope / microlens (the sensor's parameters, metres)")
DEFAULT_PERIOD = 0     # refocus / depth on a galvo stream: its first scan period, DEFAULT_VIEWS views
GALVO_ONLY, KALEIDOSCOPE_ONLY = ("period", "views"), ("time",)


def add_parsers(sub) -> None:
    lf_args = argparse.ArgumentParser(add_help=False)
    lf_args.add_argument("file", help="event file")
    lf_args.add_argument("--method", help="reconstruction: direct, highpass, complementary, galvo, periods (default: "
                                          "direct with --start-frame, else periods / highpass); periods: galvo, "
                                          "the demo's solver, each pixel at its own depth from focus; galvo: one "
                                          "depth for the whole image (2-8x faster, near depths read up to 10 %% far)")
    lf_args.add_argument("--start-frame", help="EXR of the linear frame at the stream start (eventfield frame)")
    lf_args.add_argument("--period", type=num(0, integer=True),      # None: not given (refused on a kaleidoscope)
                         help=f"galvo: scan period index (default {DEFAULT_PERIOD})")
    lf_args.add_argument("--views", type=num(MIN_VIEWS, MAX_VIEWS, integer=True),
                         help=f"galvo: views per scan period (default {DEFAULT_VIEWS})")
    lf_args.add_argument("--time", type=num(0), help="kaleidoscope: time in ms (default: stream end)")
    lf_args.add_argument("--calibration", help="calibration JSON (eventfield calibrate): galvo view phase, depth "
                                               "model; kaleidoscope view registration, flat field; a camera "
                                               "recording (.raw, .dat, .aedat4) takes its optics from it")
    lf_args.add_argument("--contrast", help=CONTRAST_HELP)
    lf_args.add_argument("--optics", help=OPTICS_HELP)
    lf_args.add_argument("--crop", metavar="X,Y,W,H", help=CROP_HELP)

    rc = sub.add_parser("reconstruct", help="log-intensity frames from events: EXR + PNG per frame")
    rc.add_argument("file")
    rc.add_argument("-o", "--output", required=True, help="output directory (created)")
    rc.add_argument("--method", default="direct", help="direct, highpass, complementary, galvo (default direct)")
    g = rc.add_mutually_exclusive_group()
    g.add_argument("--times", help="comma-separated times in ms")
    g.add_argument("--fps", type=num(0, 1e6, lo_open=True),
                   help="frames per second over the whole stream, from the start frame's time (default 1000; a "
                        "stream shorter than 1 ms gives one frame, at its end)")
    rc.add_argument("--start-frame", help="EXR of the linear frame at the stream start (or at --start-time)")
    rc.add_argument("--start-time", type=num(), metavar="MS",
                    help="the start frame's time in ms on the file's clock (a frame camera beside the event camera; "
                         "default: the stream's start); the events up to it are in the frame, frames come after it")
    rc.add_argument("--contrast", help=CONTRAST_HELP)
    rc.add_argument("--optics", help=OPTICS_HELP + " (--method galvo)")
    rc.add_argument("--calibration", help="calibration JSON (eventfield calibrate) for --method galvo: the galvo's "
                                          "view phase and depth model, in the solve; a recording without optics "
                                          "takes its optics from it")
    rc.add_argument("--crop", metavar="X,Y,W,H", help=CROP_HELP)
    rc.add_argument("--cutoff", type=num(0, MAX_CUTOFF_HZ, lo_open=True),
                    help="filter cutoff in Hz (highpass, complementary; default 5)")

    rf = sub.add_parser("refocus", parents=[lf_args], help="refocus the light field at one or more depths")
    rf.add_argument("-o", "--output", required=True, help="PNG path (EXR alongside; _<depth> suffix for several)")
    rf.add_argument("--depth", required=True, help="comma-separated depths in scene units (inf allowed)")
    rf.add_argument("--follow", metavar="VX,VY", type=velocity, help="make content moving at VX,VY px/s sharp")

    dp = sub.add_parser("depth", parents=[lf_args], help="depth from focus: EXR (depth, confidence, reason) + colour "
                                                         "PNG")
    dp.add_argument("-o", "--output", required=True, help="PNG path (EXR alongside)")
    dp.add_argument("--near", type=num(0, lo_open=True), required=True, help="nearest depth searched (scene units)")
    dp.add_argument("--far", type=num(0, lo_open=True), required=True, help="farthest depth searched (scene units)")
    dp.add_argument("--planes", type=num(2, MAX_PLANES, integer=True), default=32, help="planes searched (default 32)")
    dp.add_argument("--measure", default=DEFAULT_MEASURE, help="focus measure: sml, tenengrad or variance (default "
                    f"{DEFAULT_MEASURE}, as depth_from_focus; the demo uses tenengrad)")
    dp.add_argument("--min-confidence", type=num(0, 1), default=0.2,
                    help="greyed out below this in the PNG (default 0.2; a confidence is near 0 or above ~0.75, "
                         "not a probability: focus/depth.py)")


def _inputs(a) -> str:
    """What a light-field output was made from: a start frame is information beyond the events (a frame
    camera beside the event camera, or a render), and the results differ with it (the near card of
    offaxis_cards: 2.6 % depth error from events alone, 0.4 % with a rendered start frame)."""
    start = getattr(a, "start_frame", None)
    return ("events + a start frame (extra information: " + os.path.abspath(start) + ")") if start else "events only"


def _out_meta(a, events, lf=None, **extra):
    """An output's metadata: what made it from what, and which calibration parts the light field ``lf`` took."""
    from .._version import __version__
    calibration = None if lf is None or not getattr(a, "calibration", None) else \
        {"file": os.path.abspath(a.calibration), "applied": lf.meta.get("calibrated", [])}
    return dict({"package_version": __version__, "command": a.command, "source": os.path.abspath(a.file),
                 "inputs": _inputs(a), "method": getattr(a, "method", None) or "default",
                 "optics": events.meta.get("optics"), "pixel_model": events.meta.get("pixel_model"),
                 "crop": events.meta.get("crop"),
                 "calibration": calibration}, **extra)


def _lightfield(a, ev, nearest: float | None = None):
    """The light field the light-field commands share, calibrated when asked (``calibration.recording``, as
    Python makes it; a calibration made for other optics than this stream's is refused before any
    reconstruction), and the stream with the optics a recording was given (the outputs' metadata records them).
    ``nearest``: the nearest depth the command needs (--near, the nearest --depth), searched by the per-period
    solver too."""
    from ..calibration import calibrated_lightfield, check_optics, load_calibration, optics_record
    from ..lightfield.streams import PERIODS, default_method, methods
    if a.method is not None and a.method not in methods("galvo"):
        raise EventFieldError(f"--method {a.method!r}: allowed: {', '.join(methods('galvo'))}")
    calibration = load_calibration(a.calibration) if a.calibration else None
    ev = give_optics(ev, a.file, a.optics, calibration)
    if calibration is not None:          # refused before the options' checks, as before any reconstruction
        check_optics(calibration, optics_record(ev.meta.get("optics", {}), ev.width, ev.height, where=a.file))
    period, views = _design_options(a, ev)
    design = (ev.meta.get("optics") or {}).get("design")
    if a.method is None:         # named, so that the outputs' metadata says which (it said "default")
        a.method = default_method(design, bool(a.start_frame))
    _warn_coarse_steps(a.file, ev)
    galvo = design == "galvo"
    if a.method == PERIODS:
        _check_periods(a, design)
        kw = dict(period=period, views=views, method=PERIODS)     # searching the nearer depths the command needs
    else:
        kw = dict(period=period if galvo else None, views=views if galvo else None,
                  time=None if a.time is None else a.time * 1e-3, method=a.method)
    try:
        with _solver_warnings_held() as held, solver_progress(f"{os.path.basename(a.file)}: solving"):
            if a.method != PERIODS:
                kw["log_start"] = start_log(a.start_frame, ev)
            lf = calibrated_lightfield(ev, calibration, where=a.file, nearest=nearest, **kw)
        lf.meta["warnings"] = [f"{a.file}: {w}" for w in held]
    except (ValueError, KeyError, StopIteration) as e:
        raise EventFieldError(f"{a.file}: {e}") from None
    return lf, ev


@contextlib.contextmanager
def _solver_warnings_held():
    """Warnings of the light field made inside (the solver's, the scan lock's), held as texts in the list
    yielded: said after the command's own checks, so a refused command says one line. Others as they come."""
    from ..focus.galvo_periods import SolverWarning
    from ..lightfield.scan_lock import ScanLockWarning
    kinds, held = (SolverWarning, ScanLockWarning), []
    with warnings.catch_warnings(record=True) as caught:
        for kind in kinds:
            warnings.simplefilter("always", kind)
        yield held
    for w in caught:
        if issubclass(w.category, kinds):
            held.append(str(w.message))
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)


def _solver_warning(lf) -> None:
    for text in lf.meta.get("warnings", ()):
        print(f"eventfield: warning: {text}", file=sys.stderr)


def _check_periods(a, design) -> None:
    """``--method periods`` (``focus.galvo_periods``: each period's image solved from its events, each pixel at
    its own depth; the default without a start frame) asked where it cannot run, said with the options' names.
    The one-depth solver (``--method galvo``) is faster, biased where depths differ: cards of offaxis_cards
    (160x120) 0.5025 / 1.2058 m against 0.4990 / 1.1963 (truth 0.5 / 1.2), 0.8 against 6.1 s a light field;
    galvo_static's (346x260) 0.549 against 0.490 m (0.491 with the rendered start frame), 27 against 59 s for
    `eventfield depth`."""
    if design != "galvo":
        raise EventFieldError(f"{a.file}: --method periods is for a galvo stream; this one is {design}")
    if a.start_frame:
        raise EventFieldError("--method periods reconstructs from the events alone: --start-frame is used by "
                              "the direct and complementary methods")


def _unanchored_warning(a, lf) -> None:
    """Galvo views that are not the images the scan moves: refocus and depth from them are unreliable (a new
    user's galvo_static: with highpass the text wall read 0.43 m; with direct and no start frame 1213 of 1430
    confident pixels were more than 10 % off, the wall at 0.40 m)."""
    if lf.kind != "galvo" or a.method not in ("highpass", "direct") or (a.method == "direct" and a.start_frame):
        return
    what = "keeps each view's changes" if a.method == "highpass" else \
        "without --start-frame integrates the events onto a flat image"
    print(f"eventfield: warning: --method {a.method} {what}, not the image the scan moves: galvo refocus and depth "
          "from it are unreliable (the default, periods, solves the image from the events)", file=sys.stderr)


def _flat_warning(a, lf) -> None:
    """Views that hold one value everywhere refocus to a constant image, which was written without a word (a
    kaleidoscope stream at --time 0: its views integrate the events before that time, and there are none)."""
    if np.ptp(lf.views) == 0:
        print(f"eventfield: warning: {a.file}: the light field's views are flat (no event changes them by the "
              "time they stand for: a kaleidoscope's views integrate the events before --time): its refocus is a "
              "constant image", file=sys.stderr)


def _calibrated(lf) -> str:
    """The console's word on a calibration: which parts the light field took."""
    return f"; calibration applied: {', '.join(lf.meta['calibrated'])}" if lf.meta.get("calibrated") else ""




def _warn_coarse_steps(path: str, ev) -> None:
    """One line on stderr when the stream's render moved the image more than a pixel a step (its metadata says,
    ``image_motion.largest_px_per_step``): its views are interpolated between rendered instants, and a light
    field built from them is wrong by as much, confidently (offaxis_cards at 8 steps a period, 5.3 px a step:
    depth 18-20 % off, against 6-7 % at the default steps)."""
    from ..simulate.image_motion import allowed_px_per_step, largest_px_per_step
    worst = largest_px_per_step(ev.meta)
    allowed = allowed_px_per_step((ev.meta.get("stepping") or {}).get("chosen"))
    if worst is not None and worst > allowed * (1 + 1e-6):
        print(f"eventfield: warning: {path} was rendered with {worst:.3g} px of image motion a step (more than "
              f"{allowed:g}): its views are interpolated, not resolved; render it with more steps",
              file=sys.stderr)


def _design_options(a, ev) -> tuple:
    """(period, views) for the stream's design; an option of the other design is refused (it was ignored:
    --period on a kaleidoscope stream, --time on a galvo one)."""
    design = (ev.meta.get("optics") or {}).get("design")
    wrong = GALVO_ONLY if design in ("kaleidoscope", "microlens") else KALEIDOSCOPE_ONLY if design == "galvo" else ()
    given = [f"--{name}" for name in wrong if getattr(a, name, None) is not None]
    if given:
        raise EventFieldError(f"{a.file}: {' and '.join(given)} {'is' if len(given) == 1 else 'are'} for "
                              f"{'a galvo' if design != 'galvo' else 'a kaleidoscope'} stream; this one is {design}")
    if getattr(a, "time", None) is not None:
        _check_times(a, ev, [a.time * 1e-3], "--time")
    return (DEFAULT_PERIOD if a.period is None else a.period), (DEFAULT_VIEWS if a.views is None else a.views)


def _check_times(a, ev, times, option: str) -> None:
    """Times (seconds) inside the stream, increasing: past its end a reconstruction keeps decaying its
    high-pass filter on no data, and was written as a result."""
    t0 = ev.start_s
    t1 = ev.end_s
    for t in times:
        if not t0 <= t <= t1 + 1e-9:
            raise EventFieldError(f"{a.file}: {option} {t * 1e3:.3f} ms: the stream covers {t0 * 1e3:.3f} to "
                                  f"{t1 * 1e3:.3f} ms (times are on the file's clock)")
    if len(times) > 1 and np.any(np.diff(times) <= 0):
        raise EventFieldError(f"{option} {getattr(a, 'times', '')}: times must be increasing")


def _refocus_roots(a, depths) -> list:
    """(depth, output root) of every refocused image, every output path checked before the light field is made
    and any image written (a failure at the second depth left the first one's files; a bad path was found only
    after the solve)."""
    if len(set(depths)) != len(depths):
        raise EventFieldError(f"--depth {a.depth}: a depth is given twice")
    roots = [(z, os.path.splitext(a.output)[0] + (f"_{z:g}" if len(depths) > 1 else "")) for z in depths]
    check_files((root + ext for _, root in roots for ext in (".png", ".exr")), "refocused image")
    return roots


# ------------------------------------------------------------------ commands
def _start_time(a, ev):
    """``--start-time`` in seconds (None: the stream's start), checked: with a start frame, inside the stream."""
    if a.start_time is None:
        return None
    if not a.start_frame:
        raise EventFieldError("--start-time is the time of --start-frame: give the frame too")
    t = a.start_time * 1e-3
    _check_times(a, ev, [t], "--start-time")
    return t


def _reconstruct_times(a, ev, start):
    """The frames' times (seconds): ``--times``, else ``--fps`` frames from the start frame's time ``start``
    (None: the stream's start)."""
    t0 = ev.start_s
    if a.times:
        times = np.array(times_ms(a.times)) * 1e-3
        _check_times(a, ev, times, "--times")
        if start is not None and times[0] < start:
            raise EventFieldError(f"--times {a.times}: {times[0] * 1e3:.3f} ms is before --start-time "
                                  f"{a.start_time:.3f} ms (frames are integrated forward from the start frame)")
        return times
    fps = a.fps or 1000.0
    first = t0 if start is None else start
    # whole frame intervals within the stream (rounding the count up put a frame past its end: a recording's
    # 9.889 ms at 400 fps read 4 frames, the last 0.111 ms after its last event); at least the stream's end
    end = ev.end_s
    n = int(math.floor((end - first) * fps + 1e-9))
    if n == 0 and a.fps:         # asked for: no frame interval fits (the default falls back to the stream's end)
        span = end - first
        raise EventFieldError(f"--fps {a.fps:g}: a frame every {1e3 / fps:.6g} ms, longer than the stream's "
                              f"{span * 1e3:.3f} ms from {first * 1e3:.3f} ms: " + (
                                  f"ask for at least {1 / span:.6g} fps, or give --times" if span > 0 else
                                  "no time is left after it for a frame"))
    return first + (np.arange(n) + 1) / fps if n else np.array([end])


def _method_arguments(a, ev, t_frame) -> dict:
    """The reconstruction method's arguments; ``t_frame``: the start frame's time (None: the stream's start)."""
    if a.start_frame and a.method not in ("direct", "complementary"):    # it was taken, ignored and recorded
        raise EventFieldError(f"--method {a.method} reconstructs from the events alone: --start-frame is used by the "
                              "direct and complementary methods")
    if a.cutoff is not None and a.method not in ("highpass", "complementary"):      # it was taken and ignored
        raise EventFieldError(f"--cutoff: --method {a.method} filters nothing; the cutoff is the highpass and "
                              "complementary methods'")
    if a.method == "direct":             # from the stream's start (its first microsecond's events count) or the frame's
        return {"log_start": start_log(a.start_frame, ev), "t_start": t_frame}
    if a.method not in ("highpass", "complementary"):
        return {}
    kw = {"cutoff_hz": 5.0 if a.cutoff is None else a.cutoff}
    if a.method == "complementary":
        start = start_log(a.start_frame, ev)
        if start is None:
            raise EventFieldError("--method complementary needs --start-frame (a frame to anchor to)")
        t0 = ev.start_s
        kw.update(frames=start[None], frame_times=[t0 if t_frame is None else t_frame])
    return kw


def run_reconstruct(a) -> int:
    from ..lightfield.reconstruct import reconstruct
    from ..plugins.pixel_model import stream_linlog_threshold
    ev = read_input(a)
    ev, applied = reconstruct_optics(a, ev)
    t_frame = _start_time(a, ev)
    times = _reconstruct_times(a, ev, t_frame)
    os.makedirs(a.output, exist_ok=True)     # every frame's files checked before the work, not as each is written
    check_files((os.path.join(a.output, f"frame_{k:04d}{x}") for k in range(len(times)) for x in (".exr", ".png")),
                "frame")
    try:
        with solver_progress(f"{os.path.basename(a.file)}: solving"):       # (the galvo methods: minutes at 720p)
            frames = reconstruct(ev, times, a.method, **_method_arguments(a, ev, t_frame))
    except ValueError as e:
        raise EventFieldError(f"{a.file}: {e}") from None
    # radiance as the light fields take it: the pixel's lin-log response inverted, the levels clipped at +-40
    # (exp beyond e^88.7 overflowed float32: +inf in the EXR); a frame at a time: converting the whole stack
    # made four more copies of it (500 frames of 1280x720 went past 6 GiB)
    warn_levels_beyond(frames, a.file)
    knee = stream_linlog_threshold(ev.meta)
    for k, t in enumerate(times):
        linear = radiance_of_levels(frames[k], a.file, knee, warn=False)
        save_image(os.path.join(a.output, f"frame_{k:04d}.png"), linear,
                   _out_meta(a, ev, method=a.method, time_s=float(t),
                             domain="linear: the pixel's lin-log response (log intensity above its knee) inverted",
                             **({"calibration": {"file": os.path.abspath(a.calibration), "applied": applied}}
                                if applied is not None else {})))
    said = f"; calibration applied: {', '.join(applied)}" if applied else ""
    print(f"wrote {len(times)} frame{'s' if len(times) != 1 else ''} ({a.method}) to {a.output}{said}")
    return 0


def run_refocus(a) -> int:
    from ..focus.refocus import refocus
    ev = read_input(a, needs_optics=True)
    depths = number_list(a.depth, "--depth", lo=0, lo_open=True, allow_inf=True)
    roots = _refocus_roots(a, depths)
    lf, ev = _lightfield(a, ev, nearest=min(depths))     # ev: with the optics given to a recording
    try:                                   # every depth before the first image
        roots = [(lf.check_depth(z, "--depth"), root) for z, root in roots]
    except ConfigError as e:
        raise EventFieldError(f"{a.file}: {e}") from None
    _unanchored_warning(a, lf)
    _flat_warning(a, lf)
    _solver_warning(lf)
    for z, root in roots:
        meta = _out_meta(a, ev, lf, depth=z, views=len(lf.views), **({"follow_px_s": a.follow} if a.follow else {}))
        save_image(root + ".png", refocus(lf, z, motion=a.follow), meta)
        print(f"wrote {root}.png/.exr (refocused at {z:g} m; from {_inputs(a)}{_calibrated(lf)})")
    return 0


def run_depth(a) -> int:
    from ..atomic import check_writable
    from ..focus.depth import MEASURES, REASON_META, depth_from_focus
    from ..images import depth_png, write_exr, write_png
    ev = read_input(a, needs_optics=True)
    if not 0 < a.near < a.far:                    # (--planes is checked by its parser)
        raise EventFieldError(f"--near {a.near} --far {a.far}: need 0 < near < far")
    if a.measure not in MEASURES:
        raise EventFieldError(f"--measure {a.measure!r}: allowed: {', '.join(MEASURES)}")
    check_writable(os.path.splitext(a.output)[0] + ".exr", "depth map")     # the PNG's sibling, before the solve
    lf, ev = _lightfield(a, ev, nearest=a.near)
    _unanchored_warning(a, lf)
    try:
        for value, name in ((a.near, "--near"), (a.far, "--far")):
            lf.check_depth(value, name)
    except ConfigError as e:
        raise EventFieldError(f"{a.file}: {e}") from None
    _solver_warning(lf)
    dm = depth_from_focus(lf, a.near, a.far, a.planes, a.measure)
    root = os.path.splitext(a.output)[0]
    meta = _out_meta(a, ev, lf, near=a.near, far=a.far, planes=a.planes, measure=a.measure, views=len(lf.views),
                     min_confidence=a.min_confidence)
    picture = depth_png(dm.depth, dm.confidence, a.near, a.far, a.min_confidence)   # before either file
    write_exr(root + ".exr", dm.channels(), {**meta, **REASON_META})
    write_png(root + ".png", picture)
    confident = (dm.confidence >= a.min_confidence) & (dm.confidence > 0)    # a failed check is never confident
    notes = dm.notes()           # why textured regions are not confident
    share = f"{int(confident.sum())} pixels, {100 * confident.mean():.3g} % of the image"
    found = (f"median depth of confident pixels {float(np.median(dm.depth[confident])):.4g} m ({share})") \
        if confident.any() else \
        f"no pixel is confident (>= {a.min_confidence:g}): no depth found (" + \
        ("see below" if notes else "too little texture, parallax or events") + ")"
    print(f"wrote {root}.exr (depth, confidence, reason) and {root}.png; {found}; from {_inputs(a)}{_calibrated(lf)}")
    for line in notes:
        print(line)
    return 0


COMMANDS = {"reconstruct": run_reconstruct, "refocus": run_refocus, "depth": run_depth}
