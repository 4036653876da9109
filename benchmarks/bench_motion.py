"""Motion a step (issue 15, item 3): where a moving scene's per-step update goes, on the active backend.

For the demo (a moving sphere and a moving cube mesh) and the fan (a moving mesh and a moving rectangle), in
one process:
1. ``set_time`` alone, synced before and after each step, split into our part (the new transforms and the
   mesh's vertex kernel, traced from Python) and Mitsuba's ``update()`` of the moved parameters (on a GPU:
   a sync, the moved mesh's bounding box as reductions read back, the acceleration structures rebuilt).
2. The same with the moving shapes loaded as Mitsuba instances (``scene/instancing.py``: ``shapegroup`` +
   ``instance``, moved by the instance's ``to_world``: no vertex kernel, no mesh bounding box, no geometry
   rebuilt). The first measurement (H100) made it CUDA's default; on the CPU it lost twice (docs/design.md).
3. Whole renders (``render_events``, device path, in memory) of both forms: render / motion / events time,
   the wall time, and the events' count (the two forms differ by float rounding of the transforms only).
   Also with every sync of the render loop removed (``no_sync_after_render``), which lets the host prepare
   the next step while the device renders: the first measurement (H100, 2026-11-26, the loop then synced
   after each render) made the loop overlap on CUDA (``backend.overlaps_steps``), so on CUDA the two columns
   now differ only by the wait the overlapped loop keeps before Mitsuba's update. The summary's split is then
   not meaningful; the wall time is.

Writes benchmarks/results/motion.json and .md. Usage: python benchmarks/bench_motion.py [--quick]
"""
import contextlib
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402
from bench_event_engine import device_name  # noqa: E402

SCENES = os.path.join(os.path.dirname(HERE), "scenes")


def update_split(timed, steps, duration):
    """Mean ms a step: our part of ``set_time`` and Mitsuba's ``update()``, each synced."""
    import drjit as dr
    moving = timed._moving
    real_update, spent = moving.update, [0.0]

    def timed_update():
        dr.sync_thread()
        t0 = time.perf_counter()
        real_update()
        dr.sync_thread()
        spent[0] += time.perf_counter() - t0

    moving.update = timed_update
    try:
        total = 0.0
        for k in range(steps + 1):
            dr.sync_thread()
            t0 = time.perf_counter()
            timed.set_time(duration * k / steps)
            dr.sync_thread()
            if k:                                       # the first step compiles
                total += time.perf_counter() - t0
            else:
                spent[0] = 0.0
    finally:
        moving.update = real_update
    return {"ours_ms": 1e3 * (total - spent[0]) / steps, "update_ms": 1e3 * spent[0] / steps}


@contextlib.contextmanager
def no_sync_after_render():
    """The render loop's ``dr.sync_thread()`` calls made no-ops (the loop's module only)."""
    from mitsuba_eventfield.simulate import render as loop

    class _NoSync:
        def __getattr__(self, name):
            return getattr(loop.backend.dr, name)

        @staticmethod
        def sync_thread():
            pass

    real, loop.dr = loop.dr, _NoSync()
    try:
        yield
    finally:
        loop.dr = real


def render_row(timed, duration, steps, sync=True):
    import drjit as dr

    import mitsuba_eventfield as ef
    with contextlib.nullcontext() if sync else no_sync_after_render():
        ef.render_events(timed, duration / steps * 3, steps=3, reuse=False)          # compile
        best = None
        for _ in range(2):
            dr.sync_thread()
            t0 = time.perf_counter()
            ev = ef.render_events(timed, duration, steps=steps, reuse=False)
            wall = time.perf_counter() - t0
            r = ev.meta["render"]
            row = {"wall_s": wall, "render_s": r["render_s"], "motion_s": r["motion_s"],
                   "events_s": r["events_s"], "events": len(ev)}
            best = row if best is None or wall < best["wall_s"] else best
    return best, ev


def scene_rows(xml, duration, steps, update_steps, **defines):
    """Both forms of the scene: its moving shapes as they are, and as instances (``scene/instancing.py``, chosen
    by ``EVENTFIELD_INSTANCES`` for each load)."""
    import mitsuba_eventfield as ef
    from mitsuba_eventfield.scene import instancing
    res = {"scene": os.path.relpath(xml, SCENES), "steps": steps, "film": defines or "the scene's"}
    forms = {}
    for name, forced in (("meshes", "0"), ("instances", "1")):
        os.environ[instancing.ENV] = forced
        forms[name] = ef.load_scene(xml, **defines)
    os.environ.pop(instancing.ENV)
    res["instanced"] = forms["instances"].instanced
    for name, timed in forms.items():
        res[name] = {"update": update_split(timed, update_steps, duration)}
    streams = {}
    for name, timed in forms.items():
        res[name]["render"], streams[name] = render_row(timed, duration, steps)
        res[name]["render_no_sync"], _ = render_row(timed, duration, steps, sync=False)
    a, b = streams["meshes"], streams["instances"]
    res["events_differ"] = None if a.equals(b) else f"{len(a)} against {len(b)} events"
    return res


def main(quick=False):
    import mitsuba as mi

    import mitsuba_eventfield as ef
    ef.set_variant(os.environ.get("EVENTFIELD_VARIANT") or None)
    cuda = mi.variant().startswith("cuda")
    demo, fan = os.path.join(SCENES, "demo", "demo.xml"), os.path.join(SCENES, "fan", "fan.xml")
    if quick:
        rows = [scene_rows(demo, 0.02, 10, 20, width=48, height=36)]
    elif cuda:              # issue 15's sizes
        rows = [scene_rows(demo, 0.1, 100, 200), scene_rows(fan, 0.02, 400, 200, width=1280, height=720)]
    else:
        rows = [scene_rows(demo, 0.1, 100, 200, width=96, height=72),
                scene_rows(fan, 0.008, 64, 100, width=346, height=260)]
    device = device_name()
    res = {"device": device, "variant": mi.variant(), "rows": rows}
    md = [f"# Motion a step: meshes against instances ({device}, {mi.variant()}, one run)", "",
          "set_time alone, synced (ms a step): our part (transforms, vertex kernel) + Mitsuba's update(). "
          "Renders (device path, in memory, best of 2): wall, and the summary's render / motion / events "
          "(s); without the loop's syncs only the wall counts. The loop overlaps host and device: "
          f"{__import__('mitsuba_eventfield').backend.overlaps_steps()}.", "",
          "| scene | steps | form | ours ms | update ms | render / motion / events s | wall s | wall, no sync s "
          "| events |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for form in ("meshes", "instances"):
            d, u, n = r[form]["render"], r[form]["update"], r[form]["render_no_sync"]
            md.append(f"| {r['scene']} | {r['steps']} | {form} | {u['ours_ms']:.3f} | {u['update_ms']:.3f} | "
                      f"{d['render_s']:.3f} / {d['motion_s']:.3f} / {d['events_s']:.3f} | {d['wall_s']:.3f} | "
                      f"{n['wall_s']:.3f} | {d['events']} |")
    md += ["", "Instanced: " + "; ".join(f"{r['scene']}: {', '.join(r['instanced']) or 'none'} (events "
                                          f"{r['events_differ'] or 'identical'})" for r in rows), ""]
    write_results("motion" + ("_quick" if quick else ""), res, md)


if __name__ == "__main__":
    main(quick="--quick" in sys.argv)
