"""What limits timing accuracy (issue 18): the analytic scene's exact events (``evaluation/analytic.py``) against
renders with 5 to 320 uniform steps, for a noise-free sampler (the midpoint rule: 16 non-jittered stratified
samples) and for Mitsuba's default independent sampler at 4 and 16 spp (fixed seed), in one run.

Where the timing error falls with the steps (quadratically: linear interpolation of a smooth log curve), the
steps set the accuracy; where it stays flat, Monte-Carlo noise does, and only more samples help (1/sqrt(spp)).
The plane moves half a pixel per step at 100 steps; C = 0.1; 64x2 film. Wall time is the render's.
Writes benchmarks/results/accuracy.json, .md and .png.  Usage: ./run bench accuracy
"""
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import RESULTS, write_results  # noqa: E402

C, DURATION = 0.1, 0.01
STEP_COUNTS = (5, 20, 80, 320)
SAMPLERS = {"midpoint 16 spp (noise-free)": {"type": "stratified", "sample_count": 16, "jitter": False},
            "independent 4 spp": {"type": "independent", "sample_count": 4},
            "independent 16 spp": {"type": "independent", "sample_count": 16}}


def run(sampler, steps):
    import mitsuba as mi

    import mitsuba_eventfield as ef
    from mitsuba_eventfield.evaluation import analytic as an
    speed = 0.5 * an.PIX / (DURATION / 100)
    timed = ef.load_scene(mi.load_dict(an.scene_dict(mi, speed, sampler)),
                          motion={"objects": {"plane": {"velocity": [speed, 0.0, 0.0]}}})
    t0 = time.perf_counter()
    ev = ef.render_events(timed, DURATION, steps=steps, threshold=C, spp=sampler["sample_count"])
    wall = time.perf_counter() - t0
    s = an.score(ev, an.truth_events(speed, DURATION, C))
    return {"steps": steps, "wall_s": wall, "events": s["events"], "exact_events": s["exact_events"],
            "count_error": s["count_error"], "timing_median_us": s["timing_median_us"],
            "timing_p99_us": s["timing_p99_us"]}


def limit(rows):
    """What sets the accuracy at the finest steps: 'steps' when 4x the steps still cut the median error by at
    least 2x (interpolation error falls as the square of the step), else 'Monte-Carlo noise'."""
    return "steps" if rows[-2]["timing_median_us"] >= 2 * rows[-1]["timing_median_us"] else "Monte-Carlo noise"


def chart(results, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mitsuba_eventfield.images import save_figure
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for name, rows in results.items():
        steps = [r["steps"] for r in rows]
        ax.loglog(steps, [r["timing_median_us"] for r in rows], "o-", label=f"{name}: median")
        ax.loglog(steps, [r["timing_p99_us"] for r in rows], "x--", alpha=0.6, label=f"{name}: p99")
    ax.set_xlabel("uniform steps over 10 ms")
    ax.set_ylabel("timestamp error against the exact events (us)")
    ax.set_title("What limits timing accuracy (analytic scene, C = 0.1)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    save_figure(fig, path, "accuracy chart")


def main():
    import mitsuba_eventfield as ef
    ef.set_variant(os.environ.get("EVENTFIELD_VARIANT") or None)
    import mitsuba as mi
    results = {name: [run(sampler, n) for n in STEP_COUNTS] for name, sampler in SAMPLERS.items()}
    limits = {name: limit(rows) for name, rows in results.items()}
    chart(results, os.path.join(RESULTS, "accuracy.png"))
    md = [f"# What limits timing accuracy (analytic scene, {mi.variant()}, one run)", "",
          "| sampler | steps | render s | events (exact) | count error | timing median us | p99 us |",
          "|---|---|---|---|---|---|---|"]
    for name, rows in results.items():
        md += [f"| {name} | {r['steps']} | {r['wall_s']:.2f} | {r['events']} ({r['exact_events']}) | "
               f"{100 * r['count_error']:.2f}% | {r['timing_median_us']:.3g} | {r['timing_p99_us']:.3g} |"
               for r in rows]
    md += [""] + [f"- {name}: accuracy limited by **{lim}**" for name, lim in limits.items()] + [
        "", "Chart: `benchmarks/results/accuracy.png`.", ""]
    res = {"variant": mi.variant(), "results": results, "limits": limits,
           "targets": {"noise-free sampler is step-limited": limits["midpoint 16 spp (noise-free)"] == "steps",
                       "independent 4 spp is noise-limited": limits["independent 4 spp"] == "Monte-Carlo noise"}}
    write_results("accuracy", res, md)


if __name__ == "__main__":
    main()
