"""The speed-accuracy chart and the tables behind it (``bench``): the statistics over seeds, the Pareto front of
each measure and where the default sits (``summarize``, ``default_position``); one panel per scene and measure,
wall time as a ratio to the scene's fastest setting against the measure, error bars, the front, the default.

``write(rows, out_dir, stem)`` writes ``<stem>.png`` (the chart), ``<stem>.md`` (the table, and where the
default sits), ``<stem>.csv`` (one row per scene and setting), ``<stem>_runs.csv`` (one row per run) and
``<stem>.json`` (everything).
"""
from __future__ import annotations

import json
import math
import os

import numpy as np

from . import bench
from .sweep import SweepTable

# one colour and marker per setting, the same in every panel (the default: a large red star)
_COLOURS = ["#1f77b4", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf", "#ff7f0e",
            "#393b79", "#637939", "#843c39", "#000000", "#e7ba52", "#6b6ecf", "#ad494a", "#8c6d31", "#e6550d"]
_MARKERS = ["o", "s", "D", "v", "^", "<", ">", "P", "X", "h", "p", "d", "H", "8", "1", "2", "3", "4"]


def _style(key: str) -> dict:
    if key == bench.DEFAULT_KEY:
        return {"color": "#d62728", "marker": "*", "markersize": 15, "markeredgecolor": "black", "zorder": 5}
    keys = [s["key"] for s in bench.SETTINGS if s["key"] != bench.DEFAULT_KEY]
    i = keys.index(key) if key in keys else len(keys)
    return {"color": _COLOURS[i % len(_COLOURS)], "marker": _MARKERS[i % len(_MARKERS)], "markersize": 7,
            "markeredgecolor": "black", "markeredgewidth": 0.4, "zorder": 4}


def _mean_std(values):
    """Mean and sample standard deviation (0 for one value)."""
    v = np.asarray([x for x in values if x is not None and math.isfinite(x)], np.float64)
    return (float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else 0.0) if len(v) else (math.nan, math.nan)


def summarize(rows) -> list:
    """One row per scene and setting: mean and standard deviation over seeds of every measure; the wall time of
    the fastest seed's run (other processes on the machine only ever add to it) and of the slowest, and their
    ratios to the scene's fastest setting; ``front``: the measures whose Pareto front it is on."""
    out = []
    rows = [r for r in rows if "refused" not in r]
    for scene in dict.fromkeys(r["scene"] for r in rows):
        group = [r for r in rows if r["scene"] == scene]
        summary = []
        for key in dict.fromkeys(r["setting"] for r in group):
            runs = [r for r in group if r["setting"] == key]
            s = {"scene": scene, "setting": key, "label": runs[0]["label"], "seeds": len(runs),
                 "spp": runs[0]["spp"], "steps": float(np.mean([r["steps"] for r in runs])),
                 "events": float(np.mean([r["events"] for r in runs]))}
            if "chosen" in runs[0]:
                s["chosen"], s["plan_s"] = runs[0]["chosen"], runs[0]["plan_s"]
            s["wall_s"], s["wall_s_max"] = min(r["wall_s"] for r in runs), max(r["wall_s"] for r in runs)
            for m in bench.MEASURES:
                if m in runs[0]:
                    s[m], s[m + "_std"] = _mean_std(r[m] for r in runs)
            summary.append(s)
        fastest = min(s["wall_s"] for s in summary)
        for s in summary:
            s["relative_time"], s["relative_time_max"] = s["wall_s"] / fastest, s["wall_s_max"] / fastest
        for m, (_, higher) in bench.MEASURES.items():
            pts = [(s["relative_time"], -s[m] if higher else s[m]) for s in summary if m in s]
            front = set(pareto(pts))
            for i, s in enumerate(x for x in summary if m in x):
                s.setdefault("front", [])
                if i in front:
                    s["front"].append(m)
        out += summary
    return out


def pareto(points) -> list:
    """Indices of the points no other point beats in both coordinates (lower is better)."""
    out = []
    for i, (a, b) in enumerate(points):
        if not any((c <= a and d <= b) and (c < a or d < b) for j, (c, d) in enumerate(points) if j != i):
            out.append(i)
    return out


def panels(summary) -> list:
    """(scene, measure) pairs that have values, in suite order."""
    return [(scene, m) for scene in dict.fromkeys(s["scene"] for s in summary) for m in bench.MEASURES
            if any(m in s for s in summary if s["scene"] == scene)]


