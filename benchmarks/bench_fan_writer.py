"""What paces a render to HDF5 when the GPU makes events faster than one writer thread stores them (issue 15,
"writing keeps up"): the fan at 1280x720, 400 steps (161 M events on an H200), rendered to .h5 with the
writer as it is and with one thing changed at a time, to find which of them the render waits on. On an H200
(2026-11-26) the render waited 0.3 s for the writer's queue while the writer was busy 1.6 of the render's
2.8 s: either the chunks arrive in bursts (a step batch's 16 M events at once) that a deeper queue would
absorb, or the writer thread loses time to the other Python threads (16 deflating, the copier, the render
loop), which a shorter GIL switch interval would show.

Variants, each rendered ``--rounds`` times in alternating order (the best wall time counts):

* as it is (from a GPU a queue depth of 4 since this benchmark's first run: ``sink.WRITER_DEPTH``);
* a queue depth of 2 and of 4 chunks (``sink.WRITER_DEPTH``): more host memory, flat in time;
* the interpreter's GIL switch interval at 1 ms and at 0.2 ms (``sys.setswitchinterval``; Python's default is
  5 ms);
* both;
* the writer's deflating threads at 8 (``EVENTFIELD_WRITER_THREADS``).

An experiment, not a target: writes benchmarks/results/fan_writer.json and .md with the machine's name.
Usage: python benchmarks/bench_fan_writer.py [--width W --height H --steps N --rounds 2] (defaults: 1280x720 and
400 steps on a GPU, 346x260 and 64 on the CPU)
"""
import argparse
import contextlib
import os
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402
from bench_event_engine import device_name  # noqa: E402

FAN = os.path.join(os.path.dirname(HERE), "scenes", "fan", "fan.xml")


@contextlib.contextmanager
def variant(depth=None, switch_s=None, threads=None):
    """The writer's queue depth, the GIL switch interval and the deflating threads set for one render."""
    from mitsuba_eventfield.simulate import sink
    saved_depth = dict(sink.WRITER_DEPTH)
    saved_switch, saved_env = sys.getswitchinterval(), os.environ.get("EVENTFIELD_WRITER_THREADS")
    if depth is not None:
        # the sink passes its depth explicitly since WRITER_DEPTH: a functools.partial around BackgroundWriter
        # (this benchmark's first form) was overridden by it, and its depth rows ran at the default
        sink.WRITER_DEPTH.update(cpu=depth, gpu=depth)
    if switch_s is not None:
        sys.setswitchinterval(switch_s)
    if threads is not None:
        os.environ["EVENTFIELD_WRITER_THREADS"] = str(threads)
    try:
        yield
    finally:
        sink.WRITER_DEPTH.update(saved_depth)
        sys.setswitchinterval(saved_switch)
        if saved_env is None:
            os.environ.pop("EVENTFIELD_WRITER_THREADS", None)
        else:
            os.environ["EVENTFIELD_WRITER_THREADS"] = saved_env


VARIANTS = {"as it is": {}, "queue depth 2": {"depth": 2}, "queue depth 4": {"depth": 4}, "GIL switch 1 ms": {"switch_s": 1e-3},
            "GIL switch 0.2 ms": {"switch_s": 2e-4}, "depth 4, switch 1 ms": {"depth": 4, "switch_s": 1e-3},
            "8 deflating threads": {"threads": 8}}


def render(scene, steps, path):
    import mitsuba_eventfield as ef
    t0 = time.perf_counter()
    s = ef.render_events(scene, 0.02, steps=steps, output=path)
    wall = time.perf_counter() - t0
    return {"wall_s": wall, "render_s": s.render_s, "events_s": s.events_s, "motion_s": s.motion_s,
            "write_s": s.write_s, "writer_busy_s": s.writer_busy_s, "writer_wait_s": s.writer_wait_s,
            "writer_tail_s": s.writer_tail_s, "writer_copy_s": s.writer_copy_s, "events": s.events,
            "beyond_render": (wall - s.render_s) / s.render_s}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--width", type=int, default=None, help="default: 1280 on a GPU, 346 on the CPU")
    parser.add_argument("--height", type=int, default=None, help="default: 720 on a GPU, 260 on the CPU")
    parser.add_argument("--steps", type=int, default=None, help="default: 400 on a GPU, 64 on the CPU")
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args(argv)
    import mitsuba as mi

    import mitsuba_eventfield as ef
    ef.set_variant(os.environ.get("EVENTFIELD_VARIANT") or None)
    # the GPU's film; on the CPU (./run bench runs every benchmark) bench_writer's fan, minutes instead of an hour
    gpu = mi.variant().startswith("cuda")
    args.width = args.width or (1280 if gpu else 346)
    args.height = args.height or (720 if gpu else 260)
    args.steps = args.steps or (400 if gpu else 64)
    scene = ef.load_scene(FAN, width=args.width, height=args.height)
    best = {}
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "fan.h5")
        ef.render_events(scene, 0.02 * 20 / args.steps, steps=20, output=path)       # compile and record
        for r in range(args.rounds):
            names = list(VARIANTS) if r % 2 == 0 else list(reversed(VARIANTS))
            for name in names:
                with variant(**VARIANTS[name]):
                    row = render(scene, args.steps, path)
                os.remove(path)
                if name not in best or row["wall_s"] < best[name]["wall_s"]:
                    best[name] = row
    res = {"device": device_name(), "film": [args.width, args.height], "steps": args.steps, "rounds": args.rounds,
           "variants": best}
    md = [f"# The fan to HDF5: what paces the writer ({res['device']})", "",
          f"The fan at {args.width}x{args.height}, {args.steps} steps over 20 ms, to .h5; each variant rendered "
          f"{args.rounds} times in alternating order, the best wall time's row (seconds). Beyond the render: "
          "(wall - render) / render.", "",
          "| variant | events | wall | render | events / motion / write | writer busy | copier busy | render "
          "waited | tail | beyond the render |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in best.items():
        md.append(f"| {name} | {r['events']} | {r['wall_s']:.2f} | {r['render_s']:.2f} | {r['events_s']:.2f} / "
                  f"{r['motion_s']:.2f} / {r['write_s']:.2f} | {r['writer_busy_s']:.2f} | {r['writer_copy_s']:.2f} | "
                  f"{r['writer_wait_s']:.2f} | {r['writer_tail_s']:.2f} | {100 * r['beyond_render']:.0f} % |")
    md.append("")
    write_results("fan_writer", res, md)


if __name__ == "__main__":
    main()
