"""Command line: a thin layer over the Python API. Errors print as one line and exit with status 2."""
from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

from .validate import number_list


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (the usage is one ``--help`` away); subcommands inherit the class."""

    def error(self, message):
        self.exit(2, f"eventfield: error: {message} (see {self.prog} --help)\n")


def _num(lo=None, hi=None, integer=False, lo_open=False):
    """An argparse type: a finite number in [lo, hi] (``lo_open``: lo excluded), checked by ``validate.number``
    so the command line and the library use one rule and one message."""
    from .errors import ConfigError
    from .validate import number

    def parse(text):
        try:
            return number(text, "value", lo, hi, integer=integer, lo_open=lo_open)
        except ConfigError as e:
            raise argparse.ArgumentTypeError(str(e).replace("value = ", "", 1)) from None
    return parse


def _parser() -> argparse.ArgumentParser:
    from ._version import __version__
    from .device.spec import MAX_DURATION_S as MAX_SCAN_S
    from .device.spec import PHASE_RANGE_DEG, VOLTS_PER_DEG_RANGE
    from .scene.bundled import bundled_scene
    from .validate import MAX_DURATION_S, MAX_PLANES, MAX_SPP, MAX_STEPS, MAX_VIEWS
    ap = _Parser(prog="eventfield", description="Render and inspect event fields.")
    ap.add_argument("--version", action="version", version=f"mitsuba-eventfield {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)

    r = sub.add_parser("render", help="render the event stream of a Mitsuba scene")
    r.add_argument("scene", help="Mitsuba scene XML (motion from <scene>.motion.toml if present)")
    r.add_argument("-o", "--output", required=True, help="event file: .h5 (DSEC layout, streamed), .npz, .txt, .aedat4")
    r.add_argument("--motion", help="motion TOML (default: <scene>.motion.toml if it exists)")
    r.add_argument("--no-motion", action="store_true", help="ignore any motion file (static scene)")
    r.add_argument("--duration", type=_num(0, MAX_DURATION_S, lo_open=True), help="simulated seconds (default: `duration` of the motion file)")
    g = r.add_mutually_exclusive_group()
    g.add_argument("--steps", type=_num(1, MAX_STEPS, integer=True), help="uniform time steps over the duration (default 100)")
    g.add_argument("--adaptive", action="store_true", help="adaptive steps bounded by --max-log-change")
    r.add_argument("--max-log-change", type=_num(0, 100, lo_open=True), default=0.5,
                   help="adaptive: largest per-pixel log change per step, as a fraction of C (default 0.5)")
    r.add_argument("--min-step", type=_num(0, MAX_DURATION_S, lo_open=True), help="adaptive: shortest step in seconds (default 1e-6)")
    r.add_argument("--max-step", type=_num(0, MAX_DURATION_S, lo_open=True), help="adaptive: longest step in seconds (default duration/20)")
    r.add_argument("--spp", type=_num(1, MAX_SPP, integer=True), default=4, help="samples per pixel per step (default 4)")
    r.add_argument("--seed", type=_num(0, 2**31 - 1, integer=True), default=0, help="sampler seed (default 0)")
    r.add_argument("--independent-seeds", action="store_true",
                   help="new seed every step (Monte-Carlo noise then fires events; for comparisons only)")
    r.add_argument("--threshold", type=_num(0, 10, lo_open=True), help="contrast threshold C for ON and OFF (default: scene's or 0.2)")
    r.add_argument("--threshold-on", type=_num(0, 10, lo_open=True), help="ON threshold (overrides --threshold)")
    r.add_argument("--threshold-off", type=_num(0, 10, lo_open=True), help="OFF threshold (overrides --threshold)")
    r.add_argument("--linlog-threshold", type=_num(0, 1e6, lo_open=True), help="radiance below which the response is linear (1e-3)")
    r.add_argument("--preset", help="event pixel preset: ideal (default), davis346, prophesee_gen4")
    r.add_argument("--pixel", action="append", default=[], metavar="NAME=VALUE",
                   help="pixel-model parameter, e.g. --pixel refractory_s=1e-4 --pixel shot_noise_hz=2 (repeatable; "
                        "see docs/pixel_model.md)")
    r.add_argument("--variant", help="Mitsuba variant or backend: cuda, llvm, llvm_ad_mono, ... (default: auto)")
    r.add_argument("--color", action="store_true", help="render in colour (rgb variant); events use luminance")
    r.add_argument("-D", "--define", action="append", default=[], metavar="NAME=VALUE",
                   help="value of an XML <default name=...> parameter, e.g. -D width=64 (repeatable)")
    r.add_argument("--preview", help="also write an event-frame PNG of the last --preview-window ms")
    r.add_argument("--preview-window", type=_num(0, 1e9, lo_open=True), default=10.0, help="preview window in ms (default 10)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument("--auto", action="store_true",
                   help="choose colour, spp and steps from cheap probes (ef.auto), print and record why")

    i = sub.add_parser("info", help="resolution, duration, counts and metadata of an event file")
    i.add_argument("file")
    i.add_argument("--json", action="store_true", help="print everything as JSON")

    p = sub.add_parser("preview", help="event frame PNG (ON red, OFF blue) over a time window")
    p.add_argument("file")
    p.add_argument("-o", "--output", required=True, help="PNG path")
    p.add_argument("--t0", type=_num(0), help="window start, ms (default: first event)")
    p.add_argument("--t1", type=_num(0), help="window end, ms (default: last event)")
    p.add_argument("--scale", type=_num(1, 64, integer=True), default=1, help="integer upscaling of the image")
    f = sub.add_parser("frame", help="render frames (linear radiance) of a scene at given times: EXR + PNG")
    f.add_argument("scene")
    f.add_argument("-o", "--output", required=True, help="EXR path (PNG alongside); several times: _0000 suffixes")
    f.add_argument("--times", default="0", help="comma-separated times in ms (default 0)")
    f.add_argument("--spp", type=_num(1, MAX_SPP, integer=True), default=16)
    f.add_argument("-D", "--define", action="append", default=[], metavar="NAME=VALUE")

    lf_args = argparse.ArgumentParser(add_help=False)
    lf_args.add_argument("file", help="event file")
    lf_args.add_argument("--method", help="reconstruction: direct, highpass, complementary, galvo (default: "
                                          "direct with --start-frame, else galvo / highpass)")
    lf_args.add_argument("--start-frame", help="EXR of the linear frame at the stream start (eventfield frame)")
    lf_args.add_argument("--period", type=_num(0, integer=True), default=0, help="galvo: scan period index (default 0)")
    lf_args.add_argument("--views", type=_num(2, MAX_VIEWS, integer=True), default=32, help="galvo: views per scan period (default 32)")
    lf_args.add_argument("--time", type=_num(0), help="kaleidoscope: time in ms (default: stream end)")
    lf_args.add_argument("--calibration", help="calibration JSON (eventfield calibrate): view phase, depth model")

    rc = sub.add_parser("reconstruct", help="log-intensity frames from events: EXR + PNG per frame")
    rc.add_argument("file")
    rc.add_argument("-o", "--output", required=True, help="output directory (created)")
    rc.add_argument("--method", default="direct", help="direct, highpass, complementary, galvo (default direct)")
    g = rc.add_mutually_exclusive_group()
    g.add_argument("--times", help="comma-separated times in ms")
    g.add_argument("--fps", type=_num(0, 1e6, lo_open=True), help="frames per second over the whole stream")
    rc.add_argument("--start-frame", help="EXR of the linear frame at the stream start")
    rc.add_argument("--cutoff", type=_num(0, 1e6, lo_open=True), default=5.0, help="filter cutoff in Hz (highpass, complementary)")

    rf = sub.add_parser("refocus", parents=[lf_args], help="refocus the light field at one or more depths")
    rf.add_argument("-o", "--output", required=True, help="PNG path (EXR alongside; _<depth> suffix for several)")
    rf.add_argument("--depth", required=True, help="comma-separated depths in scene units (inf allowed)")

    dp = sub.add_parser("depth", parents=[lf_args], help="depth from focus: EXR (depth, confidence) + colour PNG")
    dp.add_argument("-o", "--output", required=True, help="PNG path (EXR alongside)")
    dp.add_argument("--near", type=_num(0, lo_open=True), required=True, help="nearest depth searched")
    dp.add_argument("--far", type=_num(0, lo_open=True), required=True, help="farthest depth searched")
    dp.add_argument("--planes", type=_num(2, MAX_PLANES, integer=True), default=32)
    dp.add_argument("--measure", default="variance", help="sml, tenengrad or variance (default)")
    dp.add_argument("--min-confidence", type=_num(0, 1), default=0.2, help="greyed out below this in the PNG")
    cal = sub.add_parser("calibrate", help="calibration from the data itself: galvo | depth | kaleidoscope")
    csub = cal.add_subparsers(dest="kind", required=True)
    cg = csub.add_parser("galvo", help="phase and curve size of the scan from a capture of a static scene")
    cg.add_argument("file", help="event file (galvo)")
    cg.add_argument("--patch", action="append", required=True, metavar="X,Y", help="textured patch centre (repeatable)")
    cg.add_argument("--views", type=_num(3, MAX_VIEWS, integer=True), default=24, help="frames reconstructed over the scan period (default 24)")
    cg.add_argument("--period", type=_num(0, integer=True), default=0, help="scan period index (default 0)")
    cg.add_argument("--start-frame", help="EXR of the linear frame at the stream start (else: galvo solver)")
    cg.add_argument("-o", "--output", required=True, help="calibration JSON (created or extended)")
    cd = csub.add_parser("depth", help="curve size against known depths from LED captures")
    cd.add_argument("captures", nargs="+", metavar="FILE:DEPTH", help="event file of the LED at DEPTH (scene units)")
    cd.add_argument("--views", type=_num(3, MAX_VIEWS, integer=True), default=24)
    cd.add_argument("-o", "--output", required=True, help="calibration JSON (created or extended)")
    ck = csub.add_parser("kaleidoscope", help="tile seams, flips, view registration, flat-field from frames")
    ck.add_argument("frame", help="EXR (linear) of a textured target at the focus distance")
    ck.add_argument("--flat", help="EXR (linear) of a uniform white target, for the flat-field")
    ck.add_argument("-o", "--output", required=True, help="calibration JSON (created or extended)")
    bn = sub.add_parser("bench", help="speed against accuracy of quality settings (chart + table)")
    bn.add_argument("scene", nargs="?", default=bundled_scene("fan/fan.xml"))
    bn.add_argument("-o", "--output", default="out/bench", help="output directory (chart, CSV)")
    bn.add_argument("--duration", type=_num(0, MAX_DURATION_S, lo_open=True), default=0.008, help="simulated seconds (default 0.008: two periods)")
    bn.add_argument("--steps", type=_num(1, MAX_STEPS, integer=True), default=64, help="steps of the default setting")
    bn.add_argument("-D", "--define", action="append", default=["width=96", "height=72"], metavar="NAME=VALUE")
    bn.add_argument("--refocus-depth", type=_num(0, lo_open=True), default=0.6, help="depth of the downstream refocus (fan: 0.6)")
    hd = sub.add_parser("hdr", help="HDR light field of a static galvo scene: events vs 8-bit exposures")
    hd.add_argument("scene", nargs="?", default=bundled_scene("hdr_leds/hdr_leds.xml"))
    hd.add_argument("-o", "--output", default="out/hdr", help="output directory (EXRs, figure, metrics JSON)")
    hd.add_argument("-D", "--define", action="append", default=[], metavar="NAME=VALUE")
    hd.add_argument("--depth", type=_num(0, lo_open=True), default=1.45, help="scene distance for the scan shifts (hdr_leds: 1.45)")
    hd.add_argument("--steps", type=_num(1, MAX_STEPS, integer=True), default=64, help="render steps over the scan period")
    hd.add_argument("--spp", type=_num(1, MAX_SPP, integer=True), default=4)
    hs = sub.add_parser("highspeed", help="galvo refocus of every scan period on named depth planes, vs truth")
    hs.add_argument("scene", nargs="?", default=bundled_scene("fan/fan.xml"))
    hs.add_argument("-o", "--output", default="out/highspeed", help="output directory (EXRs, PNGs, figure, metrics)")
    hs.add_argument("-D", "--define", action="append", default=[], metavar="NAME=VALUE",
                    help="XML parameters (for the fan, on top of width=240 height=180 amplitude=2 mirror_distance=0.2)")
    hs.add_argument("--plane", action="append", default=None, metavar="NAME=DEPTH",
                    help="refocus plane (repeatable; default for the fan: fan=0.6 wall=1.5)")
    hs.add_argument("--periods", type=_num(1, 1e6, integer=True), help="scan periods (default: the motion file's duration)")
    hs.add_argument("--views", type=_num(2, MAX_VIEWS, integer=True), default=40, help="views per scan period (default 40)")
    hs.add_argument("--start", choices=("frame", "events"), default="frame",
                    help="start frame the views integrate onto: one rendered frame, or the galvo solver")
    tf = sub.add_parser("track-focus", help="galvo focus tracking of an object moving in depth, vs Mitsuba depth")
    tf.add_argument("scene", nargs="?", default=bundled_scene("dart/galvo.xml"))
    tf.add_argument("-o", "--output", default="out/track", help="output directory (PNGs, EXR, figure, metrics)")
    tf.add_argument("-D", "--define", action="append", default=[], metavar="NAME=VALUE")
    tf.add_argument("--roi", type=_num(0, 1), nargs=4, default=[0.58, 0.44, 0.78, 0.56], metavar=("X0", "Y0", "X1", "Y1"),
                    help="object region in the first period, fractions of the image (default: the dart)")
    tf.add_argument("--near", type=_num(0, lo_open=True), default=0.6, help="nearest depth searched (default 0.6)")
    tf.add_argument("--far", type=_num(0, lo_open=True), default=1.5, help="farthest depth searched (default 1.5)")
    tf.add_argument("--object-far", type=_num(0, lo_open=True), default=1.6,
                    help="ground truth: object pixels are nearer than this (default 1.6; the dart's wall is at 1.8)")
    tf.add_argument("--background", type=_num(0, lo_open=True), default=1.8, help="background depth for comparison (default 1.8)")
    tf.add_argument("--planes", type=_num(2, MAX_PLANES, integer=True), default=24, help="depth planes searched (default 24)")
    tf.add_argument("--periods", type=_num(1, 1e6, integer=True), help="scan periods (default: the motion file's duration)")
    tf.add_argument("--views", type=_num(2, MAX_VIEWS, integer=True), default=40, help="views per scan period (default 40)")
    sm = sub.add_parser("slomorf", help="slow-motion refocus: kaleidoscope events + 120 fps RGB frames, scored")
    sm.add_argument("scene", nargs="?", help="kaleidoscope scene (default: the bundled scenes/falling)")
    sm.add_argument("-o", "--output", default="out/slomorf", help="output directory (frames, video, metrics)")
    sm.add_argument("-D", "--define", action="append", default=[], metavar="NAME=VALUE", help="XML default")
    sm.add_argument("--fps", type=_num(0, 1e4, lo_open=True), default=120.0, help="RGB camera frame rate (default 120)")
    sm.add_argument("--factor", type=_num(2, 64, integer=True), default=8, help="frames per RGB frame interval (default 8)")
    sm.add_argument("--depths", default="0.55,0.8,1.4", help="refocus depths (default: falling's post, block, wall)")
    sm.add_argument("--duration", type=_num(0, MAX_DURATION_S, lo_open=True), help="seconds (default: the motion file's)")
    sm.add_argument("--spp", type=_num(1, MAX_SPP, integer=True), default=4)
    sd = sub.add_parser("scanrate-depth", help="a metric depth map per galvo scan period, vs Mitsuba's depth")
    sd.add_argument("scene", nargs="?", default=bundled_scene("runner/runner.xml"))
    sd.add_argument("-o", "--output", default="out/scanrate", help="output directory (EXRs, PNGs, figure, metrics)")
    sd.add_argument("-D", "--define", action="append", default=[], metavar="NAME=VALUE")
    sd.add_argument("--periods", type=_num(1, 1e6, integer=True), help="scan periods (default: the motion file's duration)")
    sd.add_argument("--views", type=_num(2, MAX_VIEWS, integer=True), default=40, help="views per scan period (default 40)")
    sd.add_argument("--near", type=_num(0, lo_open=True), default=0.4, help="nearest depth plane (default 0.4)")
    sd.add_argument("--far", type=_num(0, lo_open=True), default=4.0, help="farthest depth plane (default 4)")
    sd.add_argument("--planes", type=_num(2, MAX_PLANES, integer=True), default=32, help="depth planes, uniform in inverse depth (default 32)")
    sd.add_argument("--min-confidence", type=_num(0, 1), default=0.6, help="pixels scored and shown (default 0.6)")
    sd.add_argument("--split-depth", type=_num(0, lo_open=True), default=1.2,
                    help="errors reported for pixels nearer / farther than this (default 1.2: runner / wall)")
    cg_ = sd.add_mutually_exclusive_group()
    cg_.add_argument("--calibration", help="calibration JSON (eventfield calibrate) instead of the nominal optics")
    cg_.add_argument("--calibrate", action="store_true",
                     help="calibrate depth first from LED captures through the same galvo (scenes/led_depth), save "
                          "it as OUTPUT/calibration.json and use it")
    rg = sub.add_parser("regression", help="compare tiny renders of the bundled scenes with reference images")
    rg.add_argument("--bless", action="store_true", help="re-render the references (after a deliberate change)")
    rg.add_argument("--references", default=os.path.join("tests", "regression"),
                    help="folder of the reference images (default: tests/regression, the repository's)")
    dev = sub.add_parser("device", help="drive the galvo through a function generator (SCPI/VISA)")
    dsub = dev.add_subparsers(dest="action", required=True)
    conn = argparse.ArgumentParser(add_help=False)
    conn.add_argument("--resource", help="VISA resource, e.g. TCPIP0::192.0.2.7::inst0::INSTR")
    conn.add_argument("--dialect", required=True, choices=("keysight", "rigol", "siglent"), help="generator dialect")
    conn.add_argument("--simulate", action="store_true", help="a simulated instrument (in memory), no hardware")
    conn.add_argument("--volts-per-deg", type=_num(*VOLTS_PER_DEG_RANGE), default=0.8,
                      help="galvo driver scaling, V per mechanical degree (default 0.8)")
    ds = dsub.add_parser("scan", parents=[conn], help="start a scan (ramped), keep it running, stop on exit")
    ds.add_argument("--curve", default="circle", choices=("circle", "line", "lissajous"), help="sine scans only")
    # frequency and amplitude limits are the galvo envelope's (device/spec.py), checked with the whole request
    ds.add_argument("--freq", type=_num(0, lo_open=True), required=True, help="Hz (x axis for lissajous)")
    ds.add_argument("--freq-y", type=_num(0, lo_open=True), help="lissajous: y frequency")
    ds.add_argument("--amplitude-deg", type=_num(0), required=True, help="mechanical degrees (x for lissajous)")
    ds.add_argument("--amplitude-y-deg", type=_num(0), help="lissajous: y amplitude")
    ds.add_argument("--phase", type=_num(*PHASE_RANGE_DEG), default=0.0, help="degrees")
    ds.add_argument("--axis", default="x", choices=("x", "y"), help="line: x or y")
    ds.add_argument("--duration", type=_num(0, MAX_SCAN_S), default=0.0,
                    help="seconds to scan, then stop (default 0: until Ctrl-C or SIGTERM)")
    ds.add_argument("--metadata", help="write the capture metadata (instrument, read-back, scan) to this JSON")
    dsub.add_parser("stop", parents=[conn], help="switch both outputs off")
    dsub.add_parser("status", parents=[conn], help="identity, settings read back, error queue")
    return ap


def _hdr(a) -> int:
    import mitsuba_eventfield as ef

    from .apps import hdr
    from .atomic import write_json
    from .images import write_exr
    if not a.depth > 0:
        raise ef.EventFieldError(f"--depth = {a.depth}: must be > 0")
    try:
        r = hdr.compare(a.scene, _pairs(a.define, "-D"), a.depth, a.steps, spp=a.spp, progress=True)
    except ValueError as e:
        raise ef.EventFieldError(str(e)) from None
    os.makedirs(a.output, exist_ok=True)
    meta = {k: v for k, v in r.meta.items() if k != "time_split_s"}
    write_exr(os.path.join(a.output, "truth.exr"), {"log": r.truth_log}, meta)
    for name, img in r.estimates.items():
        write_exr(os.path.join(a.output, f"{name}.exr"), {"log": img}, meta)
    hdr.figure(r, os.path.join(a.output, "hdr.png"))
    write_json(os.path.join(a.output, "metrics.json"), {"errors": r.errors, "dynamic_range": r.dynamic_range, **r.meta})
    print(r.report())
    print("time split: " + ", ".join(f"{k} {v:.1f} s" for k, v in r.meta["time_split_s"].items())
          + f"; wrote {a.output}/hdr.png, EXRs (log) and metrics.json")
    return 0


FAN_DEFAULTS = {"define": ["width=240", "height=180", "amplitude=2", "mirror_distance=0.2"],
                "plane": ["fan=0.6", "wall=1.5"]}


def _pairs(items, what):
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ValueError(f"{what} {item!r}: expected NAME=VALUE")
        out[key] = value
    return out


def _application(run, write, wrote, output: str) -> int:
    """Run an application, write its outputs, print its report: bad input is one line, no traceback."""
    from .errors import EventFieldError
    try:
        result = run()
        paths = write(result)
    except ValueError as e:
        raise EventFieldError(str(e)) from None
    print(result.report())
    print("wrote " + wrote(paths))
    return 0


def _highspeed(a) -> int:
    from .apps import highspeed
    fan = os.path.basename(a.scene) == "fan.xml"

    def run():
        defines = _pairs((FAN_DEFAULTS["define"] if fan else []) + a.define, "-D")
        planes = _pairs(a.plane if a.plane is not None else (FAN_DEFAULTS["plane"] if fan else []), "--plane")
        return highspeed.refocus_planes(a.scene, planes, defines, a.periods, a.views, a.start, progress=True)
    return _application(run, lambda r: highspeed.write_planes(r, a.output),
                        lambda p: f"{p['figure']}, per-plane EXRs and PNGs, {p['metrics']}", a.output)


def _track_focus(a) -> int:
    from .apps import highspeed
    return _application(
        lambda: highspeed.track_focus_depth(a.scene, a.roi, a.near, a.far, a.object_far, a.planes, a.background,
                                            _pairs(a.define, "-D"), a.periods, a.views, progress=True),
        lambda r: highspeed.write_track(r, a.output),
        lambda p: f"{p['figure']}, per-period PNGs, {p['exr']}, {p['metrics']}", a.output)


def _scanrate_depth(a) -> int:
    from .apps import scanrate
    from .calibration import load_calibration, save_calibration
    from .errors import EventFieldError
    calibration = load_calibration(a.calibration) if a.calibration else None
    if a.calibrate:
        try:
            calibration = scanrate.calibrate_depth(a.scene, _pairs(a.define, "-D"), progress=True)
        except ValueError as e:
            raise EventFieldError(str(e)) from None
        os.makedirs(a.output, exist_ok=True)
        d = calibration["depth"]
        print(f"depth calibration (LED at {len(d.depths)} depths): pivot {d.pivot:.4g}, rms {d.rms_inverse:.3f} "
              f"px/rad -> " + save_calibration(os.path.join(a.output, "calibration.json"), **calibration))
    return _application(
        lambda: scanrate.run(a.scene, _pairs(a.define, "-D"), a.periods, a.views, a.near, a.far, a.planes,
                             min_confidence=a.min_confidence, split_depth=a.split_depth, calibration=calibration,
                             progress=True),
        lambda r: scanrate.write_outputs(r, a.output),
        lambda p: f"{p['figure']}, {len(p['exr'])} depth EXRs and PNGs, {p['metrics']}", a.output)


def _slomorf(a) -> int:
    import mitsuba_eventfield as ef

    from .apps import slomorf
    depths = number_list(a.depths, "--depths", lo=0, lo_open=True)
    try:
        r = slomorf.slomorf(a.scene or slomorf.DEFAULT_SCENE, _pairs(a.define, "-D"), a.fps, a.factor, a.duration,
                            depths, a.spp, progress=True)
    except ValueError as e:
        raise ef.EventFieldError(str(e)) from None
    os.makedirs(a.output, exist_ok=True)
    written = slomorf.write_outputs(r, a.output)
    print(r.report())
    print(f"wrote {a.output}: {len(written['frames'])} frames, {len(written['refocus'])} refocused images, "
          "slomorf.mp4, slomorf.gif, slomorf.png, metrics.json")
    return 0


def _bench(a) -> int:
    from .evaluation import bench
    from .evaluation.sweep import SweepTable
    os.makedirs(a.output, exist_ok=True)
    defines = dict(item.partition("=")[::2] for item in a.define)
    rows = bench.run(a.scene, a.duration, a.steps, defines, a.refocus_depth)
    SweepTable(rows).to_csv(os.path.join(a.output, "bench.csv"))
    chart = bench.chart(rows, os.path.join(a.output, "bench.png"), f"{os.path.basename(a.scene)}: speed vs accuracy")
    for r in rows:
        print(f"{r['setting']:28s} time x{r.get('relative_time', 0):6.2f}  product err {r['product_error']:.4f}  "
              f"timing err {r['timing_error']:.4f}  count err {r['count_error']:.4f}{'  (Pareto)' if r.get('pareto') else ''}")
    print(f"default on or near the Pareto front: {bench.default_on_front(rows)}; wrote {chart}")
    return 0


def _regression(a) -> int:
    from .errors import EventFieldError
    from .evaluation import regression
    if a.bless:
        for path in regression.bless(a.references):
            print(f"wrote {path}")
        return 0
    if not os.path.isdir(a.references):
        raise EventFieldError(f"--references {a.references}: no such folder (run from the repository root, or "
                              "name the folder of the reference images)")
    problems = regression.check_all(a.references)
    for p in problems:
        print(p)
    print("regression images: " + ("all match" if not problems else f"{len(problems)} difference(s)"))
    return 1 if problems else 0


def _device_curve(a, spec):
    """The scan curve a ``device scan`` request names (validated by the scan module)."""
    import mitsuba_eventfield as ef
    common = {"phase": a.phase} if a.curve != "lissajous" else {}
    if a.curve == "lissajous":
        return ef.make_curve("lissajous", freq_x=a.freq, freq_y=a.freq_y or a.freq, amplitude_x=a.amplitude_deg,
                             amplitude_y=a.amplitude_y_deg if a.amplitude_y_deg is not None else a.amplitude_deg,
                             phase_x=a.phase, max_angle_deg=spec.max_mech_deg, where="device scan")
    if a.curve == "line":
        return ef.make_curve("line", frequency=a.freq, amplitude=a.amplitude_deg, axis=a.axis,
                             max_angle_deg=spec.max_mech_deg, where="device scan", **common)
    return ef.make_curve(a.curve, frequency=a.freq, amplitude=a.amplitude_deg, max_angle_deg=spec.max_mech_deg,
                         where="device scan", **common)


def _device(a) -> int:
    import time

    from .atomic import write_json
    from .device import GalvoController, GalvoSpec, dialect, open_transport
    from .device.spec import check_duration
    spec = GalvoSpec(volts_per_deg=a.volts_per_deg)
    dialect(a.dialect)
    curve = duration = None
    if a.action == "scan":      # every check happens before a connection is even opened
        curve = _device_curve(a, spec)
        duration = check_duration(a.duration)
        GalvoController(None, a.dialect, spec).plan(curve)
    # The context manager switches the outputs off before the connection closes, on every way out of this
    # block: a refusal, a failed metadata write, Ctrl-C, SIGTERM (main turns it into an exception).
    with GalvoController(open_transport(a.dialect, a.resource, a.simulate), a.dialect, spec) as ctl:
        if a.action == "status":
            print(f"instrument: {ctl.identity()}")
            for ch in (1, 2):
                print(f"channel {ch}: " + ", ".join(f"{k} {v}" for k, v in ctl.read_channel(ch).items()))
            errs = ctl.errors()
            print("error queue: " + ("; ".join(f"{c}: {m}" for c, m in errs) if errs else "empty"))
        elif a.action == "stop":
            ctl.outputs_off()
            print("outputs off")
        else:
            ctl.start(curve)
            print(f"scanning {curve.name} at {a.freq:g} Hz, {a.amplitude_deg:g} deg on {ctl.identity()}; read-back "
                  "matches")
            if a.metadata:
                write_json(a.metadata, ctl.metadata(curve), "metadata")
            end = time.monotonic() + duration if duration > 0 else float("inf")
            while time.monotonic() < end:
                time.sleep(max(0.0, min(0.2, end - time.monotonic())))
            ctl.stop()
            print("stopped: outputs off")
    return 0


def _times_ms(text, what="--times"):
    from .validate import number_list
    return number_list(text, what, lo=0, hi=1e9)


def _start_log(path, events):
    """Log intensity (as the pixel sees it) of a linear EXR frame, checked against the stream's size."""
    import mitsuba_eventfield as ef

    from .plugins.pixel_model import linlog_np
    if path is None:
        return None
    img = _luminance_channel(path)
    if img.shape != (events.height, events.width):
        raise ef.EventFieldError(f"{path}: needs a Y (or R) channel of {events.width}x{events.height}, got "
                                 f"{img.shape[::-1]}")
    return linlog_np(img, events.meta.get("pixel_model", {}).get("linlog_threshold", 1e-3))


