"""HDF5 event writing (issue 15, "writing keeps up"): H5EventWriter's chunks deflated on a thread pool and stored
with write_direct_chunk, against HDF5's own shuffle + deflate filters on the writing thread (``threads=0``).

Events: the fan (scenes/fan, 346x260, 2 scan periods, 64 steps) rendered once into memory, a real event stream's
compressibility. Each setting writes it as a render streams it (appends of the render's chunk size, here a
sixteenth of the stream) three times; the fastest counts. Every file is read back and compared, and their sizes
are given; the default thread count also with HDF5 chunks four times larger (the writer thread's own work
is per chunk, and on a GPU that thread paced the fan to HDF5: results/gpu_h200.md). Then the fan rendered to
.h5 with the writer's default threads and with ``threads=0``: the summary's writer_busy_s (the background
writer's time) against render_s, and writer_wait_s (the render blocked on the writer: the measure of a disk or
compression bottleneck).

Then a GPU-sized stream (the fan tiled $EVENTFIELD_WRITER_TILES times: 16 on 8 or more cores, else 4; 0 skips it)
at HDF5 chunks of 65,536 to 1 M events, with the serial floor at each.

Writes benchmarks/results/writer.json and .md with the machine's name.  Usage: ./run bench writer
"""
import os
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402
from bench_event_engine import device_name  # noqa: E402

FAN = os.path.join(os.path.dirname(HERE), "scenes", "fan", "fan.xml")


BIG_CHUNK = 4 * 65536       # the writer thread's own work is per HDF5 chunk: fewer, larger chunks share it


