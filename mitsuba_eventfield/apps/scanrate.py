"""Depth at the scan rate (paper section 6): one metric depth map per galvo scan period, scored against Mitsuba.

Each scan period of events gives one light field (``highspeed.capture``: views integrated from the events onto
each period's start image, solved from the events alone by default, and placed at their scan angles) and so one
depth map from focus (``depth.depth_from_focus``): at 100 Hz, 100 depth maps per second. Refocus maps each view with the exact two-mirror geometry
(``optics.galvo``), so "sharpest refocus plane" is metric depth across the whole field (off-axis pixels move
(1 + t^2) times more per mirror turn than on-axis ones; one shift per view read them too far).

* ``calibration``: optionally, a galvo/depth calibration from the data (``calibration.calibrated_events``: the
  per-period solver solves with it too; ``calibrate_depth`` makes the depth one from LED captures through the
  same galvo) instead of the nominal optics. One made for other optics (scan, film, lens, mirror pivots) is
  refused before anything is rendered.

Ground truth is Mitsuba's own depth (``truth.truth_depth``) at the middle of each period. Errors are relative
depth errors on *textured* pixels (log-gradient of the rendered centre view, which the depth maps are aligned
to, above ``texture_threshold``: depth from focus knows nothing where there is no texture) that the method is confident about, reported separately for pixels nearer
and farther than ``split_depth`` (the runner and the wall behind it), with the coverage (share of textured
pixels that are confident).
"""
from __future__ import annotations

import math
import os
import textwrap
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError
from ..focus.depth import REASON_META, depth_from_focus
from ..scene import bundled_scene, load_scene
from ..simulate.render import render_events
from .result import AppResult, time_split_line


@dataclass
class ScanRateDepth(AppResult):
    depth_maps: list                    # DepthMap per scan period (metric)
    truth: list                         # z (H, W) per period, at its middle
    textured: list                      # bool (H, W) per period: where depth is measurable
    errors: list                        # per period: {"near", "far": median |rel err|, "near_p90", "far_p90",
                                        # "coverage", ...}
    times: np.ndarray                   # middle of each period (s)
    period_s: float
    meta: dict = field(default_factory=dict)

    def summary(self) -> dict:
        """Median over periods of each error, and the worst period."""
        out = {}
        for key in ("near", "far", "coverage"):
            vals = np.array([e[key] for e in self.errors], dtype=np.float64)
            vals = vals[np.isfinite(vals)]          # a period with no confident pixel there has no error
            out[key] = {"median": float(np.median(vals)) if vals.size else None,
                        "worst": (float(vals.max() if key != "coverage" else vals.min())) if vals.size else None}
        return out

    def report(self) -> str:
        lines = [f"inputs: {self.meta.get('inputs', 'events only')}",
                 f"{len(self.depth_maps)} depth maps at {1 / self.period_s:g} per second; median |relative depth "
                 f"error| on confident (>= {self.meta['min_confidence']:g}) textured pixels:"]
        for k, e in enumerate(self.errors):
            def err(name):
                return (f"{e[name]:.3f} (p90 {e[name + '_p90']:.2f})" if e[name + "_pixels"] else
                        "no confident pixel")
            near_z = (f"; near object median z {e['near_truth_z']:.3f} m (estimated {e['near_estimate_z']:.3f} m)"
                      if e["near_pixels"] else "")
            lines.append(f"  period {k} ({self.times[k] * 1e3:5.1f} ms): near (z < {self.meta['split_depth']:g} m) "
                         f"{err('near')}, far {err('far')}; {100 * e['coverage']:.0f}% of textured pixels "
                         f"confident{near_z}")
        lines.append(time_split_line(self.meta["time_split_s"]))
        return "\n".join(lines)

    def write(self, out_dir: str) -> dict:
        return write_outputs(self, out_dir)

    def figure(self, path: str) -> str:
        return figure(self, path)


LED_SCENE = "led_depth/led.xml"                     # bundled (scene.bundled_scene)
CALIBRATION_DEPTHS = (0.4, 0.55, 0.75, 1.0, 1.4, 2.0)     # spans the runner and its wall, densest where dS/dz is


