"""Where the downstream methods fail (issue 18, part 6): refocus against object speed, depth from focus against
texture contrast, galvo calibration against pixel noise, the events-only reconstruction against depth range
(``mitsuba_eventfield.evaluation.failure``). Each chart plots the error against the knob, with the region where
the method flags or refuses its result shaded; a point returned unflagged beyond the sweep's tolerance would be
ringed as "silent".

Writes benchmarks/results/failure_<sweep>.png (refocus, depth, depth_range, calibration, reconstruction), failure.md and
failure.json. Usage: ./run bench failure [NAME ...]   (70 s on 2 cores)
"""
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import RESULTS, write_results  # noqa: E402

COLOURS = {"ok": "tab:blue", "flagged": "tab:orange", "refused": "tab:red"}
MARKERS = {"ok": "o", "flagged": "^", "refused": "x"}


def _shade(ax, rows, key="value", log=False):
    """Shade, around each knob value, the share of its points that were flagged or refused."""
    xs = sorted({r[key] for r in rows})
    edges = []
    for i, x in enumerate(xs):
        f = (lambda v: np.log10(v)) if log else (lambda v: v)
        g = (lambda v: 10 ** v) if log else (lambda v: v)
        lo = g(0.5 * (f(xs[i - 1]) + f(x))) if i else x
        hi = g(0.5 * (f(x) + f(xs[i + 1]))) if i + 1 < len(xs) else x
        share = np.mean([r["status"] != "ok" for r in rows if r[key] == x])
        edges.append((lo, hi, share))
    first = True
    for lo, hi, share in edges:
        if share > 0:
            ax.axvspan(lo, hi, color="tab:orange", alpha=0.12 + 0.18 * share, lw=0,
                       label="flagged or refused" if first else None)
            first = False


def _points(ax, sweep, y_of=lambda r: r["error"], label_prefix=""):
    for status in ("ok", "flagged"):
        rows = [r for r in sweep.rows if r["status"] == status and y_of(r) is not None]
        if rows:
            ax.plot([r["value"] for r in rows], [y_of(r) for r in rows], MARKERS[status], color=COLOURS[status],
                    ms=7, label=f"{label_prefix}{status}")
    silent = [r for r in sweep.silent if y_of(r) is not None]
    if silent:
        ax.plot([r["value"] for r in silent], [y_of(r) for r in silent], "o", mfc="none", mec="k", ms=13, mew=1.5,
                label="silent (unflagged, beyond tolerance)")


def matplotlib_null():
    from matplotlib.ticker import NullFormatter
    return NullFormatter()


def _finish(fig, title, path):
    """Title, layout, and the PNG written by the project's one figure writer (atomic, then closed)."""
    from mitsuba_eventfield.images import save_figure
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, path, "failure chart")


def _figure(ncols=2):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, ncols, figsize=(6.2 * ncols, 4.4))
    return fig, axes


def chart_refocus(sweep, path):
    from mitsuba_eventfield.focus.refocus import MOTION_LIMIT_PX
    fig, (a, b) = _figure()
    rows = sorted(sweep.rows, key=lambda r: r["value"])
    x = [r["value"] for r in rows]
    a.plot(x, [r["error"] for r in rows], "-", color="0.6", lw=1, zorder=0)
    _shade(a, sweep.rows)
    _points(a, sweep)
    a.axhline(sweep.tolerance, ls="--", color="0.3", lw=1, label=f"tolerance ({sweep.tolerance:.1f} dB)")
    a.set(xlabel="card speed (px per scan period)", ylabel="refocus PSNR on the card (dB)",
          title="(a) refocus at the card's depth")
    b.plot(x, x, ":", color="0.5", label="true motion")
    b.plot(x, [r["measured_motion_px"] for r in rows], "o-", color="tab:purple", label="view_motion (measured)")
    b.axhline(MOTION_LIMIT_PX, ls="--", color="tab:orange", label=f"limit {MOTION_LIMIT_PX:g} px")
    b.set(xlabel="card speed (px per scan period)", ylabel="motion over the views (px)",
          title="(b) motion measured from the views")
    for ax in (a, b):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="best")
    _finish(fig, "Refocus vs object speed (exact views, 96x72, 24 views, card at 0.5 m)", path)


