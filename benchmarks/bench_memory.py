"""Peak host memory against render length (issue 15): the fan (moving blades, 250 Hz galvo scan) rendered to
HDF5 for 10x different durations; with events kept on the device in bounded chunks and a bounded writer queue,
the peak resident memory should not grow with the duration (target <= 1.1x). Each run is its own process
(peak RSS from getrusage). CPU numbers on the CPU; run under CUDA for the GPU's (GPU memory then also counts).

Fan at 346x260 (the CPU cannot render 1280x720 for 0.5 s in a benchmark), 40 steps per 4 ms period, 4 spp:
0.02 s (200 steps) against 0.2 s (2000 steps). Writes benchmarks/results/memory.json and .md.
Usage: ./run bench memory
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
duration, out = float(sys.argv[1]), sys.argv[2]
timed = ef.load_scene(sys.argv[3], width=346, height=260)
t0 = time.perf_counter()
s = ef.render_events(timed, duration, steps=int(round(duration / 1e-4)), output=out, event_buffer_mb=16)
print(json.dumps({"peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "events": s.events,
                  "wall_s": time.perf_counter() - t0, "variant": __import__("mitsuba").variant()}))
"""


def run(duration):
    with tempfile.TemporaryDirectory() as tmp:
        r = subprocess.run([sys.executable, "-c", CHILD, str(duration), os.path.join(tmp, "fan.h5"), FAN],
                           capture_output=True, text=True, check=True)
    return json.loads(r.stdout[r.stdout.rindex("{"):])          # after any Mitsuba log lines


def main():
    short, long_ = run(0.02), run(0.2)
    ratio = long_["peak_rss_mb"] / short["peak_rss_mb"]
    res = {"short": short, "long": long_, "ratio": ratio, "targets": {"peak RSS flat (<= 1.1x)": ratio <= 1.1}}
    md = [f"# Peak host memory against render length (fan 346x260, {short['variant']}, one run each)", "",
          "| duration | steps | events | peak RSS MB | wall s |", "|---|---|---|---|---|",
          f"| 0.02 s | 200 | {short['events']} | {short['peak_rss_mb']:.0f} | {short['wall_s']:.1f} |",
          f"| 0.2 s | 2000 | {long_['events']} | {long_['peak_rss_mb']:.0f} | {long_['wall_s']:.1f} |", "",
          f"Peak RSS ratio 10x duration: **{ratio:.3f}** (target <= 1.1).", ""]
    write_results("memory", res, md)


if __name__ == "__main__":
    main()
