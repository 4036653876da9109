"""Pixel-model cost (issue 6; issue 15 part 1): event generation with every effect on vs the ideal pixel, in one run.

Event generation = everything the summary's ``events_s`` holds: the pixel kernels, counts, fill, sort, refractory,
shot noise and readout cap (and, for steps held in batches, holding the frame); the render itself is excluded.
Target: <= 2x. Demo scene, 346x260, 4 spp, 60 uniform steps. Three models: the ideal pixel and every effect,
each with its steps committed in batches as the render chooses (``simulate/step_batch.py``), and every effect
a step at a time as before the realistic pixel batched (``event_batch.one_frame_a_step``: on the CPU its NumPy
host path). Each is rendered once to compile, then three times, alternating; the fastest counts.
Writes benchmarks/results/pixel.json and .md.  Usage: ./run bench pixel
"""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402
from bench_event_engine import device_name  # noqa: E402

DEMO = os.path.join(os.path.dirname(HERE), "scenes", "demo", "demo.xml")
EVERYTHING = {"threshold_sigma": 0.03, "threshold_jitter": 0.01, "refractory_s": 2e-4, "leak_rate_hz": 0.1,
              "leak_jitter": 0.1, "shot_noise_hz": 1.0, "cutoff_hz": 300.0, "timestamp_resolution_us": 1.0,
              "readout_cap": 12e6, "readout_cap_native_pixels": 346 * 260}


def main(steps=60, reps=3):
    import contextlib
    import mitsuba_eventfield as ef
    from mitsuba_eventfield.plugins.event_batch import one_frame_a_step
    scene = ef.load_scene(DEMO)
    models = {"ideal": ({}, contextlib.nullcontext), "all effects": (EVERYTHING, contextlib.nullcontext),
              "all effects, a step at a time": (EVERYTHING, one_frame_a_step)}
    runs = {}
    for name, (pixel, context) in models.items():
        with context():
            ef.render_events(scene, 12 * 0.5e-3, steps=12, pixel=pixel)       # compile (whole batches too)
    for _ in range(reps):
        for name, (pixel, context) in models.items():
            with context():
                r = ef.render_events(scene, steps * 0.5e-3, steps=steps, pixel=pixel).meta["render"]
            ms = 1e3 * r["events_s"] / r["steps"]
            if name not in runs or ms < runs[name]["events_ms_per_step"]:
                runs[name] = {"events_ms_per_step": ms, "events": r["events"],
                              "render_ms_per_step": 1e3 * r["render_s"] / r["steps"],
                              "dropped_readout": r["dropped_readout"], "dropped_refractory": r["dropped_refractory"]}
    ideal = runs["ideal"]["events_ms_per_step"]
    ratio = runs["all effects"]["events_ms_per_step"] / ideal
    stepwise = runs["all effects, a step at a time"]["events_ms_per_step"] / ideal
    same = runs["all effects"]["events"] == runs["all effects, a step at a time"]["events"]
    res = {"device": device_name(), "runs": runs, "all_over_ideal": ratio, "stepwise_over_ideal": stepwise,
           "batched_equals_stepwise_count": same, "targets": {"all effects <= 2x ideal": ratio <= 2.0}}
    md = [f"# Pixel-model cost (demo scene, 346x260, 4 spp; {res['device']})", "",
          "| pixel | event generation ms/step | events |", "|---|---|---|"]
    md += [f"| {k} | {v['events_ms_per_step']:.2f} | {v['events']} |" for k, v in runs.items()]
    md += ["", f"All effects / ideal: **{ratio:.2f}x** (target <= 2x; a step at a time {stepwise:.2f}x); render "
           f"{runs['ideal']['render_ms_per_step']:.1f} ms/step for comparison. Fastest of {reps} renders each.", ""]
    write_results("pixel", res, md)


if __name__ == "__main__":
    main()
