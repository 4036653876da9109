"""The event engine (issue 15): events made on the device (count, prefix sum, fill, sort in Dr.Jit) against
the host path (NumPy expansion and sort), on a synthetic frame stack and inside renders, in one run.

Frame stack: a textured plane translating at 1.5 px per frame plus a bar rotating about the image centre, 2 kHz
frames, C = 0.2, ideal pixel: what issue 15 measured on an H100. Throughput is pixel-steps per second of the
converter (``events_from_frames``: upload, pixel kernel, events, one host copy per chunk), excluding the frame
synthesis, best of four runs (two rounds over the paths, each a first untimed run for compilation and
allocation, then two), for five paths: the frames (uploaded once, untimed) and the events on the device, the
events left on the device (``on_device=True``: no host copy, the events synced before the clock stops), as chosen (frames batched, ``event_batch``), one frame a step
(``event_batch.one_frame_a_step()``) and the NumPy host path (``event_integrator.host_path()``). Renders:
demo and fan scenes, what beyond the radiance render costs (events + motion + write, and the whole wall time,
as fractions of the render) for the device path with its events left on the device (``on_device=True``), the
device path (steps committed in batches, ``simulate/step_batch.py``), the same with the render loop's other
choice of overlapping host and device (``backend.overlaps_steps``), the device path a step at a time, and the
host path. Every run compares the paths' events (on the same frames for
the converter; renders also compare the renderer with itself).

Writes benchmarks/results/event_engine.json and .md; the device name is recorded with every number.
Usage: ./run bench event_engine   (or python benchmarks/bench_event_engine.py [--quick])
"""
import math
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402

SCENES = os.path.join(os.path.dirname(HERE), "scenes")


def _path(name):
    """``device`` (and ``on_device``, its events left on the device): as the code chooses (the converter
    batches frames, ``event_batch``); ``device_other_loop``: the same with the render loop's other choice
    of ``backend.overlaps_steps`` (overlapped on the CPU, synced after each render on CUDA);
    ``device_per_step``: the device path one frame a kernel; ``host``: the NumPy path."""
    import contextlib
    from mitsuba_eventfield.plugins.event_batch import one_frame_a_step
    from mitsuba_eventfield.plugins.event_integrator import host_path
    if name == "device_other_loop":
        return _other_loop()
    return host_path() if name == "host" else one_frame_a_step() if name == "device_per_step" else \
        contextlib.nullcontext()


def _other_loop():
    import contextlib

    from mitsuba_eventfield import backend

    @contextlib.contextmanager
    def flipped():
        before = os.environ.get(backend.OVERLAP_ENV)
        os.environ[backend.OVERLAP_ENV] = "0" if backend.overlaps_steps() else "1"
        try:
            yield
        finally:
            if before is None:
                os.environ.pop(backend.OVERLAP_ENV)
            else:
                os.environ[backend.OVERLAP_ENV] = before
    return flipped()


