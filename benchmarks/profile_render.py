"""Where a short render's wall time goes beyond its renders (issue 15, the GPU demo target): on an H200 the
demo's 100 steps took 0.22 s by wall against 0.13 s for the same instants rendered alone, while the summary's
events, motion and write came to about 0.05 s. This profiles the render on the host (cProfile, the render
thread; a function that waits on the device holds the wait) and lists the functions by cumulative and by own
time, with the run's summary, so that fixed costs (set-up, the accuracy-limit frame, the drain) and per-step
ones read off one table. A profile, not a target: it writes only benchmarks/results/render_profile.md and .json.
Usage: python benchmarks/profile_render.py [SCENE] [--steps N] [--duration S]   (default: the demo, 100, 0.1)
"""
import argparse
import cProfile
import os
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
    args = parser.parse_args(argv)
    import mitsuba as mi

    import mitsuba_eventfield as ef
    ef.set_variant(os.environ.get("EVENTFIELD_VARIANT") or None)
    scene = ef.load_scene(args.scene)
    ef.render_events(scene, args.duration, steps=args.steps)                  # compile and record
    t0 = time.perf_counter()
    stream = ef.render_events(scene, args.duration, steps=args.steps)
    wall = time.perf_counter() - t0
    profiler = cProfile.Profile()
    profiler.enable()
    ef.render_events(scene, args.duration, steps=args.steps)
    profiler.disable()
    stats = pstats.Stats(profiler)
    summary = stream.meta["render"]
    res = {"device": device_name(), "variant": mi.variant(), "scene": os.path.relpath(args.scene, ROOT),
           "steps": args.steps, "duration_s": args.duration, "wall_s": wall, "events": len(stream),
           "summary": {k: summary.get(k) for k in ("render_s", "events_s", "motion_s", "write_s", "wall_s")},
           "by_cumulative": profile_rows(stats, "cumulative", 40), "by_own": profile_rows(stats, "tottime", 25)}
    s = res["summary"]
    md = [f"# A render's host time, function by function ({res['device']}, {res['variant']})", "",
          f"{res['scene']}, {args.steps} steps over {args.duration} s, {len(stream)} events: wall {wall:.3f} s "
          f"unprofiled; the summary's render {s['render_s']:.3f}, events {s['events_s']:.3f}, motion "
          f"{s['motion_s']:.3f}, write {s['write_s']:.3f} s. The profiled run (cProfile adds its own cost):", ""]
    for title, rows in (("By cumulative time", res["by_cumulative"]), ("By own time", res["by_own"])):
        md += [f"## {title}", "", "| function | calls | own ms | cumulative ms |", "|---|---|---|---|"]
        md += [f"| `{r['function']}` | {r['calls']} | {r['own_ms']:.2f} | {r['cumulative_ms']:.2f} |" for r in rows]
        md.append("")
    write_results("render_profile", res, md)


if __name__ == "__main__":
    main()
