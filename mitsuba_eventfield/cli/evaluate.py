"""Speed against accuracy (``bench``) and the regression images (``regression``)."""
from __future__ import annotations

import os

from ..errors import EventFieldError
from ..scene.bundled import bundled_scene
from ..validate import MAX_DURATION_S, MAX_STEPS
from .args import add_defines, defines, num


def add_parsers(sub) -> None:
    bn = sub.add_parser("bench", help="speed against accuracy of quality settings (chart + table)")
    bn.add_argument("scene", nargs="?", default=bundled_scene("fan/fan.xml"))
    bn.add_argument("-o", "--output", default="out/bench", help="output directory (chart, CSV)")
    bn.add_argument("--duration", type=num(0, MAX_DURATION_S, lo_open=True), default=0.008,
                    help="simulated seconds (default 0.008: two periods)")
    bn.add_argument("--steps", type=num(1, MAX_STEPS, integer=True), default=64, help="steps of the default setting")
    add_defines(bn, default=["width=96", "height=72"])
    bn.add_argument("--refocus-depth", type=num(0, lo_open=True), default=0.6,
                    help="depth of the downstream refocus (fan: 0.6)")
    rg = sub.add_parser("regression", help="compare tiny renders of the bundled scenes with reference images")
    rg.add_argument("--bless", action="store_true", help="re-render the references (after a deliberate change)")
    rg.add_argument("--references", metavar="DIR",
                    help="folder of the reference images (default: tests/regression under the current folder, "
                         "the repository's, when it exists; required otherwise)")


def run_bench(a) -> int:
    from ..evaluation import bench
    from ..evaluation.sweep import SweepTable
    os.makedirs(a.output, exist_ok=True)
    rows = bench.run(a.scene, a.duration, a.steps, defines(a), a.refocus_depth)
    SweepTable(rows).to_csv(os.path.join(a.output, "bench.csv"))
    chart = bench.chart(rows, os.path.join(a.output, "bench.png"), f"{os.path.basename(a.scene)}: speed vs accuracy")
    for r in rows:
        print(f"{r['setting']:28s} time x{r.get('relative_time', 0):6.2f}  product err {r['product_error']:.4f}  "
              f"timing err {r['timing_error']:.4f}  count err {r['count_error']:.4f}"
              f"{'  (Pareto)' if r.get('pareto') else ''}")
    print(f"default on or near the Pareto front: {bench.default_on_front(rows)}; wrote {chart}")
    return 0


REPOSITORY_REFERENCES = os.path.join("tests", "regression")     # from the repository root; the library has none


def run_regression(a) -> int:
    from ..evaluation import regression
    if a.references is None:
        if not os.path.isdir(REPOSITORY_REFERENCES):
            raise EventFieldError(f"--references DIR is required: no {REPOSITORY_REFERENCES} here (run from the "
                                  "repository root, or name the folder of the reference images)")
        a.references = REPOSITORY_REFERENCES
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


COMMANDS = {"bench": run_bench, "regression": run_regression}
