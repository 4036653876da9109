"""``eventfield scan-frequency``: the paper's scan-frequency experiment (Fig. 11) on the spinning fan, or any galvo
scene whose scan frequency is its ``frequency`` XML default: per frequency, light fields from events with and
without the readout cap, refocused and scored against the renderer (``apps.scan_frequency.sweep``)."""
from __future__ import annotations

from ..apps.scan_frequency import FREQUENCIES
from ..validate import MAX_SPP, MAX_VIEWS, number_list
from .args import add_defines, defines, num, pairs

NAME = "scan-frequency"


def add_parsers(sub) -> None:
    sf = sub.add_parser(NAME, help="refocus a moving fan at rising galvo scan frequencies, with and without the "
                                   "sensor's readout cap, scored against the renderer")
    sf.add_argument("scene", nargs="?", help="galvo scene with a `frequency` XML default (default: the bundled fan "
                                            "at 160x120)")
    sf.add_argument("-o", "--output", default="out/scan_frequency",
                    help="output directory (figure, EXRs, metrics.json)")
    add_defines(sf)
    sf.add_argument("--plane", action="append", default=None, metavar="NAME=DEPTH",
                    help="refocus plane, scored on its pixels; the first is shown (repeatable; default for the fan: "
                         "fan=0.6 wall=1.5)")
    sf.add_argument("--frequencies", default=",".join(f"{f:g}" for f in FREQUENCIES),
                    help="scan frequencies in Hz, multiples of 1 / duration (default "
                         + ",".join(f"{f:g}" for f in FREQUENCIES) + ")")
    sf.add_argument("--duration-ms", type=num(0, 1000, lo_open=True), default=8.0,
                    help="events rendered per frequency, ms (default 8)")
    sf.add_argument("--views", type=num(2, MAX_VIEWS, integer=True), default=24, help="views per scan period "
                                                                                      "(default 24)")
    cap = sf.add_mutually_exclusive_group()
    cap.add_argument("--cap-scale", type=num(0, 1e6, lo_open=True), default=5.0,
                     help="readout cap: the IMX636's 1.066 GEPS per 1280x720, scaled to the film, times this "
                          "(default 5)")
    cap.add_argument("--no-cap", action="store_true", help="only the pixel without a readout limit")
    sf.add_argument("--start", choices=("frame", "events"), default="frame",
                    help="what each light field integrates onto: a rendered frame at t = 0 (extra information), or "
                         "the events alone")
    sf.add_argument("--spp", type=num(1, MAX_SPP, integer=True), default=4)


def run_scan_frequency(a) -> int:
    from ..apps import scan_frequency
    from ..atomic import check_output_dir
    from ..output_folders import output_dir_run
    from .apps import _application
    frequencies = number_list(a.frequencies, "--frequencies", lo=0, lo_open=True)
    planes = pairs(a.plane, "--plane") if a.plane is not None else None
    check_output_dir(a.output)

    def run():
        return scan_frequency.sweep(a.scene, frequencies, planes, defines(a), a.duration_ms * 1e-3, a.views,
                                    readout_cap=not a.no_cap, cap_scale=a.cap_scale, start=a.start, spp=a.spp,
                                    progress=True)
    with output_dir_run(a.output, NAME):
        return _application(run, a.output,
                            lambda p: f"{p['figure']}, {len(p['exr'])} EXRs (refocused crops per frequency), "
                                      f"{p['metrics']}")


COMMANDS = {NAME: run_scan_frequency}