def calibrate_depth(scene_path: str, defines: dict | None = None, depths=CALIBRATION_DEPTHS, views: int = 24,
                    progress: bool = False):
    """The paper's one calibration step for depth from a galvo (its supplement): an LED at known depths, seen
    through the same galvo as ``scene_path`` (fov, pivots, scan and film copied from its sensor), one scan period
    of events each; the LED's track from the events alone (``calibration.fit_led``, no start frame) gives the
    curve scale at each depth, and ``calibration.fit_depth`` the disparity model. Returns {"depth": DepthCalibration} for ``run``, made for
    the optics of ``scene_path`` (its ``optics`` record), which ``run`` checks against the scene it is used on."""
    from ..calibration import fit_depth_from_tracks, fit_led, galvo_scale_limit, optics_record
    from ..optics.galvo import GalvoGeometry
    from ..optics.scan import curve_from_dict
    target = load_scene(scene_path, **(defines or {}))
    optics = target.sensor.optics_metadata()
    if optics.get("design") != "galvo":
        raise ConfigError(f"{scene_path}: depth calibration needs a galvo sensor (got {optics.get('design')!r})")
    scan = optics["scan"]
    if scan["curve"] != "circle":
        raise ConfigError(f"{scene_path}: the LED calibration here expects a circular scan (got {scan['curve']!r})")
    w, h = (int(v) for v in target.sensor.film().size())
    curve = curve_from_dict(scan)
    record = optics_record(optics, w, h, where=scene_path)
    limit = galvo_scale_limit(record)
    fits = []
    for z in depths:
        led = load_scene(bundled_scene(LED_SCENE), width=w, height=h, depth=float(z), radius=0.006 * float(z),
                            fov=optics["fov_x_deg"], mirror_distance=optics["mirror_distance"],
                            mirror_separation=optics["mirror_separation"], frequency=scan["frequency"],
                            amplitude=scan["amplitude"], phase=scan["phase"])
        events = render_events(led, curve.period, steps=_led_steps(led, curve.period, views), progress=progress)
        fits.append(fit_led(events, samples=views, scale_limit=limit))   # the LED's track from its events alone
    depth = fit_depth_from_tracks(list(depths), fits, GalvoGeometry.from_optics(record, w, h))
    depth.optics = record
    return {"depth": depth}


def _led_steps(led, period: float, views: int) -> int:
    """Steps of one scan period of the LED: four a view, and more where the scan moves the image more than
    ``MAX_PX_PER_STEP`` a step (the point's events would be interpolated between rendered instants: at 160x120
    and 24 views, 1.11 px a step, and the render warned under a command that chose its steps itself). Not the
    default steps' 0.5 px: the LED fit's rms moves from render to render without a trend (160x120, runner's
    galvo: 0.78 px/rad at 96 steps, 0.47 at 107, 1.07 at the default's 234), so the fewest within 1 px."""
    from ..simulate.image_motion import MAX_PX_PER_STEP, scan_px_per_step
    steps = 4 * views
    px = scan_px_per_step(led, period, steps) or 0.0
    return max(steps, math.ceil(steps * px / MAX_PX_PER_STEP))


def _check_calibration(calibration: dict, scene_path: str, defines, captured):
    """The optics record of the data the calibration will act on, after refusing a calibration made for other
    optics: before rendering anything (from the scene's sensor), or from a given capture's events."""
    from ..calibration import check_optics, optics_record
    if captured is not None:
        ev = captured.events
        record = optics_record(ev.meta.get("optics", {}), ev.width, ev.height, where=scene_path)
    else:
        sensor = load_scene(scene_path, **(defines or {})).sensor
        w, h = (int(v) for v in sensor.film().size())
        record = optics_record(sensor.optics_metadata(), w, h, where=scene_path)
    check_optics(calibration, record)
    return record


