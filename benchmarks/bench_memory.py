"""Peak host memory against render length (issue 15): the fan (moving blades, 250 Hz galvo scan) rendered to
HDF5 for 10x different durations; with events kept on the device in bounded chunks and a bounded writer queue,
the peak resident memory should not grow with the duration (target <= 1.1x; the writer holds glibc's mmap
threshold for it: ``events/writer.py``). Each run is its own process
(peak RSS from getrusage). CPU numbers on the CPU; run under CUDA for the GPU's (GPU memory then also counts).

Fan at 346x260 (the CPU cannot render 1280x720 for 0.5 s in a benchmark), 40 steps per 4 ms period, 4 spp:
0.05 s (500 steps) against 0.5 s (5000 steps), the issue's durations (the first ~200 steps warm Dr.Jit's and the
C allocator's caches, some 25 MB reached once and not grown: a shorter first run would count it as growth), like
with like: once with every pixel rendered each step and once
with the static-pixel split (``simulate/static_pixels.py``) forced on for both lengths. The split starts by
itself only from ``MIN_PERIODS`` scan periods, so a plain 0.05 s against 0.5 s run would compare two methods:
the split holds one period of static frames, its masks and its recorded wavefronts, a fixed cost that does not
grow with the duration (its own row says how much). In memory (no output file) the events themselves are the
result and grow with the duration by design (13 bytes each, ``events/buffer.py``): there the memory held beyond
the process before the render and the events' own bytes should not grow with them. 0.05 s against 0.1 s; target:
that overhead grows by <= 5 % of what the events grow by. Writes
benchmarks/results/memory.json and .md.
Usage: ./run bench memory   (python benchmarks/bench_memory.py --every-pixel-only: the every-pixel pair alone)
"""
import json
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402

FAN = os.path.join(os.path.dirname(HERE), "scenes", "fan", "fan.xml")
CHILD = r"""
import json, resource, sys, time
import mitsuba_eventfield as ef
from mitsuba_eventfield.simulate import static_pixels
duration, out, split = float(sys.argv[1]), sys.argv[2], sys.argv[4] == "split"
static_pixels.MIN_PERIODS = 1                      # with the split: on at every length (it needs two periods)
timed = ef.load_scene(sys.argv[3], width=346, height=260)
t0 = time.perf_counter()
s = ef.render_events(timed, duration, steps=int(round(duration / 1e-4)), output=out, event_buffer_mb=16,
                     reuse=split)
print(json.dumps({"peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "events": s.events,
                  "duration": duration, "steps": s.steps, "wall_s": time.perf_counter() - t0,
                  "variant": __import__("mitsuba").variant(), "gpu_mb": gpu_used_mb()}))
"""

# Under CUDA, the GPU memory in use when the render has returned: Dr.Jit's allocator keeps the blocks it freed
# in its cache (nothing here flushes it), so this is the render's peak device footprint plus the CUDA context.
# The GPU is this process's alone on the device machine. None on the CPU.
GPU_USED = r"""
def gpu_used_mb():
    import subprocess
    import mitsuba as mi
    if not mi.variant().startswith("cuda"):
        return None
    import drjit as dr
    dr.sync_thread()
    q = subprocess.run(["nvidia-smi", "--query-gpu=memory.used", "--format=csv,noheader,nounits"],
                       capture_output=True, text=True)
    return float(q.stdout.split()[0]) if q.returncode == 0 and q.stdout.strip() else None
"""
CHILD = GPU_USED + CHILD

IN_MEMORY = r"""
import json, resource, sys, time
import mitsuba_eventfield as ef
duration = float(sys.argv[1])
timed = ef.load_scene(sys.argv[2], width=346, height=260)
ef.render_events(timed, 0.001, steps=10)                     # compiled, recorded: the process as a user has it
with open("/proc/self/statm") as f:
    before = int(f.read().split()[1]) * resource.getpagesize() / 2**20
t0 = time.perf_counter()
ev = ef.render_events(timed, duration, steps=int(round(duration / 1e-4)), reuse=False)
print(json.dumps({"peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "before_mb": before,
                  "events": len(ev), "events_mb": len(ev) * 13 / 2**20, "wall_s": time.perf_counter() - t0}))
"""


def run_in_memory(duration):
    r = subprocess.run([sys.executable, "-c", IN_MEMORY, str(duration), FAN], capture_output=True, text=True,
                       check=True)
    return json.loads(r.stdout[r.stdout.rindex("{"):])


