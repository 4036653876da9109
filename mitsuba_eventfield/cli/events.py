"""Commands that make and inspect event streams: ``render``, ``convert``, ``frame``, ``info``, ``preview``."""
from __future__ import annotations

import json
import os

from ..errors import EventFieldError
from ..scene.sampler import SAMPLERS
from ..validate import DEFAULT_SPP, FRAME_SPP, MAX_DURATION_S, MAX_SEED, MAX_SPP, MAX_STEPS, MAX_THRESHOLD
from .args import add_defines, check_files, defines, num, pairs, save_image, times_ms

PIXEL_INTEGERS = ("seed", "readout_cap_native_pixels")
# the suffixes events.io.FORMATS writes (not imported here: it loads h5py, and --help should be quick)
EVENT_FILE_HELP = ("event file: .h5 / .hdf5 (DSEC layout, streamed), .npz, .txt, .aedat4 (streamed); .raw / .evt "
                   "(Prophesee EVT 3.0, or 2.0 for spans over 16.8 s), .dat (written at the end)")
CONVERT_DETAILS = (". Frames are linear intensity: floats as they are, 8- and 16-bit integers divided by 255 "
                   "and 65535 (--srgb decodes gamma-encoded ones first); colour frames become luminance. Times: "
                   "a video's own frame rate, or --fps, or --times FILE (seconds, one a frame); an image folder "
                   "(natural name order) needs --fps or --times; an .npz carries 'frames' and its times in "
                   "seconds ('times') or microseconds ('timestamps_us'). Between frames the log brightness is "
                   "taken as linear in time.")


def add_parsers(sub) -> None:
    _add_render(sub)
    _add_convert(sub)
    i = sub.add_parser("info", help="resolution, duration, counts and metadata of an event file")
    i.add_argument("file")
    i.add_argument("--json", action="store_true", help="print everything as JSON")
    p = sub.add_parser("preview", help="event frame PNG (ON red, OFF blue) over a time window")
    p.add_argument("file")
    p.add_argument("-o", "--output", required=True, help="PNG path")
    p.add_argument("--t0", type=num(), help="window start, ms (default: first event; may be negative)")
    p.add_argument("--t1", type=num(), help="window end, ms (default: last event)")
    p.add_argument("--scale", type=num(1, 64, integer=True),
                   help="integer upscaling of the image (default: a small sensor's to about 400 px)")
    f = sub.add_parser("frame", help="render frames (linear radiance) of a scene at given times: EXR + PNG")
    f.add_argument("scene")
    f.add_argument("-o", "--output", required=True, help="EXR path (PNG alongside); several times: _0000 suffixes")
    f.add_argument("--times", default="0", help="comma-separated times in ms (default 0)")
    f.add_argument("--spp", type=num(1, MAX_SPP, integer=True), default=FRAME_SPP,
                   help=f"samples per pixel (default {FRAME_SPP}, as ef.render_frames; a start frame for events: the "
                        f"render's own, {DEFAULT_SPP} by default, which gives the very image the event pixel saw)")
    f.add_argument("--seed", type=num(0, MAX_SEED, integer=True), default=0,
                   help="sampler seed (default 0; a start frame for events: the render's --seed)")
    f.add_argument("--sampler", choices=SAMPLERS,
                   help="in place of the scene's own (a start frame for an --auto render that chose another)")
    add_defines(f)