def run(scene_path: str, defines: dict | None = None, periods: int | None = None, views: int = 40,
        near: float = 0.4, far: float = 4.0, planes: int = 32, measure: str = "tenengrad",
        min_confidence: float = 0.6, split_depth: float = 1.2, texture_threshold: float = 0.1,
        calibration: dict | None = None, start: str = "events", progress: bool = False, captured=None) -> ScanRateDepth:
    """Render the scene's scan periods of events, one metric depth map per period (planes uniform in inverse
    depth over [near, far]), each scored against Mitsuba's depth at the period's middle.

    Views are mapped onto the reference with the exact galvo geometry (``optics.galvo``), so the sharpest
    plane is metric depth across the field. ``captured``: a ``highspeed.capture`` of the scene to reuse."""
    from ..evaluation.truth import centre_frame, textured, truth_depth
    from .highspeed import capture
    if not (0 < near < far):
        raise ConfigError(f"near = {near}, far = {far}: need 0 < near < far (scene units)")
    if not (0 <= min_confidence < 1):
        raise ConfigError(f"min_confidence = {min_confidence}: must be in [0, 1)")
    if not (isinstance(planes, (int, np.integer)) and planes >= 2):
        raise ConfigError(f"planes = {planes!r}: must be an integer >= 2")
    if not split_depth > 0:
        raise ConfigError(f"split_depth = {split_depth}: must be > 0 (scene units)")
    if calibration:
        _check_calibration(calibration, scene_path, defines, captured)
    cap = captured or capture(scene_path, defines, periods, views, start, progress=progress,
                              depth_range=(near, far), truth_views=False, calibration=calibration)
    t0 = time.perf_counter()
    lfs = cap.lightfields
    if calibration and not lfs[0].meta.get("calibrated"):   # a capture solved without it: solve with it
        from .capture import lightfields
        lfs = lightfields(cap.events, cap.timed, len(lfs[0].views), start, depth_range=(near, far),
                          calibration=calibration)[0]
    maps = [depth_from_focus(lf, near, far, planes, measure) for lf in lfs]
    t1 = time.perf_counter()
    times = np.array([float(lf.times.mean()) for lf in cap.lightfields])
    truths, texs, errors = [], [], []
    for dm, t in zip(maps, times):
        z = truth_depth(cap.timed, t)
        tex = textured(centre_frame(cap.timed, t), texture_threshold) & np.isfinite(z)   # aligned with z
        good = tex & (dm.confidence >= min_confidence)
        rel = np.abs(dm.depth - z) / z
        e = {"coverage": float(good.sum() / max(tex.sum(), 1))}
        for name, sel in (("near", z < split_depth), ("far", z >= split_depth)):
            m = good & sel
            e[name] = float(np.median(rel[m])) if m.any() else float("nan")
            e[name + "_p90"] = float(np.percentile(rel[m], 90)) if m.any() else float("nan")   # the tail
            e[name + "_pixels"] = int(m.sum())
        m = good & (z < split_depth)
        e["near_truth_z"] = float(np.median(z[m])) if m.any() else float("nan")
        e["near_estimate_z"] = float(np.median(dm.depth[m])) if m.any() else float("nan")
        truths.append(z)
        texs.append(tex)
        errors.append(e)
    t2 = time.perf_counter()
    meta = {"scene": scene_path, "defines": dict(defines or {}), "views": len(cap.lightfields[0].views),
            "periods": len(cap.lightfields), "views_per_period": len(cap.lightfields[0].views),
            "planes": planes, "measure": measure, "near": near, "far": far, "split_depth": split_depth,
            "min_confidence": min_confidence, "texture_threshold": texture_threshold, "start": start,
            "inputs": cap.lightfields[0].meta["inputs"],
            "calibrated": sorted(calibration) if calibration else [],
            "events": len(cap.events), "depth_maps_per_second": 1 / cap.period_s,
            "pixel_model": cap.events.meta["pixel_model"], "optics": cap.events.meta["optics"],
            "time_split_s": {**cap.seconds, "depth_from_focus": t1 - t0, "ground_truth_depth": t2 - t1}}
    return ScanRateDepth(maps, truths, texs, errors, times, cap.period_s, meta)