def frame_stack(width, height, frames, rate_hz=2000.0, speed=1.5):
    """Textured translation (``speed`` px a frame) + rotating bar, linear intensity in [0.05, 1]."""
    rng = np.random.default_rng(0)
    tex = rng.random((height // 4 + 2, (width + int(speed * frames)) // 4 + 4)).astype(np.float32)
    import cv2
    tex = cv2.resize(tex, (tex.shape[1] * 4, tex.shape[0] * 4), interpolation=cv2.INTER_CUBIC)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    out = np.empty((frames, height, width), np.float32)
    for i in range(frames):
        shift = speed * i
        x0 = int(shift)
        a = shift - x0
        img = (1 - a) * tex[:height, x0:x0 + width] + a * tex[:height, x0 + 1:x0 + 1 + width]
        ang = 2 * np.pi * 50.0 * i / rate_hz
        d = np.abs(-(xx - width / 2) * np.sin(ang) + (yy - height / 2) * np.cos(ang))
        bar = np.clip(4.0 - d, 0, 1)
        out[i] = np.clip(0.05 + 0.6 * img * (1 - bar) + 0.95 * bar, 0.05, 1.0)
    return out, np.arange(frames) / rate_hz


def _convert(stack, times, name, device_stack=None):
    """One conversion by path ``name``; ``on_device`` keeps the events on the device, synced before the clock
    stops (the events made, not merely queued); ``device_frames`` does too, from frames already on the device
    (``device_stack``, uploaded once before the clock starts: what a GPU pipeline has)."""
    import mitsuba_eventfield as ef
    if name not in ("on_device", "device_frames"):
        return ef.events_from_frames(stack, times, threshold=0.2)
    import drjit as dr
    frames = device_stack if name == "device_frames" else stack
    ev = ef.events_from_frames(frames, times, threshold=0.2, on_device=True)
    dr.eval(ev.xy, ev.t, ev.p)
    dr.sync_thread()
    return ev


def converter(width, height, frames):
    import mitsuba as mi
    stack, times = frame_stack(width, height, frames)
    device_stack = mi.TensorXf(stack)
    paths = ("device_frames", "on_device", "device", "device_per_step", "host")
    walls, streams = {name: float("inf") for name in paths}, {}
    # two rounds over the paths (this VM's speed drifts by 30 % within minutes), in each a path's first
    # conversion untimed (it compiles, and lets the allocator see the sizes: a first full run is 2-5x slower on
    # the CPU, fresh memory), then two timed; the best of the four counts. Alternating every run instead
    # measured the allocator churning between the paths' chunk sizes (1280x720: batched 32 M against 85 M)
    for _ in range(2):
        for name in paths:
            with _path(name):
                streams[name] = _convert(stack, times, name, device_stack)
                for _ in range(2):
                    t0 = time.perf_counter()
                    ev = _convert(stack, times, name, device_stack)
                    walls[name] = min(walls[name], time.perf_counter() - t0)
                    del ev
    res = {name: {"wall_s": walls[name], "events": len(streams[name]),
                  "mpix_steps_per_s": width * height * (frames - 1) / walls[name] / 1e6,
                  "mev_per_s": len(streams[name]) / walls[name] / 1e6, "stream": streams[name]} for name in paths}
    host = res["host"].pop("stream")
    device, per_step = res["device"].pop("stream"), res["device_per_step"].pop("stream")
    on_device = res["on_device"].pop("stream").numpy()
    device_frames = res["device_frames"].pop("stream").numpy()
    same = device.equals(host) and per_step.equals(host) and on_device.equals(device) and \
        device_frames.equals(device)
    return {"width": width, "height": height, "frames": frames, "identical": bool(same),
            "difference": {"device_per_step": _difference(device, per_step), "host": _difference(device, host),
                           "on_device": _difference(device, on_device),
                           "device_frames": _difference(device, device_frames)},
            **res}


def render_overhead(scene, duration, steps, reps=3, **defines):
    """Each path's render of ``scene`` ``reps`` times, alternating (the machine's quiet spells fall on all of
    them), after a warm-up render of its own freshly loaded scene; the fastest by wall time counts. Beyond the
    render: the summary's events + motion + write against its render time (as the summary prints it), and the
    whole wall time against the render time (setup, the accuracy-limit frame and work the summary's timers
    miss: a kernel queued behind the render counts as render time there)."""
    import drjit as dr

    import mitsuba_eventfield as ef
    paths = ("on_device", "device", "device_other_loop", "device_per_step", "host")
    scenes, best, streams = {}, {}, {}
    for name in paths:
        scenes[name] = ef.load_scene(scene, **defines)
        with _path(name):
            ef.render_events(scenes[name], duration / steps * 3, steps=3, reuse=False)   # compile
    for _ in range(reps):
        for name in paths:
            with _path(name):
                t0 = time.perf_counter()
                ev = ef.render_events(scenes[name], duration, steps=steps, reuse=False,
                                      on_device=name == "on_device")
                if name == "on_device":           # the events made, not merely queued
                    dr.eval(ev.xy, ev.t, ev.p)
                    dr.sync_thread()
                wall = time.perf_counter() - t0
            r = ev.meta["render"]
            beyond = r["events_s"] + r["motion_s"] + r["write_s"]
            row = {"render_s": r["render_s"], "events_s": r["events_s"], "write_s": r["write_s"],
                   "motion_s": r["motion_s"], "wall_s": wall, "beyond_render_pct": 100 * beyond / r["render_s"],
                   "wall_beyond_render_pct": 100 * (wall - r["render_s"]) / r["render_s"], "events": r["events"]}
            if name not in best or wall < best[name]["wall_s"]:
                best[name] = row
            if name not in streams:
                streams[name] = ev.numpy() if name == "on_device" else ev
            del ev
    alone = render_only(scenes["device"], duration, steps, reps)
    for name in paths:
        best[name]["wall_beyond_render_only_pct"] = 100 * (best[name]["wall_s"] - alone) / alone
    d, others = streams["device"], [k for k in paths if k != "device"]
    return {"scene": os.path.relpath(scene, SCENES), "steps": steps, "reps": reps, "render_only_wall_s": alone,
            "overlapped": __import__("mitsuba_eventfield").backend.overlaps_steps(),
            "identical": all(d.equals(streams[k]) for k in others),
            "difference": {k: _difference(d, streams[k]) for k in others}, **best}


def render_only(timed, duration, steps, reps):
    """Wall time of the same instants' radiance renders alone: ``set_time`` and the loop's frozen render
    (``frames.FrameRenderer``, the scene's spp and the loop's fixed seed), no events, one sync at the end;
    fastest of ``reps``. The baseline of "beyond the render" by wall time: on a GPU the loop overlaps the
    host's work with the device's (``backend.overlaps_steps``), so its own render/motion split is not one."""
    import drjit as dr

    from mitsuba_eventfield.simulate.frames import FrameRenderer
    renderer = FrameRenderer(timed.scene.integrator().inner, timed.sensor.sampler().sample_count())
    times = np.linspace(0.0, duration, steps + 1)
    for t in times[:3]:                                  # recordings of the frozen render
        timed.set_time(float(t))
        renderer.render(timed, 0)
    best = math.inf
    for _ in range(reps):
        dr.sync_thread()
        t0 = time.perf_counter()
        for t in times:
            timed.set_time(float(t))
            frame = renderer.render(timed, 0)
        dr.eval(frame)
        dr.sync_thread()
        best = min(best, time.perf_counter() - t0)
    return best


def _difference(a, b):
    """Where two streams differ (None when they do not)."""
    if a.equals(b):
        return None
    if len(a) != len(b):
        return f"{len(a)} against {len(b)} events"
    bad = {k: int(np.count_nonzero(getattr(a, k) != getattr(b, k))) for k in "xytp"}
    return f"events differing per column: {bad}"


def device_name():
    import mitsuba as mi
    variant = mi.variant()
    if variant.startswith("cuda"):
        import subprocess
        try:
            return subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True,
                                  text=True, check=True).stdout.strip().splitlines()[0]
        except (OSError, subprocess.CalledProcessError, IndexError):
            return "CUDA GPU (name unknown)"
    return f"CPU, {os.cpu_count()} threads (LLVM)"


def main(quick=False):
    import mitsuba_eventfield as ef
    ef.set_variant(os.environ.get("EVENTFIELD_VARIANT") or None)
    sizes = [(346, 260, 40 if quick else 200)] + ([] if quick else [(1280, 720, 60)])
    conv = [converter(*s) for s in sizes]
    demo, fan = os.path.join(SCENES, "demo", "demo.xml"), os.path.join(SCENES, "fan", "fan.xml")
    if __import__("mitsuba").variant().startswith("cuda") and not quick:
        # issue 15's own rows on a GPU: the demo for 0.1 s in 100 steps, the fan at 1280x720 for 20 ms in 400
        # steps (165 M events; two repetitions, device minutes are scarce)
        renders = [render_overhead(demo, 0.1, 100, reps=2),
                   render_overhead(fan, 0.02, 400, reps=2, width=1280, height=720)]
    else:
        renders = [render_overhead(demo, 0.02, 20 if quick else 40)]
        if not quick:
            renders.append(render_overhead(fan, 0.008, 64, width=346, height=260))
    device = device_name()
    res = {"device": device, "variant": __import__("mitsuba").variant(), "converter": conv, "renders": renders,
           "targets": {"batched, per-step and host events identical on the same frames":
                       all(c["identical"] for c in conv)}}
    md = [f"# Event engine: device path against host path ({device}, {res['variant']})", "",
          "Converter (synthetic 2 kHz stack, ideal pixel, C = 0.2; Mpix-steps/s):", "",
          "| film | frames | events | frames and events on the device | events left on the device | device, "
          "batched, to the host | device, a frame a step | host | batched / per step | batched / host | all "
          "identical |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in conv:
        f, o, d, s, h = (c[k]["mpix_steps_per_s"]
                         for k in ("device_frames", "on_device", "device", "device_per_step", "host"))
        md.append(f"| {c['width']}x{c['height']} | {c['frames']} | {c['device']['events']} | {f:.1f} | {o:.1f} | "
                  f"{d:.1f} | {s:.1f} | {h:.1f} | {d / s:.2f}x | {d / h:.2f}x | {c['identical']} |")
    md += ["", "Renders (fastest of the repetitions by wall time; beyond the render: the summary's events + motion "
           "+ write, and the whole wall time, each as % of the render):", "",
           "| scene | steps | events | path | render s | events / motion / write s | beyond render | wall beyond "
           "render | wall beyond the renders alone |", "|---|---|---|---|---|---|---|---|---|"]
    other = "synced after each render" if renders and renders[0]["overlapped"] else "overlapped"
    labels = {"on_device": "device, events left there", "device": "device, steps in batches",
              "device_other_loop": f"device, steps in batches, loop {other}",
              "device_per_step": "device, a step a commit", "host": "host"}
    for r in renders:
        for k, label in labels.items():
            d = r[k]
            md.append(f"| {r['scene']} | {r['steps']} | {d['events']} | {label} | {d['render_s']:.3f} | "
                      f"{d['events_s']:.3f} / {d['motion_s']:.3f} / {d['write_s']:.3f} | "
                      f"{d['beyond_render_pct']:.1f}% | {d['wall_beyond_render_pct']:.1f}% | "
                      f"{d['wall_beyond_render_only_pct']:.1f}% |")
    md += ["", "Renders with identical events on every path: "
           + ", ".join(f"{r['scene']} {r['identical']}" for r in renders) + ". The render rows compare separate "
           "renders, so they also compare the renderer with itself: the fan (moving mesh, acceleration structure "
           "rebuilt every step) has been seen to differ by a timestamp or two between two renders of the same path "
           "and seed. The converter rows feed the same frames to every path and are the test of the engine. "
           "The summary's timers run on the render thread while kernels run asynchronously: an event kernel "
           "still queued when the next render starts counts as render time, which is why the wall column is "
           "given too (it also holds the render's setup and its accuracy-limit frame). The last column compares "
           "the whole wall time with that of the same instants rendered alone (set_time and the loop's frozen "
           "render, no events: "
           + ", ".join(f"{r['scene']} {r['render_only_wall_s']:.3f} s" for r in renders) + "), the measure "
           "where the loop overlaps host and device work (on a GPU: "
           + ("on here" if renders and renders[0]["overlapped"] else "off here") + ").", ""]
    write_results("event_engine", res, md)


if __name__ == "__main__":
    main(quick="--quick" in sys.argv)