def _add_render(sub) -> None:
    r = sub.add_parser("render", help="render the event stream of a Mitsuba scene")
    r.add_argument("scene", help="Mitsuba scene XML (motion from <scene>.motion.toml if present)")
    r.add_argument("-o", "--output", required=True, help=EVENT_FILE_HELP)
    r.add_argument("--motion", help="motion TOML (default: <scene>.motion.toml if it exists)")
    r.add_argument("--no-motion", action="store_true", help="ignore any motion file (static scene)")
    r.add_argument("--duration", type=num(0, MAX_DURATION_S, lo_open=True),
                   help="simulated seconds (default: `duration` of the motion file)")
    g = r.add_mutually_exclusive_group()
    g.add_argument("--steps", type=num(1, MAX_STEPS, integer=True),
                   help="uniform time steps over the duration (default: as many as the known image motion "
                        "needs, 0.5 px a step, 2 px where Monte-Carlo noise is large, uniform under a scan, "
                        "placed by the motion without one where that saves a tenth; 100 where the motion is "
                        "unknown)")
    g.add_argument("--adaptive", nargs="?", const="auto", choices=("auto", "motion", "log-change"),
                   help="adaptive steps: 'motion' (placed before rendering so the known image motion, galvo scan "
                        "and moving objects, stays under --px-per-step), 'log-change' (sized while rendering by "
                        "--max-log-change), or without a value: motion where it is known, else log change")
    r.add_argument("--px-per-step", type=num(0, 100, lo_open=True), default=1.0,
                   help="adaptive by motion: largest image motion per step in pixels (default 1)")
    r.add_argument("--max-log-change", type=num(0, 100, lo_open=True), default=0.5,
                   help="adaptive: largest per-pixel log change per step, as a fraction of C (default 0.5)")
    r.add_argument("--min-step", type=num(0, MAX_DURATION_S, lo_open=True),
                   help="adaptive: shortest step in seconds (default 1e-6)")
    r.add_argument("--max-step", type=num(0, MAX_DURATION_S, lo_open=True),
                   help="adaptive: longest step in seconds (default duration/20)")
    r.add_argument("--spp", type=num(1, MAX_SPP, integer=True), default=DEFAULT_SPP,
                   help=f"samples per pixel per step (default {DEFAULT_SPP})")
    r.add_argument("--spp-changing", type=num(1, MAX_SPP, integer=True), metavar="N",
                   help="samples where they matter: pixels whose brightness changes during the render (found by "
                        "probe renders) get N samples per step, the others --spp")
    r.add_argument("--seed", type=num(0, MAX_SEED, integer=True), default=0,
                   help="sampler seed, and the pixel model's (mismatch, noise) unless --pixel seed=N names another "
                        "(default 0)")
    r.add_argument("--warmup", type=_time_arg("--warmup", hi=10.0), metavar="TIME", default=0.0,
                   help="render this long before the start and drop its events (a time with a unit, e.g. 0.3s): a "
                        "pixel that has been running, its photoreceptor low-pass settled (the render says how long "
                        "one needs)")
    r.add_argument("--no-reuse", action="store_true",
                   help="render every pixel at every step (default: a static scene renders one scan period; a "
                        "moving one, over enough scan periods to pay for its masks, renders the pixels moving objects "
                        "cannot change once per period)")
    r.add_argument("--independent-seeds", action="store_true",
                   help="new seed every step (Monte-Carlo noise then fires events; for comparisons only)")
    _add_thresholds(r, "scene's or 0.2")
    r.add_argument("--linlog-threshold", type=num(0, 1e6, lo_open=True),
                   help="radiance below which the response is linear (1e-3)")
    _add_pixel_options(r, "the scene's own pixel (ideal unless its integrator names a preset; its threshold)")
    r.add_argument("--color", action="store_true", help="render in colour (rgb variant); events use luminance")
    add_defines(r)
    r.add_argument("--preview", help="also write an event-frame PNG of the last --preview-window ms")
    r.add_argument("--preview-window", type=num(0, 1e9, lo_open=True), default=10.0,
                   help="preview window in ms (default 10)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument("--checkpoint-every", type=num(0, 1e9, lo_open=True), metavar="SECONDS",
                   help="save the render's state every so many wall seconds (.h5 output), so that an interrupted "
                        "render can go on with --resume")
    r.add_argument("--resume", action="store_true",
                   help="continue an interrupted render of this output from its last checkpoint (same options)")
    r.add_argument("--auto", action="store_true",
                   help="choose colour, spp and steps from cheap probes (ef.auto), print and record why")
    r.add_argument("--timing-accuracy", type=_time_arg("--timing-accuracy"), metavar="TIME",
                   help="with --auto (implied): the median timestamp error wanted, with a unit (20us, 0.5ms, 1e-5s; "
                        "at least 1us); the sampler, spp and steps are chosen by the accuracy-limit model")


def _add_pixel_options(r, default: str) -> None:
    r.add_argument("--preset", help="event pixel preset: ideal, davis346, prophesee_gen4; it sets the whole pixel, "
                                    "its thresholds included (ideal and davis346 C = 0.2, prophesee_gen4 0.25; "
                                    f"--threshold and --pixel change them); default: {default}")
    r.add_argument("--pixel", action="append", default=[], metavar="NAME=VALUE",
                   help="pixel-model parameter, e.g. --pixel refractory_s=1e-4 --pixel shot_noise_hz=2 (repeatable; "
                        "see docs/pixel_model.md)")
    r.add_argument("--variant", help="Mitsuba variant or backend: cuda, llvm, llvm_ad_mono, ... (default: auto)")
    r.add_argument("--event-buffer-mb", type=num(0, 1e6, lo_open=True), default=64.0,
                   help="device memory for events before they move to the host and the file writer, and the most "
                        "that crosses at once (default 64)")


