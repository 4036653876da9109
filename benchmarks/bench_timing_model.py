"""The timing model on a rendered scene (issue 18): what ``--timing-accuracy``'s plan predicts
(``simulate.auto``) and what a render says of itself (``simulate.accuracy_limit``, the closing note), against
timing errors measured on the demo at 48x36 over 10 ms.

The analytic scene has exact events (``bench_accuracy``); a rendered scene has none, so the reference here is a
converged render: 1024 spp and 400 steps (25 us a step). Each test render (4 to 256 spp, 200 steps: 50 us, whose
step error is small beside the noise measured) is scored as the analytic scene is (every reference event to the
nearest event of the same pixel and polarity), and by the k-th event against the k-th where a pixel's counts
agree (timing alone, no missing or extra event in it). The reference's own noise adds to both (about 1.1x at 256
spp if the noise halves per 4x the samples). A second render with another seed, compared with the first in the
same way (``events.pairing``), measures the Monte-Carlo part alone, with no reference. Until 2026-11-28 both
estimates took slopes over one step and were 2.5-10x optimistic here (74 us predicted at 64 spp, 563 measured);
they now take the baseline where the error stops growing with it (``accuracy_limit.event_slopes``).
Writes benchmarks/results/timing_model.json and .md.
Usage: ./run bench timing_model
"""
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402

ROOT = os.path.dirname(HERE)
SCENE = os.path.join(ROOT, "scenes", "demo", "demo.xml")
SIZE = {"width": 48, "height": 36}
DURATION, REFERENCE_SPP, REFERENCE_STEPS, STEPS = 0.01, 1024, 400, 200
SPPS = (4, 16, 64, 256)


def _by_pixel(ev, pol, width):
    keys = (ev.y.astype(np.int64) * width + ev.x)[ev.p == pol]
    order = np.argsort(keys, kind="stable")             # (times stay in order within a pixel)
    keys, times = keys[order], ev.t[ev.p == pol][order]
    pixels, starts = np.unique(keys, return_index=True)
    return dict(zip(pixels.tolist(), np.split(times, starts[1:])))


def timing_errors_us(ev, ref, width: int) -> dict:
    """Two readings of the timing error against the reference: ``nearest``, every reference event to the nearest
    event of its pixel and polarity (a missing or extra event counts as the distance to the next one), and
    ``equal_counts``, the k-th event against the k-th of each pixel and polarity whose counts agree
    (``events.pairing``: the timing alone). Medians in us, and the share of the reference's events paired."""
    from mitsuba_eventfield.events.pairing import paired_time_differences
    nearest = []
    for pol in (1, -1):
        test = _by_pixel(ev, pol, width)
        for pixel, a in _by_pixel(ref, pol, width).items():
            b = test.get(pixel)
            if b is not None:
                i = np.clip(np.searchsorted(b, a), 0, len(b) - 1)
                nearest.append(np.minimum(np.abs(b[i] - a), np.abs(b[np.maximum(i - 1, 0)] - a)))
    paired = paired_time_differences(ev, ref)
    return {"nearest": float(np.median(np.concatenate(nearest))), "equal_counts": float(np.median(paired["dt_us"])),
            "agreeing_share": paired["share_b"]}


def main():
    import mitsuba_eventfield as ef
    from mitsuba_eventfield.events.pairing import two_seed_timing_us
    from mitsuba_eventfield.simulate import auto
    ef.set_variant("llvm_ad_mono")

    def scene():
        return ef.load_scene(SCENE, **SIZE)
    t0 = time.perf_counter()
    ref = ef.render_events(scene(), DURATION, steps=REFERENCE_STEPS, spp=REFERENCE_SPP, seed=7)
    ref_s = time.perf_counter() - t0
    probe = scene()
    model = auto._noise_model(probe, auto._slope_frames(probe, DURATION / 200, 4, DURATION), 4)
    rows = []
    for spp in SPPS:
        ev = ef.render_events(scene(), DURATION, steps=STEPS, spp=spp)
        err = timing_errors_us(ev, ref, SIZE["width"])
        other = ef.render_events(scene(), DURATION, steps=STEPS, spp=spp, seed=1)
        rows.append({"spp": spp, "events": len(ev), "measured_us": err["nearest"], "equal_counts_us":
                     err["equal_counts"], "agreeing_share": err["agreeing_share"],
                     "two_seeds_us": two_seed_timing_us(ev, other),
                     "render_estimate_us": ev.meta["render"]["timing_limit"]["noise_us"],
                     "render_slope_baseline_us": ev.meta["render"]["timing_limit"]["slope_baseline_us"],
                     "render_slope_resolved": ev.meta["render"]["timing_limit"]["slope_resolved"],
                     "plan_us": auto._predict(model, spp)[0]})
    res = {"scene": "demo/demo.xml", "size": SIZE, "duration_s": DURATION, "reference_events": len(ref),
           "reference_s": ref_s, "rows": rows, "targets": {}}
    md = [f"# The timing model on a rendered scene (demo 48x36, {DURATION * 1e3:g} ms, CPU, one run)", "",
          f"Reference: {REFERENCE_SPP} spp, {REFERENCE_STEPS} steps, {len(ref)} events ({ref_s:.0f} s). Test renders: "
          f"{STEPS} steps, fixed seed.", "",
          "| spp | events | measured: nearest event, median us | measured: k-th event where counts agree, median us "
          "(share of events) | two seeds' renders, the same, / sqrt 2 | the render's own estimate us | the plan's "
          "prediction us | the render's slope baseline us |", "|---|---|---|---|---|---|---|---|"]
    md += [f"| {r['spp']} | {r['events']} | {r['measured_us']:.0f} | {r['equal_counts_us']:.0f} "
           f"({r['agreeing_share']:.0%}) | {r['two_seeds_us']:.0f} | {r['render_estimate_us']:.0f} | "
           f"{r['plan_us']:.0f} | {r['render_slope_baseline_us']:.0f}{'' if r['render_slope_resolved'] else '*'} |"
           for r in rows]
    ratios = [r[k] / r["equal_counts_us"] for r in rows for k in ("plan_us", "render_estimate_us")]
    md += ["", "Both estimates are of the form sigma / |dL/dt| (Monte-Carlo noise over the log slope, the median "
           "over events), the slope taken over growing time baselines up to where the error stops growing with "
           "the baseline and the frames' noise no longer swamps it (accuracy_limit.event_slopes; until 2026-11-28 "
           "over one step: 74 us predicted at 64 spp where 563 us was measured; an unresolved baseline is marked "
           f"*). Here they are {min(ratios):.2g}x to {max(ratios):.2g}x the measured k-th-event error "
           "(below 1: optimistic). On the analytic scene they are within 2x of the exact errors (accuracy.md, "
           "test_auto_timing.py). The same render with another seed, compared event by event where counts agree, "
           "measures the Monte-Carlo part directly (its difference holds two renders' noise: / sqrt 2).", ""]
    write_results("timing_model", res, md)


if __name__ == "__main__":
    main()
