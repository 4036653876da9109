"""The paper's applications, one command each: ``hdr``, ``highspeed``, ``track-focus``, ``slomorf``,
``scanrate-depth``. Each runs the application's Python function, writes its outputs and prints its report."""
from __future__ import annotations

import os
import sys

from ..errors import EventFieldError
from ..scene.bundled import bundled_scene
from ..validate import MAX_DURATION_S, MAX_PLANES, MAX_SPP, MAX_STEPS, MAX_VIEWS, number_list
from .args import add_defines, defines, num, pairs


def add_parsers(sub) -> None:
    dm = sub.add_parser("demo", help="the main job: a galvo event field, refocused on two cards and a depth map, "
                                     "from the events alone")
    dm.add_argument("-o", "--output", default="out/demo", help="output directory (events, PNGs, EXRs, metrics)")
    dm.add_argument("--width", type=num(16, 4096, integer=True), default=160, help="film width (default 160)")
    dm.add_argument("--height", type=num(12, 4096, integer=True), default=120, help="film height (default 120)")
    dm.add_argument("--views", type=num(4, MAX_VIEWS, integer=True), default=32,
                    help="views per scan period (default 32)")
    hd = sub.add_parser("hdr", help="HDR light field of a static galvo scene: events vs 8-bit exposures (one view; "
                                     "--lightfield: all views, refocused at several depths)")
    hd.add_argument("scene", nargs="?", help="static galvo scene (default: scenes/hdr_leds; with --lightfield "
                                             "scenes/hdr_depth)")
    hd.add_argument("-o", "--output", default="out/hdr", help="output directory (EXRs, figure, metrics JSON)")
    add_defines(hd)
    hd.add_argument("--depth", type=num(0, lo_open=True),
                    help="scene distance for the scan shifts (default: hdr_leds' 1.45; with --lightfield the harmonic "
                         "mean of --depths)")
    hd.add_argument("--steps", type=num(1, MAX_STEPS, integer=True),
                    help="render steps over the scan period (default 64; with --lightfield 1 px of scan per step)")
    hd.add_argument("--spp", type=num(1, MAX_SPP, integer=True), default=4)
    hd.add_argument("--lightfield", action="store_true", help="the light field of one scan period with the scene's "
                    "event pixel, refocused at --depths, against 8-bit exposures of the same views")
    hd.add_argument("--depths", help="with --lightfield: refocus depths (default: hdr_depth's card and wall, 0.6,1.5)")
    hd.add_argument("--views", type=num(2, MAX_VIEWS, integer=True),
                    help="with --lightfield: views per scan period (default 32)")
    _add_galvo_apps(sub)
    sm = sub.add_parser("slomorf", help="slow-motion refocus: kaleidoscope events + 120 fps RGB frames, scored")
    sm.add_argument("scene", nargs="?", help="kaleidoscope scene (default: the bundled scenes/falling)")
    sm.add_argument("-o", "--output", default="out/slomorf", help="output directory (frames, video, metrics)")
    add_defines(sm)
    sm.add_argument("--fps", type=num(0, 1e4, lo_open=True), default=120.0, help="RGB camera frame rate (default 120)")
    sm.add_argument("--factor", type=num(2, 64, integer=True), default=8, help="frames per RGB frame interval (default 8)")
    sm.add_argument("--depths", default="0.55,0.8,1.4",
                    help="refocus depths (default: falling's post, block, wall; for scenes/dart/kaleidoscope.xml "
                         "give 0.95,1.8: the dart and the wall)")
    sm.add_argument("--duration", type=num(0, MAX_DURATION_S, lo_open=True), help="seconds (default: the motion file's)")
    sm.add_argument("--spp", type=num(1, MAX_SPP, integer=True), default=4)


def _periods_and_views(parser) -> None:
    parser.add_argument("--periods", type=num(1, 1e6, integer=True),
                        help="scan periods (default: the motion file's duration)")
    parser.add_argument("--views", type=num(2, MAX_VIEWS, integer=True), default=40,
                        help="views per scan period (default 40)")


def _start_option(parser) -> None:
    parser.add_argument("--start", choices=("events", "frame"), default="events",
                        help="where each period's image comes from: 'events' (default: solved from the events "
                             "alone) or 'frame' (a rendered frame at t = 0: a conventional camera the rig lacks)")