def _add_convert(sub) -> None:
    summary = ("events from frames you already have: a video, a folder of images or an .npz stack (frames, "
               "times), through the same pixel model as render")
    c = sub.add_parser("convert", help=summary, description=summary[0].upper() + summary[1:] + CONVERT_DETAILS)
    c.add_argument("input", help="video file (OpenCV), folder of images (natural name order) or .npz")
    c.add_argument("-o", "--output", required=True, help=EVENT_FILE_HELP)
    clock = c.add_mutually_exclusive_group()
    clock.add_argument("--fps", type=num(0, 1e9, lo_open=True),
                       help="frame rate (image folders need it or --times; overrides a video's own; .npz stacks "
                            "carry times in seconds, 'times', or microseconds, 'timestamps_us')")
    clock.add_argument("--times", metavar="FILE",
                       help="the frames' times in seconds, one a line (text; '#' comments) or a .npy array: "
                            "frames at uneven times, e.g. ESIM's or rpg_vid2e's timestamps.txt")
    _add_thresholds(c, "the preset's; 0.2 for the ideal pixel")
    c.add_argument("--srgb", action="store_true", help="decode gamma-encoded (sRGB) frames to linear light first")
    _add_pixel_options(c, "ideal, C = 0.2")
    c.add_argument("--seed", type=num(0, MAX_SEED, integer=True),
                   help="the pixel model's seed (mismatch and noise draws; default 0), as --pixel seed=N")
    c.add_argument("--quiet", action="store_true", help="no progress bar")


def _add_thresholds(parser, default: str) -> None:
    """--threshold and the per-polarity --threshold-on / --threshold-off (render and convert alike)."""
    parser.add_argument("--threshold", type=num(0, MAX_THRESHOLD, lo_open=True),
                        help=f"contrast threshold C for ON and OFF (default: {default})")
    parser.add_argument("--threshold-on", type=num(0, MAX_THRESHOLD, lo_open=True),
                        help="ON threshold (overrides --threshold)")
    parser.add_argument("--threshold-off", type=num(0, MAX_THRESHOLD, lo_open=True),
                        help="OFF threshold (overrides --threshold)")


def run_convert(a) -> int:
    from ..backend import set_variant
    from ..simulate.convert import events_from_frames
    set_variant(a.variant)
    pixel = pixel_overrides(a.pixel)
    if a.seed is not None:
        if pixel.get("seed", a.seed) != a.seed:
            raise EventFieldError(f"--seed {a.seed} and --pixel seed={pixel['seed']}: give the seed once")
        pixel["seed"] = a.seed
    summary = events_from_frames(a.input, a.times, fps=a.fps, preset=a.preset, pixel=pixel,
                                 threshold=a.threshold, threshold_on=a.threshold_on, threshold_off=a.threshold_off,
                                 srgb=a.srgb, output=a.output, progress=not a.quiet,
                                 event_buffer_mb=a.event_buffer_mb)
    print(summary.format())
    return 0


def pixel_overrides(items) -> dict:
    """--pixel NAME=NUMBER values as numbers (integers for the integer fields); ``preset=NAME`` as text (the
    preset those values change, as ``--preset``)."""
    out = {}
    for name, value in pairs(items, "--pixel").items():
        if name == "preset":
            out[name] = value
            continue
        try:
            out[name] = int(value) if name in PIXEL_INTEGERS else float(value)
        except ValueError:
            kind = "an integer" if name in PIXEL_INTEGERS else "a number"
            raise EventFieldError(f"--pixel {name}={value!r}: {name} takes {kind}") from None
    return out


