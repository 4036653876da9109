"""Event-file read throughput (issue 16): ef.read_events on each input format, ~2M events at 640x480.

Each file is written once (h5, npz, txt, aedat4 by this package's writers; RAW EVT 2.0 / 3.0 and DAT by faery's,
as a camera's software would) and read three times; the best read counts. AEDAT4 is also read through the
dv-processing child process (``read_aedat4``), the reader faery replaced. Writes benchmarks/results/readers.json
and .md.  Usage: ./run bench readers [N_EVENTS]
"""
import os
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402

FORMATS = [("h5", ".h5", None), ("npz", ".npz", None), ("txt", ".txt", None), ("aedat4", ".aedat4", None),
           ("raw evt2", ".raw", "evt2"), ("raw evt3", ".raw", "evt3"), ("dat", ".dat", None)]


def _stream(ef, n):
    rng = np.random.default_rng(0)
    t = np.sort(rng.integers(0, 10_000_000, n))
    return ef.EventStream(rng.integers(0, 640, n), rng.integers(0, 480, n), t, rng.choice([-1, 1], n), 640, 480,
                          {"duration_us": 10_000_000})


def _best_read(read, path, repeats=3):
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        ev = read(path)
        best = min(best, time.perf_counter() - t0)
    return best, ev


def main(n=2_000_000):
    import mitsuba_eventfield as ef
    from mitsuba_eventfield.events.aedat import read_aedat4
    stream = _stream(ef, n)
    runs = {}
    with tempfile.TemporaryDirectory() as d:
        for name, ext, version in FORMATS:
            path = os.path.join(d, name.replace(" ", "_") + ext)
            ef.write_events(path, stream, version)
            s, ev = _best_read(ef.read_events, path)
            assert ev.equals(stream), name
            runs[name] = {"events": n, "read_s": s, "events_per_s": n / s, "bytes": os.path.getsize(path)}
        path = os.path.join(d, "aedat4.aedat4")
        s, ev = _best_read(read_aedat4, path)
        assert ev.equals(stream)
        runs["aedat4 (dv-processing child)"] = {"events": n, "read_s": s, "events_per_s": n / s,
                                                "bytes": os.path.getsize(path)}
    res = {"events": n, "runs": runs, "targets": {}}
    md = [f"# Event-file reads ({n / 1e6:g}M events, 640x480, best of 3)", "",
          "| format | read s | Mevents/s | bytes/event |", "|---|---|---|---|"]
    md += [f"| {k} | {v['read_s']:.3f} | {v['events_per_s'] / 1e6:.1f} | {v['bytes'] / n:.2f} |"
           for k, v in runs.items()]
    md += ["", "RAW, DAT and AEDAT4 are decoded by faery; AEDAT4's dv-processing reader is the fallback when faery "
           "is not installed.", ""]
    write_results("readers", res, md)


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:]))