def default_position(summary, time_tolerance: float = 0.05) -> list:
    """Per panel, where the default sits: on the (strict) Pareto front or not, and the settings that beat it beyond
    the noise of the measurement (``beaten_by``): as fast (at most ``time_tolerance`` slower) and more accurate by
    more than the two settings' standard deviations over seeds together, or faster by more than
    ``time_tolerance`` and not less accurate by more than that. Wall times of equal-cost settings differ by a few
    per cent from run to run, so a default off the strict front that nothing beats so is on the front within the
    noise (``within_noise``)."""
    out = []
    for scene, m in panels(summary):
        rows = [s for s in summary if s["scene"] == scene and m in s]
        d = next((s for s in rows if s["setting"] == bench.DEFAULT_KEY), None)
        if d is None:
            continue
        sign = -1 if bench.MEASURES[m][1] else 1

        def beats(s):
            gain, noise = sign * (d[m] - s[m]), math.hypot(s[m + "_std"], d[m + "_std"])
            as_fast = s["relative_time"] <= d["relative_time"] * (1 + time_tolerance)
            faster = s["relative_time"] * (1 + time_tolerance) < d["relative_time"]
            return (as_fast and gain > noise) or (faster and gain >= -noise)
        beaten_by = [s["setting"] for s in rows if s is not d and beats(s)]
        on_front = m in d.get("front", [])
        out.append({"scene": scene, "measure": m, "on_front": on_front, "within_noise": on_front or not beaten_by,
                    "value": d[m], "relative_time": d["relative_time"], "beaten_by": beaten_by})
    return out


