"""High-speed refocus with the galvo (paper section 6): one light field per scan period, refocused after capture.

Pipeline (``refocus_planes`` and ``track_focus_depth``, one Python call each):

1. render ``periods`` scan periods of events, steps sized so the scan moves the image at most ``px_per_step``
   pixels per step (``lightfield.galvo_steps_per_period``);
2. per period, ``views`` views (evenly spaced in time over the period) integrated from the events onto one
   start frame (``start="frame"``: a conventional frame at t = 0, e.g. the RGB camera behind a beam splitter;
   ``start="events"``: the static-scene galvo solver on the first period, right wherever nothing moved then, and
   only up to a constant: those light fields carry an unknown overall gain, which refocus and depth ignore but
   PSNR against the rendered views does not) and placed at their scan angles: a light field every period (250
   per second at 250 Hz);
3. refocus each light field on named depth planes, or follow an object moving in depth (focus tracking: the
   sharpest depth inside a region that follows the object by template matching).

Ground truth is the renderer's: the same views rendered directly (same sampler seed, so the same Monte-Carlo
noise as the frames the events came from) and refocused by the same code, scored with PSNR/SSIM (``quality``); Mitsuba's depth AOV for the depth of the tracked object and for
the regions that each plane should bring into focus. ``selectivity`` checks that refocus does what it says:
the focus measure (tenengrad) of a plane's own region is higher when refocused on that plane than on the others.
"""
from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError, EventFieldError
from ..scene import load_scene
from .capture import START_METHODS, Capture, _check_positive, capture  # noqa: F401  (the shared capture stage)
from .highspeed_outputs import planes_figure, track_figure, write_planes, write_track  # noqa: F401  (outputs)
from .result import AppResult, time_split_line

# The fan's documented set-up (docs/gallery): larger film and scan than the scene's own defaults, two planes.
FAN_DEFAULTS = {"define": ["width=240", "height=180", "amplitude=2", "mirror_distance=0.2"],
                "plane": ["fan=0.6", "wall=1.5"]}

def _meta(cap: Capture, scene_path, defines, **kw) -> dict:
    ev = cap.events
    return {"scene": scene_path, "defines": dict(defines or {}), "events": len(ev), "periods": len(cap.lightfields),
            "views_per_period": len(cap.lightfields[0].views), "scan_period_s": cap.period_s,
            "light_fields_per_second": 1 / cap.period_s, "inputs": cap.lightfields[0].meta["inputs"],
            "pixel_model": ev.meta["pixel_model"],
            "optics": ev.meta["optics"], "render": ev.meta.get("render", {}), **kw}


# ----------------------------------------------------------------------------------------- refocus on planes

@dataclass
class PlaneRefocus(AppResult):
    planes: dict                 # name -> depth
    refocused: dict              # name -> (P, H, W): from events, one image per period
    truth: dict                  # name -> (P, H, W): the rendered views refocused the same way
    scores: dict                 # name -> {"psnr_db": [per period], "ssim": [...]}
    selectivity: dict            # name -> min over other planes of focus(own region @ own) / focus(@ other)
    period_s: float
    meta: dict = field(default_factory=dict)
    conventional: np.ndarray | None = None   # a conventional camera's frame around the middle period
    conventional_blur: dict = field(default_factory=dict)   # name -> its mean |difference| from the instant, over
                                                             # the mean instant, on the plane's region

    def report(self) -> str:
        gain = self.meta.get("scoring_gain", 1.0)
        lines = [f"inputs: {self.meta['inputs']}" + (f" (one overall gain fitted for scoring: x{gain:.3g}; events "
                                                      "record changes, not levels)" if gain != 1.0 else ""),
                 f"{len(next(iter(self.refocused.values())))} refocused light fields per plane, "
                 f"{1 / self.period_s:g} per second; against the rendered views refocused alike:",
                 "  plane        depth   PSNR dB (mean, min)   SSIM (mean, min)   focus selectivity"]
        for name, z in self.planes.items():
            p, s = np.array(self.scores[name]["psnr_db"]), np.array(self.scores[name]["ssim"])
            sel = self.selectivity[name]
            lines.append(f"  {name:<10} {z:7.3g}   {p.mean():7.2f} {p.min():7.2f}       {s.mean():6.3f} {s.min():6.3f}"
                         + (f"        {sel:.2f}x" if sel is not None else
                            "        - (no textured pixel at this depth: its scores measure nothing)"))
        if self.conventional is not None:
            lines.append(f"  a conventional {self.meta['conventional_fps']:g} fps frame (pinhole, same view) differs "
                         "from the instant it is centred on by "
                         + ", ".join(f"{100 * v:.0f}% on the {n}" for n, v in self.conventional_blur.items())
                         + " (motion blur; and it cannot refocus)")
        lines.append(time_split_line(self.meta["time_split_s"], indent="  "))
        return "\n".join(lines)

    def write(self, out_dir: str) -> dict:
        return write_planes(self, out_dir)

    def figure(self, path: str) -> str:
        return planes_figure(self, path)


