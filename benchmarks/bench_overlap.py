"""Whether the render loop should overlap host and device work (``backend.overlaps_steps``): an interleaved A/B.

Single runs disagreed. On an H200, ``bench_event_engine`` had the synced loop faster (demo 50 % against 66 %
beyond the renders alone, fan 101 % against 134 %), while ``bench_motion`` had the overlapped one faster
(demo 0.141 against 0.165 s). A render of 0.15 s is at the mercy of one slow launch, so here both choices
render the same loaded scene in alternating pairs (ABBA order, so neither always goes first), after a warm-up
of each; the table gives each choice's median and fastest wall time, and in how many pairs the overlapped
loop won. Both choices must give the same events (they do in tests/simulate/test_determinism.py; checked
again here on every run).

Writes benchmarks/results/overlap.json and .md (the device's name with every number).
Usage: python benchmarks/bench_overlap.py [--quick] [--pairs N]
"""
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402
from bench_event_engine import device_name  # noqa: E402

SCENES = os.path.join(os.path.dirname(HERE), "scenes")


def _render(timed, duration, steps, overlap: bool):
    """One in-memory render with the loop's overlap forced to ``overlap``: (wall s, events)."""
    import mitsuba_eventfield as ef
    from mitsuba_eventfield import backend
    before = os.environ.get(backend.OVERLAP_ENV)
    os.environ[backend.OVERLAP_ENV] = "1" if overlap else "0"
    try:
        t0 = time.perf_counter()
        ev = ef.render_events(timed, duration, steps=steps, reuse=False)
        return time.perf_counter() - t0, ev
    finally:
        if before is None:
            os.environ.pop(backend.OVERLAP_ENV)
        else:
            os.environ[backend.OVERLAP_ENV] = before


def ab(scene, duration, steps, pairs, **defines):
    import mitsuba_eventfield as ef
    timed = ef.load_scene(scene, **defines)
    for overlap in (False, True):                       # compile both loops' kernels and recordings
        _render(timed, duration / steps * 3, 3, overlap)
    walls, streams, wins = {False: [], True: []}, {}, 0
    for i in range(pairs):
        order = (False, True) if i % 2 == 0 else (True, False)
        pair = {}
        for overlap in order:
            wall, ev = _render(timed, duration, steps, overlap)
            pair[overlap] = wall
            walls[overlap].append(wall)
            streams.setdefault(overlap, ev)
        wins += pair[True] < pair[False]
    row = {"scene": os.path.relpath(scene, SCENES), "steps": steps, "pairs": pairs, "wins_overlapped": wins,
           "identical": streams[False].equals(streams[True]), "events": len(streams[False])}
    for overlap, name in ((False, "synced"), (True, "overlapped")):
        row[f"{name}_median_s"] = statistics.median(walls[overlap])
        row[f"{name}_best_s"] = min(walls[overlap])
        row[f"{name}_walls_s"] = walls[overlap]
    row["median_gain_pct"] = 100 * (1 - row["overlapped_median_s"] / row["synced_median_s"])
    return row


def main(quick=False, pairs=None):
    import mitsuba as mi

    import mitsuba_eventfield as ef
    ef.set_variant(os.environ.get("EVENTFIELD_VARIANT") or None)
    gpu = mi.variant().startswith("cuda")
    pairs = pairs or (2 if quick else 6)
    fan = {"width": 1280, "height": 720} if gpu and not quick else {"width": 346, "height": 260}
    cases = [(os.path.join(SCENES, "demo", "demo.xml"), 0.1, 20 if quick else 100, {}),
             (os.path.join(SCENES, "fan", "fan.xml"), 0.02, 16 if quick else (400 if gpu else 64), fan)]
    device = device_name()
    rows = [ab(scene, duration, steps, pairs, **defines) for scene, duration, steps, defines in cases]
    md = [f"# The render loop's overlap of host and device: interleaved A/B ({device}, {mi.variant()})", "",
          f"Each scene loaded once; {pairs} pairs of in-memory renders in ABBA order after a warm-up of each "
          "choice; wall time per render. The default here: "
          + ("overlapped" if ef.backend.overlaps_steps() else "synced after each render") + ".", "",
          "| scene | steps | synced median / best s | overlapped median / best s | median gain | overlapped won "
          "| same events |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        md.append(f"| {r['scene']} | {r['steps']} | {r['synced_median_s']:.3f} / {r['synced_best_s']:.3f} | "
                  f"{r['overlapped_median_s']:.3f} / {r['overlapped_best_s']:.3f} | {r['median_gain_pct']:+.1f} % "
                  f"| {r['wins_overlapped']} of {r['pairs']} | {r['identical']} |")
    write_results("overlap", {"device": device, "variant": mi.variant(), "rows": rows}, md + [""])


if __name__ == "__main__":
    args = sys.argv[1:]
    main(quick="--quick" in args, pairs=int(args[args.index("--pairs") + 1]) if "--pairs" in args else None)