def figure(result: ScanRateDepth, path: str, columns: int = 4) -> str:
    """Per period (columns): Mitsuba's depth, the estimate on confident pixels, and its error map."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..images import depth_colourbar, depth_colours, save_figure
    n = len(result.depth_maps)
    pick = np.unique(np.linspace(0, n - 1, min(columns, n)).round().astype(int))
    lo, hi = result.meta["near"], float(np.nanmax([np.nanmax(np.where(np.isfinite(z), z, np.nan))
                                                   for z in result.truth]))
    fig, axes = plt.subplots(3, len(pick), figsize=(3.2 * len(pick), 7.2), squeeze=False)
    cmap, norm = depth_colours(lo, hi, bad="black")          # depth_png's scale: near red, inverse depth
    err_cmap = plt.get_cmap("viridis").copy()
    err_cmap.set_bad("black")
    for j, k in enumerate(pick):
        dm, z, e = result.depth_maps[k], result.truth[k], result.errors[k]
        shown = np.where(result.textured[k] & (dm.confidence >= result.meta["min_confidence"]), dm.depth, np.nan)
        rel = np.abs(shown - z) / z
        panels = ((z, f"Mitsuba depth, {result.times[k] * 1e3:.0f} ms", {"cmap": cmap, "norm": norm}),
                  (shown, f"events: near err {e['near']:.3f}, far {e['far']:.3f}", {"cmap": cmap, "norm": norm}),
                  (rel, "|relative error| (0..0.2)", {"cmap": err_cmap, "vmin": 0, "vmax": 0.2}))
        for i, (img, title, kw) in enumerate(panels):
            im = axes[i, j].imshow(np.ma.masked_invalid(img), **kw)
            axes[i, j].set_title(title, fontsize=7)
            axes[i, j].axis("off")
            if j == len(pick) - 1 and i < 2:
                depth_colourbar(fig, im, axes[i, j])
            elif j == len(pick) - 1:
                fig.colorbar(im, ax=axes[i, j], fraction=0.046)
    # wrapped to the figure's width (about 14 characters of 9 pt an inch): one line ran off both sides of a one-
    # or two-period figure
    title = (f"Depth at the scan rate: {result.meta['depth_maps_per_second']:g} metric depth maps per second "
             "(confident textured pixels; black: no estimate)")
    fig.suptitle(textwrap.fill(title, int(14 * 3.2 * len(pick))), fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path)


def write_outputs(result: ScanRateDepth, out_dir: str) -> dict:
    """Per period an EXR (depth, confidence, reason, truth) and a colour depth PNG; the figure; metrics.json."""
    from ..atomic import write_json
    from ..images import depth_png, write_exr, write_png
    os.makedirs(out_dir, exist_ok=True)
    paths = {"exr": [], "png": []}
    near, far = result.meta["near"], result.meta["far"]
    for k, (dm, z) in enumerate(zip(result.depth_maps, result.truth)):
        meta = {**result.meta, "period_index": k, "time_s": float(result.times[k])}
        paths["exr"].append(write_exr(os.path.join(out_dir, f"depth_p{k:03d}.exr"),
                                      {**dm.channels(), "truth": np.where(np.isfinite(z), z, 0.0)},
                                      {**meta, **REASON_META}))
        p = os.path.join(out_dir, f"depth_p{k:03d}.png")
        write_png(p, depth_png(dm.depth, dm.confidence, near, far, result.meta["min_confidence"]))
        paths["png"].append(p)
    paths["figure"] = figure(result, os.path.join(out_dir, "scanrate_depth.png"))
    paths["metrics"] = write_json(os.path.join(out_dir, "metrics.json"),
                                  {"errors": result.errors, "summary": result.summary(),
                                   "times_s": result.times.tolist(), **result.meta})
    return paths


def paper_rows(result: ScanRateDepth) -> list:
    """The paper's Fig. 12 (depth of a runner at 100 Hz) as a table row."""
    from .highspeed import _command
    near = np.median([e["near"] for e in result.errors])
    far = np.median([e["far"] for e in result.errors])
    cover = np.mean([e["coverage"] for e in result.errors])
    return [{"figure": "Fig. 12", "claim": "Depth of a running person at the 100 Hz scan rate, by depth from focus "
             "on each scan period's light field, calibrated to metric depth.",
             "measured": f"{len(result.depth_maps)} depth maps at {1 / result.period_s:g} per second from "
             f"{result.meta['inputs']}: median |relative depth error| {near:.3f} on the runner, {far:.3f} on the "
             f"wall, on {100 * cover:.0f}% of textured pixels (against Mitsuba's depth).",
             "command": _command("scanrate-depth", result),
             "differs": "Nominal optics by default (the paper calibrates with an LED: --calibrate does that from "
             "events); simulated runner."}]
