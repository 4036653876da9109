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
    t0 = time.perf_counter()
    fast = ef.render_events(timed, dur, steps=steps)
    t1 = time.perf_counter()
    full = ef.render_events(timed, dur, steps=steps, reuse=False)
    t2 = time.perf_counter()
    r = fast.meta["render"]
    return {"resolution": f"{width}x{height}", "amplitude_deg": amplitude, "periods": periods, "steps": steps, "events": len(full),
            "identical_events": fast.equals(full), "reuse_s": t1 - t0, "full_s": t2 - t1,
            "speedup": (t2 - t1) / (t1 - t0), "rendered_steps": steps + 1 - r["reused_steps"] - r["copied_steps"],
            "reused_steps": r["reused_steps"], "copied_steps": r["copied_steps"]}


def galvo_vs_perspective(width=346, height=260, spp=4, reps=15):
    import drjit as dr
    import mitsuba as mi

    import mitsuba_eventfield as ef
    ef.set_variant()
    with open(SCENE) as f:
        xml = f.read()
    persp = xml.replace('<sensor type="galvo" id="camera">', '<sensor type="perspective" id="camera">')
    for tag in ("mirror_distance", "mirror_separation", "frequency", "amplitude"):
        persp = "\n".join(ln for ln in persp.splitlines() if f'name="{tag}"' not in ln or "<default" in ln)
    persp = "\n".join(ln for ln in persp.splitlines() if 'name="curve"' not in ln)
    path = os.path.join(os.path.dirname(SCENE), ".bench_perspective.xml")
    with open(path, "w") as f:
        f.write(persp)
    try:
        scenes = {"galvo": mi.load_file(SCENE, width=str(width), height=str(height)),
                  "perspective": mi.load_file(path, width=str(width), height=str(height))}
    finally:
        os.remove(path)
    integ = mi.load_dict({"type": "path", "max_depth": 2})
    times = {k: [] for k in scenes}
    for _ in range(3):
        for s in scenes.values():
            dr.eval(mi.render(s, integrator=integ, spp=spp))
    for _ in range(reps):
        for k, s in scenes.items():
            dr.sync_thread()
            t = time.perf_counter()
            img = mi.render(s, integrator=integ, spp=spp)
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
                  f"**{reuse['speedup']:.1f}x** faster than rendering every step; rendered {reuse['rendered_steps']} "
                  f"steps, reused {reuse['reused_steps']} frames, copied {reuse['copied_steps']} steps of events; "
                  f"identical events: {reuse['identical_events']}")
    md += [f"- render time galvo / perspective ({cam['resolution']}, {cam['spp']} spp, median of "
           f"{cam['repetitions']}): **{cam['ratio']:.3f}** (target <= 1.1)", ""]
    write_results("galvo", res, md)


if __name__ == "__main__":
    main()