def _auto_plan(a, motion, scene_defines):
    """--auto: the plan's choices written into ``a``; returns the metadata that records them."""
    from ..backend import set_variant
    from ..scene import load_scene
    from ..simulate import auto
    duration = a.duration
    if duration is None:
        probe = load_scene(a.scene, motion=motion, **scene_defines)
        duration = probe.motion.duration if probe.motion and probe.motion.duration else None
        if duration is None:
            raise EventFieldError("--auto needs --duration (or `duration` in the motion file)")
    plan = auto.plan(a.scene, duration, threshold=a.threshold, defines=scene_defines,
                     timing_accuracy=a.timing_accuracy, preset=a.preset, pixel=pixel_overrides(a.pixel))
    print("automatic choices:\n  " + plan.report().replace("\n", "\n  "))
    set_variant(a.variant, plan.color)
    a.spp, a.steps, a.duration, a.auto_plan = plan.spp, plan.steps, duration, plan
    return {"auto_plan": plan.as_dict()}


def _time_arg(what: str, hi: float = 1.0):
    """argparse type of a time option (``what``): seconds from a time with a unit, up to ``hi`` (one-line error
    otherwise)."""
    import argparse

    from ..errors import ConfigError
    from ..simulate.auto import parse_time

    def parse(text):
        try:
            return parse_time(text, what, hi)
        except ConfigError as e:
            raise argparse.ArgumentTypeError(str(e).replace(f"{what} ", "", 1)) from None
    return parse


def run_render(a) -> int:
    from ..backend import set_variant
    from ..scene import load_scene
    from ..simulate.render import render_events
    set_variant(a.variant, a.color)
    if a.no_motion and a.motion:      # the file was ignored without a word, even when it did not exist
        raise EventFieldError(f"--motion {a.motion} and --no-motion: give one")
    motion = None if a.no_motion else (a.motion or "auto")
    scene_defines = defines(a)
    extra = _auto_plan(a, motion, scene_defines) if a.auto or a.timing_accuracy else None
    scene = a.auto_plan.load(a.scene, motion) if extra else load_scene(a.scene, motion=motion, **scene_defines)
    summary = render_events(
        scene, a.duration, steps=a.steps, adaptive={None: False, "auto": True}.get(a.adaptive, a.adaptive),
        max_log_change=a.max_log_change, px_per_step=a.px_per_step,
        min_step=a.min_step, max_step=a.max_step, spp=a.spp, seed=a.seed,
        seed_mode="independent" if a.independent_seeds else "fixed", threshold=a.threshold,
        threshold_on=a.threshold_on, threshold_off=a.threshold_off, linlog_threshold=a.linlog_threshold,
        output=a.output, progress=not a.quiet, preset=a.preset, pixel=pixel_overrides(a.pixel), extra_meta=extra,
        event_buffer_mb=a.event_buffer_mb, checkpoint_s=a.checkpoint_every, resume=a.resume,
        spp_changing=a.spp_changing, reuse=not a.no_reuse, warmup=a.warmup)
    print(summary.format())
    if a.preview:                # every format reads back (a .txt file too: it was skipped without a word)
        _render_preview(a)
    return 0


def _render_preview(a) -> None:
    from ..events.io import read_events, summarize_events
    from ..events.preview import write_preview
    _, ends = summarize_events(a.output, count=False)      # (an HDF5 file: its last window alone is read)
    # (a .txt file keeps no t_start_us: its duration alone ended the window one first-event time early)
    end = max(ends.start_us + ends.duration_us, int(ends.t[-1]) if len(ends) else 0)
    t0 = max(ends.start_us, end - int(round(a.preview_window * 1e3)))
    ev = ends if len(ends) > 2 else read_events(a.output, window=(t0, end + 1))    # (> 2: read whole, not HDF5)
    write_preview(a.preview, ev, t0, end + 1)
    print(f"wrote {os.path.abspath(a.preview)} (events of {(end - t0) / 1e3:g} ms up to the end)")


def run_info(a) -> int:
    from ..events.io import summarize_events
    from ..simulate import checkpoint
    if os.path.isdir(a.file) and a.file.rstrip("/").endswith(checkpoint.SUFFIX):   # an interrupted render
        print(checkpoint.describe(os.path.abspath(a.file.rstrip("/"))))
        return 0
    s, ev = summarize_events(a.file)      # ev: the first and last events at least (an HDF5 file is not read whole)
    if a.json:
        print(json.dumps({"summary": s, "meta": ev.meta}, indent=2, default=str))
        return 0
    m = ev.meta
    print(f"{a.file}: {s['width']}x{s['height']}, {s['events']} events ({s['on']} ON, {s['off']} OFF), "
          f"duration {s['duration_s'] * 1e3:.3f} ms, {s['rate_ev_per_s']:.4g} ev/s")
    if len(ev):
        print(f"timestamps {ev.t[0]} .. {ev.t[-1]} us")
    for key in ("optics", "pixel_model", "spp", "seed", "seed_mode", "stepping", "variant", "package_version"):
        if key in m:
            print(f"  {key}: {json.dumps(m[key], default=str)}")
    if "scene" in m:
        print(f"  scene: {m['scene'].get('scene_path')}")
    if "optics" not in m:           # a camera recording: what the commands that read it need besides
        print("  optics: none recorded (a camera recording): refocus, depth and calibrate take them from "
              "--calibration or --optics FILE.json")
    if "threshold_on" not in (m.get("pixel_model") or {}):
        print("  contrast thresholds: none recorded: reconstruct, refocus, depth and calibrate take --contrast "
              "ON[,OFF]")
    return 0