def _luminance_channel(path):
    """The Y (or else R) channel of an EXR frame, with a named error when it has neither."""
    import mitsuba_eventfield as ef

    from .images import read_exr
    channels, _ = read_exr(path)
    img = channels.get("Y", channels.get("R"))
    if img is None:
        raise ef.EventFieldError(f"{path}: needs a Y (or R) channel; it has {', '.join(sorted(channels)) or 'none'}")
    return img


def _out_meta(a, events, **extra):
    from ._version import __version__
    return dict({"package_version": __version__, "command": a.command, "source": os.path.abspath(a.file),
                 "optics": events.meta.get("optics"), "pixel_model": events.meta.get("pixel_model")}, **extra)


def _save_image(png_path, linear, meta, suffix=""):
    from .images import to_uint8, write_exr, write_png
    root = os.path.splitext(png_path)[0] + suffix
    write_exr(root + ".exr", {"Y": linear}, meta)
    write_png(root + ".png", to_uint8(linear))
    return root


def _frame(a) -> int:
    import mitsuba_eventfield as ef
    defines = dict(item.partition("=")[::2] for item in a.define)
    scene = ef.load_scene(a.scene, **defines)
    times = [t * 1e-3 for t in _times_ms(a.times)]
    frames = ef.render_frames(scene, times, spp=a.spp, log=False)
    for k, (t, img) in enumerate(zip(times, frames)):
        root = _save_image(a.output.replace(".exr", ".png"), img, {"scene": os.path.abspath(a.scene), "time_s": t,
                                                                    "spp": a.spp}, f"_{k:04d}" if len(times) > 1 else "")
        print(f"wrote {root}.exr/.png (t = {t * 1e3:g} ms)")
    return 0


