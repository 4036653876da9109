"""Pixel-model cost (issue 6): event generation with every effect on vs the ideal pixel, in one run.

Event generation = the step's dense pixel kernel, the sparse expansion, sorting, refractory and readout
(RenderSummary.events_s); the render itself is excluded. Target: <= 2x. Demo scene, 346x260, 4 spp.
Writes benchmarks/results/pixel.json and .md.  Usage: ./run bench pixel
"""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402

DEMO = os.path.join(os.path.dirname(HERE), "scenes", "demo", "demo.xml")
EVERYTHING = {"threshold_sigma": 0.03, "threshold_jitter": 0.01, "refractory_s": 2e-4, "leak_rate_hz": 0.1,
              "leak_jitter": 0.1, "shot_noise_hz": 1.0, "cutoff_hz": 300.0, "timestamp_resolution_us": 1.0,
              "readout_cap": 12e6, "readout_cap_native_pixels": 346 * 260}


def main(steps=60):
    import mitsuba_eventfield as ef
    scene = ef.load_scene(DEMO)
    runs = {}
    for name, pixel in (("ideal", {}), ("all effects", EVERYTHING)):
        ef.render_events(scene, 4 * 0.5e-3, steps=4, pixel=pixel)                  # compile
        r = ef.render_events(scene, steps * 0.5e-3, steps=steps, pixel=pixel).meta["render"]
        runs[name] = {"events_ms_per_step": 1e3 * r["events_s"] / r["steps"], "events": r["events"],
                      "render_ms_per_step": 1e3 * r["render_s"] / r["steps"],
                      "dropped_readout": r["dropped_readout"], "dropped_refractory": r["dropped_refractory"]}
    ratio = runs["all effects"]["events_ms_per_step"] / runs["ideal"]["events_ms_per_step"]
    res = {"runs": runs, "all_over_ideal": ratio, "targets": {"all effects <= 2x ideal": ratio <= 2.0}}
    md = ["# Pixel-model cost (demo scene, 346x260, 4 spp)", "", "| pixel | event generation ms/step | events |",
          "|---|---|---|"]
    md += [f"| {k} | {v['events_ms_per_step']:.2f} | {v['events']} |" for k, v in runs.items()]
    md += ["", f"All effects / ideal: **{ratio:.2f}x** (target <= 2x); render {runs['ideal']['render_ms_per_step']:.1f} "
           "ms/step for comparison.", ""]
    write_results("pixel", res, md)


if __name__ == "__main__":
    main()
