"""Pixel-model cost (issue 6; issue 15 part 1): event generation with every effect on vs the ideal pixel, in one run.

Event generation = everything the summary's ``events_s`` holds: the pixel kernels, counts, fill, sort, refractory,
shot noise and readout cap (and, for steps held in batches, holding the frame); the render itself is excluded.
Target: <= 2x. Demo scene, 346x260, 4 spp, 60 uniform steps. Three models: the ideal pixel and every effect,
each with its steps committed in batches as the render chooses (``simulate/step_batch.py``), and every effect
a step at a time as before the realistic pixel batched (``event_batch.one_frame_a_step``: on the CPU its NumPy
host path). Each is rendered once to compile, then three times, alternating; the fastest counts.

What limits the ratio (the "where the time goes" table): the demo's own frames (``render_frames``, the render's
fixed seed) converted by ``events_from_frames`` with each model, with Dr.Jit's kernel history on: the event
kernels' execution time a frame against the whole conversion's, so kernel arithmetic and host work (tracing,
launches, the sort's setup, the host result) show apart; and the floor the realistic model's random numbers
set, a kernel doing nothing but a step's draws (two PCG32 draws and their Box-Muller normal for the threshold
jitter, three for shot noise) for every pixel, against the ideal pixel's whole event kernels.
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
    res["breakdown"], floor = breakdown(steps), random_floor(346 * 260, 4)
    res["random_draws_ms_per_step"] = floor
    md += ["Where the time goes (the demo's frames through the converter, 4 frames a kernel, kernel history on; "
           "ms a frame):", "", "| pixel | whole conversion | event kernels | the rest (host: tracing, launches, "
           "result) |", "|---|---|---|---|"]
    md += [f"| {k} | {v['wall_ms']:.2f} | {v['kernel_ms']:.2f} | {v['wall_ms'] - v['kernel_ms']:.2f} |"
           for k, v in res["breakdown"].items()]
    ideal_kernels = res["breakdown"]["ideal"]["kernel_ms"]
    md += ["", f"The realistic model's random numbers alone (a kernel doing only a step's five PCG32 draws and the "
           f"jitter's Box-Muller normal, every pixel): **{floor:.2f} ms a step**, against {ideal_kernels:.2f} ms "
           f"for all of the ideal pixel's event kernels: the draws alone are "
           f"{floor / ideal_kernels:.1f}x the ideal pixel's kernels, before the model's other arithmetic.", ""]
    write_results("pixel", res, md)


def breakdown(steps):
    """Per model, the conversion of the demo's frames: wall and event-kernel milliseconds a frame."""
    import time
    import numpy as np
    import drjit as dr
    import mitsuba_eventfield as ef
    times = np.arange(steps + 1) * 0.5e-3
    frames = ef.render_frames(DEMO, times, log=False)
    out = {}
    for name, pixel in (("ideal", {}), ("all effects", EVERYTHING)):
        ef.events_from_frames(frames[:9], times[:9], pixel=pixel)        # compile and record
        best = None
        for _ in range(3):
            dr.kernel_history()
            dr.set_flag(dr.JitFlag.KernelHistory, True)
            t0 = time.perf_counter()
            ef.events_from_frames(frames, times, pixel=pixel)
            wall = time.perf_counter() - t0
            history = dr.kernel_history()
            dr.set_flag(dr.JitFlag.KernelHistory, False)
            kernels = sum(k.get("execution_time", 0.0) for k in history)     # ms
            row = {"wall_ms": 1e3 * wall / steps, "kernel_ms": kernels / steps}
            if best is None or row["wall_ms"] < best["wall_ms"]:
                best = row
        out[name] = best
    return out


def random_floor(n_pix, frames, reps=20):
    """Milliseconds a step of a kernel that only makes a realistic step's random numbers for ``n_pix`` pixels
    (the jitter's two draws and Box-Muller normal, the noise's three draws), ``frames`` steps a kernel as a
    chunk's count pass loops them; fastest of ``reps``."""
    import time
    import drjit as dr
    import mitsuba as mi
    rng = mi.PCG32(size=n_pix, initstate=mi.UInt64(1), initseq=dr.arange(mi.UInt64, n_pix))

    def run():
        def body(b, state, acc):
            r = mi.PCG32(rng)
            r.state = state
            g = mi.warp.square_to_std_normal(mi.Point2f(r.next_float32(), r.next_float32()))
            acc = acc + g.x + g.y + r.next_float32() + r.next_float32() + r.next_float32()
            return b + 1, r.state, acc
        bound = dr.opaque(mi.UInt32, frames)
        out = dr.while_loop((dr.zeros(mi.UInt32, n_pix), rng.state, dr.zeros(mi.Float, n_pix)),
                            lambda b, s, a: b < bound, body)
        dr.eval(*out)
        dr.sync_thread()
    run()
    best = None
    for _ in range(reps):
        t0 = time.perf_counter()
        run()
        best = min(best or 1e9, time.perf_counter() - t0)
    return 1e3 * best / frames


if __name__ == "__main__":
    main()