def _reconstruct(a) -> int:
    import numpy as np

    import mitsuba_eventfield as ef
    ev = ef.read_events(a.file)
    t0 = ev.meta.get("t_start_us", 0) * 1e-6
    if a.times:
        times = np.array(_times_ms(a.times)) * 1e-3
    else:
        fps = a.fps or 1000.0
        n = max(1, int(round(ev.duration_us * 1e-6 * fps)))
        times = t0 + (np.arange(n) + 1) / fps
    kw = {}
    if a.method == "direct":
        kw = {"log_start": _start_log(a.start_frame, ev), "t_start": t0}
    elif a.method in ("highpass", "complementary"):
        kw = {"cutoff_hz": a.cutoff}
        if a.method == "complementary":
            start = _start_log(a.start_frame, ev)
            if start is None:
                raise ef.EventFieldError("--method complementary needs --start-frame (a frame to anchor to)")
            kw.update(frames=start[None], frame_times=[t0])
    try:
        frames = ef.reconstruct.reconstruct(ev, times, a.method, **kw)
    except ValueError as e:
        raise ef.EventFieldError(f"{a.file}: {e}") from None
    os.makedirs(a.output, exist_ok=True)
    for k, (t, log_img) in enumerate(zip(times, frames)):
        _save_image(os.path.join(a.output, f"frame_{k:04d}.png"), np.exp(log_img),
                    _out_meta(a, ev, method=a.method, time_s=float(t), domain="linear = exp(log intensity)"))
    print(f"wrote {len(times)} frames ({a.method}) to {a.output}")
    return 0