def _panel(ax, summary, scene, measure) -> None:
    rows = [s for s in summary if s["scene"] == scene and measure in s]
    for s in rows:
        ax.errorbar(s["relative_time"], s[measure], xerr=[[0.0], [s["relative_time_max"] - s["relative_time"]]],
                    yerr=s[measure + "_std"],
                    linestyle="none", elinewidth=0.9, capsize=2, ecolor=_style(s["setting"])["color"],
                    **_style(s["setting"]))
    front = sorted((s for s in rows if measure in s.get("front", [])), key=lambda s: s["relative_time"])
    ax.plot([s["relative_time"] for s in front], [s[measure] for s in front], "--", color="black", lw=1, zorder=3)
    ax.scatter([s["relative_time"] for s in front], [s[measure] for s in front], s=260, facecolors="none",
               edgecolors="black", linewidths=0.8, zorder=3)
    label, higher = bench.MEASURES[measure]
    if not higher and all(s[measure] > 0 for s in rows):
        _log_axis(ax.yaxis, ax.set_yscale)
    _log_axis(ax.xaxis, ax.set_xscale, suffix="x")
    p = next((p for p in default_position(summary) if (p["scene"], p["measure"]) == (scene, measure)), None)
    where = "" if p is None else ("default on the front" if p["on_front"] else
                                  "default on the front within the noise" if p["within_noise"] else
                                  f"default beaten by {len(p['beaten_by'])} setting(s)")
    ax.set_title(f"{scene}: {label}\n{where}", fontsize=9)
    ax.set_xlabel("wall time / fastest setting", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(True, which="both", alpha=0.25)


def _log_axis(axis, set_scale, suffix="") -> None:
    """Log scale with plain labels at 1, 2 and 5 of each decade (no 2 x 10^0), none on the minor ticks."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter
    set_scale("log")
    axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}{suffix}"))
    axis.set_minor_formatter(NullFormatter())


def chart(summary, path: str, title: str = "") -> str:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from ..images import save_figure
    pairs = panels(summary)
    ncols = min(4, len(pairs) + 1)
    nrows = math.ceil((len(pairs) + 1) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.3 * ncols, 3.7 * nrows), squeeze=False)
    axes = axes.ravel()
    for ax, (scene, measure) in zip(axes, pairs):
        _panel(ax, summary, scene, measure)
    for ax in axes[len(pairs):]:
        ax.axis("off")
    labels = dict((s["setting"], s["label"]) for s in summary)
    handles = [Line2D([], [], linestyle="none", **_style(k)) for k in labels]
    handles += [Line2D([], [], color="black", ls="--", lw=1),
                Line2D([], [], linestyle="none", marker="o", markersize=13, markerfacecolor="none",
                       markeredgecolor="black")]
    names = list(labels.values()) + ["Pareto front", "on the front"]
    axes[len(pairs)].legend(handles, names, loc="center", fontsize=8, frameon=False, title_fontsize=8,
                             title="settings; error bars: 1 s.d. of the error over seeds,\n"
                                   "wall time from the fastest seed's run to the slowest")
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return save_figure(fig, path, "speed-accuracy chart")


def _fmt(v, std=None) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    text = f"{v:.3g}"
    return text if std is None or std <= 1e-9 * abs(v) else f"{text} ± {std:.2g}"


def markdown(summary, positions, meta: dict, refused=()) -> list:
    md = [f"# Speed against accuracy ({meta.get('variant', '')}, {meta.get('seeds')} seeds per setting)", "",
          "Wall time: the render's (kernels compiled beforehand), of the fastest seed's run (other processes only "
          "ever add time), the slowest in brackets; x fastest: its ratio to the scene's fastest setting. Errors: "
          "mean ± s.d. over seeds. Pareto: the measures whose front the setting is on. Chart: "
          + meta.get("chart", ""), ""]
    for scene in dict.fromkeys(s["scene"] for s in summary):
        rows = [s for s in summary if s["scene"] == scene]
        measures = [m for m in bench.MEASURES if any(m in s for s in rows)]
        ref = meta.get("reference_wall_s", {}).get(scene)
        md += [f"## {scene}" + (f" (reference: {ref:.1f} s)" if ref else " (exact events)"), "",
               "| setting | steps | wall s (slowest seed) | x fastest | "
               + " | ".join(bench.MEASURES[m][0] for m in measures) + " | Pareto |",
               "|---|---|---|---|" + "---|" * len(measures) + "---|"]
        for s in rows:
            name = s["label"] + (f": {s['chosen']}" if s.get("chosen") else "")
            md.append(f"| {name} | {s['steps']:.0f} | {s['wall_s']:.3g} ({s['wall_s_max']:.3g}) | "
                      f"{_fmt(s['relative_time'])} | " + " | ".join(_fmt(s[m], s[m + '_std']) for m in measures)
                      + f" | {', '.join(s.get('front', [])) or '-'} |")
        md += [f"\n{r['label']}: refused: {r['refused']}" for r in refused if r["scene"] == scene] + [""]
    md += ["## Where the default sits", "", BEYOND_NOISE, ""]
    md += [f"- {line}" for line in position_lines(summary, positions)] + [""]
    return md


BEYOND_NOISE = ("A setting beats the default beyond the noise when it is as fast (at most 5 % slower) and more "
                "accurate by more than the two settings' standard deviations over seeds together, or more than 5 % "
                "faster and not less accurate by more than that.")


def position_lines(summary, positions) -> list:
    """One sentence per panel: the default's value and time, on the front or which settings beat it."""
    labels = {(s["scene"], s["setting"]): s["label"] for s in summary}
    out = []
    for p in positions:
        head = (f"{p['scene']}, {bench.MEASURES[p['measure']][0]}: default {p['value']:.3g} at "
                f"{p['relative_time']:.2f}x the fastest")
        if p["on_front"]:
            out.append(head + ": on the Pareto front")
        elif not p["beaten_by"]:
            out.append(head + ": off the strict front, but nothing beats it beyond the noise: on the front within "
                              "the noise")
        else:
            beaters = "; ".join(labels[(p["scene"], k)] for k in p["beaten_by"])
            out.append(head + f": not on the front; beaten beyond the noise by {beaters}")
    return out


def write(rows, out_dir: str, stem: str, meta: dict | None = None, title: str = "") -> dict:
    """Chart, tables and JSON of a bench run (raw ``rows`` of ``bench.run``) in ``out_dir``; returns the paths."""
    os.makedirs(out_dir, exist_ok=True)
    summary = summarize(rows)
    positions = default_position(summary)
    paths = {k: os.path.join(out_dir, f"{stem}{ext}") for k, ext in
             (("chart", ".png"), ("table", ".md"), ("csv", ".csv"), ("runs", "_runs.csv"), ("json", ".json"))}
    meta = dict(meta or {}, chart=os.path.basename(paths["chart"]))
    meta["reference_wall_s"] = {r["scene"]: r["reference_wall_s"] for r in rows if "reference_wall_s" in r}
    chart(summary, paths["chart"], title)
    SweepTable([dict(s, front=";".join(s.get("front", []))) for s in summary]).to_csv(paths["csv"])
    SweepTable(rows).to_csv(paths["runs"])
    from ..atomic import atomic_output
    with atomic_output(paths["table"], "bench table") as tmp, open(tmp, "w") as f:
        f.write("\n".join(markdown(summary, positions, meta, [r for r in rows if "refused" in r])))
    with atomic_output(paths["json"], "bench results") as tmp, open(tmp, "w") as f:
        json.dump({"meta": meta, "summary": summary, "default_position": positions, "runs": rows}, f, indent=1)
    return paths
