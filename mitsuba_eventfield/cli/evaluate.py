"""Speed against accuracy (``bench``) and the regression images (``regression``)."""
from __future__ import annotations

import os

from ..errors import EventFieldError
from ..validate import MAX_DURATION_S, MAX_STEPS
from .args import add_defines, defines, num


def add_parsers(sub) -> None:
    from ..evaluation.bench import SUITE
    suite = ",".join(s.name for s in SUITE)
    bn = sub.add_parser("bench", help="speed against accuracy of a render's levers (spp, sampler, steps, seeds, "
                                      f"adaptive) on the suite's {len(SUITE)} scenes, or one: chart + tables")
    bn.add_argument("scene", nargs="?", help=f"one scene file instead of the suite ({suite})")
    bn.add_argument("-o", "--output", default="out/bench",
                    help="output directory: bench_suite.png/.md/.csv/.json (one scene: bench_<name>.*)")
    bn.add_argument("--scenes", help=f"suite scenes to run, comma-separated (default: all: {suite})")
    bn.add_argument("--settings", help="settings to run, comma-separated keys (default: all; see the table in "
                                       "mitsuba_eventfield.evaluation.bench.SETTINGS)")
    bn.add_argument("--seeds", type=num(1, 20, integer=True),
                    help="runs per setting, each with its own seed: the error bars (default 5)")
    bn.add_argument("--duration", type=num(0, MAX_DURATION_S, lo_open=True),
                    help="one scene: simulated seconds (default: `duration` of its motion file)")
    bn.add_argument("--steps", type=num(1, MAX_STEPS, integer=True), default=100,
                    help="one scene: the 1x of the uniform-step ladder, 1/4 to 4x (default 100; the default "
                         "setting takes the render's own steps)")
    add_defines(bn, help_text="one scene: value of an XML <default name=...> parameter, e.g. -D width=64 "
                              "(repeatable)")
    bn.add_argument("--refocus-depth", type=num(0, lo_open=True),
                    help="one galvo scene: also score the refocus of its first scan period at this depth")
    rg = sub.add_parser("regression", help="compare tiny renders of the bundled scenes with reference images")
    rg.add_argument("--bless", action="store_true", help="re-render the references (after a deliberate change)")
    rg.add_argument("--references", metavar="DIR",
                    help="folder of the reference images (default: tests/regression under the current folder, "
                         "the repository's, when it exists; required otherwise)")


def _bench_scenes(a, bench) -> list:
    """The scenes of a bench run, every argument checked before anything renders."""
    if a.scene is None:
        if a.define or a.duration is not None or a.refocus_depth is not None:
            raise EventFieldError("-D, --duration and --refocus-depth apply to one scene (eventfield bench SCENE); "
                                  "the suite's scenes have their own")
        return bench.pick_scenes(a.scenes.split(",") if a.scenes is not None else None)
    if a.scenes is not None:
        raise EventFieldError("give one scene file or --scenes, not both")
    from ..scene import load_scene
    probe = load_scene(a.scene, **defines(a))          # a bad scene file fails here, in one line
    sensor = probe.sensor
    design = sensor.optics_metadata().get("design") if hasattr(sensor, "optics_metadata") else None
    if a.refocus_depth is not None and design != "galvo":      # it was ignored: the refocus is a galvo's
        raise EventFieldError(f"{a.scene}: --refocus-depth scores a galvo's refocus; this scene's sensor is "
                              f"{design or 'a conventional camera'}")
    duration = a.duration or (probe.motion.duration if probe.motion and probe.motion.duration else None)
    if duration is None:
        raise EventFieldError(f"{a.scene}: no duration (pass --duration, or set `duration` in its motion file)")
    return [bench.single(a.scene, duration, a.steps, defines(a), a.refocus_depth)]


def run_bench(a) -> int:
    from ..backend import ensure_variant
    from ..evaluation import bench, bench_chart
    ensure_variant()
    specs = _bench_scenes(a, bench)
    settings = bench.pick_settings(a.settings.split(",") if a.settings is not None else None)   # "": none named
    seeds = bench.SEEDS if a.seeds is None else tuple(range(1, a.seeds + 1))
    rows = bench.run(specs, settings, seeds)
    import mitsuba as mi
    stem = "bench_suite" if a.scene is None else f"bench_{specs[0].name}"
    title = ("speed against accuracy: " + ", ".join(s.name for s in specs) + f" ({len(seeds)} seeds per setting, "
             f"{mi.variant()}, {bench.THREADS} render thread on a {os.cpu_count()}-CPU machine)")
    paths = bench_chart.write(rows, a.output, stem, {"variant": mi.variant(), "seeds": len(seeds),
                                                     "cpus": os.cpu_count(), "threads": bench.THREADS}, title)
    summary = bench_chart.summarize(rows)
    print(bench_chart.BEYOND_NOISE)
    for line in bench_chart.position_lines(summary, bench_chart.default_position(summary)):
        print(line)
    print("wrote " + ", ".join(paths.values()))
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