def _lightfield(a, ev):
    import mitsuba_eventfield as ef
    calibration = optics = None
    if a.calibration:          # refused before any reconstruction when made for other optics than this stream's
        from .calibration import apply_to_lightfield, check_optics, load_calibration, optics_record
        calibration = load_calibration(a.calibration)
        optics = optics_record(ev.meta.get("optics", {}), ev.width, ev.height, where=a.file)
        check_optics(calibration, optics)
    try:
        lf = ef.lightfield.from_events(ev, period=a.period, views=a.views,
                                       time=None if a.time is None else a.time * 1e-3, method=a.method,
                                       log_start=_start_log(a.start_frame, ev))
    except (ValueError, KeyError, StopIteration) as e:
        raise ef.EventFieldError(f"{a.file}: {e}") from None
    return apply_to_lightfield(lf, calibration, optics) if calibration is not None else lf


def _galvo_frames(ev, period, views, start_frame_log=None):
    """Reconstructed log frames and their times over one scan period of a galvo stream."""
    import mitsuba_eventfield as ef

    from .optics.scan import curve_from_dict
    optics = ev.meta.get("optics", {})
    if optics.get("design") != "galvo":
        raise ef.EventFieldError("not a galvo event stream (optics.design != 'galvo')")
    curve = curve_from_dict(optics["scan"])
    try:
        t0 = ef.lightfield.galvo_period_starts(ev, [period])[period]
    except ValueError as e:
        raise ef.EventFieldError(f"--period: {e}") from None
    times = ef.lightfield.galvo_view_times(optics, t0, views)     # bin centres, as the light-field commands use
    method = "direct" if start_frame_log is not None else "galvo"
    kw = {"log_start": start_frame_log, "t_start": t0} if start_frame_log is not None else {"t_start": t0}
    return ef.reconstruct.reconstruct(ev, times, method, **kw), times, curve


