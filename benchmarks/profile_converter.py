"""Where the converter's time goes on the active backend (issue 15, the converter's pixel-steps target): the
frames-and-events-on-the-device path of ``bench_event_engine`` (the same synthetic 2 kHz stack, ideal pixel,
C = 0.2; and the same translating ten times slower, a sparser stack) with Dr.Jit's kernel history on. Per
film: the wall time, the kernels' summed execution time, and the kernels grouped by kind and size class (a
sort pass, the count pass and the fill each show as their own rows), so that the gap between the wall time
and the kernels (host tracing, launches, syncs) and the costliest kernels read off one table. A profile, not a target: it writes only benchmarks/results/converter_profile.md and
.json. Usage: python benchmarks/profile_converter.py [--quick]
"""
import collections
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import profile_rows, write_results  # noqa: E402
from bench_event_engine import device_name, frame_stack  # noqa: E402


def profile(width, height, frames, speed=1.5, reps=3):
    import drjit as dr
    import mitsuba as mi

    import mitsuba_eventfield as ef
    stack, times = frame_stack(width, height, frames, speed=speed)
    device_stack = mi.TensorXf(stack)

    def convert():
        ev = ef.events_from_frames(device_stack, times, threshold=0.2, on_device=True)
        dr.eval(ev.xy, ev.t, ev.p)
        dr.sync_thread()
        return len(ev)

    convert()                                              # compile and record
    best = None
    for _ in range(reps):
        dr.kernel_history()                                # empties it
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        t0 = time.perf_counter()
        events = convert()
        wall = time.perf_counter() - t0
        history = dr.kernel_history()
        dr.set_flag(dr.JitFlag.KernelHistory, False)
        if best is None or wall < best[0]:
            best = (wall, events, history)
    wall, events, history = best
    groups = collections.defaultdict(lambda: [0, 0.0])
    for k in history:
        kind = str(k.get("type", "?")).split(".")[-1]
        size = int(k.get("size", 0))
        label = f"{kind}, {k.get('operation_count', '?')} ops, size {_size_class(size)}"
        groups[label][0] += 1
        groups[label][1] += float(k.get("execution_time", 0.0))
    kernels_ms = sum(v[1] for v in groups.values())
    rows = sorted(({"kernel": key, "launches": n, "ms": ms} for key, (n, ms) in groups.items()),
                  key=lambda r: -r["ms"])
    return {"width": width, "height": height, "frames": frames, "speed_px": speed, "events": events,
            "events_per_pixel_step": events / (width * height * (frames - 1)), "wall_ms": 1e3 * wall,
            "kernels_ms": kernels_ms, "launches": len(history),
            "mpix_steps_per_s": width * height * (frames - 1) / wall / 1e6, "groups": rows,
            "host": host_profile(convert)}


def host_profile(convert, top=12):
    """The host side of one conversion: the Python functions with the most time of their own (cProfile, which
    slows Python down; a function that waits for the device, a sync, holds the wait as its own time)."""
    import cProfile
    import pstats
    prof = cProfile.Profile()
    prof.enable()
    convert()
    prof.disable()
    return profile_rows(pstats.Stats(prof), "tottime", top)


def _size_class(n):
    """A size as a power-of-two class (kernels of one kind differ in size from chunk to chunk)."""
    return f"~2^{max(0, n - 1).bit_length()}" if n > 1 else str(n)


def main(quick=False):
    import mitsuba as mi

    import mitsuba_eventfield as ef
    ef.set_variant(os.environ.get("EVENTFIELD_VARIANT") or None)
    sizes = [(346, 260, 40 if quick else 200)] + ([] if quick else [(1280, 720, 60)])
    device = device_name()
    # the benchmark's stack, then the same translating ten times slower: the kernels' cost follows the events
    # (1.0-1.2 a pixel-step there, 0.18-0.33 here; the rotating bar alone makes 0.08-0.23)
    res = [profile(*s, speed=speed) for speed in (1.5, 0.15) for s in sizes]
    md = [f"# The converter's time, kernel by kernel ({device}, {mi.variant()})", "",
          "Frames and events on the device (the synthetic 2 kHz stack of bench_event_engine, ideal pixel, "
          "C = 0.2), fastest of 3 with Dr.Jit's kernel history on (which itself syncs after each kernel: the "
          "wall time here is above bench_event_engine's).", ""]
    for r in res:
        md += [f"## {r['width']}x{r['height']}, {r['frames']} frames, translation {r['speed_px']} px a frame: "
               f"{r['events']} events ({r['events_per_pixel_step']:.2f} a pixel-step)", "",
               f"Wall {r['wall_ms']:.1f} ms ({r['mpix_steps_per_s']:.0f} M pixel-steps/s); kernels "
               f"{r['kernels_ms']:.1f} ms in {r['launches']} launches; the rest (host, launches, syncs) "
               f"{r['wall_ms'] - r['kernels_ms']:.1f} ms.", "",
               "| kernel (kind, operations, size) | launches | ms | share of the kernels |", "|---|---|---|---|"]
        md += [f"| {g['kernel']} | {g['launches']} | {g['ms']:.2f} | {100 * g['ms'] / max(r['kernels_ms'], 1e-9):.0f} % |"
               for g in r["groups"][:15]]
        md += ["", "The host side of one conversion (cProfile; a function that waits on the device holds the wait):",
               "", "| function | calls | own ms |", "|---|---|---|"]
        md += [f"| `{h['function']}` | {h['calls']} | {h['own_ms']:.2f} |" for h in r["host"]]
        md.append("")
    write_results("converter_profile", {"device": device, "variant": mi.variant(), "films": res}, md)


if __name__ == "__main__":
    main(quick="--quick" in sys.argv[1:])