def _add_galvo_apps(sub) -> None:
    hs = sub.add_parser("highspeed", help="galvo refocus of every scan period on named depth planes, vs truth")
    hs.add_argument("scene", nargs="?", default=bundled_scene("fan/fan.xml"))
    hs.add_argument("-o", "--output", default="out/highspeed", help="output directory (EXRs, PNGs, figure, metrics)")
    add_defines(hs, help_text="XML parameters (for the fan, on top of width=240 height=180 amplitude=2 "
                              "mirror_distance=0.2)")
    hs.add_argument("--plane", action="append", default=None, metavar="NAME=DEPTH",
                    help="refocus plane (repeatable; default for the fan: fan=0.6 wall=1.5)")
    _periods_and_views(hs)
    _start_option(hs)
    tf = sub.add_parser("track-focus", help="galvo focus tracking of an object moving in depth, vs Mitsuba depth")
    tf.add_argument("scene", nargs="?", default=bundled_scene("dart/galvo.xml"))
    tf.add_argument("-o", "--output", default="out/track", help="output directory (PNGs, EXR, figure, metrics)")
    add_defines(tf)
    tf.add_argument("--roi", type=num(0, 1), nargs=4, default=[0.58, 0.44, 0.78, 0.56],
                    metavar=("X0", "Y0", "X1", "Y1"),
                    help="object region in the first period, fractions of the image (default: the dart)")
    tf.add_argument("--near", type=num(0, lo_open=True), default=0.6, help="nearest depth searched (default 0.6)")
    tf.add_argument("--far", type=num(0, lo_open=True), default=1.5, help="farthest depth searched (default 1.5)")
    tf.add_argument("--object-far", type=num(0, lo_open=True), default=1.6,
                    help="ground truth: object pixels are nearer than this (default 1.6; the dart's wall is at 1.8)")
    tf.add_argument("--background", type=num(0, lo_open=True), default=1.8,
                    help="background depth for comparison (default 1.8)")
    tf.add_argument("--planes", type=num(2, MAX_PLANES, integer=True), default=24,
                    help="depth planes searched (default 24)")
    _periods_and_views(tf)
    _start_option(tf)
    sd = sub.add_parser("scanrate-depth", help="a metric depth map per galvo scan period, vs Mitsuba's depth")
    sd.add_argument("scene", nargs="?", default=bundled_scene("runner/runner.xml"))
    sd.add_argument("-o", "--output", default="out/scanrate", help="output directory (EXRs, PNGs, figure, metrics)")
    add_defines(sd)
    _periods_and_views(sd)
    _start_option(sd)
    sd.add_argument("--near", type=num(0, lo_open=True), default=0.4, help="nearest depth plane (default 0.4)")
    sd.add_argument("--far", type=num(0, lo_open=True), default=4.0, help="farthest depth plane (default 4)")
    sd.add_argument("--planes", type=num(2, MAX_PLANES, integer=True), default=32,
                    help="depth planes, uniform in inverse depth (default 32)")
    sd.add_argument("--min-confidence", type=num(0, 1), default=0.6, help="pixels scored and shown (default 0.6)")
    sd.add_argument("--split-depth", type=num(0, lo_open=True), default=1.2,
                    help="errors reported for pixels nearer / farther than this (default 1.2: runner / wall)")
    cal = sd.add_mutually_exclusive_group()
    cal.add_argument("--calibration", help="calibration JSON (eventfield calibrate) instead of the nominal optics")
    cal.add_argument("--calibrate", action="store_true",
                     help="calibrate depth first from LED captures through the same galvo (scenes/led_depth), save "
                          "it as OUTPUT/calibration.json and use it")


def _application(run, output: str, wrote) -> int:
    """Run an application, write its outputs (``AppResult.write``), print its report: bad input is one line,
    no traceback."""
    try:
        result = run()
        paths = result.write(output)
    except ValueError as e:
        raise EventFieldError(str(e)) from None
    print(result.report())
    print("wrote " + wrote(paths))
    for line in result.failed_checks():          # the report says FAILED mid-table; said where it is seen
        print(f"eventfield: warning: {line}", file=sys.stderr)
    return 0


def run_demo(a) -> int:
    from ..apps import demo

    def wrote(p):
        return (f"{a.output}/: demo.png (the four results side by side), preview.png (the events: every edge "
                "fires as the scan sweeps it), refocus_0.5m.png (near card sharp), refocus_1.2m.png (far card "
                f"sharp), depth.png/.exr (depth map), events.h5, {os.path.basename(p['metrics'])}")
    return _application(lambda: demo.run(a.width, a.height, a.views, progress=True), a.output, wrote)