def _calibrate(a) -> int:
    import mitsuba_eventfield as ef

    from . import calibration as cal
    try:
        if a.kind == "galvo":
            ev = ef.read_events(a.file)
            patches = []
            for p in a.patch:
                xy = number_list(p, "--patch", lo=0)
                if len(xy) != 2 or xy[0] >= ev.width or xy[1] >= ev.height:
                    raise ef.EventFieldError(f"--patch {p!r}: expected X,Y inside the {ev.width}x{ev.height} frame")
                patches.append(tuple(xy))
            frames, times, curve = _galvo_frames(ev, a.period, a.views, _start_log(a.start_frame, ev))
            optics = cal.optics_record(ev.meta["optics"], ev.width, ev.height, where=a.file)
            result = cal.fit_galvo(frames, times, curve, patches, scale_limit=cal.galvo_scale_limit(optics))
            cal.save_calibration(a.output, optics, galvo=result)
            print(f"galvo: phase {result.phase_deg:.2f} +- {result.std['phase_deg']:.2f} deg at the first frame "
                  f"({result.clock_phase_deg:.2f} deg at t = 0), curve radius "
                  f"{result.radius_px()[0]:.3f} x {result.radius_px()[1]:.3f} px, rms {result.rms_px:.3f} px "
                  f"({result.frames_used} matches) -> {a.output}")
        elif a.kind == "depth":
            depths, scales, scales_y, records = [], [], [], {}
            for item in a.captures:
                path, _, depth = item.rpartition(":")
                try:
                    depth = float(depth)
                except ValueError:
                    raise ef.EventFieldError(f"{item!r}: expected FILE:DEPTH") from None
                ev = ef.read_events(path)
                frames, times, curve = _galvo_frames(ev, 0, a.views)
                records[path] = cal.optics_record(ev.meta["optics"], ev.width, ev.height, where=path)
                fit = cal.fit_tracks([cal.track_point(np.exp(frames))], times, curve,
                                     scale_limit=cal.galvo_scale_limit(records[path]))
                depths.append(depth)
                scales.append(fit.scale_px_per_rad[0])
                scales_y.append(fit.scale_px_per_rad[1])
            optics = cal.same_optics(records)          # one set-up for all the captures
            result = cal.fit_depth(depths, scales, scales_y)
            cal.save_calibration(a.output, optics, depth=result)
            print(f"depth: inverse model rms {result.rms_inverse:.3f} px/rad (pivot {result.pivot:.4g}), linear "
                  f"model rms {result.rms_linear:.3f} px/rad; best: {result.best} -> {a.output}")
        else:
            from .images import read_exr
            frame = _luminance_channel(a.frame)
            result = cal.register(np.log(np.maximum(frame, 1e-6)))
            optics = cal.kaleidoscope_record(frame.shape[1], frame.shape[0], result.n,
                                             read_exr(a.frame)[1].get("optics"), where=a.frame)
            if a.flat:
                flat = _luminance_channel(a.flat)
                if flat.shape != frame.shape:
                    raise ef.EventFieldError(f"{a.flat}: flat frame is {flat.shape[1]}x{flat.shape[0]}, the frame "
                                             f"{a.frame} is {frame.shape[1]}x{frame.shape[0]}: they must match")
                cal.flat_field(result, flat)
            cal.save_calibration(a.output, optics, kaleidoscope=result)
            worst = max(abs(c) for v in result.views for c in v["offset"])
            print(f"kaleidoscope: {result.n}x{result.n} views of {result.tile[0]}x{result.tile[1]} px, largest "
                  f"offset {worst:.3f} px -> {a.output}")
    except ValueError as e:
        raise ef.EventFieldError(str(e)) from None
    return 0


