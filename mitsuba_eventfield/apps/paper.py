"""The paper side by side: every figure and table of "Event fields" (CVPR 2025), what it claims, what this
project measures on its bundled scenes, the command that regenerates it, and where the two differ and why.

``generate(out_dir, doc_path)`` (``eventfield paper``) runs each result's Python call (the same one its command
runs), writes its outputs under ``out_dir/<key>/``, copies its figure next to the document and writes the
document from the results' ``paper_rows``: no number in it is typed by hand. ``quick=True`` runs each at a
reduced size (the test suite's), and the document says so. Figures and tables the project does not reproduce
as a number (the teaser, the hardware photographs) are listed with what stands for them.
"""
from __future__ import annotations

import os
import shutil
import time
from dataclasses import dataclass

from ..atomic import atomic_output
from ..errors import ConfigError, EventFieldError


@dataclass(frozen=True)
class Entry:
    key: str
    run: object           # quick (bool) -> AppResult
    rows: object          # AppResult -> list of row dicts


def _scene(*parts):
    from ..scene import bundled_scene
    return bundled_scene("/".join(parts))


def _demo(quick):
    from . import demo
    return demo.run(64, 48, 12) if quick else demo.run()


def _fan(quick):
    from . import highspeed
    size = ["width=96", "height=72"] if quick else []
    defines = dict(v.split("=") for v in highspeed.FAN_DEFAULTS["define"] + size)
    return highspeed.refocus_planes(_scene("fan", "fan.xml"), {"fan": 0.6, "wall": 1.5}, defines,
                                    periods=1 if quick else None, views=16 if quick else 40, conventional_fps=None)


def _dart(quick):
    from . import highspeed
    return highspeed.track_focus_depth(_scene("dart", "galvo.xml"), (0.58, 0.44, 0.78, 0.56), 0.6, 1.5, 1.6,
                                       background_depth=1.8, defines={"width": 96, "height": 72} if quick else None,
                                       periods=2 if quick else None, views=16 if quick else 40)


def _runner(quick):
    from . import scanrate
    return scanrate.run(_scene("runner", "runner.xml"), {"width": 96, "height": 72} if quick else None,
                        periods=1 if quick else None, views=16 if quick else 40)


def _hdr(quick):
    from . import hdr
    return hdr.compare(_scene("hdr_leds", "hdr_leds.xml"), {"width": 96, "height": 72} if quick else None,
                       depth=1.45, steps_per_period=32 if quick else 64)


def _slomorf(quick):
    from . import slomorf
    # the paper's Fig. 8 is 6x (720 fps from 120); the app's default 8x is its Fig. 9's (the dart)
    return slomorf.slomorf(slomorf.DEFAULT_SCENE, {"views_px": 96} if quick else None,
                           duration=2 / 120 if quick else None, factor=6)


def _hdr_lightfield(quick):
    from . import hdr
    return hdr.lightfield(defines={"width": 96, "height": 72} if quick else None, views=24 if quick else 32)


def _dart_kaleidoscope(quick):
    from . import slomorf
    return slomorf.slomorf(_scene("dart", "kaleidoscope.xml"), {"width": 216, "height": 144} if quick else None,
                           factor=8, depths=(0.95, 1.8))


def _designs(quick):
    from . import designs
    return designs.compare(periods=2, views=12, film=96) if quick else designs.compare()


def _grid(quick):
    from . import designs
    return designs.grid_experiment(film=96 if quick else None)


def _scan_frequency(quick):
    from . import scan_frequency
    if quick:
        return scan_frequency.sweep(frequencies=(250, 500), defines={"width": 96, "height": 72}, duration=0.008,
                                    views=16, cap_scale=8)
    return scan_frequency.sweep()


def _from_metrics(result):
    """Rows the result's own ``write`` put in its metrics.json (those that need its command line)."""
    return None


def _rows(module_name):
    def rows(result):
        import importlib
        return importlib.import_module(f"{__package__}.{module_name}").paper_rows(result)
    return rows


ENTRIES = [Entry("demo", _demo, _rows("demo")), Entry("highspeed", _fan, _rows("highspeed")),
           Entry("track", _dart, _rows("highspeed")), Entry("scanrate", _runner, _rows("scanrate")),
           Entry("hdr", _hdr, _rows("hdr")), Entry("hdr_lightfield", _hdr_lightfield, _rows("hdr_lightfield")),
           Entry("slomorf", _slomorf, _rows("slomorf_outputs")),
           Entry("slomorf_dart", _dart_kaleidoscope, _rows("slomorf_outputs")),
           Entry("designs", _designs, _from_metrics), Entry("grid", _grid, _from_metrics),
           Entry("scan_frequency", _scan_frequency, _rows("scan_frequency"))]