def run(duration, mode):
    with tempfile.TemporaryDirectory() as tmp:
        r = subprocess.run([sys.executable, "-c", CHILD, str(duration), os.path.join(tmp, "fan.h5"), FAN, mode],
                           capture_output=True, text=True, check=True)
    return json.loads(r.stdout[r.stdout.rindex("{"):])          # after any Mitsuba log lines


def overhead_mb(mem):
    """What an in-memory render holds beyond the process before it and the events it returns."""
    return mem["peak_rss_mb"] - mem["before_mb"] - mem["events_mb"]


def main(every_pixel_only=False):
    """``every_pixel_only`` (``--every-pixel-only``): the to-file pair with every pixel rendered and nothing
    else, which is what a GPU session has the minutes for."""
    modes = {"every pixel": "all"} if every_pixel_only else {"every pixel": "all", "static-pixel split": "split"}
    runs = {name: (run(0.05, mode), run(0.5, mode)) for name, mode in modes.items()}
    ratios = {name: long_["peak_rss_mb"] / short["peak_rss_mb"] for name, (short, long_) in runs.items()}
    gpu_ratios = {name: long_["gpu_mb"] / short["gpu_mb"] for name, (short, long_) in runs.items()
                  if short.get("gpu_mb")}
    mem = {} if every_pixel_only else {d: run_in_memory(d) for d in (0.05, 0.1)}
    targets = {f"{name}: peak RSS flat (<= 1.1x)": r <= 1.1 for name, r in ratios.items()}
    targets.update({f"{name}: GPU memory flat (<= 1.1x)": r <= 1.1 for name, r in gpu_ratios.items()})
    mem_ratio = None
    if mem:
        mem_ratio = ((overhead_mb(mem[0.1]) - overhead_mb(mem[0.05]))
                     / (mem[0.1]["events_mb"] - mem[0.05]["events_mb"]))
        targets["in memory: what is held beyond the events grows <= 5 % of the events"] = mem_ratio <= 0.05
    res = {"runs": {name: {"short": s, "long": l} for name, (s, l) in runs.items()}, "ratios": ratios,
           "in_memory": {str(d): m for d, m in mem.items()}, "in_memory_overhead_growth_share": mem_ratio,
           "targets": targets}
    variant = runs["every pixel"][0]["variant"]
    gpu = any(r.get("gpu_mb") for pair in runs.values() for r in pair)
    md = [f"# Peak host memory against render length (fan 346x260, {variant}, one run each, to HDF5)", "",
          "| pixels rendered | duration | steps | events | peak RSS MB | " + ("GPU MB in use after | " if gpu else "")
          + "wall s |", "|---|---|---|---|---|" + ("---|" if gpu else "") + "---|"]
    for name, pair in runs.items():
        md += [f"| {name} | {r['duration']:g} s | {r['steps']} | {r['events']} | {r['peak_rss_mb']:.0f} | "
               + (f"{r['gpu_mb']:.0f} | " if gpu else "") + f"{r['wall_s']:.1f} |" for r in pair]
    md += [""] + [f"Peak RSS ratio for 10x the duration, {name}: **{r:.3f}** (target <= 1.1)."
                  for name, r in ratios.items()]
    md += [f"GPU memory ratio for 10x the duration, {name}: **{r:.3f}** (target <= 1.1; Dr.Jit's allocator keeps "
           "what it freed, so the memory in use after the render is its peak plus the CUDA context)."
           for name, r in gpu_ratios.items()]
    if "static-pixel split" in runs:
        md += ["", f"The split's fixed cost at 0.5 s: "
               f"{runs['static-pixel split'][1]['peak_rss_mb'] - runs['every pixel'][1]['peak_rss_mb']:+.0f} MB "
               "(one period of static frames, masks, recorded wavefronts; it does not grow with the duration)."]
    if mem:
        md += ["", "In memory (no file; every pixel rendered; the events are the result, 13 bytes each):", "",
               "| duration | events | events MB | resident before MB | peak MB | held beyond the events MB |",
               "|---|---|---|---|---|---|"]
        md += [f"| {d:g} s | {m['events']} | {m['events_mb']:.0f} | {m['before_mb']:.0f} | {m['peak_rss_mb']:.0f} "
               f"| {overhead_mb(m):.0f} |" for d, m in mem.items()]
        md += ["", f"From 0.05 to 0.1 s what is held beyond the events grows by **{100 * mem_ratio:.1f} %** of "
               "what the events grow by (target <= 5 %)."]
    md += [""]
    write_results("memory", res, md)


if __name__ == "__main__":
    main(every_pixel_only="--every-pixel-only" in sys.argv)