def _refocus(a) -> int:
    import mitsuba_eventfield as ef
    ev = ef.read_events(a.file)
    depths = number_list(a.depth, "--depth", lo=0, lo_open=True, allow_inf=True)
    lf = _lightfield(a, ev)
    for z in depths:
        root = _save_image(a.output, ef.refocus(lf, z), _out_meta(a, ev, depth=z, views=len(lf.views)),
                           f"_{z:g}" if len(depths) > 1 else "")
        print(f"wrote {root}.png/.exr (refocused at {z:g})")
    return 0


def _depth(a) -> int:
    import mitsuba_eventfield as ef

    from .images import depth_png, write_exr, write_png
    ev = ef.read_events(a.file)
    if not (0 < a.near < a.far) or a.planes < 2:
        raise ef.EventFieldError(f"--near {a.near} --far {a.far} --planes {a.planes}: need 0 < near < far, planes >= 2")
    if a.measure not in ef.depth.MEASURES:
        raise ef.EventFieldError(f"--measure {a.measure!r}: allowed: {', '.join(ef.depth.MEASURES)}")
    lf = _lightfield(a, ev)
    dm = ef.depth_from_focus(lf, a.near, a.far, a.planes, a.measure)
    root = os.path.splitext(a.output)[0]
    meta = _out_meta(a, ev, near=a.near, far=a.far, planes=a.planes, measure=a.measure, views=len(lf.views))
    write_exr(root + ".exr", {"depth": dm.depth, "confidence": dm.confidence}, meta)
    write_png(root + ".png", depth_png(dm.depth, dm.confidence, a.near, a.far, a.min_confidence))
    print(f"wrote {root}.exr (depth, confidence) and {root}.png; median depth of confident pixels "
          f"{float(np.median(dm.depth[dm.confidence >= a.min_confidence])) if (dm.confidence >= a.min_confidence).any() else float('nan'):.4g}")
    return 0