# a plane's name names its output files (NAME.exr, NAME_p000.png): a path ("../x") wrote outside the output
# folder, and "conventional" overwrote the conventional frame's EXR
PLANE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}")
RESERVED_PLANE_NAMES = ("conventional", "highspeed", "metrics")


def _check_planes(planes: dict) -> dict:
    if not planes:
        raise ConfigError("planes (--plane NAME=DEPTH): give at least one name=depth")
    out = {}
    for name, z in planes.items():
        if not PLANE_NAME.fullmatch(str(name)) or str(name) in RESERVED_PLANE_NAMES:
            raise ConfigError(f"plane {name!r}: a name of letters, digits, '_' and '-' (up to 64, names its output "
                             f"files), not {', '.join(RESERVED_PLANE_NAMES)}")
        try:
            z = float(z)
        except (TypeError, ValueError):
            raise ConfigError(f"plane {name!r}: depth = {z!r} is not a number (scene units, > 0)") from None
        if not (z > 0 and math.isfinite(z)):
            raise ConfigError(f"plane {name!r}: depth = {z!r} must be a finite number > 0 (scene units)")
        out[str(name)] = z
    return out


def _selectivity(planes: dict, focus: dict) -> dict:
    """Per plane: focus of its own region refocused at it over the best of the other planes (None where no
    textured pixel lies at its depth: nothing to compare; it printed "nanx")."""
    out = {}
    for n in planes:
        others = [np.nanmean(focus[n][m]) for m in planes if m != n] if np.isfinite(focus[n][n]).any() else []
        out[n] = float(np.nanmean(focus[n][n]) / max(others)) if others else None
    return out