def chart_depth(sweep, path):
    fig, (a, b) = _figure()
    rows = sorted(sweep.rows, key=lambda r: r["value"])
    x = [r["value"] for r in rows]
    a.plot(x, [r["error_all_pixels"] for r in rows], "s--", color="0.5", ms=5,
           label="all scored pixels (confidence ignored)")
    _shade(a, sweep.rows, log=True)
    _points(a, sweep, label_prefix="confident pixels, ")
    a.axhline(sweep.tolerance, ls="--", color="0.3", lw=1, label=f"tolerance ({sweep.tolerance:.0%})")
    a.set(xscale="log", yscale="log", xlabel="texture contrast c", ylabel="median |relative depth error|",
          title="(a) depth error")
    b.plot(x, [r["confident_share"] for r in rows], "o-", color="tab:green")
    _shade(b, sweep.rows, log=True)
    b.axhline(0.5, ls="--", color="0.3", lw=1, label="flagged below half")
    b.set(xscale="log", ylim=(-0.03, 1.03), xlabel="texture contrast c", ylabel="share of scored pixels confident",
          title="(b) confidence >= 0.5")
    c_range = (0.7 * min(x), min(0.97, 1.08 * max(x)))
    top = b.secondary_xaxis("top", functions=(lambda c: np.log((1 + c) / (1 - np.minimum(c, 0.999))) / 0.1,
                                              lambda r: np.tanh(r * 0.1 / 2)))
    top.set_xlabel("peak-to-peak log contrast / event threshold", fontsize=8)
    a.set_ylim(0.007, 20)
    none = [r["value"] for r in rows if r["error"] is None]
    if none:
        a.plot(none, [0.009] * len(none), "v", color=COLOURS["flagged"], ms=7, label="no confident pixel")
    ticks = [v for v in (0.02, 0.05, 0.1, 0.2, 0.5, 0.9) if c_range[0] <= v <= c_range[1]]
    for ax, where in ((a, "upper right"), (b, "center right")):
        ax.set_xlim(*c_range)
        ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
        ax.xaxis.set_minor_formatter(matplotlib_null())
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8, loc=where, ncol=2 if ax is a else 1)
    _finish(fig, "Depth from focus vs texture contrast (events + start frame, tenengrad, 0.3-3 m)", path)


def chart_depth_range(sweep, path):
    fig, (a, b) = _figure()
    rows = sorted(sweep.rows, key=lambda r: r["value"])
    x = [r["value"] for r in rows]
    card = float(sweep.unit.split("card at ")[1].split(" m")[0])
    a.plot(x, [r["error_all_card_pixels"] for r in rows], "s--", color="0.5", ms=5,
           label="all card pixels (confidence ignored)")
    _shade(a, sweep.rows)
    _points(a, sweep, label_prefix="confident card pixels, ")
    none = [r["value"] for r in rows if r["error"] is None]
    if none:
        a.plot(none, [0.0012] * len(none), "v", color=COLOURS["flagged"], ms=7, label="no confident pixel")
    a.axhline(sweep.tolerance, ls="--", color="0.3", lw=1, label=f"tolerance ({sweep.tolerance:.0%})")
    a.set(yscale="log", ylim=(0.001, 3), ylabel="median |relative depth error|", title="(a) the card's depth")
    b.plot(x, [r["confident_share"] for r in rows], "o-", color="tab:green", label="confident (>= 0.5)")
    b.plot(x, [r["beyond_range_share"] for r in rows], "d:", color="tab:brown", label="flagged beyond the range")
    _shade(b, sweep.rows)
    b.set(ylim=(-0.03, 1.03), ylabel="share of the card's pixels", title="(b) what the depth map says")
    for ax in (a, b):
        ax.axvline(card, color="k", lw=0.8, ls=":", label=f"card depth ({card:g} m)")
        ax.set(xlabel="nearest depth searched (m)")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8, loc="center left" if ax is b else "lower right", ncol=1)
    _finish(fig, "Depth from focus vs depth range (the card nearer than the range searched)", path)


