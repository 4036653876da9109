"""Resolution as a lever (issue 18, part 2): the speed-against-accuracy suite's step settings on the fan (galvo,
250 Hz circle, one 4 ms scan period, 4 spp) at three film sizes, each against its own converged reference
(``evaluation.bench``: 256 multi-jittered spp, 4x the steps; per-pixel event-count error, 2 seeds).

Why: the suite runs tiny films (48x36), where 25 steps per period beat 100 (fewer steps, fewer Monte-Carlo
noise events). The same steps move a larger film's image further per step (pixels scale with the film), so the
steps a render needs grow with resolution; this measures where uniform step counts, steps placed by image motion
and the default (uniform steps as many as the image motion needs, ``stepping.default_steps``) sit as the film
grows.

Writes benchmarks/results/resolution.{md,json,png}. About 10 minutes on 2 cores (the 173x130 reference is most).
Usage: ./run bench resolution   (--chart-only: redraw the chart from resolution.json)
"""
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import RESULTS, write_results  # noqa: E402

SIZES = ((48, 36), (96, 72), (173, 130))
SETTINGS = ("steps/4", "steps/2", "steps*1", "steps*2", "16spp/2", "default", "motion0.5", "motion1", "motion2")
SEEDS = (1, 2)


def main():
    import mitsuba_eventfield as ef
    from mitsuba_eventfield.evaluation import bench
    from mitsuba_eventfield.evaluation.bench_chart import summarize
    ef.quiet_mitsuba_log()
    t0 = time.perf_counter()
    rows = []
    for w, h in SIZES:
        spec = bench.BenchScene(f"fan {w}x{h}", "fan/fan.xml", 0.004, defines={"width": w, "height": h},
                                refocus_depth=0.6)
        rows += bench.run_scene(spec, bench.pick_settings(list(SETTINGS)), SEEDS)
    summary = summarize(rows)
    md = ["# Resolution as a lever: the fan at three film sizes", "",
          f"One 4 ms scan period of `scenes/fan/fan.xml` (250 Hz circle), {len(SEEDS)} seeds a setting, each size "
          "against its own reference (256 multi-jittered spp, 400 steps). Wall time: the render's, one thread, "
          "fastest seed. px per step: the image motion of one step, the scan's (galvo geometry) and the blades' "
          "(projected bounds) together; for steps placed by image motion, their bound. Error: per-pixel "
          "event-count error (L1, "
          "relative), mean over seeds; refocus: PSNR of the period refocused at 0.6 m on textured pixels.", "",
          "| film | setting | steps | px per step | wall s | event-count error | refocus PSNR (dB) | fewest count "
          "errors at 4 spp |", "|---|---|---|---|---|---|---|---|"]
    out = {"sizes": {}, "rows": rows}
    for w, h in SIZES:
        name = f"fan {w}x{h}"
        mine = [s for s in summary if s["scene"] == name]
        best = min((s for s in mine if s["spp"] == 4), key=lambda s: s["count_error"])
        for s in mine:
            runs = [r for r in rows if r["scene"] == name and r["setting"] == s["setting"]]
            px = _px(runs[0])
            md.append(f"| {w}x{h} | {s['label']} | {s['steps']:.0f} | {px:.2f} | {s['wall_s']:.2f} | "
                      f"{s['count_error']:.3f} ± {s.get('count_error_std', 0):.3f} | "
                      f"{s.get('refocus_psnr_db', float('nan')):.1f} | {'**best**' if s is best else ''} |")
        out["sizes"][name] = {"fewest_count_errors_at_4spp": best["setting"]}
    md += ["", f"Bench time {time.perf_counter() - t0:.0f} s.", ""]
    write_results("resolution", out, md)
    _chart(summary, rows, os.path.join(RESULTS, "resolution.png"))


def _px(row) -> float:
    """A run's image motion a step: the render's note for uniform steps, else the setting's bound."""
    if row.get("px_per_step") is not None:
        return row["px_per_step"]
    from mitsuba_eventfield.evaluation import bench
    return next(c["px_per_step"] for c in bench.SETTINGS if c["key"] == row["setting"])


def _chart(summary, rows, path):
    """Count error against the image motion of one step (scan and blades), a line per film size for the
    uniform ladder, a star for the default and diamonds for steps placed by image motion (their bound): the
    optima line up in pixels a step, not in steps."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mitsuba_eventfield.images import save_figure
    fig, ax = plt.subplots(figsize=(7.5, 4.6), layout="constrained")
    for (w, h), colour in zip(SIZES, ("tab:blue", "tab:orange", "tab:green")):
        name = f"fan {w}x{h}"
        px = {r["setting"]: _px(r) for r in rows if r["scene"] == name}
        uniform = sorted((s for s in summary if s["scene"] == name and s["spp"] == 4
                          and s["setting"].startswith("steps")), key=lambda s: px[s["setting"]])
        ax.plot([px[s["setting"]] for s in uniform], [s["count_error"] for s in uniform], "o-", color=colour,
                label=f"{w}x{h}, 4 spp, 25-200 uniform steps")
        d = next(s for s in summary if s["scene"] == name and s["setting"] == "default")
        ax.plot([px["default"]], [d["count_error"]], "*", color=colour, markersize=14)
        motion = [s for s in summary if s["scene"] == name and s["setting"].startswith("motion")]
        ax.plot([px[s["setting"]] for s in motion], [s["count_error"] for s in motion], "D", color=colour,
                markerfacecolor="none", markersize=9)
    ax.set_xscale("log")
    ax.set_xlabel("image motion of one step (scan + blades), px\nlines: uniform steps; star: the default "
                  "(uniform, as many as the motion needs); diamonds: steps placed by image motion", fontsize=8)
    ax.set_ylabel("per-pixel event-count error vs converged")
    ax.set_title("The fan, one scan period at 4 spp: fewest count errors near 2 px a step")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    save_figure(fig, path)


def chart_from_results():
    """Redraw the chart from resolution.json (no renders)."""
    import json
    from mitsuba_eventfield.evaluation.bench_chart import summarize
    with open(os.path.join(RESULTS, "resolution.json")) as f:
        rows = json.load(f)["rows"]
    _chart(summarize(rows), rows, os.path.join(RESULTS, "resolution.png"))


if __name__ == "__main__":
    chart_from_results() if "--chart-only" in sys.argv else main()