def refocus_planes(scene_path: str, planes: dict, defines: dict | None = None, periods: int | None = None,
                   views: int = 40, start: str = "events", region_tolerance: float = 0.15, spp: int = 4,
                   conventional_fps: float | None = 60.0, progress: bool = False) -> PlaneRefocus:
    """Refocus every scan period's light field on each named plane ({name: depth}), scored against the rendered
    views. A plane's region (for ``selectivity``): textured pixels whose true depth at the middle of the period
    is within ``region_tolerance`` (relative) of the plane's depth. ``conventional_fps``: also render what a
    conventional camera at that frame rate records around the middle period (``truth.conventional_frame``; the
    paper's 60 Hz comparison) and how far it is from the instant it is centred on, per plane's region (motion
    blur; a pinhole has no defocus to compare); None: skip. ``start``: ``events`` (default, events alone) or
    ``frame`` (events + a rendered frame at t = 0, ``capture``); from events alone the images carry one unknown
    overall gain, which scoring fits once per capture (``quality.fit_gain``) and the report states."""
    from ..evaluation.quality import fit_gain
    from ..evaluation.quality import scores as quality_scores
    from ..evaluation.truth import centre_frame, check_planes_seen, textured, truth_depth
    from ..focus.measures import focus_measure
    from ..focus.refocus import refocus
    planes = _check_planes(planes)
    timed = load_scene(scene_path, **(defines or {}))        # every plane seen somewhere, before the render
    span = periods * timed.scan_period if periods and timed.scan_period else \
        (timed.motion.duration if timed.motion is not None and timed.motion.duration else 0.0)
    check_planes_seen(timed, planes, np.unique([0.0, span / 2, span]), region_tolerance, scene_path)
    cap = capture(scene_path, defines, periods, views, start, spp=spp, progress=progress)
    t0 = time.perf_counter()
    def stacks(lfs):       # (a moving plane's blur is what this scores, not a mistake: 20 warnings a run before)
        return {n: np.stack([refocus(lf, z, on_motion="ignore") for lf in lfs]) for n, z in planes.items()}
    refocused = stacks(cap.lightfields)
    t1 = time.perf_counter()
    truth = stacks(cap.truth_lightfields)
    gain = 1.0 if start == "frame" else fit_gain(np.stack(list(refocused.values())), np.stack(list(truth.values())))
    scores = {n: {"psnr_db": [], "ssim": []} for n in planes}
    focus = {n: {m: [] for m in planes} for n in planes}       # region n refocused on plane m
    depth_maps = []                                             # Mitsuba depth per period (reused below)
    for k, lf in enumerate(cap.truth_lightfields):
        t_mid = float(lf.times.mean())
        z_true = truth_depth(cap.timed, t_mid)
        depth_maps.append(z_true)
        tex = textured(centre_frame(cap.timed, t_mid))         # the centre view: sharp, aligned with z_true
        for n in planes:
            s = quality_scores(gain * refocused[n][k], truth[n][k])
            for key in s:
                scores[n][key].append(s[key])
            region = tex & (np.abs(z_true / planes[n] - 1) < region_tolerance)
            for m in planes:
                fm = focus_measure(refocused[m][k], "tenengrad")
                focus[n][m].append(float(fm[region].mean()) if region.any() else float("nan"))
    selectivity = _selectivity(planes, focus)
    t2 = time.perf_counter()
    conventional, blur = None, {}
    if conventional_fps is not None:
        from ..evaluation.truth import conventional_frame
        k = len(cap.lightfields) // 2
        t_mid = float(cap.lightfields[k].times.mean())
        conventional = conventional_frame(cap.timed, t_mid, conventional_fps, spp=spp)
        instant = centre_frame(cap.timed, t_mid, log=False, spp=spp)
        z_true = depth_maps[k]
        for n in planes:
            region = np.abs(z_true / planes[n] - 1) < region_tolerance
            if region.any():
                blur[n] = float(np.abs(conventional - instant)[region].mean() / instant[region].mean())
    t3 = time.perf_counter()
    return PlaneRefocus(planes, refocused, truth, scores, selectivity, cap.period_s, _meta(
        cap, scene_path, defines, planes=planes, start=start, region_tolerance=region_tolerance, scoring_gain=gain,
        conventional_fps=conventional_fps,
        time_split_s={**cap.seconds, "refocus": t1 - t0, "scoring": t2 - t1, "conventional_camera": t3 - t2}),
        conventional, blur)


# ------------------------------------------------------------------------------------------- focus tracking

@dataclass
class FocusTrack(AppResult):
    depths: np.ndarray           # (P,) metric depth per period (sharpest exact refocus)
    truth: np.ndarray            # (P,) median true depth of the object inside its region, mid-period
    rois: np.ndarray             # (P, 4) x0, y0, x1, y1 followed per period (pixels)
    images: np.ndarray           # (P, H, W) refocused where the object is sharpest
    background: np.ndarray       # (P, H, W) refocused on ``background_depth`` for comparison
    times: np.ndarray            # (P,) middle of each period (s)
    velocities: np.ndarray       # (P, 2) image velocity of the object (px/s) taken out of the refocus
    truth_spread: np.ndarray     # (P, 2) 25th and 75th percentile of the object's depth in its region: the
                                 # object's own extent in depth, against which "its depth" is defined
    meta: dict = field(default_factory=dict)

    @property
    def relative_errors(self) -> np.ndarray:
        return np.abs(self.depths - self.truth) / self.truth

    def report(self) -> str:
        lines = [f"inputs: {self.meta['inputs']}",
                 "period  t (ms)   chosen z   true z (object's p25-p75)   |rel err|"]
        for k, (t, z, zt, (a, b)) in enumerate(zip(self.times, self.depths, self.truth, self.truth_spread)):
            lines.append(f"  {k:4d} {t * 1e3:8.2f} {z:10.3f} {zt:8.3f} ({a:.3f}-{b:.3f}) {abs(z - zt) / zt:12.3f}")
        e = self.relative_errors
        lines.append(f"median |relative depth error| {np.median(e):.3f}, max {e.max():.3f}")
        lines.append(time_split_line(self.meta["time_split_s"]))
        return "\n".join(lines)

    def write(self, out_dir: str) -> dict:
        return write_track(self, out_dir)

    def figure(self, path: str) -> str:
        return track_figure(self, path)


