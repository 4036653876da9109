"""The paper's comparison of the two optical designs, one command each: ``compare-designs`` (kaleidoscope
against galvo at object speeds 1x to 8x, with their event rates) and ``grid-experiment`` (a grid sliding
horizontally). Each runs its Python function (``apps.designs``), writes its outputs and prints its report."""
from __future__ import annotations

from ..validate import MAX_SPP, MAX_VIEWS, number_list
from .apps import _application
from .args import num


def _common(parser, name: str, output: str) -> None:
    parser.add_argument("-o", "--output", default=output, help="output directory (figure, images, metrics.json)")
    parser.add_argument("--galvo", help=f"galvo scene (default: the bundled scenes/{name}/galvo.xml)")
    parser.add_argument("--kaleidoscope", help=f"kaleidoscope scene (default: scenes/{name}/kaleidoscope.xml)")
    parser.add_argument("--film", type=num(30, 4096, integer=True),
                        help="film width and height of both sensors, a multiple of the kaleidoscope's n views a "
                             "side (default: the scenes' own)")
    parser.add_argument("--spp", type=num(1, MAX_SPP, integer=True), default=4, help="samples per pixel (default 4)")


def add_parsers(sub) -> None:
    cd = sub.add_parser("compare-designs", help="kaleidoscope vs galvo on one scene at object speeds 1x-8x: "
                                                "refocus scores on the static and moving objects, event rates")
    _common(cd, "designs", "out/designs")
    cd.add_argument("--speeds", default="1,2,4,8", help="object speed factors (default 1,2,4,8)")
    cd.add_argument("--periods", type=num(1, 100, integer=True), default=2, help="scan periods per speed (default 2)")
    cd.add_argument("--views", type=num(4, MAX_VIEWS, integer=True), default=16,
                    help="galvo views per scan period (default 16)")
    cd.add_argument("--depth", type=num(0, lo_open=True),
                    help="refocus depth (default: the kaleidoscope's focus distance)")
    ge = sub.add_parser("grid-experiment", help="a grid sliding horizontally: the kaleidoscope's events miss the "
                                                "horizontal lines, the galvo's fire on both orientations")
    _common(ge, "moving_grid", "out/grid")
    ge.add_argument("--periods", type=num(1, 100, integer=True), default=1,
                    help="galvo scan periods of events (default 1)")
    ge.add_argument("--texture", help="the grid's texture (default: grid.png beside the galvo scene)")


def _in_output_dir(command: str, a, run, wrote) -> int:
    """``_application`` inside the output folder's manifest (``output_folders.output_dir_run``), the folder checked first."""
    from ..atomic import check_output_dir
    from ..output_folders import output_dir_run
    check_output_dir(a.output)
    with output_dir_run(a.output, command):
        return _application(run, a.output, wrote)


def run_compare_designs(a) -> int:
    from ..apps import designs
    speeds = number_list(a.speeds, "--speeds", lo=0, hi=64, lo_open=True)
    return _in_output_dir("compare-designs", a, lambda: designs.compare(
        a.galvo, a.kaleidoscope, speeds, a.periods, a.views, a.film, a.spp, a.depth, progress=True), wrote=lambda p: (
        f"{p['figure']}, {len(p['png'])} PNGs and {len(p['exr'])} EXRs of the refocused images, {p['metrics']}"))


def run_grid_experiment(a) -> int:
    from ..apps import designs
    return _in_output_dir("grid-experiment", a, lambda: designs.grid_experiment(
        a.galvo, a.kaleidoscope, a.periods, a.film, a.spp, a.texture, progress=True),
        wrote=lambda p: f"{p['figure']}, event-rate EXRs, {p['metrics']}")


COMMANDS = {"compare-designs": run_compare_designs, "grid-experiment": run_grid_experiment}