def run_preview(a) -> int:
    from ..events.io import read_events, summarize_events
    from ..events.preview import window_outside, write_preview
    t0 = None if a.t0 is None else int(round(a.t0 * 1e3))
    t1 = None if a.t1 is None else int(round(a.t1 * 1e3))
    if t0 is not None and t1 is not None and t1 <= t0:       # [t0, t1): empty when t1 = t0
        raise EventFieldError(f"--t0 {a.t0:g} --t1 {a.t1:g}: the window [t0, t1) holds no time (ms): t1 must be "
                              "after t0")
    _, ends = summarize_events(a.file, count=False)     # (an HDF5 file: only the window's events are read)
    start = ends.start_us
    end = start + int(ends.duration_us)
    if window_outside(ends, t0, t1):                                        # said with the options' names
        raise EventFieldError(f"{a.file}: the window {'' if a.t0 is None else f'--t0 {a.t0:g} '}"
                              f"{'' if a.t1 is None else f'--t1 {a.t1:g} '}is outside the stream, which covers "
                              f"{_ms(start)} to {_ms(end)} ms")
    ev = ends if len(ends) > 2 else read_events(a.file, window=(t0, t1))    # (> 2: read whole, not HDF5)
    write_preview(a.output, ev, t0, t1, scale=a.scale)
    print(f"wrote {a.output}: {len(ev.time_window(t0, t1))} events in the window")
    return 0


def _ms(us: int) -> str:
    """Integer microseconds as milliseconds with every digit kept (``%g`` printed 1.23457e+06 for both ends of
    a recording at t = 1234.57 s) and no trailing zeros."""
    return f"{us / 1e3:.3f}".rstrip("0").rstrip(".")


def run_frame(a) -> int:
    from ..scene import load_scene
    from ..scene.sampler import plugin_name
    from ..simulate.render import render_frames
    from ..simulate.summary import sensor_optics
    times = [t * 1e-3 for t in times_ms(a.times)]
    roots = _frame_roots(a.output, len(times))
    scene = load_scene(a.scene, sampler={"type": a.sampler} if a.sampler else None, **defines(a))
    frames = render_frames(scene, times, spp=a.spp, seed=a.seed, log=False)
    optics = sensor_optics(scene)     # what calibrate kaleidoscope records and compares (lens, tube)
    samples = {"spp": a.spp, "seed": a.seed, "sampler": plugin_name(scene.sensor.sampler().class_name())}
    for t, img, (exr, png) in zip(times, frames, roots):
        meta = {"scene": os.path.abspath(a.scene), "time_s": t, **samples, "optics": optics}
        save_image(png, img, meta, exr=exr)
        print(f"wrote {exr} and {png} (t = {t * 1e3:g} ms)")
    return 0


def _frame_roots(output: str, count: int) -> list:
    """(EXR, PNG) paths of each of ``count`` frames (``_0000`` suffixes for several), all checked before any
    rendering: the PNG beside the EXR was checked only when written (a folder in its place failed the command
    after the EXR had replaced the user's), and the PNG's name was made by replacing every ".exr" in the path
    (a folder x.exr.d became x.png.d)."""
    root, ext = os.path.splitext(output)
    paths = [(f"{root}{f'_{k:04d}' if count > 1 else ''}{ext}", f"{root}{f'_{k:04d}' if count > 1 else ''}.png")
             for k in range(count)]
    check_files((path for pair in paths for path in pair), "frame")
    return paths


COMMANDS = {"render": run_render, "convert": run_convert, "info": run_info, "preview": run_preview, "frame": run_frame}
