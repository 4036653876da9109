"""The converter's chunk shape on the active backend (issue 15, the converter's pixel-steps target): frames per
kernel (``events_from_frames(frames_per_kernel=)``) against the time sort's radix width
(``event_fill.PASS_BITS``), with frames and events left on the device, on the synthetic 2 kHz stack of
bench_event_engine (dense: 1.0-1.2 events a pixel-step) and the same translating ten times slower (sparse).

Why: on an H200 the converter made 2,341 / 3,631 M pixel-steps/s (346x260 / 1280x720) against a target of
4,000 / 12,000; 40 % of its kernel time was the time sort (two 8-bit passes for a 64-frame chunk's 15-bit
key), and 2.9 of its 7.0 ms went to the host, launches and syncs (four chunks: one sync each). More frames a
chunk means fewer syncs but a longer key; a wider pass means fewer passes but a larger histogram. The H200's
answer (chunk_shape_h200.md) set CUDA's frames a kernel; wider passes were unstable there (16 bits
misordered events), so CUDA's width is set by stability (event_fill.PASS_BITS). On the CPU the defaults came
from such a sweep (``event_batch.LANE_STEPS``, ``event_fill.PASS_BITS``). Every variant must give the same events (checked
here: a variant that does not is reported, not timed). Rounds interleave the variants; fastest of the rounds.

Writes benchmarks/results/chunk_shape.json and .md. Usage: python benchmarks/bench_chunk_shape.py [--quick]
"""
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402
from bench_event_engine import device_name, frame_stack  # noqa: E402


def sweep(width, height, frames, speed, frames_per_kernel, pass_bits, rounds):
    import drjit as dr
    import mitsuba as mi

    import mitsuba_eventfield as ef
    from mitsuba_eventfield.plugins import event_fill
    stack, times = frame_stack(width, height, frames, speed=speed)
    tensor = mi.TensorXf(stack)
    key = "cuda" if mi.variant().startswith("cuda") else "llvm"
    default_bits = event_fill.PASS_BITS[key]

    def convert(fpk, bits):
        event_fill.PASS_BITS[key] = bits
        try:
            ev = ef.events_from_frames(tensor, times, threshold=0.2, on_device=True, frames_per_kernel=fpk)
            dr.eval(ev.xy, ev.t, ev.p)
            dr.sync_thread()
            return ev
        finally:
            event_fill.PASS_BITS[key] = default_bits

    variants = [(f, b) for f in frames_per_kernel for b in pass_bits]
    reference = convert(None, default_bits)
    best, same = {}, {}
    for v in variants:                          # compile and record each shape; check its events
        same[v] = convert(*v).equals(reference)
    for _ in range(rounds):
        for v in variants:
            if not same[v]:
                continue
            t0 = time.perf_counter()
            convert(*v)
            best[v] = min(best.get(v, float("inf")), time.perf_counter() - t0)
    steps = width * height * (frames - 1)
    rows = [{"frames_per_kernel": f or "default", "pass_bits": b, "same_events": same[(f, b)],
             "mpix_steps_per_s": steps / best[(f, b)] / 1e6 if (f, b) in best else None} for f, b in variants]
    return {"width": width, "height": height, "frames": frames, "speed_px": speed, "events": len(reference),
            "events_per_pixel_step": len(reference) / steps, "default_pass_bits": default_bits, "rows": rows}


def main(quick=False):
    import mitsuba as mi

    import mitsuba_eventfield as ef
    ef.set_variant(os.environ.get("EVENTFIELD_VARIANT") or None)
    cuda = mi.variant().startswith("cuda")
    films = [(346, 260, 40 if quick else 200)] + ([] if quick else [(1280, 720, 60)])
    fpk = [None, 16, 64, 200] if cuda else [None, 2, 8]
    # CUDA: 8 (the default) and 16, a width Dr.Jit's CUDA histogram does not keep stable (event_fill.PASS_BITS):
    # where a key takes one pass that wide, the events differ (that row is reported, not timed); a key of 17+
    # bits splits into passes of 9 bits, which an H200 still keeps stable
    bits = [8, 16] if cuda else [11, 20]
    res = [sweep(*film, speed, fpk, bits, 2 if quick else 3) for speed in (1.5, 0.15) for film in films]
    md = [f"# The converter's chunk shape ({device_name()}, {mi.variant()})", "",
          "Frames and events on the device, the synthetic 2 kHz stack (ideal pixel, C = 0.2), M pixel-steps/s, "
          "fastest of interleaved rounds; frames per kernel (default: `event_batch.default_frames_per_kernel`) "
          "against the time sort's radix pass width (`event_fill.PASS_BITS`; a key splits into passes of equal "
          "width up to it). A variant whose events differ is not timed (-): on CUDA a pass too wide for Dr.Jit's "
          "stable histogram (beyond 9-10 bits on an H200) misorders them.", "",
          "| film | frames | events a pixel-step | frames a kernel | pass bits | M pixel-steps/s | same events |",
          "|---|---|---|---|---|---|---|"]
    for r in res:
        for row in r["rows"]:
            speed = f"{row['mpix_steps_per_s']:.0f}" if row["mpix_steps_per_s"] else "-"
            md.append(f"| {r['width']}x{r['height']} | {r['frames']} | {r['events_per_pixel_step']:.2f} | "
                      f"{row['frames_per_kernel']} | {row['pass_bits']} | {speed} | {row['same_events']} |")
    res_all = {"device": device_name(), "variant": mi.variant(), "films": res,
               "targets": {"every shape at the default pass width gives the same events":
                           all(row["same_events"] for r in res for row in r["rows"]
                               if row["pass_bits"] == r["default_pass_bits"])}}
    write_results("chunk_shape", res_all, md + [""])


if __name__ == "__main__":
    main(quick="--quick" in sys.argv[1:])
