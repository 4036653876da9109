"""What the event path adds to a render, kernel by kernel (issue 15's render targets): the same instants rendered
alone (``bench_event_engine.render_only``: ``set_time`` and the loop's frozen render, no events) against
``render_events`` with the events left on the device, each with Dr.Jit's kernel history on. The difference of
the kernels' summed execution times is the device work the events add; the rest of the wall time's difference
is host work and waiting (tracing, launches, reads that drain the queue). The history syncs after each kernel,
so both wall times here exceed the benchmarks'; their difference still splits into those two parts (the
renders alone hold three warm-up recordings of the frozen render there, the render with events one frame
rendered with a second seed: about two renders in 401 fewer for the events than they cost). Then the
same two without the history, alternating (what a render costs), and the host profile of the render with
events (cProfile by own time). A profile,
not a target: it writes only benchmarks/results/render_kernels.md and .json.

Usage: python benchmarks/profile_render_kernels.py [--quick]   (the fan at 1280x720, 400 steps over 20 ms; quick:
96x72, 80 steps)
"""
import collections
import cProfile
import math
import os
import pstats
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import profile_rows, write_results  # noqa: E402
from bench_event_engine import device_name, render_only  # noqa: E402
from profile_converter import _size_class  # noqa: E402

FAN = os.path.join(os.path.dirname(HERE), "scenes", "fan", "fan.xml")


def _history(run):
    """(wall s, kernels grouped as {label: [launches, ms]}) of one ``run()`` with the kernel history on."""
    import drjit as dr
    dr.sync_thread()
    dr.kernel_history()                                    # empties it
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        t0 = time.perf_counter()
        run()
        dr.sync_thread()
        wall = time.perf_counter() - t0
        history = dr.kernel_history()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    groups = collections.defaultdict(lambda: [0, 0.0])
    for k in history:
        label = (f"{str(k.get('type', '?')).split('.')[-1]}, {k.get('operation_count', '?')} ops, "
                 f"size {_size_class(int(k.get('size', 0)))}")
        groups[label][0] += 1
        groups[label][1] += float(k.get("execution_time", 0.0))
    return wall, dict(groups)


def profile(width, height, steps, duration=0.02):
    import drjit as dr

    import mitsuba_eventfield as ef
    timed = ef.load_scene(FAN, width=width, height=height)
    ef.render_events(timed, duration / steps * 3, steps=3, reuse=False, on_device=True)      # compile
    render_only(timed, duration, steps, 1)                                                   # and record

    def with_events():
        ev = ef.render_events(timed, duration, steps=steps, reuse=False, on_device=True)
        dr.eval(ev.xy, ev.t, ev.p)
        with_events.events = len(ev)
    with_events()
    runs = {"renders alone": _history(lambda: render_only(timed, duration, steps, 1)),
            "events left on the device": _history(with_events)}
    # the same two without the history (no sync after each kernel: what a user's render costs), alternating
    walls = {"renders alone": math.inf, "events left on the device": math.inf}
    for _ in range(3):
        # its own timed loop: the frozen render's warm-up recordings before it are left out
        walls["renders alone"] = min(walls["renders alone"], render_only(timed, duration, steps, 1))
        t0 = time.perf_counter()
        with_events()
        dr.sync_thread()
        walls["events left on the device"] = min(walls["events left on the device"], time.perf_counter() - t0)
    prof = cProfile.Profile()
    prof.enable()
    with_events()
    dr.sync_thread()
    prof.disable()
    out_host = profile_rows(pstats.Stats(prof), "tottime", 25)
    out = {"width": width, "height": height, "steps": steps, "events": with_events.events, "runs": {},
           "host": out_host}
    for name, (wall, groups) in runs.items():
        out["runs"][name] = {"wall_s": wall, "kernels_s": sum(v[1] for v in groups.values()) / 1e3,
                             "launches": sum(v[0] for v in groups.values()), "groups": groups,
                             "wall_no_history_s": walls[name]}
    alone, events = runs["renders alone"][1], runs["events left on the device"][1]
    none = [0, 0.0]
    added = {k: [events.get(k, none)[0] - alone.get(k, none)[0], events.get(k, none)[1] - alone.get(k, none)[1]]
             for k in events.keys() | alone.keys()}
    out["added"] = sorted(({"kernel": k, "launches": n, "ms": ms} for k, (n, ms) in added.items() if n or ms),
                          key=lambda r: -r["ms"])
    return out


def main(quick=False):
    import mitsuba as mi

    import mitsuba_eventfield as ef
    ef.set_variant(os.environ.get("EVENTFIELD_VARIANT") or None)
    r = profile(96, 72, 80) if quick else profile(1280, 720, 400)
    a, e = r["runs"]["renders alone"], r["runs"]["events left on the device"]
    kernels, wall = e["kernels_s"] - a["kernels_s"], e["wall_s"] - a["wall_s"]
    md = [f"# What the event path adds to a render, kernel by kernel ({device_name()}, {mi.variant()})", "",
          f"The fan at {r['width']}x{r['height']}, {r['steps']} steps over 20 ms, {r['events']} events left on "
          "the device, against the same instants rendered alone; one run each with Dr.Jit's kernel history on "
          "(a sync after every kernel: both walls are above the benchmarks').", "",
          "| run | wall s | kernels s | launches | wall without the history, best of 3 alternating, s |",
          "|---|---|---|---|---|"]
    md += [f"| {name} | {v['wall_s']:.3f} | {v['kernels_s']:.3f} | {v['launches']} | {v['wall_no_history_s']:.3f} |"
           for name, v in r["runs"].items()]
    plain = e["wall_no_history_s"] - a["wall_no_history_s"]
    md += ["", f"With the history on, the events add {wall:.3f} s of wall time: {kernels:.3f} s of kernels, "
           f"{wall - kernels:.3f} s on the host (tracing, launches, reads, waiting). Without it they add "
           f"{plain:.3f} s ({100 * plain / a['wall_no_history_s']:.1f} % of the renders alone).", "",
           "The kernels they add or change (launches and ms against the renders alone; negative: fewer there):", "",
           "| kernel (kind, operations, size) | launches | ms |", "|---|---|---|"]
    md += [f"| {g['kernel']} | {g['launches']} | {g['ms']:.2f} |" for g in r["added"][:20]]
    md += ["", "The host side of the render with events (cProfile, by own time; a function that waits on the "
           "device holds the wait):", "", "| function | calls | own ms | cumulative ms |", "|---|---|---|---|"]
    md += [f"| `{h['function']}` | {h['calls']} | {h['own_ms']:.2f} | {h['cumulative_ms']:.2f} |" for h in r["host"]]
    write_results("render_kernels", {"device": device_name(), "variant": mi.variant(), **r}, md)
    print("\n".join(md))


if __name__ == "__main__":
    main(quick="--quick" in sys.argv[1:])
