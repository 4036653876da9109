"""Where a short render's wall time goes beyond its renders (issue 15, the GPU demo target): on an H200 the
demo's 100 steps took 0.22 s by wall against 0.13 s for the same instants rendered alone, while the summary's
events, motion and write came to about 0.05 s. This profiles the render on the host (cProfile: the render
thread, and from Python 3.12 on, where cProfile runs on sys.monitoring, every other thread too: the writer's,
its pool's; a function that waits on the device holds the wait) and lists the functions by cumulative and by own
time, with the run's summary, so that fixed costs (set-up, the accuracy-limit frame, the drain) and per-step
ones read off one table. A profile, not a target: it writes only benchmarks/results/render_profile.md and .json.
With ``--output FILE`` the events go to that file (written by the background writer: the render thread's
rows show what handing chunks over costs it: the joins, the device-to-host copies, the waits on a full queue); ``-D NAME=VALUE`` sets the scene's XML defaults (a film size). A scene other than
the demo writes render_profile_<its name>.md; ``--preset NAME`` renders with that pixel model (a preset of
``pixel_model.PRESETS``, e.g. davis346) and adds _<NAME> to the file's name.
Usage: python benchmarks/profile_render.py [SCENE] [--steps N] [--duration S] [--output F] [-D NAME=VALUE]...
(default: the demo, 100 steps, 0.1 s, in memory)
"""
import argparse
import cProfile
import os
import platform
import pstats
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import profile_rows, write_results  # noqa: E402
from bench_event_engine import device_name  # noqa: E402

ROOT = os.path.dirname(HERE)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", nargs="?", default=os.path.join(ROOT, "scenes", "demo", "demo.xml"))
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--duration", type=float, default=0.1)
    parser.add_argument("--output", default=None, help="an event file (.h5, ...) instead of memory")
    parser.add_argument("-D", dest="defines", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument("--preset", default=None, help="a pixel-model preset (default: the ideal pixel)")
    args = parser.parse_args(argv)
    xml = dict(d.split("=", 1) for d in args.defines)
    default_scene = os.path.abspath(args.scene) == os.path.join(ROOT, "scenes", "demo", "demo.xml")
    name = "render_profile" if default_scene else \
        "render_profile_" + os.path.splitext(os.path.basename(args.scene))[0]
    name += f"_{args.preset}" if args.preset else ""
    import mitsuba as mi

    import mitsuba_eventfield as ef
    ef.set_variant(os.environ.get("EVENTFIELD_VARIANT") or None)
    scene = ef.load_scene(args.scene, **xml)

    def render():
        result = ef.render_events(scene, args.duration, steps=args.steps, output=args.output,
                                  pixel={"preset": args.preset} if args.preset else None)
        if args.output is None:
            return len(result), result.meta["render"]
        return result.events, result.as_dict()
    render()                                                # compile and record
    t0 = time.perf_counter()
    events, summary = render()
    wall = time.perf_counter() - t0
    profiler = cProfile.Profile()
    profiler.enable()
    render()
    profiler.disable()
    if args.output:
        os.remove(args.output)
    stats = pstats.Stats(profiler)
    res = {"device": device_name(), "variant": mi.variant(), "scene": os.path.relpath(args.scene, ROOT),
           "steps": args.steps, "duration_s": args.duration, "wall_s": wall, "events": events,
           "output": os.path.splitext(args.output)[1] if args.output else "memory", "defines": xml,
           "pixel": args.preset or "ideal", "python": platform.python_version(),
           # cProfile moved onto sys.monitoring in Python 3.12, whose events come from every thread
           "threads_profiled": "every thread (the writer's and its pool's too)" if sys.version_info >= (3, 12)
           else "the render thread only",
           "summary": {k: summary.get(k) for k in ("render_s", "events_s", "motion_s", "write_s", "wall_s")},
           "by_cumulative": profile_rows(stats, "cumulative", 40), "by_own": profile_rows(stats, "tottime", 25)}
    s = res["summary"]
    md = [f"# A render's host time, function by function ({res['device']}, {res['variant']})", "",
          f"{res['scene']} ({' '.join(args.defines) or 'as it is'}; pixel: {res['pixel']}), {args.steps} steps over {args.duration} s, {events} "
          f"events to {res['output']}: wall {wall:.3f} s "
          f"unprofiled; the summary's render {s['render_s']:.3f}, events {s['events_s']:.3f}, motion "
          f"{s['motion_s']:.3f}, write {s['write_s']:.3f} s. The profiled run (cProfile adds its own cost; "
          f"Python {res['python']}: {res['threads_profiled']}):", ""]
    for title, rows in (("By cumulative time", res["by_cumulative"]), ("By own time", res["by_own"])):
        md += [f"## {title}", "", "| function | calls | own ms | cumulative ms |", "|---|---|---|---|"]
        md += [f"| `{r['function']}` | {r['calls']} | {r['own_ms']:.2f} | {r['cumulative_ms']:.2f} |" for r in rows]
        md.append("")
    write_results(name, res, md)


if __name__ == "__main__":
    main()