def write_once(stream, path, threads, chunk=65536, pieces=16):
    import mitsuba_eventfield as ef
    n = len(stream)
    step = -(-n // pieces)
    t0 = time.perf_counter()
    with ef.H5EventWriter(path, stream.width, stream.height, threads=threads, chunk=chunk) as w:
        for k in range(0, n, step):
            w.append(stream.x[k:k + step], stream.y[k:k + step], stream.t[k:k + step], stream.p[k:k + step])
    return time.perf_counter() - t0


def writer_alone(stream, settings, reps=3):
    import mitsuba_eventfield as ef
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for threads, chunk in settings:
            # a new name each time: ext4 (auto_da_alloc) writes a file out to disk when it is renamed over
            # another (the writer's last step): 28-43 ms for 50 MB on this machine, against 0.06 ms to a new name
            paths = [os.path.join(tmp, f"t{threads}_{chunk}_{k}.h5") for k in range(reps)]
            best = min(write_once(stream, path, threads, chunk) for path in paths)
            path = paths[0]
            rows.append({"threads": threads, "chunk": chunk, "write_s": best, "mev_per_s": len(stream) / best / 1e6,
                         "mib": os.path.getsize(path) / 2**20, "identical": ef.read_events(path).equals(stream)})
    return rows


def serial_floor(stream, threads, reps=3, chunk=65536, pieces=16):
    """The same writes with every chunk's deflating replaced by bytes made once (a file that does not read
    back): what is left is the writer thread's own work (appends, joins, HDF5's chunk writes, the file), the
    rate no number of deflating threads can pass."""
    from mitsuba_eventfield.events import hdf5
    made, real = {}, hdf5.deflate_chunk

    def once(values, level, shuffle):
        key = (values.dtype.str, len(values))
        if key not in made:
            made[key] = real(values, level, shuffle)
        return made[key]
    hdf5.deflate_chunk = once
    try:
        with tempfile.TemporaryDirectory() as tmp:
            best = min(write_once(stream, os.path.join(tmp, f"floor{k}.h5"), threads, chunk, pieces)
                       for k in range(reps))     # a new name each time (writer_alone says why)
    finally:
        hdf5.deflate_chunk = real
    return {"threads": threads, "chunk": chunk, "write_s": best, "mev_per_s": len(stream) / best / 1e6}


GPU_PIECE = 5_161_000     # events a GPU render hands the writer at once (its 64 MiB device buffer, 13 bytes each)
LARGE_CHUNKS = (65536, 262144, 1 << 20)


def tiled(stream, tiles):
    """The fan's events repeated ``tiles`` times one after another (each copy shifted past the last): a stream
    of a GPU render's size (the fan at 1280x720 makes 161 M) with a real stream's compressibility."""
    import numpy as np

    import mitsuba_eventfield as ef
    span = int(stream.t[-1]) - int(stream.t[0]) + 1
    t = np.concatenate([stream.t + k * span for k in range(tiles)])
    return ef.EventStream(np.tile(stream.x, tiles), np.tile(stream.y, tiles), t, np.tile(stream.p, tiles),
                          stream.width, stream.height)


def large_stream_rows(stream, threads, tiles, reps=2):
    """A GPU-sized stream appended in the pieces a GPU render hands over, at HDF5 chunks of 65,536 (the
    default) to 1 M events: write time and the writer thread's serial floor at each. The writer thread's
    work is per chunk (four direct chunk writes, a space check, a future), and on the H200's 16-core host its
    floor (99-131 M events/s at 65,536) was what paced the fan to HDF5; the 4.8 M-event stream above has too
    few large chunks to keep 16 threads busy, so larger chunks are judged here."""
    big = tiled(stream, tiles)
    pieces = -(-len(big) // GPU_PIECE)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for chunk in LARGE_CHUNKS:
            best = min(write_once(big, os.path.join(tmp, f"c{chunk}_{k}.h5"), threads, chunk, pieces)
                       for k in range(reps))
            mib = os.path.getsize(os.path.join(tmp, f"c{chunk}_0.h5")) / 2**20
            floor = serial_floor(big, threads, reps, chunk, pieces)
            rows.append({"chunk": chunk, "threads": threads, "events": len(big), "write_s": best,
                         "mev_per_s": len(big) / best / 1e6, "mib": mib, "floor_mev_per_s": floor["mev_per_s"]})
            for name in os.listdir(tmp):
                os.remove(os.path.join(tmp, name))
    return rows


def render_to_file(threads_label, patch):
    """The fan rendered to .h5 (a warm-up render first); ``patch``: the writer's default thread count."""
    import mitsuba_eventfield as ef
    from mitsuba_eventfield.events import hdf5
    original = hdf5.default_compression_threads
    if patch is not None:
        hdf5.default_compression_threads = lambda: patch
    try:
        scene = ef.load_scene(FAN, width=346, height=260)
        with tempfile.TemporaryDirectory() as tmp:
            ef.render_events(scene, 0.008 / 64 * 3, steps=3, reuse=False, output=os.path.join(tmp, "w.h5"))
            s = ef.render_events(scene, 0.008, steps=64, reuse=False, output=os.path.join(tmp, "fan.h5"))
    finally:
        hdf5.default_compression_threads = original
    return {"threads": threads_label, "events": s.events, "render_s": s.render_s, "wall_s": s.wall_s,
            "writer_busy_s": s.writer_busy_s, "writer_wait_s": s.writer_wait_s, "writer_tail_s": s.writer_tail_s,
            "write_s": s.write_s}


def main():
    import mitsuba_eventfield as ef
    from mitsuba_eventfield.events.hdf5 import default_compression_threads
    ef.set_variant(os.environ.get("EVENTFIELD_VARIANT") or None)
    stream = ef.render_events(ef.load_scene(FAN, width=346, height=260), 0.008, steps=64, reuse=False)
    cores = default_compression_threads()
    # 4 and 8 where the cores allow: on an H200's 16-core host, 16 threads wrote slower than 2 while the
    # shuffle held the GIL (results/gpu_h200.md); the rows between show where more threads stop paying
    settings = [(threads, 65536) for threads in sorted({0, 1, 2, 4, 8, cores}) if threads <= cores] \
        + [(cores, BIG_CHUNK)]
    alone = writer_alone(stream, settings)
    floor = serial_floor(stream, cores)
    tiles = int(os.environ.get("EVENTFIELD_WRITER_TILES", 16 if cores >= 8 else 4))
    large = large_stream_rows(stream, cores, tiles) if tiles > 0 else []
    renders = [render_to_file(f"default ({cores})", None), render_to_file("0", 0)]
    base = alone[0]                                   # threads 0: HDF5's own filters
    res = {"device": device_name(), "events": len(stream), "writer": alone, "serial_floor": floor,
           "large_stream": large, "renders": renders,
           "targets": {"every file reads back as the stream": all(r["identical"] for r in alone),
                       "deflating on threads is faster than HDF5's filters on one":
                           min(r["write_s"] for r in alone if r["threads"]) < base["write_s"]}}
    md = [f"# HDF5 event writing ({res['device']})", "",
          f"The fan, 346x260, 2 scan periods in 64 steps: {len(stream)} events, 13 bytes each uncompressed; "
          "gzip level 1 + shuffle, chunks of 65,536 events (the default; the last row 4x larger); appended in 16 "
          "pieces; fastest of 3.", "",
          "| threads | chunk, events | write s | M events/s | vs HDF5's filters | file MiB | reads back |",
          "|---|---|---|---|---|---|---|"]
    for r in alone:
        label = "0 (HDF5's filters, writing thread)" if r["threads"] == 0 else str(r["threads"])
        md.append(f"| {label} | {r['chunk']:,} | {r['write_s']:.3f} | {r['mev_per_s']:.1f} | "
                  f"{base['write_s'] / r['write_s']:.2f}x | {r['mib']:.2f} | {r['identical']} |")
    md += ["", f"The writer thread's own work ({cores} threads, every chunk's deflating replaced by bytes made "
           f"once, `serial_floor`): {floor['write_s']:.3f} s, **{floor['mev_per_s']:.0f} M events/s**, the rate no "
           "number of deflating threads can pass.", ""]
    if large:
        md += [f"A GPU-sized stream: the fan's events {tiles} times over ({large[0]['events']:,} events), appended "
               f"in pieces of {GPU_PIECE:,} (what a GPU render hands over), {cores} threads, fastest of 2; the "
               "serial floor as above, at each chunk size:", "",
               "| chunk, events | write s | M events/s | file MiB | serial floor, M events/s |", "|---|---|---|---|---|"]
        md += [f"| {r['chunk']:,} | {r['write_s']:.3f} | {r['mev_per_s']:.1f} | {r['mib']:.1f} | "
               f"{r['floor_mev_per_s']:.0f} |" for r in large] + [""]
    md += ["The fan rendered to .h5 (one render each, after a warm-up; the writer runs beside the render):", "",
           "| writer threads | events | render s | writer busy s | render blocked on the writer s | tail s |",
           "|---|---|---|---|---|---|"]
    for r in renders:
        md.append(f"| {r['threads']} | {r['events']} | {r['render_s']:.3f} | {r['writer_busy_s']:.3f} | "
                  f"{r['writer_wait_s']:.3f} | {r['writer_tail_s']:.3f} |")
    md.append("")
    write_results("writer", res, md)


if __name__ == "__main__":
    main()
