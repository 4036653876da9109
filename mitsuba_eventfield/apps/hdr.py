"""HDR light fields (paper section 6): what the event pixel's log response keeps that a frame camera clips.

A static scene under the galvo scan fires events at every edge, whatever its brightness: the galvo solver
(:func:`reconstruct.galvo_start_image`) turns one scan period of events into the log image, up to one unknown
constant. That constant is fixed by one conventional frame: the median log difference over the pixels the long
exposure records well (codes 10..245 of 8 bits). Everything else comes from the events.

The frame camera is modelled as an ideal 8-bit sensor at two exposures, both set from the ground truth so the
comparison favours the frames: ``short`` puts the brightest pixel at 95% of full scale, ``long`` puts the median
pixel at 18% grey (auto-exposure). Each is turned back into log radiance (code / exposure; code 0 read as half a
code). All errors are |log radiance| errors in the pixel's own lin-log domain, against a noise-free render of the
same view, over all pixels and over two regions: ``bright`` (clipped by the long exposure) and ``dark`` (below
10 codes in the short one).

``lightfield`` (``hdr_lightfield``) is the light-field version: one scan period's views, refocused at several
depths, against 8-bit exposures of the same views refocused alike, with a realistic event pixel.
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError
from ..scene.timed import load_scene
from ..simulate.render import render_events, render_frames
from .result import AppResult, time_split_line

LDR_BITS = 8
WELL_EXPOSED = (10, 245)        # codes a frame records with < 10% quantisation error and no clipping


def ldr_exposures(linear: np.ndarray) -> dict:
    """{"short": exposure, "long": exposure} (code full scale per unit radiance) as documented above."""
    return {"short": 0.95 / float(np.max(linear)), "long": 0.18 / float(np.median(linear))}


def ldr_codes(linear: np.ndarray, exposure: float, bits: int = LDR_BITS) -> np.ndarray:
    """Integer codes of an ideal frame camera: round(exposure x radiance x full scale), clipped."""
    full = 2 ** bits - 1
    return np.clip(np.rint(exposure * np.asarray(linear, np.float64) * full), 0, full).astype(np.int64)


def ldr_to_linear(codes: np.ndarray, exposure: float, bits: int = LDR_BITS) -> np.ndarray:
    """Radiance a frame's codes stand for (code 0 read as half a code: the expected value under it)."""
    full = 2 ** bits - 1
    return np.maximum(codes, 0.5) / full / exposure


@dataclass
class HDRComparison(AppResult):
    truth_log: np.ndarray                  # ground truth, lin-log domain of the pixel
    estimates: dict                        # name -> log image: "events", "ldr_short", "ldr_long"
    errors: dict                           # name -> {"all", "bright", "dark"}: mean |log error|
    dynamic_range: float                   # max / min ground-truth radiance
    regions: dict                          # "bright" / "dark" boolean masks
    meta: dict = field(default_factory=dict)

    def report(self) -> str:
        lines = [f"dynamic range {self.dynamic_range:.3g}:1 ({20 * math.log10(self.dynamic_range):.0f} dB); "
                 f"bright pixels {int(self.regions['bright'].sum())}, dark pixels {int(self.regions['dark'].sum())}",
                 "mean |log error|       all    bright    dark   worst region"]
        for name, e in self.errors.items():
            lines.append(f"  {name:<14} {e['all']:9.3f} {e['bright']:9.3f} {e['dark']:7.3f} {e['worst_region']:9.3f}")
        if "extra_information" in self.meta:
            lines.append(f"extra information: {self.meta['extra_information']}")
        if "time_split_s" in self.meta:
            lines.append(time_split_line(self.meta["time_split_s"]))
        return "\n".join(lines)

    def write(self, out_dir: str) -> dict:
        return write_outputs(self, out_dir)

    def figure(self, path: str) -> str:
        return figure(self, path)


