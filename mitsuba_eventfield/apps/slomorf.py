"""SloMoRF (paper section 6.3): slow-motion refocus from a kaleidoscope seen by an event camera and, through a
beam splitter, by a 120 fps RGB camera with the same views.

The splitter is ideal and lossless here: both cameras see the full radiance of the same film. A real 50/50
splitter halves each one's light, which for the event pixel is a constant in log (no events change, except
near the lin-log knee) and for the RGB camera an exposure setting. The RGB frames are instantaneous (no
motion blur within an exposure).

One call, ``slomorf(scene)``, does the whole application and scores it against the renderer's ground truth:

1. **Events** of the kaleidoscope film over the clip, in a mono variant: the event pixel responds to log
   luminance (``render_events``).
2. **RGB keyframes** at ``fps`` of the same film, in a colour variant (the scene is reloaded after the variant
   switch: Mitsuba objects belong to one variant), fixed seed, linear radiance.
3. **Interpolation** to ``factor`` x ``fps``. The per-pixel log change between instants is the events integrated
   by ``reconstruct.direct`` (C x (ON - OFF)). Between keyframes k and k+1, at time t:

   * forward  ``F = RGB_k * exp(dlog(t_k -> t))``,  backward ``B = RGB_k+1 * exp(-dlog(t -> t_k+1))``;
   * fused ``w_F F + w_B B``. Both estimates are right in luminance (to within one threshold); they differ in
     colour wherever the pixel changed, because the events only carry a luminance gain. A pixel that fired
     only between t_k and t has, at t, the content it shows at t_k+1: the backward estimate is right, colour
     and all, and vice versa. So the default fusion (``"events"``) weights each side by the events *on the
     other side*: ``w_F = n(t -> t_k+1) / n(t_k -> t_k+1)``, with time-distance weights where a pixel did not fire.
     The plain time-distance blend (``"time"``: ``w_B = (t - t_k) / (t_k+1 - t_k)``) is kept for comparison;
     measured on scenes/falling it is worse (table in docs/gallery/README.md).

   A luminance gain can push one channel far past anything the camera saw (a blue square turning yellow
   multiplies blue by ~5), and refocus averages in linear radiance, so such values would tint whole defocused
   regions: each estimate's channels are capped at their maximum over the two keyframes. Measured at the
   default size: refocus PSNR 29.8 -> 31.9 dB (uncapped it was below linear blending's 30.9), frames
   24.6 -> 25.3 dB.

   Baseline: linear blending of the two keyframes with the time-distance weights (what a frame-only camera can
   do without motion estimation). It ghosts when an object moves by a sizeable part of itself between frames.
   TimeLens (the paper's choice) adds learned warping and synthesis; this is the model-free event method, and a
   learned one could replace ``interpolate`` without touching the rest.
4. **Refocus** of every interpolated film: its n x n views (``lightfield.from_spatial``, linear, RGB) shifted
   and added at each depth (``refocus.refocus``).
5. **Scores** against ground-truth RGB renders at every interpolated instant (rendered for scoring only): PSNR
   and SSIM of the frames and of their refocused images (refocus of the truth with the same algorithm), for
   the event interpolation and for the linear blend. Images are scored as shown: linear radiance clipped to
   [0, 1], gamma 1/2.2, 8 bits (``to_display``), the encoding of the PNG/MP4 outputs; the bundled scene is lit
   to stay below 1. PSNR is also given on the *moving* pixels (8-bit difference > 2 from either bracketing
   keyframe), where the methods differ; full-frame numbers are dominated by the static background.
   A focus check uses Mitsuba's depth AOV: for each refocus depth, the pixels whose true depth is closest to it
   (within 10% in inverse depth) must be sharpest (Tenengrad) in the image refocused at that depth.

Scenes: ``scenes/falling`` (the default, paper Fig. 8) and ``scenes/dart/kaleidoscope.xml`` (Fig. 9: the dart
at 8x, 960 fps from 120 fps, refocused with ``depths=(0.95, 1.8)``, on the dart and on the wall). Measured on the
dart at its default 288 x 192 film, events against linear blending: frames 32.5 / 25.7 dB, moving pixels
21.5 / 14.8 dB, refocused 35.9 / 30.2 dB (at the dart's depth 33.6 / 27.6 dB). The dart's image moves by about its
own length between RGB frames, so no keyframe holds its colour where it is at the instants between them. The
event interpolation gets its luminance right, in the colours of what was there before (grey-blue, not orange).

Timings (render events / render RGB keyframes / render truth / interpolate / refocus / score, and write in
``write_outputs``) go into ``meta["time_split_s"]``.
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError
from ..evaluation.truth import check_planes_seen
from ..scene import bundled_scene, load_scene
from ..simulate.render import render_events, render_frames
from .result import AppResult, focus_check_failures, time_split_line
from .slomorf_outputs import figure, to_display, write_outputs  # noqa: F401  (the outputs: their own module)

DEFAULT_SCENE = bundled_scene("falling/falling.xml")
FPS_RANGE = (1.0, 10000.0)          # RGB camera frame rate (Hz)
FACTOR_RANGE = (2, 64)              # frames made per RGB frame interval
FUSIONS = ("events", "time")
METHODS = ("events", "events_time", "linear")     # scored estimates: fusions and the baseline
DEFAULT_DEPTHS = (0.55, 0.8, 1.4)   # scenes/falling: the post, the block (focus plane), the wall (the dart: 0.95, 1.8)
MOVING_LEVEL = 2                    # 8-bit difference from a keyframe that marks a pixel as moving
FOCUS_BAND = 0.10                   # focus check: true depth within 10% of a refocus depth (inverse depth)


@dataclass
class SloMoRFResult(AppResult):
    times: np.ndarray              # (T,) seconds: every output instant (keyframes included)
    is_key: np.ndarray             # (T,) bool: instants of RGB keyframes
    frames: dict                   # "truth", "events", "events_time", "linear" -> (T, H, W, 3) linear RGB films
    depths: tuple
    refocused: dict                # same keys -> (T, len(depths), h, w, 3) linear RGB
    metrics: dict
    meta: dict = field(default_factory=dict)

    def report(self) -> str:
        m = self.metrics
        names = {"events": "events (event-count fusion)", "events_time": "events (time fusion)",
                 "linear": "linear blend (baseline)"}
        asked = self.meta.get("duration_asked_s")
        lines = [f"{self.meta['duration_s'] * 1e3:.3f} ms simulated" + (
                     f" ({asked * 1e3:g} ms asked, cut to whole {self.meta['fps']:g} fps frame intervals)"
                     if asked is not None else ""),
                 f"{m['interpolated_frames']} interpolated frames ({self.meta['factor']}x {self.meta['fps']:g} fps), "
                 f"films {self.meta['film'][0]}x{self.meta['film'][1]}, views {self.meta['view'][0]}x"
                 f"{self.meta['view'][1]}; scored as 8-bit gamma-2.2 images of radiance clipped to [0, 1]",
                 f"{'':30s} {'frames PSNR':>11s} {'moving PSNR':>11s} {'SSIM':>7s} {'worst PSNR':>10s}"
                 f" {'refocus PSNR':>12s} {'SSIM':>7s}"]
        for k in METHODS:
            f, r = m["frames"][k], m["refocus"][k]
            lines.append(f"{names[k]:30s} {f['psnr']:11.2f} {f['psnr_moving']:11.2f} {f['ssim']:7.4f} "
                         f"{f['psnr_worst']:10.2f} {r['psnr']:12.2f} {r['ssim']:7.4f}")
        lines.append("refocus PSNR per depth (events / linear): " + ", ".join(
            f"{z:g}: {m['refocus']['events']['per_depth'][i]['psnr']:.2f} / "
            f"{m['refocus']['linear']['per_depth'][i]['psnr']:.2f}" for i, z in enumerate(self.depths)))
        fc = m["focus_check"]
        lines.append("focus check (region at each depth sharpest when refocused there): " + ", ".join(
            f"{c['depth']:g}: {'ok' if c['sharpest_at_own_depth'] else 'FAILED'} (x{c['ratio_to_next_best']:.2f}, "
            f"{c['pixels']} px)" for c in fc["regions"]))
        lines.append(time_split_line(self.meta["time_split_s"]))
        return "\n".join(lines)

    def failed_checks(self) -> list:
        return focus_check_failures(self.metrics["focus_check"]["regions"], "slomorf")

    def write(self, out_dir: str) -> dict:
        return write_outputs(self, out_dir)

    def figure(self, path: str) -> str:
        return figure(self, path)


def _check(fps, factor, depths, duration):
    lo, hi = FPS_RANGE
    if not (isinstance(fps, (int, float)) and math.isfinite(fps) and lo <= fps <= hi):
        raise ConfigError(f"fps = {fps!r}: must be a number in {lo:g}..{hi:g} (Hz)")
    lo, hi = FACTOR_RANGE
    if isinstance(factor, bool) or not isinstance(factor, (int, np.integer)) or not lo <= factor <= hi:
        raise ConfigError(f"factor = {factor!r}: must be an integer in {lo}..{hi} (frames per RGB frame interval)")
    depths = tuple(float(z) for z in depths)
    if not depths or not all(z > 0 for z in depths):
        raise ConfigError(f"depths = {depths!r}: must be one or more depths > 0 (scene units; inf allowed)")
    if duration is not None and not (math.isfinite(duration) and duration >= 1.0 / fps):
        raise ConfigError(f"duration = {duration!r}: must be at least one RGB frame interval (>= {1.0 / fps:g} s)")
    return float(fps), int(factor), depths


def interpolate(key_a, key_b, log_ab, log_tb, count_at=None, count_tb=None, w_b=0.5, fusion="events"):
    """Linear RGB at t between keyframes a (t_a) and b (t_b) from the events' log changes.

    ``log_ab``: log change t_a -> t, ``log_tb``: t -> t_b, per pixel (H, W); ``count_*``: event counts in the
    same spans (needed by the ``events`` fusion); ``w_b`` = (t - t_a) / (t_b - t_a). See the module docstring.
    """
    if fusion not in FUSIONS:
        raise ConfigError(f"fusion = {fusion!r}: allowed: {', '.join(FUSIONS)}")
    # cap each channel at its largest value in the two keyframes (module docstring)
    ceiling = np.maximum(key_a.max(axis=(0, 1)), key_b.max(axis=(0, 1)))
    forward = np.minimum(key_a * np.exp(log_ab)[..., None], ceiling)
    backward = np.minimum(key_b * np.exp(-log_tb)[..., None], ceiling)
    wb = np.full(log_ab.shape, float(w_b))
    if fusion == "events":
        total = count_at + count_tb
        fired = total > 0
        wb[fired] = count_at[fired] / total[fired]
    wb = wb[..., None]
    return (1 - wb) * forward + wb * backward


def _variant_for(color: bool):
    """Our variant of the active backend (cuda/llvm) in mono or colour."""
    from .. import backend
    current = backend.mi.variant() or ""
    return backend.set_variant(current.split("_")[0] if current.split("_")[0] in ("cuda", "llvm") else None, color)


def _depth_views(timed, times, optics):
    """True depth (Mitsuba's depth AOV) of the reference (centre) view at each time: (T, h, w)."""
    from .. import backend
    from ..lightfield.views import extract_views
    mi = backend.mi
    integ = mi.load_dict({"type": "aov", "aovs": "z:depth"})
    out = []
    for t in times:
        timed.set_time(float(t))
        z = np.array(mi.render(timed.scene, integrator=integ, spp=1))[..., 0]
        out.append(extract_views(z, optics).view(0, 0))
    return np.stack(out)


def _frame_scores(est8, truth8, moving):
    from ..evaluation.quality import psnr, ssim
    est, truth = est8 / 255.0, truth8 / 255.0          # display codes, white = 1 (``quality``)
    moving_psnr = psnr(est[moving], truth[moving], 1.0) if moving.any() else float("nan")
    return psnr(est, truth, 1.0), ssim(est, truth, 1.0), moving_psnr


def _aggregate(rows):
    """Mean of per-frame scores (PSNR of a perfect frame is infinite: capped at 100 dB)."""
    a = np.array(rows, dtype=np.float64)
    a = np.where(np.isinf(a), 100.0, a)
    return {"psnr": float(np.nanmean(a[:, 0])), "ssim": float(np.nanmean(a[:, 1])),
            "psnr_moving": float(np.nanmean(a[:, 2])), "psnr_worst": float(np.nanmin(a[:, 0]))}


def focus_check(refocused, depth_views, depths, is_key):
    """For each refocus depth: over the instants that are not keyframes (``is_key`` False), the pixels whose
    true depth (``depth_views``, (T, h, w)) is within FOCUS_BAND (inverse depth) of it and nearest to it, and
    their Tenengrad focus in the image refocused at every depth (``refocused``: (T, D, h, w, C), channels
    averaged). Also used by ``hdr_lightfield`` (one instant, one channel)."""
    from ..focus.measures import focus_measure
    inv = 1.0 / np.asarray(depths)
    regions = []
    for i, z in enumerate(depths):
        score, pixels = np.zeros(len(depths)), 0
        for t in np.nonzero(~is_key)[0]:
            true_inv = 1.0 / np.maximum(depth_views[t], 1e-6)
            mask = np.abs(true_inv - inv[i]) <= FOCUS_BAND * inv[i]
            if len(depths) > 1:
                others = np.delete(inv, i)
                mask &= np.abs(true_inv - inv[i]) < np.min(np.abs(true_inv[..., None] - others), axis=-1)
            if not mask.any():
                continue
            pixels += int(mask.sum())
            for j in range(len(depths)):
                score[j] += focus_measure(refocused[t, j].mean(-1), "tenengrad")[mask].sum()
        regions.append({"depth": z, "pixels": pixels, "focus_per_depth": score.tolist(),
                        "sharpest_at_own_depth": bool(pixels > 0 and int(np.argmax(score)) == i),
                        "ratio_to_next_best": float(score[i] / max(np.max(np.delete(score, i)), 1e-30))
                        if len(depths) > 1 and pixels else float("nan")})
    return {"measure": "tenengrad", "band_inverse_depth": FOCUS_BAND, "regions": regions,
            "all_sharpest_at_own_depth": all(r["sharpest_at_own_depth"] for r in regions)}


def _capture(scene_path, defines, fps, factor, duration, depths, spp, seed, steps_per_frame, progress, split):
    """What the rig records: kaleidoscope events (mono) and the RGB camera's keyframes. Returns (the colour
    scene, events, optics, output times, key mask, keyframes, duration, the duration before its cut to whole
    frame intervals)."""
    t0 = time.perf_counter()
    _variant_for(color=False)
    timed = load_scene(scene_path, **defines)
    if duration is None:
        duration = timed.motion.duration if timed.motion and timed.motion.duration else None
        if duration is None:
            raise ConfigError(f"{scene_path}: duration not given and the scene has no motion file duration")
        _check(fps, factor, depths, duration)
    asked = duration                            # the motion file's too: a cut is said (the report)
    intervals = int(math.floor(duration * fps + 1e-6))
    duration = intervals / fps
    optics = timed.sensor.optics_metadata() if hasattr(timed.sensor, "optics_metadata") else {}
    if optics.get("design") not in ("kaleidoscope", "microlens"):
        raise ConfigError(f"{scene_path}: SloMoRF needs a kaleidoscope (or microlens) sensor; the scene's "
                          f"sensor is {type(timed.sensor).__name__}")
    # a depth with nothing on it scored NaN after every render (the defaults are scenes/falling's): said first
    check_planes_seen(timed, {f"--depths {z:g}": z for z in depths}, [0.0, duration / 2, duration], FOCUS_BAND,
                      scene_path, min_pixels=1, depth_at=lambda t: _depth_views(timed, [t], optics)[0])
    events = render_events(timed, duration, steps=intervals * steps_per_frame, spp=spp, seed=seed,
                           progress=progress)
    t1 = time.perf_counter()
    split["render_events"] = t1 - t0
    _variant_for(color=True)
    timed_rgb = load_scene(scene_path, **defines)
    times = np.arange(intervals * factor + 1) / (fps * factor)
    is_key = np.arange(len(times)) % factor == 0
    keys = render_frames(timed_rgb, times[is_key], spp=spp, seed=seed, log=False, rgb=True)
    split["render_rgb_frames"] = time.perf_counter() - t1
    return timed_rgb, events, optics, times, is_key, keys, duration, asked


def slow_motion_frames(events, keys, times, is_key, factor: int) -> dict:
    """The algorithm, without any scoring: the films between RGB keyframes ``keys`` at ``times[is_key]``,
    from the events between them. {"events", "events_time", "linear"} -> (T, H, W, 3) linear RGB (keyframes
    copied at key instants)."""
    from ..events.stream import EventStream
    from ..lightfield import reconstruct

    # cumulative log change and event counts from t = 0 at every output instant: one pass each
    log_cum = reconstruct.direct(events, times, t_start=0.0)
    ones = EventStream(events.x, events.y, events.t, np.ones_like(events.p), events.width, events.height,
                       events.meta)
    count_cum = reconstruct.direct(ones, times, t_start=0.0, c_on=1.0, c_off=1.0)
    key_at = np.empty((len(times),) + keys.shape[1:], np.float32)
    key_at[is_key] = keys
    frames = {}
    for name in METHODS:
        frames[name] = np.empty_like(key_at)
        frames[name][is_key] = keys
    for j in np.nonzero(~is_key)[0]:
        a, b = (j // factor) * factor, (j // factor + 1) * factor
        ka, kb = key_at[a].astype(np.float64), key_at[b].astype(np.float64)
        wb = (j - a) / factor
        d_at, d_tb = log_cum[j] - log_cum[a], log_cum[b] - log_cum[j]
        n_at, n_tb = count_cum[j] - count_cum[a], count_cum[b] - count_cum[j]
        frames["events"][j] = interpolate(ka, kb, d_at, d_tb, n_at, n_tb, wb, "events")
        frames["events_time"][j] = interpolate(ka, kb, d_at, d_tb, w_b=wb, fusion="time")
        frames["linear"][j] = (1 - wb) * ka + wb * kb
    return frames


def refocus_films(films, times, optics, depths) -> np.ndarray:
    """(T, D, h, w, 3): every film split into its views and refocused at each depth."""
    from ..focus.refocus import refocus
    from ..lightfield.model import from_spatial
    out = None
    for j, film in enumerate(films):
        lf = from_spatial(film, optics, time=float(times[j]), log=False)
        imgs = np.stack([refocus(lf, z) for z in depths]).astype(np.float32)
        if out is None:
            out = np.empty((len(films),) + imgs.shape, np.float32)
        out[j] = imgs
    return out


def _meta(scene_path, defines, fps, factor, duration, depths, spp, seed, steps_per_frame, is_key, truth, view,
          events, optics, split) -> dict:
    return {"scene": os.path.abspath(scene_path), "defines": defines, "fps": fps, "factor": factor,
            "output_fps": fps * factor, "duration_s": duration, "rgb_frames": int(is_key.sum()),
            "depths": list(depths), "spp": spp, "seed": seed, "steps_per_frame": steps_per_frame,
            "film": [int(truth.shape[2]), int(truth.shape[1])], "view": [int(view[1]), int(view[0])],
            "events": len(events), "fusion": "events: each side weighted by the event count on the other side; "
            "time-distance weights where a pixel did not fire", "baseline": "linear blend of the bracketing frames",
            "score_domain": "8-bit, gamma 1/2.2, of linear radiance clipped to [0, 1]",
            "moving_pixels": f"8-bit difference > {MOVING_LEVEL} from either bracketing keyframe",
            "inputs": "kaleidoscope events + RGB keyframes (the truth is rendered for scoring only)",
            "optics": optics, "pixel_model": events.meta.get("pixel_model"),
            "package_version": events.meta.get("package_version"), "time_split_s": split}


def slomorf(scene_path: str, defines: dict | None = None, fps: float = 120.0, factor: int = 8,
            duration: float | None = None, depths=DEFAULT_DEPTHS, spp: int = 4, seed: int = 0,
            steps_per_frame: int | None = None, progress: bool = False) -> SloMoRFResult:
    """Slow-motion refocus of a kaleidoscope scene, scored against the renderer (module docstring): the
    capture (``_capture``), the algorithm (``slow_motion_frames``, ``refocus_films``), then the scoring.

    ``duration``: seconds (default: the motion file's), cut to whole RGB frame intervals; ``steps_per_frame``:
    event-render steps per RGB frame interval (default 4 x factor); ``spp``/``seed``: for events and frames.
    """
    from .. import backend
    fps, factor, depths = _check(fps, factor, depths, duration)
    steps_per_frame = 4 * factor if steps_per_frame is None else int(steps_per_frame)
    if steps_per_frame < 1:
        raise ConfigError(f"steps_per_frame = {steps_per_frame}: must be an integer >= 1")
    defines = dict(defines or {})
    previous = backend.mi.variant()
    split = {}
    try:
        timed_rgb, events, optics, times, is_key, keys, duration, asked = _capture(
            scene_path, defines, fps, factor, duration, depths, spp, seed, steps_per_frame, progress, split)
        t2 = time.perf_counter()
        truth = np.empty((len(times),) + keys.shape[1:], np.float32)      # for scoring only
        truth[is_key] = keys
        truth[~is_key] = render_frames(timed_rgb, times[~is_key], spp=spp, seed=seed, log=False, rgb=True)
        depth_views = _depth_views(timed_rgb, times, optics)
        t3 = time.perf_counter()
        split["render_truth_for_scoring"] = t3 - t2
        frames = dict(truth=truth, **slow_motion_frames(events, keys, times, is_key, factor))
        t4 = time.perf_counter()
        split["interpolate"] = t4 - t3
        refocused = {"events": refocus_films(frames["events"], times, optics, depths)}
        t5 = time.perf_counter()
        refocused.update({name: refocus_films(films, times, optics, depths) for name, films in frames.items()
                          if name != "events"})       # the truth and the comparisons: for scoring only
        split["refocus"] = t5 - t4
        split["refocus_for_scoring"] = time.perf_counter() - t5
        t6 = time.perf_counter()
        metrics = _score(frames, refocused, is_key, depths, factor)
        metrics["focus_check"] = focus_check(refocused["events"], depth_views, depths, is_key)
        split["score"] = time.perf_counter() - t6
    finally:
        if previous and backend.mi.variant() != previous:
            backend.set_variant(previous)
    meta = _meta(scene_path, defines, fps, factor, duration, depths, spp, seed, steps_per_frame, is_key, truth,
                 refocused["truth"].shape[2:4], events, optics, split)
    if abs(asked - duration) > 1e-12:                                # cut to whole frame intervals: said
        meta["duration_asked_s"] = float(asked)
    refocused = {name: refocused[name] for name in frames}           # the order of the films, as before
    return SloMoRFResult(times, is_key, frames, depths, refocused, metrics, meta)


def _score(frames, refocused, is_key, depths, factor):
    truth8 = to_display(frames["truth"])
    truth_rf8 = to_display(refocused["truth"])
    metrics = {"interpolated_frames": int((~is_key).sum()), "frames": {}, "refocus": {}}
    for name in METHODS:
        est8, est_rf8 = to_display(frames[name]), to_display(refocused[name])
        rows, rf_rows = [], [[] for _ in depths]
        for j in np.nonzero(~is_key)[0]:
            a, b = (j // factor) * factor, (j // factor + 1) * factor
            diff = lambda k: np.abs(truth8[j].astype(np.int16) - truth8[k]).max(-1) > MOVING_LEVEL  # noqa: E731
            rows.append(_frame_scores(est8[j], truth8[j], diff(a) | diff(b)))
            for i in range(len(depths)):
                ta, tb = truth_rf8[a, i].astype(np.int16), truth_rf8[b, i].astype(np.int16)
                moving = (np.abs(truth_rf8[j, i] - ta).max(-1) > MOVING_LEVEL) | \
                         (np.abs(truth_rf8[j, i] - tb).max(-1) > MOVING_LEVEL)
                rf_rows[i].append(_frame_scores(est_rf8[j, i], truth_rf8[j, i], moving))
        metrics["frames"][name] = _aggregate(rows)
        per_depth = [dict(_aggregate(r), depth=z) for r, z in zip(rf_rows, depths)]
        metrics["refocus"][name] = dict(_aggregate([row for r in rf_rows for row in r]), per_depth=per_depth)
    return metrics
