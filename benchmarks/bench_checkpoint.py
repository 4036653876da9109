"""Cost of checkpoints (issue 16): the same render to HDF5 without checkpoints, with one every 2 s of wall time
and with one every 0.5 s (segments closed, pixel state saved, segments merged at the end), in one run.

Demo scene, 346x260, 4 spp, 200 steps (about 7 s); a first uncheckpointed render warms every cache. Writes benchmarks/results/checkpoint.json and .md.
Usage: ./run bench checkpoint
"""
import os
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402

DEMO = os.path.join(os.path.dirname(HERE), "scenes", "demo", "demo.xml")


def main(steps=200):
    import mitsuba_eventfield as ef
    ef.set_variant(os.environ.get("EVENTFIELD_VARIANT") or None)
    scene = ef.load_scene(DEMO)
    ef.render_events(scene, steps * 5e-4, steps=steps)               # warm-up: kernels, page cache
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, every in (("none", None), ("every 2 s", 2.0), ("every 0.5 s", 0.5)):
            out = os.path.join(tmp, f"{len(runs)}.h5")
            t0 = time.perf_counter()
            s = ef.render_events(scene, steps * 5e-4, steps=steps, output=out, checkpoint_s=every)
            runs[name] = {"wall_s": time.perf_counter() - t0, "events": s.events}
    base = runs["none"]["wall_s"]
    for r in runs.values():
        r["overhead_pct"] = 100 * (r["wall_s"] / base - 1)
    import mitsuba as mi
    res = {"variant": mi.variant(), "runs": runs,
           "targets": {"checkpoints every 2 s cost <= 5 %": runs["every 2 s"]["overhead_pct"] <= 5.0}}
    md = [f"# Checkpoint cost (demo scene, 346x260, 4 spp, {steps} steps, {mi.variant()}, one run)", "",
          "| checkpoints | wall s | overhead | events |", "|---|---|---|---|"]
    md += [f"| {k} | {v['wall_s']:.2f} | {v['overhead_pct']:+.1f}% | {v['events']} |" for k, v in runs.items()]
    md.append("")
    write_results("checkpoint", res, md)


if __name__ == "__main__":
    main()