def _pixel_overrides(items):
    import mitsuba_eventfield as ef
    out = {}
    for item in items:
        name, eq, value = item.partition("=")
        try:
            out[name] = int(value) if name in ("seed", "readout_cap_native_pixels") else float(value)
        except ValueError:
            raise ef.EventFieldError(f"--pixel {item!r}: expected NAME=NUMBER") from None
        if not eq:
            raise ef.EventFieldError(f"--pixel {item!r}: expected NAME=NUMBER")
    return out


def _render(a) -> int:
    import os

    import mitsuba_eventfield as ef
    ef.set_variant(a.variant, a.color)
    motion = None if a.no_motion else (a.motion or "auto")
    defines = {}
    for item in a.define:
        name, eq, value = item.partition("=")
        if not eq or not name:
            raise ef.EventFieldError(f"-D {item!r}: expected NAME=VALUE")
        defines[name] = value
    extra = None
    if a.auto:
        duration = a.duration
        if duration is None:
            probe = ef.load_scene(a.scene, motion=motion, **defines)
            duration = probe.motion.duration if probe.motion and probe.motion.duration else None
            if duration is None:
                raise ef.EventFieldError("--auto needs --duration (or `duration` in the motion file)")
        plan = ef.auto.plan(a.scene, duration, threshold=a.threshold or 0.2, defines=defines)
        print("automatic choices:\n  " + plan.report().replace("\n", "\n  "))
        ef.set_variant(a.variant, plan.color)
        a.spp, a.steps, a.duration = plan.spp, plan.steps, duration
        extra = {"auto_plan": plan.as_dict()}
    scene = ef.load_scene(a.scene, motion=motion, **defines)
    fmt_ext = os.path.splitext(a.output)[1].lower()
    summary = ef.render_events(
        scene, a.duration, steps=a.steps, adaptive=a.adaptive, max_log_change=a.max_log_change,
        min_step=a.min_step, max_step=a.max_step, spp=a.spp, seed=a.seed,
        seed_mode="independent" if a.independent_seeds else "fixed", threshold=a.threshold,
        threshold_on=a.threshold_on, threshold_off=a.threshold_off, linlog_threshold=a.linlog_threshold,
        output=a.output, progress=not a.quiet, preset=a.preset, pixel=_pixel_overrides(a.pixel), extra_meta=extra)
    print(summary.format())
    if a.preview:
        ev = ef.read_events(a.output) if fmt_ext != ".txt" else None
        if ev is not None:
            end = int(ev.meta.get("t_start_us", 0)) + ev.duration_us
            t0 = max(int(ev.meta.get("t_start_us", 0)), end - int(round(a.preview_window * 1e3)))
            ef.write_preview(a.preview, ev, t0, end + 1, scale=2 if max(ev.width, ev.height) < 400 else 1)
            print(f"wrote {os.path.abspath(a.preview)} (events of {(end - t0) / 1e3:g} ms up to the end)")
    return 0