def chart_calibration(sweep, path):
    fig, axes = _figure()
    sources = list(dict.fromkeys(r["frames"] for r in sweep.rows))
    top = max([r["error"] or 0 for r in sweep.rows] + [r.get("unguarded_error") or 0 for r in sweep.rows])
    for ax, source in zip(axes, sources):
        rows = [r for r in sweep.rows if r["frames"] == source]
        shown = [dict(r, value=max(r["value"], 10.0)) for r in rows]          # the noise-free point at 10 Hz
        sub = type(sweep)(**{**sweep.__dict__, "rows": shown})
        _shade(ax, shown, log=True)
        _points(ax, sub, y_of=lambda r: None if r["error"] is None else 100 * r["error"])
        guarded = [r for r in shown if r["status"] == "refused" and r.get("unguarded_error") is not None]
        if guarded:
            ax.plot([r["value"] for r in guarded], [100 * r["unguarded_error"] for r in guarded], "x",
                    color="tab:red", ms=8, mew=2, label="refused (error it would have returned)")
        bare = [r for r in shown if r["status"] == "refused" and r.get("unguarded_error") is None]
        if bare:
            ax.plot([r["value"] for r in bare], [100 * top * 1.15] * len(bare), "v", color="tab:red", ms=7,
                    label="refused (no fit possible)")
        ax.axhline(100 * sweep.tolerance, ls="--", color="0.3", lw=1, label=f"tolerance ({sweep.tolerance:.0%})")
        ax.set(xscale="log", xlabel="shot-noise rate (Hz per pixel)", ylabel="scale error (%)",
               title=f"frames: {source}", ylim=(0, 100 * top * 1.25))
        ticks = sorted({r["value"] for r in shown})
        ax.set_xticks(ticks, ["0" if t == 10.0 and not any(r["value"] == 10.0 for r in rows) else f"{t:g}"
                              for t in ticks])
        ax.xaxis.set_minor_formatter(matplotlib_null())
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8, loc="upper left")
    _finish(fig, "Galvo calibration vs pixel noise (patch at the centre, 24 frames, 3 seeds per rate)", path)


def chart_reconstruction(sweep, path):
    from mitsuba_eventfield.focus.galvo_periods import MAX_OUTLIERS
    fig, (a, b) = _figure()
    rows = sorted(sweep.rows, key=lambda r: r["value"])
    x = [r["value"] for r in rows]
    near = rows[0]["near_searched"]
    a.plot(x, [r["error"] for r in rows], "-", color="0.6", lw=1, zorder=0)
    a.plot(x, [r["card_log_error"] for r in rows], "s--", color="0.5", ms=5, label="card pixels only")
    _shade(a, sweep.rows)
    _points(a, sweep)
    a.axhline(sweep.tolerance, ls="--", color="0.3", lw=1, label=f"tolerance ({sweep.tolerance:.3f})")
    b.plot(x, [r["outliers"] for r in rows], "o-", color="tab:purple", label="equations turned down")
    b.plot(x, [min(r["card_depth_error"], 5.0) for r in rows], "d:", color="tab:brown",
           label="card depth |error| (relative, capped at 5)")
    b.axhline(MAX_OUTLIERS, ls="--", color="tab:orange", label=f"MAX_OUTLIERS {MAX_OUTLIERS:g}")
    b.set(yscale="log")
    for ax in (a, b):
        ax.axvline(near, color="k", lw=0.8, ls=":", label=f"nearest depth searched ({near:.2f} m)")
        ax.set(xlabel="card depth (m)")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8, loc="best")
    a.set(ylabel="start-image log error (RMS)", title="(a) image error (textured pixels)")
    b.set(ylabel="share / relative error", title="(b) what the period reports, and its depth map")
    _finish(fig, "Events-only reconstruction vs depth range (one period, 24 views, wall at 1.5 m)", path)


CHARTS = {"refocus": chart_refocus, "depth": chart_depth, "depth_range": chart_depth_range,
          "calibration": chart_calibration,
          "reconstruction": chart_reconstruction}


def main(names=None):
    from mitsuba_eventfield.evaluation import failure
    names = names or list(failure.SWEEPS)
    results, md = {"sweeps": {}, "seconds": {}}, ["# Where the downstream methods fail", "",
                                                  "Regenerate: `./run bench failure` (see the module docstring).", ""]
    for name in names:
        t0 = time.perf_counter()
        sweep = failure.SWEEPS[name]()
        results["seconds"][name] = time.perf_counter() - t0
        path = os.path.join(RESULTS, f"failure_{name}.png")
        CHARTS[name](sweep, path)
        results["sweeps"][name] = sweep.as_dict()
        md += [f"## {sweep.method}: {sweep.parameter}", "", f"Chart: failure_{name}.png. {sweep.notes}.", "",
               f"Tolerance on the error: {sweep.tolerance:.4g}; points returned unflagged beyond it (silent): "
               f"**{len(sweep.silent)}** of {len(sweep.rows)}; sweep time {results['seconds'][name]:.0f} s.", ""]
        md += sweep.markdown() + [""]
    results["targets"] = {f"{n}: no silent failures": results["sweeps"][n]["silent"] == 0 for n in names}
    write_results("failure", results, md)


if __name__ == "__main__":
    main(sys.argv[1:])