# the paper's figures and tables that are not a measurement, with what stands for each in this project
NOT_MEASURED = [
    ("Fig. 1", "Teaser: event fields capture light fields at high speed, resolution and dynamic range.",
     "the rows below, one per result."),
    ("Fig. 2", "A Blender plugin renders event fields physically.",
     "Mitsuba 3 sensor plugins (kaleidoscope, galvo) and a Dr.Jit event integrator, checked against an analytic "
     "scene's exact events (mitsuba_eventfield/evaluation/analytic.py; ./run bench accuracy charts it)."),
    ("Fig. 3", "Kaleidoscope design: main lens, four-mirror tube, beam splitter to an RGB camera.",
     "the kaleidoscope sensor plugin (tile layout tested against independent ray traces); the beam splitter is "
     "modelled as ideal in SloMoRF."),
    ("Fig. 4", "Galvanometer design: a two-axis mirror in front of the event camera.",
     "the galvo sensor plugin (exact two-mirror geometry, mitsuba_eventfield/optics/galvo.py) and the device "
     "layer for a real controller (docs/device.md)."),
    ("Fig. 13 (suppl.)", "Template matching in the reconstructed views traces the scan's circle.",
     "galvo calibration from the data (docs/calibration.md, eventfield calibrate galvo)."),
    ("Fig. 15 (suppl.)", "Depth calibrated with an LED at 7 depths, depth linear in disparity.",
     "eventfield scanrate-depth --calibrate: the LED's track from events alone at 6 depths, fitted to the exact "
     "model S = p + q/z (docs/calibration.md)."),
]


def _copy_figure(paths: dict, key: str, doc_dir: str):
    fig = paths.get("figure")
    if not fig or not os.path.exists(fig):
        return None
    os.makedirs(os.path.join(doc_dir, "paper"), exist_ok=True)
    target = os.path.join(doc_dir, "paper", f"{key}.png")
    with atomic_output(target, "paper figure") as tmp:    # whole or not at all, and never over a user's file
        shutil.copyfile(fig, tmp)
    return os.path.relpath(target, doc_dir)


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def document(rows: list, quick: bool, seconds: float) -> str:
    """Markdown of ``rows`` (dicts with figure, claim, measured, command, differs, and optionally image)."""
    size = "reduced sizes (`--quick`)" if quick else "the documented default sizes"
    lines = ["# The paper side by side", "",
             "Generated by `eventfield paper` (mitsuba_eventfield/apps/paper.py) at " + size + f" in {seconds:.0f} s;"
             " every number below comes from the run of the command in its row. Scores are against the "
             "renderer's ground truth (converged views, Mitsuba's depth).", "",
             "| paper | what the paper shows | what this project measures | command | differs because |",
             "|---|---|---|---|---|"]
    for r in rows:
        measured = _cell(r["measured"]) + (f" ![{r['figure']}]({r['image']})" if r.get("image") else "")
        cmd = f"`{r['command']}`" if r.get("command") else ""
        lines.append(f"| {_cell(r['figure'])} | {_cell(r['claim'])} | {measured} | {cmd} | {_cell(r['differs'])} |")
    return "\n".join(lines) + "\n"


def generate(out_dir: str, doc_path: str, only=None, quick: bool = False, progress: bool = False) -> list:
    """Run the results (all, or the keys in ``only``), write their outputs and the document; return the rows."""
    from ..atomic import atomic_output
    from ..output_folders import keep_outputs
    keys = [e.key for e in ENTRIES]
    unknown = sorted(set(only or []) - set(keys))
    if unknown:
        raise ConfigError(f"paper: unknown result(s) {', '.join(unknown)}; allowed: {', '.join(keys)}")
    doc_dir = os.path.dirname(os.path.abspath(doc_path))
    t0 = time.perf_counter()
    rows, failed = [], []
    for entry in ENTRIES:
        if only and entry.key not in only:
            continue
        if progress:
            print(f"[paper] {entry.key} ...", flush=True)
        try:
            result = entry.run(quick)
        except (EventFieldError, ValueError) as e:     # one result's failure does not cost the others' runs
            failed.append(f"{entry.key}: {' '.join(str(e).split())}")
            continue
        paths = result.write(os.path.join(out_dir, entry.key))
        keep_outputs(out_dir)                      # stays if a later result fails (as the refusal below says)
        image = _copy_figure(paths, entry.key, doc_dir)
        own = entry.rows(result)
        if own is None:
            import json
            with open(paths["metrics"]) as f:
                own = json.load(f)["paper"]
        rows += [dict(r, image=image) for r in own]
    rows += [{"figure": f, "claim": c, "measured": "Not a measurement; " + m, "command": "", "differs": ""}
             for f, c, m in NOT_MEASURED]
    rows.sort(key=_paper_order)
    if failed:                                      # no document with rows missing: say what failed, keep the rest
        raise EventFieldError(f"paper: {len(failed)} result(s) failed, {doc_path} not written; their outputs are in "
                              f"{out_dir}/: " + "; ".join(failed))
    with atomic_output(doc_path, "paper document") as tmp, open(tmp, "w") as f:
        f.write(document(rows, quick, time.perf_counter() - t0))
    return rows


def _paper_order(row) -> tuple:
    """Table 1 first, then figures by number."""
    label = row["figure"]
    if label.startswith("Table"):
        return (0, label)
    digits = "".join(ch if ch.isdigit() else " " for ch in label).split()
    return (1, int(digits[0]) if digits else 99, label)