def load_static_scan(scene_path: str, defines: dict | None = None):
    """(timed scene, scan period) of a static scene seen through a periodic galvo scan: what an HDR light field
    from one scan period needs (the scan alone moves the image, so one period of events sees everything)."""
    timed = load_scene(scene_path, **(defines or {}))
    if not timed.is_static:
        raise ConfigError(f"{scene_path}: the HDR light field from one scan period needs a static scene")
    if not timed.scan_period:
        raise ConfigError(f"{scene_path}: needs a galvo sensor with a periodic scan")
    return timed, timed.scan_period


def compare(scene_path: str, defines: dict | None = None, depth: float = math.inf, steps_per_period: int = 64,
            samples: int = 16, spp: int = 4, progress: bool = False) -> HDRComparison:
    """Render one scan period of events of a static galvo scene, reconstruct its HDR log image and score it and
    two 8-bit exposures against the ground truth. ``depth``: distance of the scene (the scan shift scales with
    1 - pivot / depth); ``samples``: views the galvo solver uses."""
    from ..lightfield.reconstruct import galvo_start_image
    from ..plugins.pixel_model import linlog_np
    timed, period = load_static_scan(scene_path, defines)
    t0 = time.perf_counter()
    events = render_events(timed, period, steps=steps_per_period, spp=spp, progress=progress)
    if not len(events):      # the events' image would be the start frame alone, scored as if recovered
        raise ConfigError(f"{scene_path}: no events in its scan period ({steps_per_period} steps): nothing to recover "
                          "the image from (more steps per period, or a scene with texture)")
    t1 = time.perf_counter()
    linlog = events.meta["pixel_model"]["linlog_threshold"]
    truth_lin = render_frames(timed, [0.0], spp=spp, log=False)[0]
    truth = linlog_np(truth_lin, linlog)
    t2 = time.perf_counter()
    est = galvo_start_image(events, 0.0, samples=samples, depth=depth)
    t3 = time.perf_counter()

    exposures = ldr_exposures(truth_lin)
    codes = {k: ldr_codes(truth_lin, e) for k, e in exposures.items()}
    estimates = {k: linlog_np(ldr_to_linear(codes[k], e), linlog) for k, e in exposures.items()}
    well = (codes["long"] >= WELL_EXPOSED[0]) & (codes["long"] <= WELL_EXPOSED[1])
    if not well.any():
        raise ConfigError(f"{scene_path}: no pixel is well exposed in the long frame: the events' offset is unknown")
    est = est + float(np.median(estimates["long"][well] - est[well]))
    estimates = {"events": est, "ldr_short": estimates["short"], "ldr_long": estimates["long"]}
    regions = {"bright": codes["long"] >= 2 ** LDR_BITS - 1, "dark": codes["short"] < WELL_EXPOSED[0]}
    errors = {}
    for name, img in estimates.items():
        err = np.abs(img - truth)
        errors[name] = {"all": float(err.mean()),
                        **{r: float(err[m].mean()) if m.any() else float("nan") for r, m in regions.items()}}
        errors[name]["worst_region"] = max(errors[name][r] for r in regions if regions[r].any())
    return HDRComparison(truth, estimates, errors, float(truth_lin.max() / max(truth_lin.min(), 1e-30)), regions,
                         {"scene": scene_path, "defines": dict(defines or {}), "events": len(events),
                          "exposures": exposures, "offset_from": "median over pixels with long-exposure codes "
                          f"{WELL_EXPOSED[0]}..{WELL_EXPOSED[1]}", "solver_depth": depth, "samples": samples,
                          "inputs": "events of one scan period + one long-exposure 8-bit frame (the truth is "
                          "rendered for scoring, and to make that frame)",
                          "extra_information": "the events' unknown constant comes from a conventional frame (the "
                          f"long exposure); the solver assumes the scene at {depth:g} (given, not measured)",
                          "steps": steps_per_period, "spp": spp,
                          "time_split_s": {"render": t1 - t0, "ground_truth": t2 - t1, "solve": t3 - t2},
                          "pixel_model": events.meta["pixel_model"], "optics": events.meta["optics"]})