def _info(a) -> int:
    import mitsuba_eventfield as ef
    ev = ef.read_events(a.file)
    s = ev.summary()
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
    return 0


def _preview(a) -> int:
    import mitsuba_eventfield as ef
    ev = ef.read_events(a.file)
    t0 = None if a.t0 is None else int(round(a.t0 * 1e3))
    t1 = None if a.t1 is None else int(round(a.t1 * 1e3))
    ef.write_preview(a.output, ev, t0, t1, scale=a.scale)
    win = ev.time_window(t0, t1)
    print(f"wrote {a.output}: {len(win)} events in the window")
    return 0


COMMANDS = {"render": _render, "info": _info, "preview": _preview, "frame": _frame, "reconstruct": _reconstruct,
            "refocus": _refocus, "depth": _depth, "calibrate": _calibrate, "device": _device,
            "regression": _regression, "bench": _bench, "hdr": _hdr, "highspeed": _highspeed,
            "track-focus": _track_focus, "slomorf": _slomorf, "scanrate-depth": _scanrate_depth}


# Every output a subcommand writes, checked in one place before any work starts (a render must not run for
# minutes and then fail on its output path). Files: (argument, what); directories: the -o of the applications.
OUTPUT_FILES = {"render": (("output", "event file"), ("preview", "preview")), "preview": (("output", "preview"),),
                "frame": (("output", "frame"),), "refocus": (("output", "refocused image"),),
                "depth": (("output", "depth map"),), "calibrate": (("output", "calibration file"),),
                "device": (("metadata", "metadata"),)}
OUTPUT_DIRS = ("reconstruct", "bench", "hdr", "highspeed", "track-focus", "slomorf", "scanrate-depth")


def _check_outputs(args) -> None:
    from .atomic import check_output_dir, check_writable
    for name, what in OUTPUT_FILES.get(args.command, ()):
        if getattr(args, name, None):
            check_writable(getattr(args, name), what)
    if args.command in OUTPUT_DIRS:
        check_output_dir(args.output)


def _signals_as_interrupts():
    """SIGINT and SIGTERM raise KeyboardInterrupt, so every ``finally`` runs (outputs off, temporary files
    removed); the signal is remembered because a library between us and the handler (Dr.Jit calling a Python
    plugin) may hand it back wrapped in another exception. Returns the previous handlers, or {} off the main
    thread (where Python allows no handlers)."""
    import signal
    import threading
    received.clear()

    def on_signal(signum, frame):
        received.append(signum)
        raise KeyboardInterrupt(signal.Signals(signum).name)
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}


received: list = []


def _one_line(e: BaseException) -> str:
    return " ".join(str(e).split()) or type(e).__name__


def main(argv=None) -> int:
    import errno
    import signal
    args = _parser().parse_args(argv)
    from .errors import EventFieldError
    previous = _signals_as_interrupts()
    try:
        _check_outputs(args)
        if args.command in OUTPUT_DIRS:
            from .atomic import output_dir_run
            with output_dir_run(args.output, args.command):
                return COMMANDS[args.command](args)
        return COMMANDS[args.command](args)
    except EventFieldError as e:
        print(f"eventfield: error: {_one_line(e)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        pass                                  # reported below, with the signal's exit status
    except BrokenPipeError:          # e.g. `eventfield info f.h5 | head`: the reader left; not an error of ours
        sys.stderr.close()
        return 0
    except OSError as e:
        if e.errno != errno.ENOSPC and not received:
            print(f"eventfield: error: {e.filename or ''}{': ' if e.filename else ''}{e.strerror or _one_line(e)}",
                  file=sys.stderr)
            return 2
        if e.errno == errno.ENOSPC:
            print(f"eventfield: error: disk full while writing {e.filename or 'the output'} (nothing was kept)",
                  file=sys.stderr)
            return 2
    except Exception as e:  # noqa: BLE001  (no traceback reaches the user; EVENTFIELD_DEBUG=1 shows it)
        if not received:
            if os.environ.get("EVENTFIELD_DEBUG"):
                raise
            print(f"eventfield: error: unexpected {type(e).__name__}: {_one_line(e)[:300]} "
                  "(EVENTFIELD_DEBUG=1 shows the traceback)", file=sys.stderr)
            return 3
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    signum = received[0] if received else signal.SIGINT
    print(f"eventfield: {'terminated' if signum == signal.SIGTERM else 'interrupted'} (no partial output kept)",
          file=sys.stderr)
    return 128 + int(signum)


if __name__ == "__main__":
    sys.exit(main())