def run_hdr(a) -> int:
    from ..apps import hdr
    if a.lightfield:
        depths = number_list(a.depths or "0.6,1.5", "--depths", lo=0, lo_open=True)
        return _application(lambda: hdr.lightfield(a.scene, defines(a), depths, a.views or 32, a.depth, a.steps,
                                                    spp=a.spp, progress=True),
                            a.output,
                            lambda p: f"{p['figure']}, {len(p['exr'])} refocused EXRs (log) and {p['metrics']}")
    if a.depths is not None or a.views is not None:      # they were ignored
        raise EventFieldError("--depths and --views apply to the light field (--lightfield); hdr alone refocuses "
                              "nothing")
    scene = a.scene or bundled_scene("hdr_leds/hdr_leds.xml")
    depth = 1.45 if a.depth is None else a.depth
    return _application(lambda: hdr.compare(scene, defines(a), depth, a.steps or 64, spp=a.spp, progress=True),
                        a.output,
                        lambda p: f"{p['figure']}, EXRs (log) and {p['metrics']}")


def run_highspeed(a) -> int:
    from ..apps import highspeed
    fan = os.path.basename(a.scene) == "fan.xml"

    def run():
        # the fan's defaults, then the user's -D over them (one list refused a -D width that a default also set)
        scene_defines = {**pairs(highspeed.FAN_DEFAULTS["define"] if fan else [], "-D"), **pairs(a.define, "-D")}
        planes = pairs(a.plane if a.plane is not None else (highspeed.FAN_DEFAULTS["plane"] if fan else []),
                       "--plane")
        return highspeed.refocus_planes(a.scene, planes, scene_defines, a.periods, a.views, a.start, progress=True)
    return _application(run, a.output,
                        lambda p: f"{p['figure']}, per-plane EXRs and PNGs, {p['metrics']}")


def run_track_focus(a) -> int:
    from ..apps import highspeed
    return _application(
        lambda: highspeed.track_focus_depth(a.scene, a.roi, a.near, a.far, a.object_far, a.planes, a.background,
                                            defines(a), a.periods, a.views, a.start, progress=True),
        a.output,
        lambda p: f"{p['figure']}, per-period PNGs, {p['exr']}, {p['metrics']}")


def run_scanrate_depth(a) -> int:
    from ..apps import scanrate
    from ..calibration import load_calibration, save_calibration
    from ..output_folders import keep_outputs
    calibration = load_calibration(a.calibration) if a.calibration else None
    if a.calibrate:
        try:
            calibration = scanrate.calibrate_depth(a.scene, defines(a), progress=True)
        except ValueError as e:
            raise EventFieldError(str(e)) from None
        os.makedirs(a.output, exist_ok=True)
        d = calibration["depth"]
        print(f"depth calibration (LED at {len(d.depths)} depths): pivot {d.pivot:.4g}, rms {d.rms_inverse:.3f} "
              f"px/rad -> " + save_calibration(os.path.join(a.output, "calibration.json"), **calibration))
        keep_outputs(a.output)            # said written: it stays if the run after it fails
    return _application(
        lambda: scanrate.run(a.scene, defines(a), a.periods, a.views, a.near, a.far, a.planes,
                             min_confidence=a.min_confidence, split_depth=a.split_depth, calibration=calibration,
                             start=a.start, progress=True),
        a.output,
        lambda p: f"{p['figure']}, {len(p['exr'])} depth EXRs and PNGs, {p['metrics']}")


def run_slomorf(a) -> int:
    from ..apps import slomorf
    depths = number_list(a.depths, "--depths", lo=0, lo_open=True)
    return _application(
        lambda: slomorf.slomorf(a.scene or slomorf.DEFAULT_SCENE, defines(a), a.fps, a.factor, a.duration, depths,
                                a.spp, progress=True),
        a.output,
        lambda p: f"{a.output}: {len(p['frames'])} frames, {len(p['refocus'])} refocused images, slomorf.mp4, "
                  "slomorf.gif, slomorf.png, metrics.json")


COMMANDS = {"demo": run_demo, "hdr": run_hdr, "highspeed": run_highspeed, "track-focus": run_track_focus, "slomorf": run_slomorf,
            "scanrate-depth": run_scanrate_depth}