def lightfield(*args, **kwargs):
    """The HDR light field refocused at several depths against 8-bit exposures of the same views:
    ``hdr_lightfield.lightfield`` (its module docstring has the method and the measured numbers)."""
    from .hdr_lightfield import lightfield as run
    return run(*args, **kwargs)


def scene_argument(path: str) -> str:
    """A scene path as a command line in the metrics' "paper" rows gives it: ``scenes/...`` for a bundled scene
    (the checkout's folder), else the path unchanged."""
    from ..scene import scenes_dir
    root, full = scenes_dir(), os.path.abspath(path)
    if os.path.commonpath([root, full]) != root:
        return path
    return "scenes/" + os.path.relpath(full, root).replace(os.sep, "/")


def paper_rows(result: HDRComparison) -> list:
    """The metrics' "paper" row: what Fig. 7 claims and what this single-view run measured."""
    e = result.errors
    cmd = f"eventfield hdr {scene_argument(result.meta['scene'])}"
    cmd += "".join(f" -D {k}={v}" for k, v in result.meta["defines"].items())
    cmd += f" --depth {result.meta['solver_depth']:.10g} --steps {result.meta['steps']} --spp {result.meta['spp']}"
    return [{"figure": "Fig. 7", "claim": "An event field keeps the whole dynamic range of a scene with bright LEDs "
             "and dark texture, where an RGB camera's short exposure loses the texture and its long exposure the "
             "LEDs.",
             "measured": f"One view of a {result.dynamic_range:.2g}:1 scene, mean |log error| on the bright pixels: "
             f"events {e['events']['bright']:.2f} vs long exposure {e['ldr_long']['bright']:.2f}; on the dark pixels: "
             f"events {e['events']['dark']:.2f} vs short exposure {e['ldr_short']['dark']:.2f}.",
             "command": cmd,
             "differs": "One reconstructed view, not the refocused light field (eventfield hdr --lightfield does "
             f"that). The pixel model is {result.meta['pixel_model'].get('preset', 'ideal')} and the scan is "
             "simulated. The frame camera is an ideal 8-bit sensor with exposures set from the truth, and the "
             "events' unknown constant comes from the long exposure. The solver is given the scene's depth "
             f"({result.meta['solver_depth']:g} m, set from how the scene was built), not a measured one."}]


def figure(result: HDRComparison, path: str) -> str:
    """Ground truth, the event-field reconstruction and both exposures on one log scale, with their errors."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..images import save_figure
    lo, hi = float(result.truth_log.min()), float(result.truth_log.max())     # the full range: clipping shows
    panels = [("ground truth (log)", result.truth_log)] + [
        (f"{name}: |err| {result.errors[name]['all']:.2f} (worst region {result.errors[name]['worst_region']:.2f})",
         img) for name, img in result.estimates.items()]
    fig, axes = plt.subplots(1, len(panels), figsize=(4 * len(panels), 3.4))
    for ax, (title, img) in zip(axes, panels):
        ax.imshow(img, cmap="gray", vmin=lo, vmax=hi)
        ax.set_title(title, fontsize=8)
        ax.axis("off")
    fig.suptitle(f"HDR light field: {result.dynamic_range:.2g}:1 radiance, one log scale for all panels", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path)


def write_outputs(result: HDRComparison, out_dir: str) -> dict:
    """The truth and every estimate as log EXRs, the figure and metrics.json in ``out_dir``; their paths."""
    from ..atomic import write_json
    from ..images import write_exr
    os.makedirs(out_dir, exist_ok=True)
    meta = {k: v for k, v in result.meta.items() if k != "time_split_s"}
    exr = [write_exr(os.path.join(out_dir, "truth.exr"), {"log": result.truth_log}, meta)]
    for name, img in result.estimates.items():
        exr.append(write_exr(os.path.join(out_dir, f"{name}.exr"), {"log": img}, meta))
    metrics = os.path.join(out_dir, "metrics.json")
    write_json(metrics, {"paper": paper_rows(result), "errors": result.errors, "dynamic_range": result.dynamic_range,
                         **result.meta})
    return {"figure": figure(result, os.path.join(out_dir, "hdr.png")), "exr": exr, "metrics": metrics}
