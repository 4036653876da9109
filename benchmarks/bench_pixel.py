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
set, kernels doing nothing but a step's draws for every pixel (the PCG32 stream the model used until 2026-11-26,
and the counter-based draws that replaced it), against the ideal pixel's whole event kernels.
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

# each effect alone, in the breakdown: which of them the realistic pixel's kernel time goes to
EFFECTS = {"mismatch alone": {"threshold_sigma": 0.03}, "jitter alone": {"threshold_jitter": 0.01},
           "refractory alone": {"refractory_s": 2e-4}, "leak alone": {"leak_rate_hz": 0.1, "leak_jitter": 0.1},
           "shot noise alone": {"shot_noise_hz": 1.0}, "low-pass alone": {"cutoff_hz": 300.0},
           "clock alone": {"timestamp_resolution_us": 1.0},
           "readout cap alone": {"readout_cap": 12e6, "readout_cap_native_pixels": 346 * 260}}


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
    res["breakdown"], floors = breakdown(steps), draw_floors(346 * 260, 4)
    res["random_draws_ms_per_step"] = floors
    md += ["Where the time goes (the demo's frames through the converter, 4 frames a kernel, kernel history on; "
           "ms a frame):", "", "| pixel | whole conversion | event kernels | the rest (host: tracing, launches, "
           "result) |", "|---|---|---|---|"]
    md += [f"| {k} | {v['wall_ms']:.2f} | {v['kernel_ms']:.2f} | {v['wall_ms'] - v['kernel_ms']:.2f} |"
           for k, v in res["breakdown"].items()]
    md += ["", "Each effect alone adds its row's event kernels less the ideal pixel's; the effects' sum against all "
           "of them together shows whether they add up or share work (one loop, one pass over the frames)."]
    ideal_kernels = res["breakdown"]["ideal"]["kernel_ms"]
    md += ["", "The realistic model's random numbers alone, a kernel making only a step's draws for every pixel "
           f"(ms a step; all of the ideal pixel's event kernels: {ideal_kernels:.2f}):", ""]
    md += [f"- {name}: **{ms:.3f}** ({ms / ideal_kernels:.2f}x the ideal pixel's kernels)"
           for name, ms in floors.items()]
    md += ["", "The model makes its counter-based draws only where a pixel fired (a few percent of the "
           "pixel-steps here), so the second line is a bound it does not reach.", ""]
    write_results("pixel", res, md)


def breakdown(steps, reps=3):
    """Per model, the conversion of the demo's frames: wall and event-kernel milliseconds a frame; the models
    alternate within each of ``reps`` rounds (a busy virtual machine slows a stretch of runs, not one model),
    and each keeps its fastest."""
    import time
    import numpy as np
    import drjit as dr
    import mitsuba_eventfield as ef
    times = np.arange(steps + 1) * 0.5e-3
    frames = ef.render_frames(DEMO, times, log=False)
    models = {"ideal": {}, **EFFECTS, "all effects": EVERYTHING}
    for pixel in models.values():
        ef.events_from_frames(frames[:9], times[:9], pixel=pixel)        # compile and record
    out = {}
    for _ in range(reps):
        for name, pixel in models.items():
            dr.kernel_history()
            dr.set_flag(dr.JitFlag.KernelHistory, True)
            t0 = time.perf_counter()
            ef.events_from_frames(frames, times, pixel=pixel)
            wall = time.perf_counter() - t0
            history = dr.kernel_history()
            dr.set_flag(dr.JitFlag.KernelHistory, False)
            kernels = sum(k.get("execution_time", 0.0) for k in history)     # ms
            row = {"wall_ms": 1e3 * wall / steps, "kernel_ms": kernels / steps}
            if name not in out or row["wall_ms"] < out[name]["wall_ms"]:
                out[name] = row
    return out


def draw_floors(n_pix, frames, reps=20):
    """Milliseconds a step of kernels that only make a realistic step's random numbers for ``n_pix`` pixels,
    ``frames`` steps a kernel as a chunk's count pass loops them; fastest of ``reps``: the per-pixel PCG32
    stream the model drew from until 2026-11-26 (five draws every step: the jitter's two and Box-Muller normal,
    the noise's three), and the counter-based draws that replaced it (``counter_rng``) as if every pixel fired
    every step (the jitter's two hashes and normal, the noise's polarity and exponential wait); the model makes
    the latter only where a pixel fired."""
    import time
    import drjit as dr
    import mitsuba as mi
    from mitsuba_eventfield.plugins import counter_rng
    rng = mi.PCG32(size=n_pix, initstate=mi.UInt64(1), initseq=dr.arange(mi.UInt64, n_pix))
    pixel, seed = dr.arange(mi.UInt32, n_pix), counter_rng.seed_array(mi, 1)

    def pcg32(b, state, acc):
        r = mi.PCG32(rng)
        r.state = state
        g = mi.warp.square_to_std_normal(mi.Point2f(r.next_float32(), r.next_float32()))
        return b + 1, r.state, acc + g.x + g.y + r.next_float32() + r.next_float32() + r.next_float32()

    def hashed(b, state, acc):
        def u(stream):
            return counter_rng.draw(mi, pixel, b, seed, stream)
        g = mi.warp.square_to_std_normal(mi.Point2f(u(counter_rng.JITTER_ON), u(counter_rng.JITTER_OFF)))
        wait = -dr.log(1.0 - u(counter_rng.NOISE_WAIT))
        return b + 1, state, acc + g.x + g.y + u(counter_rng.NOISE_POLARITY) + wait

    def run(body):
        bound = dr.opaque(mi.UInt32, frames)
        out = dr.while_loop((dr.zeros(mi.UInt32, n_pix), rng.state, dr.zeros(mi.Float, n_pix)),
                            lambda b, s, a: b < bound, body)
        dr.eval(*out)
        dr.sync_thread()
    floors = {}
    for name, body in (("PCG32, five draws every step (before)", pcg32),
                       ("counter-based, as if every pixel fired", hashed)):
        run(body)
        best = None
        for _ in range(reps):
            t0 = time.perf_counter()
            run(body)
            best = min(best or 1e9, time.perf_counter() - t0)
        floors[name] = 1e3 * best / frames
    return floors


if __name__ == "__main__":
    main()
