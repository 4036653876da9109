"""The paper's applications (issue 10) at their documented default sizes: where the time goes. Ratios from one
run: each stage as a share of its application's total, and everything after the event render relative to the
event render itself. Absolute seconds are recorded in the JSON for reference only (shared, noisy machines).

Target: every application finishes in minutes on the 2-core CI machine; its processing (everything that is not
rendering events or ground truth) costs less than rendering its events.

Writes benchmarks/results/applications.json and .md.  Usage: ./run bench applications
"""
import math
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402

SCENES = os.path.join(ROOT, "scenes")
# stages that render ground truth or comparisons for scoring only: a user with real data has none of them
REFERENCE_STAGES = {"ground_truth_views", "ground_truth_depth", "ground_truth", "render_truth_for_scoring",
                    "refocus_for_scoring", "scoring", "score", "conventional_camera"}
RENDER_STAGES = {"render_events", "render", "render_rgb_frames"}


def _applications():
    from mitsuba_eventfield.apps import hdr, highspeed, scanrate, slomorf
    from mitsuba_eventfield.apps.highspeed import FAN_DEFAULTS
    fan_defines = dict(item.split("=") for item in FAN_DEFAULTS["define"])
    return {
        "slomorf (falling, 360x360, 8x)": lambda: slomorf.slomorf(slomorf.DEFAULT_SCENE),
        "high-speed refocus (fan, 240x180, 5 periods)": lambda: highspeed.refocus_planes(
            os.path.join(SCENES, "fan", "fan.xml"), {"fan": 0.6, "wall": 1.5}, fan_defines),
        "focus tracking (dart, 240x180, 6 periods)": lambda: highspeed.track_focus_depth(
            os.path.join(SCENES, "dart", "galvo.xml"), (0.58, 0.44, 0.78, 0.56), 0.6, 1.5, 1.6),
        "depth at scan rate (runner, 160x120, 4 periods)": lambda: scanrate.run(
            os.path.join(SCENES, "runner", "runner.xml")),
        "HDR light field (hdr_leds, 160x120, 1 period)": lambda: hdr.compare(
            os.path.join(SCENES, "hdr_leds", "hdr_leds.xml"), depth=1.45),
    }


def main():
    import mitsuba_eventfield as ef
    ef.render_frames(ef.load_scene(os.path.join(SCENES, "demo", "demo.xml"), width=32, height=24), [0.0])  # warm-up
    rows = {}
    for name, call in _applications().items():
        t = time.perf_counter()
        result = call()
        wall = time.perf_counter() - t
        split = dict(result.meta["time_split_s"])
        total = sum(split.values())
        render = sum(v for k, v in split.items() if k in RENDER_STAGES)
        processing = sum(v for k, v in split.items() if k not in RENDER_STAGES | REFERENCE_STAGES)
        rows[name] = {"wall_s": wall, "split_s": split, "share": {k: v / total for k, v in split.items()},
                      "processing_over_render": processing / render if render else math.nan}
    res = {"applications": rows,
           "targets": {f"{n}: processing < render": r["processing_over_render"] < 1 for n, r in rows.items()}}
    md = ["# Applications benchmark (issue 10): where the time goes, at the documented default sizes", "",
          "| application | stages, share of its total | processing / event render |", "|---|---|---|"]
    for n, r in rows.items():
        shares = ", ".join(f"{k.replace('_', ' ')} {100 * v:.0f}%" for k, v in r["share"].items())
        md.append(f"| {n} | {shares} | **{r['processing_over_render']:.2f}** |")
    slowest = max(rows.values(), key=lambda r: r["wall_s"])["wall_s"]
    md += ["", f"Slowest application / fastest: {slowest / min(r['wall_s'] for r in rows.values()):.1f}x. "
           "Processing = everything but rendering events (and RGB frames) and what is rendered or computed for scoring.",
           ""]
    write_results("applications", res, md)


if __name__ == "__main__":
    main()
