"""Event-file write and read throughput (issues 15, 16): ef.write_events and ef.read_events on each format,
~2M events at 640x480.

Each file is written three times (h5, npz, txt, aedat4 by this package's writers; RAW EVT 2.0 / 3.0 and DAT by
faery's, as a camera's software would) and read three times; the best of each counts. The writers replaced are
timed in the same run for the ratio: text by ``np.savetxt``, AEDAT4 by dv-processing's writer (an
``EventStore.push_back`` an event; when dv-processing is installed). AEDAT4 is also read through the
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


def _best(run, repeats=3):
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = run()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _savetxt(path, ev):
    """The text writer before events/text.py."""
    with open(path, "w") as f:
        f.write(f"{ev.width} {ev.height}\n")
        np.savetxt(f, np.column_stack([ev.t * 1e-6, ev.x, ev.y, (ev.p > 0).astype(np.int64)]),
                   fmt=["%.6f", "%d", "%d", "%d"])


def _dv_writer(path, ev, chunk=1 << 16):
    """The AEDAT4 writer before faery's encoder: dv-processing, a Python call an event."""
    import dv_processing as dv
    writer = dv.io.MonoCameraWriter(path, dv.io.MonoCameraWriter.EventOnlyConfig("bench", (ev.width, ev.height)))
    for i in range(0, len(ev), chunk):
        store = dv.EventStore()
        for ti, xi, yi, pi in zip(ev.t[i:i + chunk].tolist(), ev.x[i:i + chunk].tolist(),
                                  ev.y[i:i + chunk].tolist(), (ev.p[i:i + chunk] > 0).tolist()):
            store.push_back(ti, xi, yi, pi)
        writer.writeEvents(store)
    del writer


def _before(d, stream, runs):
    """The replaced writers, timed beside ours."""
    import importlib.util
    before = {"txt": _savetxt}
    if importlib.util.find_spec("dv_processing") is not None:
        before["aedat4"] = _dv_writer
    for name, write in before.items():
        path = os.path.join(d, f"before.{name}")
        s, _ = _best(lambda: write(path, stream))
        runs[name]["write_before_s"] = s


def main(n=2_000_000):
    import mitsuba_eventfield as ef
    from mitsuba_eventfield.events.aedat import read_aedat4
    stream = _stream(ef, n)
    runs = {}
    with tempfile.TemporaryDirectory() as d:
        for name, ext, version in FORMATS:
            path = os.path.join(d, name.replace(" ", "_") + ext)
            w, _ = _best(lambda: ef.write_events(path, stream, version))
            s, ev = _best(lambda: ef.read_events(path))
            assert ev.equals(stream), name
            runs[name] = {"events": n, "write_s": w, "read_s": s, "events_per_s": n / s,
                          "bytes": os.path.getsize(path)}
        _before(d, stream, runs)
        path = os.path.join(d, "aedat4.aedat4")
        s, ev = _best(lambda: read_aedat4(path))
        assert ev.equals(stream)
        runs["aedat4 (dv-processing child)"] = {"events": n, "read_s": s, "events_per_s": n / s,
                                                "bytes": os.path.getsize(path)}
    res = {"events": n, "runs": runs, "targets": {}}
    md = [f"# Event-file writes and reads ({n / 1e6:g}M events, 640x480, best of 3, one run)", "",
          "| format | write s | ns an event | writer before, s | ours / before | read s | Mevents/s | bytes/event |",
          "|---|---|---|---|---|---|---|---|"]
    for k, v in runs.items():
        w, b = v.get("write_s"), v.get("write_before_s")
        md.append(f"| {k} | {'-' if w is None else f'{w:.3f}'} | {'-' if w is None else f'{w / n * 1e9:.0f}'} | "
                  f"{'-' if b is None else f'{b:.3f}'} | {'-' if b is None else f'{b / w:.1f}x faster'} | "
                  f"{v['read_s']:.3f} | {v['events_per_s'] / 1e6:.1f} | {v['bytes'] / n:.2f} |")
    md += ["", "Writers before: text through `np.savetxt` (a Python formatting call a value), AEDAT4 through "
           "dv-processing (`EventStore.push_back` an event, its only way in from Python); now text lines are laid "
           "out by array operations (events/text.py, the same bytes) and AEDAT4 packets go to faery's encoder "
           "(LZ4). A write includes the checks of the events and of the disk, and the rename into place.",
           "", "RAW, DAT and AEDAT4 are decoded by faery; AEDAT4's dv-processing reader is the fallback when faery "
           "is not installed.", ""]
    write_results("readers", res, md)


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:]))
