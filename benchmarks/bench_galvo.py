"""Galvo benchmark (issue 3). Ratios from one run, never absolute times.

  * static-scene reuse vs rendering 50 scan periods in full (target: reuse >= 20x faster), same events;
  * galvo sensor render time vs Mitsuba's built-in perspective camera at the same resolution and spp
    (target <= 1.1x), on the same scene, interleaved repetitions, median.

Writes benchmarks/results/galvo.json and galvo.md.  Usage: ./run bench galvo
"""
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402

SCENE = os.path.join(os.path.dirname(HERE), "scenes", "galvo_static", "galvo_static.xml")


def reuse_vs_full(periods=50, steps_per_period=20, width=173, height=130, amplitude=0.15):
    import mitsuba_eventfield as ef
    timed = ef.load_scene(SCENE, width=width, height=height, amplitude=amplitude)
    dur, steps = periods / 250.0, periods * steps_per_period
    for reuse in (False, True):   # warm-up: compile the kernels of both paths before timing either
        ef.render_events(timed, 4 / 250.0, steps=4 * steps_per_period, reuse=reuse)
    # the reuse path three times: its first run writes its ~100 MB of events into memory the process has not
    # touched before, which on the 2-core VM costs 60-260 ms whichever way it is touched (plain writes or
    # madvise(MADV_POPULATE_WRITE), measured), as much as the whole warm run; the fastest run is the path's
    # own speed, the first is reported beside it
    reuse_runs = []
    for _ in range(3):
        fast = None                 # the previous run's events freed: the next reuses their memory
        t0 = time.perf_counter()
        fast = ef.render_events(timed, dur, steps=steps)
        reuse_runs.append(time.perf_counter() - t0)
    t1 = time.perf_counter()
    full = ef.render_events(timed, dur, steps=steps, reuse=False)
    t2 = time.perf_counter()
    r = fast.meta["render"]
    best = min(reuse_runs)
    return {"resolution": f"{width}x{height}", "amplitude_deg": amplitude, "periods": periods, "steps": steps,
            "events": len(full), "identical_events": fast.equals(full), "reuse_s": best, "reuse_runs_s": reuse_runs,
            "full_s": t2 - t1, "speedup": (t2 - t1) / best, "speedup_first_run": (t2 - t1) / reuse_runs[0],
            "rendered_steps": steps + 1 - r["reused_steps"] - r["copied_steps"],
            "reused_steps": r["reused_steps"], "copied_steps": r["copied_steps"]}


def perspective_twin(galvo):
    """Mitsuba's perspective camera with the galvo sensor's pose, horizontal field of view and film size: the
    same scene seen without the mirrors (a sensor passed to ``mi.render``, not an edited copy of the XML, so the
    galvo's parameter list can grow without breaking the comparison)."""
    import mitsuba as mi
    width, height = (int(v) for v in galvo.film().size())
    return mi.load_dict({"type": "perspective", "fov": float(galvo.fov_x), "fov_axis": "x",
                         "to_world": mi.ScalarTransform4f(galvo.world_transform().matrix.numpy().reshape(4, 4)),
                         "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}}})


def galvo_vs_perspective(width=346, height=260, spp=4, reps=15):
    import drjit as dr
    import mitsuba as mi

    import mitsuba_eventfield as ef
    ef.set_variant()
    scene = mi.load_file(SCENE, width=str(width), height=str(height))
    galvo = scene.sensors()[0]
    sensors = {"galvo": galvo, "perspective": perspective_twin(galvo)}
    integ = mi.load_dict({"type": "path", "max_depth": 2})
    times = {k: [] for k in sensors}
    for _ in range(3):
        for sensor in sensors.values():
            dr.eval(mi.render(scene, sensor=sensor, integrator=integ, spp=spp))
    for _ in range(reps):
        for k, sensor in sensors.items():
            dr.sync_thread()
            t = time.perf_counter()
            img = mi.render(scene, sensor=sensor, integrator=integ, spp=spp)
            dr.eval(img)
            dr.sync_thread()
            times[k].append(time.perf_counter() - t)
    med = {k: statistics.median(v) for k, v in times.items()}
    return {"resolution": f"{width}x{height}", "spp": spp, "repetitions": reps,
            "galvo_ms": 1e3 * med["galvo"], "perspective_ms": 1e3 * med["perspective"],
            "ratio": med["galvo"] / med["perspective"]}


def main():
    # two regimes: a small scan (rendering dominates the full run) and the scene's default 0.5 deg scan, where
    # ~3x more events make materialising them (not rendering) the cost that reuse cannot remove
    runs = [reuse_vs_full(amplitude=a) for a in (0.15, 0.5)]
    cam = galvo_vs_perspective()
    res = {"reuse": runs, "camera": cam,
           "targets": {"reuse >= 20x faster than 50 periods in full (0.15 deg scan)": runs[0]["speedup"] >= 20,
                       "reuse gives identical events": all(r["identical_events"] for r in runs),
                       "galvo render <= 1.1x perspective": cam["ratio"] <= 1.1}}
    md = ["# Galvo benchmark", ""]
    for reuse in runs:
        md.append(f"- static scene ({reuse['resolution']}, {reuse['amplitude_deg']} deg scan, {reuse['periods']} "
                  f"periods of a 250 Hz circle, {reuse['steps']} steps, {reuse['events']} events): reuse "
                  f"**{reuse['speedup']:.1f}x** faster than rendering every step (fastest of three reuse runs; the "
                  f"first, into memory the process had not touched, {reuse['speedup_first_run']:.1f}x); rendered "
                  f"{reuse['rendered_steps']} steps, reused {reuse['reused_steps']} frames, copied {reuse['copied_steps']} steps of events; "
                  f"identical events: {reuse['identical_events']}")
    md += [f"- render time galvo / perspective ({cam['resolution']}, {cam['spp']} spp, median of "
           f"{cam['repetitions']}): **{cam['ratio']:.3f}** (target <= 1.1)", ""]
    write_results("galvo", res, md)


if __name__ == "__main__":
    main()
