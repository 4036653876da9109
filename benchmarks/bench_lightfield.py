"""Light-field processing benchmark (issue 5). Ratios from one run, never absolute times.

Target: processing one galvo scan period into a depth map (its 32 views reconstructed from events, 32 depth
planes, 346x260) takes less time than rendering that period (32 steps, 4 spp). Reported per focus measure.

Writes benchmarks/results/lightfield.json and .md.  Usage: ./run bench lightfield
"""
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402

SCENE = os.path.join(os.path.dirname(HERE), "scenes", "galvo_static", "galvo_static.xml")


def main(views=32, planes=32):
    import mitsuba_eventfield as ef
    scene = ef.load_scene(SCENE)                               # 346x260
    period = scene.scan_period
    ef.render_events(scene, period / 8, steps=views // 8, reuse=False)   # compile
    t = time.perf_counter()
    ev = ef.render_events(scene, period, steps=views, reuse=False)
    render_s = time.perf_counter() - t
    start = ef.render_frames(scene, [0.0])[0]
    rows = {}
    for measure in ef.depth.MEASURES:
        t = time.perf_counter()
        lf = ef.lightfield.from_events(ev, views=views, log_start=start)
        t_rec = time.perf_counter() - t
        ef.depth_from_focus(lf, 0.4, 4.0, planes, measure)
        total = time.perf_counter() - t
        rows[measure] = {"reconstruct_s": t_rec, "processing_s": total, "processing_over_render": total / render_s}
    res = {"resolution": f"{ev.width}x{ev.height}", "views": views, "planes": planes, "events": len(ev),
           "render_period_s": render_s, "measures": rows,
           "targets": {f"processing < rendering ({m})": r["processing_over_render"] < 1 for m, r in rows.items()}}
    md = [f"# Light-field processing benchmark ({res['resolution']}, {views} views, {planes} planes, "
          f"{len(ev)} events)", "", "| focus measure | processing / rendering one scan period |", "|---|---|"]
    md += [f"| {m} | **{r['processing_over_render']:.2f}** |" for m, r in rows.items()]
    md += ["", "Target: < 1 (processing one period into a depth map is faster than rendering it).", ""]
    write_results("lightfield", res, md)


if __name__ == "__main__":
    main()
