"""Speed against accuracy (issue 18): ``eventfield bench`` over its six-scene suite (the analytic scene, the demo,
the fan behind the galvo, the kaleidoscope's moving grid, the off-axis cards for depth, the demo through a noisy
davis346 pixel), every setting with 5 seeds, into benchmarks/results/: bench_suite.png (the chart),
bench_suite.md (the table and where the default sits), bench_suite.csv (one row per scene and setting),
bench_suite_runs.csv (one row per run) and bench_suite.json. About 15 minutes on 2 idle cores, up to 30 when
other work shares them.
Usage: ./run bench speed_accuracy  (extra arguments go to eventfield bench, e.g. --scenes analytic)
"""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import RESULTS  # noqa: E402


def main() -> int:
    import mitsuba_eventfield as ef
    from mitsuba_eventfield.cli.main import main as eventfield
    ef.set_variant(os.environ.get("EVENTFIELD_VARIANT") or None)
    return eventfield(["bench", "-o", RESULTS] + sys.argv[1:])


if __name__ == "__main__":
    sys.exit(main())
