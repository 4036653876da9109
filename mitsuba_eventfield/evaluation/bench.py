"""Speed against accuracy: quality settings of a render against a converged reference, in one run.

Each setting renders the same scene and duration; the reference uses many samples and fine steps. Errors:

* ``count``: relative error of the number of events;
* ``timing``: where the events land in time, as the L1 distance of net-count frames in short windows
  (``window_s``), relative to the reference's;
* ``product``: relative L2 error of a downstream product, the light field of the first scan period refocused
  at ``refocus_depth`` (galvo scenes) or the last film's log frame (others).

Wall time is relative to the default setting. The Pareto front (no other setting both faster and more
accurate, on the product error) is marked in the chart.
"""
from __future__ import annotations

import time

import numpy as np

from ..backend import set_variant
from ..focus.refocus import refocus
from ..lightfield.model import from_events
from ..lightfield.reconstruct import direct
from ..scene.timed import load_scene
from ..simulate.render import render_events, render_frames

DEFAULT = {"name": "default (4 spp, uniform)", "spp": 4, "steps_factor": 1}
SETTINGS = [
    {"name": "1 spp", "spp": 1, "steps_factor": 1},
    DEFAULT,
    {"name": "16 spp", "spp": 16, "steps_factor": 1},
    {"name": "4 spp, half steps", "spp": 4, "steps_factor": 0.5},
    {"name": "4 spp, 2x steps", "spp": 4, "steps_factor": 2},
    {"name": "4 spp, adaptive", "spp": 4, "adaptive": True},
    {"name": "4 spp, independent seeds", "spp": 4, "steps_factor": 1, "seed_mode": "independent"},
    {"name": "16 spp, independent seeds", "spp": 16, "steps_factor": 1, "seed_mode": "independent"},
    {"name": "4 spp, rgb", "spp": 4, "steps_factor": 1, "color": True},
]
REFERENCE = {"name": "reference", "spp": 64, "steps_factor": 8}


def _net_frames(ev, duration, window_s):
    edges = np.arange(0, duration + 1e-12, window_s) * 1e6
    frames = []
    for a, b in zip(edges[:-1], edges[1:]):
        frames.append(ev.time_window(int(a), int(b)).signed_counts())
    return np.stack(frames).astype(np.float64)


def _product(ev, scene, refocus_depth, views=16):
    optics = ev.meta.get("optics", {})
    if optics.get("design") == "galvo":
        start = render_frames(scene, [0.0], spp=64)[0]
        lf = from_events(ev, period=0, views=views, log_start=start)
        return np.log(np.maximum(refocus(lf, refocus_depth), 1e-6))
    return direct(ev, [ev.duration_us * 1e-6], render_frames(scene, [0.0], spp=64)[0], 0.0)[0]


def run(scene_path: str, duration: float, steps: int, defines: dict | None = None, refocus_depth: float = 0.6,
        window_s: float = 2.5e-4, settings=None) -> list:
    """One row per setting (and the reference): wall time, errors. Colour settings run in the rgb variant."""
    defines = defines or {}
    rows, outputs = [], {}
    for cfg in [REFERENCE] + list(settings or SETTINGS):
        color = cfg.get("color", False)
        set_variant(color=color)
        scene = load_scene(scene_path, **defines)
        kw = dict(spp=cfg["spp"], seed_mode=cfg.get("seed_mode", "fixed"))
        if cfg.get("adaptive"):
            kw.update(adaptive=True, max_log_change=0.5, max_step=duration / steps)
        else:
            kw.update(steps=max(1, int(round(steps * cfg["steps_factor"]))))
        render_events(scene, duration / 8, **dict(kw, steps=2) if not cfg.get("adaptive") else kw)  # compile
        t0 = time.perf_counter()
        ev = render_events(scene, duration, reuse=False, **kw)
        wall = time.perf_counter() - t0
        set_variant(color=False)
        mono_scene = load_scene(scene_path, **defines)
        outputs[cfg["name"]] = (ev, _net_frames(ev, duration, window_s), _product(ev, mono_scene, refocus_depth))
        rows.append({"setting": cfg["name"], "wall_s": wall, "events": len(ev),
                     "steps": ev.meta["render"]["steps"], "spp": cfg["spp"]})
    ref_ev, ref_frames, ref_product = outputs[REFERENCE["name"]]
    default_wall = next(r["wall_s"] for r in rows if r["setting"] == DEFAULT["name"])
    for r in rows:
        ev, frames, product = outputs[r["setting"]]
        r["count_error"] = abs(len(ev) - len(ref_ev)) / max(len(ref_ev), 1)
        r["timing_error"] = float(np.abs(frames - ref_frames).sum() / max(np.abs(ref_frames).sum(), 1))
        r["product_error"] = float(np.linalg.norm(product - ref_product) / max(np.linalg.norm(ref_product), 1e-12))
        r["relative_time"] = r["wall_s"] / default_wall
    front = pareto([(r["relative_time"], r["product_error"]) for r in rows if r["setting"] != REFERENCE["name"]])
    names = [r["setting"] for r in rows if r["setting"] != REFERENCE["name"]]
    for r in rows:
        r["pareto"] = r["setting"] in {names[i] for i in front}
    return rows


def pareto(points) -> list:
    """Indices of the points no other point beats in both coordinates (lower is better)."""
    out = []
    for i, (a, b) in enumerate(points):
        if not any((c <= a and d <= b) and (c < a or d < b) for j, (c, d) in enumerate(points) if j != i):
            out.append(i)
    return out


def chart(rows, path: str, title: str = "") -> str:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..images import save_figure
    pts = [r for r in rows if r["setting"] != REFERENCE["name"]]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, metric, label in ((axes[0], "product_error", "refocused light field: relative error"),
                              (axes[1], "timing_error", "event timing: relative L1 error")):
        for r in pts:
            style = dict(marker="*", s=180, color="tab:red") if r["setting"] == DEFAULT["name"] else \
                dict(marker="o", s=50, color="tab:blue" if r["pareto"] else "tab:gray")
            ax.scatter(r["relative_time"], r[metric], zorder=3, **style)
            ax.annotate(r["setting"], (r["relative_time"], r[metric]), fontsize=7, xytext=(4, 3),
                        textcoords="offset points")
        front = sorted((r for r in pts if r["pareto"]), key=lambda r: r["relative_time"])
        if metric == "product_error":
            ax.plot([r["relative_time"] for r in front], [r[metric] for r in front], "--", color="tab:blue",
                    label="Pareto front")
            ax.legend(fontsize=8)
        ax.set_xscale("log"), ax.set_yscale("log")
        ax.set_xlabel("wall time relative to the default"), ax.set_ylabel(label)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, "chart")


def default_on_front(rows, tolerance: float = 1.25) -> bool:
    """True if the default is on the Pareto front, or within ``tolerance`` x of it in error at its speed."""
    pts = [r for r in rows if r["setting"] != REFERENCE["name"]]
    d = next(r for r in pts if r["setting"] == DEFAULT["name"])
    if d["pareto"]:
        return True
    faster_or_equal = [r["product_error"] for r in pts if r["pareto"] and r["relative_time"] <= d["relative_time"]]
    return bool(faster_or_equal) and d["product_error"] <= tolerance * min(faster_or_equal)