def _check_roi(roi) -> tuple:
    try:
        x0, y0, x1, y1 = (float(v) for v in roi)
    except (TypeError, ValueError):
        raise ConfigError(f"roi = {roi!r}: expected four numbers x0, y0, x1, y1 (fractions of the image)") from None
    if not (0 <= x0 < x1 <= 1 and 0 <= y0 < y1 <= 1):
        raise ConfigError(f"roi = {tuple(roi)}: must be fractions 0 <= x0 < x1 <= 1, 0 <= y0 < y1 <= 1 of the image")
    return x0, y0, x1, y1


def roi_pixels(roi, width: int, height: int) -> tuple:
    """(x0, y0, x1, y1) in pixels from fractions of the image size (so one ROI serves every resolution)."""
    x0, y0, x1, y1 = _check_roi(roi)
    px = (int(round(x0 * width)), int(round(y0 * height)), int(round(x1 * width)), int(round(y1 * height)))
    if px[2] - px[0] < 3 or px[3] - px[1] < 3:
        raise ConfigError(f"roi = {tuple(roi)} is {px[2] - px[0]} x {px[3] - px[1]} pixels at {width} x {height}: "
                         "needs at least 3 x 3")
    return px


def track_focus_depth(scene_path: str, roi, near: float, far: float, object_far: float, planes: int = 24,
                      background_depth: float | None = None, defines: dict | None = None,
                      periods: int | None = None, views: int = 40, start: str = "events", smooth: float = 0.0,
                      compensate_motion: bool = True, spp: int = 4, progress: bool = False,
                      captured: Capture | None = None) -> FocusTrack:
    """Follow an object moving in depth: per scan period, the depth in [near, far] at which the object's region
    is sharpest; the region starts at ``roi`` (fractions of the image) and follows the object by template
    matching; with ``compensate_motion`` the object's image velocity is taken out of the views
    (``tracking.track_focus``); refocus maps every view exactly (``optics.galvo``), so the sharpest depth is
    metric across the field. ``captured``: a ``capture`` of the
    scene to reuse. Truth: the median Mitsuba depth of the region's pixels nearer than ``object_far`` (the
    object's pixels, the background being farther), with their 25th-75th percentiles (``truth_spread``)."""
    from ..evaluation.truth import truth_depth
    from ..focus.refocus import depth_planes, refocus
    from ..focus.tracking import track_focus
    if not (0 < near < far and object_far > near):
        raise ConfigError(f"near = {near}, far = {far}, object_far = {object_far}: need 0 < near < far and "
                         "object_far > near (scene units)")
    _check_roi(roi)                                   # before rendering: bad input costs nothing
    _check_positive("planes", planes, integer=True, low=1)

    def before_render(timed, periods, period):
        optics = timed.sensor.optics_metadata() if hasattr(timed.sensor, "optics_metadata") else {}
        n = int(optics.get("n", 1)) if optics.get("design") == "kaleidoscope" else 1     # one view's image
        roi_pixels(roi, timed.film_size[0] // n, timed.film_size[1] // n)    # 1 x 0 px failed after the render
        # the scoring needs the object in view in every period: past it, the render was thrown away
        gone = [k for k in range(periods) if not np.any(truth_depth(timed, (k + 0.5) * period) < object_far)]
        if gone:
            raise EventFieldError(f"{scene_path}: periods = {periods}: no part of the scene is nearer than "
                                  f"object_far = {object_far} in periods {gone} (Mitsuba's depth at each "
                                  "period's middle): the object is out of view there; capture fewer periods")

    cap = captured or capture(scene_path, defines, periods, views, start, spp=spp, progress=progress,
                              depth_range=(near, max(far, background_depth or far)), truth_views=False,
                              before_render=before_render)
    h, w = cap.lightfields[0].shape
    roi_px = roi_pixels(roi, w, h)
    t0 = time.perf_counter()
    depths, images, rois, velocities = track_focus(cap.lightfields, depth_planes(near, far, planes), roi_px,
                                                   smooth=smooth, follow=True, compensate_motion=compensate_motion)
    bg = far if background_depth is None else background_depth
    background = np.stack([refocus(lf, bg, on_motion="ignore") for lf in cap.lightfields])
    t1 = time.perf_counter()
    times = np.array([float(lf.times.mean()) for lf in cap.lightfields])
    truth, spread = [], []
    for k, t in enumerate(times):
        x0, y0, x1, y1 = rois[k]
        z = truth_depth(cap.timed, t)[y0:y1, x0:x1]
        obj = z[z < object_far]
        truth.append(float(np.median(obj)) if obj.size else float("nan"))
        spread.append(np.percentile(obj, [25, 75]) if obj.size else [float("nan")] * 2)
    truth = np.array(truth)
    if np.isnan(truth).any():
        lost = [int(k) for k in np.flatnonzero(np.isnan(truth))]
        raise EventFieldError(f"{scene_path}: the tracked region holds no pixel nearer than object_far = "
                              f"{object_far} in periods {lost}: the object was lost (start roi {tuple(roi)})")
    t2 = time.perf_counter()
    return FocusTrack(depths, truth, np.array(rois), images, background, times, velocities, np.array(spread), _meta(
        cap, scene_path, defines, roi=list(map(float, roi)), near=near, far=far, planes=planes,
        compensate_motion=compensate_motion,
        object_far=object_far, background_depth=bg, start=start, smooth=smooth,
        time_split_s={**cap.seconds, "focus_tracking": t1 - t0, "ground_truth_depth": t2 - t1}))


def _command(name: str, result, extra: str = "") -> str:
    """The command line that regenerates ``result`` (its scene, defines and start), for the paper table."""
    from .hdr import scene_argument
    cmd = f"eventfield {name} {scene_argument(result.meta['scene'])}"
    cmd += "".join(f" -D {k}={v}" for k, v in result.meta["defines"].items()) + extra
    cmd += f" --periods {result.meta['periods']} --views {result.meta['views_per_period']}"
    return cmd + ("" if result.meta["start"] == "events" else " --start frame")


def _spin_note(scene_path: str) -> str:
    """The fan's speed where it is not the paper's Fig. 10 (300 rpm, 0.2 s a turn), from the scene's motion file."""
    import os
    from ..scene.motion import load_motion, motion_path_for
    path = motion_path_for(scene_path)
    rpms = sorted({o.spin_rpm for o in load_motion(path).objects.values() if o.spin_rpm}) \
        if os.path.exists(path) else []
    if not rpms or rpms == [300.0]:
        return ""
    turn = 360.0 * rpms[-1] / 60.0
    return (f" The fan turns at {', '.join(f'{v:g}' for v in rpms)} rpm (the paper's Fig. 10: 300; its Fig. 11: "
            f"480), {turn * 0.004:.1f} deg in a 250 Hz scan period where the paper's turns 7.2.")


def paper_rows(result) -> list:
    """The paper's Fig. 10 (fan refocus at 250 Hz) or Fig. 9's galvo counterpart (the dart) as table rows."""
    inputs = result.meta["inputs"]
    if isinstance(result, PlaneRefocus):
        psnr = ", ".join(f"{n} {np.mean(result.scores[n]['psnr_db']):.1f} dB" for n in result.planes)
        sel = ", ".join(f"{n} {v:.2f}x" for n, v in result.selectivity.items() if v is not None)
        planes = "".join(f" --plane {n}={z:g}" for n, z in result.planes.items())
        return [{"figure": "Fig. 10", "claim": "A galvo at 250 Hz gives a light field every scan period of a scene "
                 "with a spinning fan, refocusable after capture on the fan or on the background.",
                 "measured": f"{len(result.refocused[next(iter(result.planes))])} light fields at "
                 f"{1 / result.period_s:g} per second from {inputs}; refocus PSNR against converged rendered views "
                 f"{psnr}; each plane's own pixels sharper refocused on it: {sel}.",
                 "command": _command("highspeed", result, planes),
                 "differs": "The paper reconstructs views with E2VID from real events; here the events-only galvo "
                 "solver on simulated events. Scoring fits one overall gain (events record no absolute level)."
                 + _spin_note(result.meta["scene"])}]
    e = result.relative_errors
    return [{"figure": "Fig. 9 (galvo)", "claim": "A dart flying at the camera is refocused at high speed; with the "
             "galvo, the sharpest refocus plane per scan period tracks its depth.",
             "measured": f"{len(e)} periods from {inputs}: median |relative depth error| {np.median(e):.3f}, max "
             f"{e.max():.3f} against Mitsuba's depth ({result.truth[0]:.2f} m -> {result.truth[-1]:.2f} m).",
             "command": _command("track-focus", result),
             "differs": "The paper's dart figure is a kaleidoscope + 120 fps RGB result (see the SloMoRF dart row); "
             "this is the galvo version, scored on depth."}]
