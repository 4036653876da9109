"""Outputs of high-speed refocus and focus tracking (``highspeed``): per-plane and per-period images, EXRs,
figures and metrics."""
from __future__ import annotations

import os

import numpy as np

from ..images import save_figure


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def planes_figure(result, path: str, period: int | None = None) -> str:
    """For one scan period: refocus from events on each plane (top) and the same refocus of the rendered views
    (bottom), one grey scale. Events-only images are shown times the gain fitted for scoring (they carry no
    absolute level), and say so."""
    plt = _pyplot()
    names = list(result.planes)
    k = len(result.refocused[names[0]]) // 2 if period is None else period
    hi = max(float(np.percentile(result.truth[n][k], 99.5)) for n in names)
    extra = result.conventional is not None
    gain = float(result.meta.get("scoring_gain", 1.0))
    source = (f"from events only, x{gain:.3g} (gain fitted for scoring)" if result.meta.get("start") == "events"
              else "from events + a frame at t = 0")
    fig, axes = plt.subplots(2, len(names) + extra, figsize=(4 * (len(names) + extra), 6.4), squeeze=False)
    for j, n in enumerate(names):
        s = result.scores[n]
        for i, (label, img) in enumerate(((source, gain * result.refocused[n][k]),
                                          ("rendered views (truth)", result.truth[n][k]))):
            ax = axes[i, j]
            ax.imshow(img, cmap="gray", vmin=0, vmax=hi)
            title = f"on {n} ({result.planes[n]:g} m), {label}"
            if i == 0:
                title += f"\nPSNR {s['psnr_db'][k]:.1f} dB, SSIM {s['ssim'][k]:.3f}"
            ax.set_title(title, fontsize=8)
            ax.axis("off")
    if extra:
        fps = result.meta["conventional_fps"]
        axes[0, -1].imshow(result.conventional, cmap="gray", vmin=0, vmax=hi)
        axes[0, -1].set_title(f"conventional {fps:g} fps frame ({1e3 / fps:.1f} ms exposure)\nmotion blur "
                              "(|frame - instant|): " + ", ".join(f"{n} {100 * v:.0f}%" for n, v in
                                                                   result.conventional_blur.items()), fontsize=8)
        axes[0, -1].axis("off")
        axes[1, -1].axis("off")
    fig.suptitle(f"High-speed refocus: scan period {k + 1} of {len(result.refocused[names[0]])} "
                 f"({1 / result.period_s:g} light fields per second)", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path)


def track_figure(result, path: str, columns: int = 6) -> str:
    """Crops around the followed object, refocused on the tracked depth (top) and on the background (middle),
    and the tracked depth against Mitsuba's over time (bottom)."""
    plt = _pyplot()
    n = len(result.depths)
    pick = np.unique(np.linspace(0, n - 1, min(columns, n)).round().astype(int))
    h, w = result.images.shape[1:3]
    fig = plt.figure(figsize=(2.2 * len(pick), 6.2))
    grid = fig.add_gridspec(3, len(pick), height_ratios=[1, 1, 1.3])
    hi = float(np.percentile(result.background, 99.5))
    for j, k in enumerate(pick):
        x0, y0, x1, y1 = result.rois[k]
        cx, cy, half = (x0 + x1) // 2, (y0 + y1) // 2, max(x1 - x0, y1 - y0)
        box = (max(0, cy - half), min(h, cy + half), max(0, cx - half), min(w, cx + half))
        for i, (img, label) in enumerate(((result.images[k], f"on {result.depths[k]:.2f} m"),
                                          (result.background[k], f"on {result.meta['background_depth']:g} m"))):
            ax = fig.add_subplot(grid[i, j])
            ax.imshow(img[box[0]:box[1], box[2]:box[3]], cmap="gray", vmin=0, vmax=hi)
            ax.set_title(f"{result.times[k] * 1e3:.0f} ms, {label}", fontsize=7)
            ax.axis("off")
    ax = fig.add_subplot(grid[2, :])
    ax.plot(result.times * 1e3, result.truth, "k-", label="Mitsuba depth (median over the object)")
    ax.plot(result.times * 1e3, result.depths, "o", color="tab:red", label="sharpest refocus depth (events)")
    ax.set_xlabel("time (ms)")
    ax.set_ylabel("depth (m)")
    ax.legend(fontsize=7)
    e = result.relative_errors
    ax.set_title(f"focus tracking at {result.meta['light_fields_per_second']:g} light fields per second: median "
                 f"|relative error| {np.median(e):.3f}, max {e.max():.3f}", fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path)


def write_planes(result, out_dir: str) -> dict:
    """EXR per plane (channels ``events_pK`` and ``truth_pK`` per period, linear), PNG per plane and period,
    the figure and metrics.json (scores, selectivity, time split, scene and optics metadata)."""

    from ..atomic import write_json
    from ..images import to_uint8, write_exr, write_png
    os.makedirs(out_dir, exist_ok=True)
    meta = {k: v for k, v in result.meta.items()}
    paths = {}
    for n in result.planes:
        channels = {}
        for k in range(len(result.refocused[n])):
            channels[f"events_p{k}"] = result.refocused[n][k]
            channels[f"truth_p{k}"] = result.truth[n][k]
            write_png(os.path.join(out_dir, f"{n}_p{k:03d}.png"), to_uint8(result.refocused[n][k]))
        paths[n] = write_exr(os.path.join(out_dir, f"{n}.exr"), channels, {**meta, "plane": n})
    if result.conventional is not None:
        paths["conventional"] = write_exr(os.path.join(out_dir, "conventional.exr"), {"Y": result.conventional},
                                          {**meta, "frame": "conventional camera, centre view, linear"})
    paths["figure"] = planes_figure(result, os.path.join(out_dir, "highspeed.png"))
    paths["metrics"] = os.path.join(out_dir, "metrics.json")
    write_json(paths["metrics"], {"scores": result.scores, "selectivity": result.selectivity,
                                   "conventional_blur": result.conventional_blur, **meta})
    return paths


def write_track(result, out_dir: str) -> dict:
    """PNG per period (refocused on the tracked depth), an EXR of them, the figure and metrics.json."""

    from ..atomic import write_json
    from ..images import to_uint8, write_exr, write_png
    os.makedirs(out_dir, exist_ok=True)
    for k, img in enumerate(result.images):
        write_png(os.path.join(out_dir, f"tracked_p{k:03d}.png"), to_uint8(img))
    paths = {"exr": write_exr(os.path.join(out_dir, "tracked.exr"),
                              {f"p{k}": img for k, img in enumerate(result.images)}, result.meta),
             "figure": track_figure(result, os.path.join(out_dir, "track.png")),
             "metrics": os.path.join(out_dir, "metrics.json")}
    write_json(paths["metrics"], {"times_s": result.times.tolist(), "depths": result.depths.tolist(),
                                   "image_velocity_px_per_s": result.velocities.tolist(),
                                   "truth": result.truth.tolist(), "truth_p25_p75": result.truth_spread.tolist(),
                                   "rois_px": result.rois.tolist(),
                                   "relative_errors": result.relative_errors.tolist(), **result.meta})
    return paths
