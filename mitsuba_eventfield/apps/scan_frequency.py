"""Scan frequency against motion and readout (the paper's Fig. 11): a spinning fan with text, seen through the
galvo at rising scan frequencies, with and without the event camera's readout cap.

One light field is one scan period. The views of a period are taken at different instants, so what moves
during the period is smeared across the refocused image: at a higher scan frequency the fan turns less per
period and its text is sharper. But every scan period makes every edge fire again, so the offered event rate
grows in proportion to the frequency; past the rate the readout can pass (an IMX636-class sensor: 1.066 GEPS
for 1280 x 720, ``plugins.pixel_model`` preset ``prophesee_gen4``, scaled to the film's pixel count and by
``cap_scale``) events are dropped at random and the refocused images, moving or static, degrade again.

``sweep`` renders, per frequency, the same ``duration`` (whole scan periods) of events twice: with the scene's
own pixel (no readout limit) and with the cap. Each period's light field (``direct`` integration onto a start
image: ``start="frame"`` is one rendered frame at t = 0, extra information the rig must have, e.g. a
conventional camera beside the event camera; ``start="events"`` the events-only period solver,
``focus.galvo_periods``) is
refocused on each plane, and scored on that plane's pixels (Mitsuba's depth at the period's middle within
``region_tolerance``) against the renderer:

* sharpness: PSNR, SSIM and edge contrast (the share of the reference's log-gradient energy present, along the
  reference's edges; noise does not count) against Mitsuba's instantaneous centre view at the period's middle
  (the motion-free picture; the methods never see it). Scored alike: the same views rendered directly and
  refocused by the same code ("views": the light field's own motion limit, no event sensor);
* fidelity: PSNR of each event light field's refocus against those rendered views refocused alike (same
  views, same motion): what the event sensor and its readout lose.

Example crops (the period nearest the middle of the capture) at the lowest, middle and highest frequency go
into the figure with one tone mapping; metrics.json carries the ``paper`` rows.

The cap's scaling. The bundled text wall is dense black print: the 0.5 deg circle fires about 26 events per
pixel per scan period, so the IMX636 budget itself (1157 events per pixel per second) would be crossed near
37 Hz. The default cap is that budget x5 (``cap_scale``), which puts the crossing near the paper's 250 Hz onset.
The frequencies stop at 500 Hz, where a GVS01x-class galvo (``optics.envelope``) still drives a 0.5 deg circle.

Measured with the defaults (fan, 160 x 120, 24 views, 8 ms per frequency, one run, 110 s on 2 CPU cores):
offered 66-251 Mev/s for 125-500 Hz against a 111 Mev/s cap (crossing 217 Hz; 0, 21, 47, 60 % dropped). Edge
contrast kept on the fan without the cap 0.11, 0.27, 0.40, 0.51 (the rendered views alike 0.12-0.53); with
the cap 0.11, 0.26, 0.29, 0.22, sharpest at 375 Hz. On the static wall without the cap 0.76-0.90, with it 0.76,
0.76, 0.57, 0.47. Lost events make direct integration drift pixel by pixel; each drifting pixel is spread over
its scan circle by the refocus (the rings in the capped crops).
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError, EventFieldError
from ..plugins.pixel_model import PRESETS, film_readout_cap
from ..scene import bundled_scene, load_scene
from ..simulate.render import render_events
from ..validate import MAX_SPP, MAX_VIEWS, number
from .result import AppResult, time_split_line

SCENE = "fan/fan.xml"                                    # bundled (scene.bundled_scene)
PLANES = {"fan": 0.6, "wall": 1.5}                      # the fan's planes (its XML: fan at 0.6 m, wall at 1.5 m)
FREQUENCIES = (125.0, 250.0, 375.0, 500.0)   # 1 kHz: the GVS01x model refuses a 0.5 deg circle there
SOURCES = {"views": "rendered views (no sensor)", "events": "events, no readout limit",
           "capped": "events through the readout cap"}
IMX636 = {k: PRESETS["prophesee_gen4"][k] for k in ("readout_cap", "readout_cap_native_pixels")}
EDGE_FLOOR = 0.02                 # edge contrast: log of max(image, 2% of its median)
TRUTH_SPP = 64                    # the instantaneous reference is converged, as capture's rendered views
PAPER_CAP_ONSET_HZ = 250.0        # the paper's prototype starts losing events beyond a 250 Hz scan


def readout_pixel(cap_scale: float = 1.0) -> dict:
    """Pixel parameters (``render_events(pixel=...)``) of the IMX636 readout cap times ``cap_scale``."""
    return {"readout_cap": IMX636["readout_cap"] * cap_scale,
            "readout_cap_native_pixels": IMX636["readout_cap_native_pixels"]}


def film_cap(pixel: dict, width: int, height: int) -> float:
    """Events per second that ``pixel``'s readout cap passes on a width x height film."""
    return film_readout_cap(pixel["readout_cap"], pixel.get("readout_cap_native_pixels"), width * height)


def offered_rates(events, duration: float) -> dict:
    """Mean event rate the pixels offer to the readout (kept + dropped) and the busiest 1 ms (kept events:
    give the stream rendered without a cap for the offered peak)."""
    dropped = int(events.meta["render"].get("dropped_readout", 0))
    ms = np.bincount((np.asarray(events.t, np.int64) - events.start_us) // 1000)
    whole = ms[:max(1, int(math.floor(duration * 1e3 + 1e-9)))]
    total = len(events) + dropped
    return {"offered_ev_s": total / duration, "peak_1ms_ev_s": float(whole.max()) * 1e3 if len(whole) else 0.0,
            "dropped_fraction": dropped / total if total else 0.0}


def edge_contrast(img, ref, mask=None, floor: float = 0.0) -> float:
    """Sharpness as the fraction of the reference's edge contrast present in ``img``: the projection of its
    log-image gradient onto the reference's, over the reference's gradient energy (on ``mask``, default all).
    Noise (which raises plain gradient-energy measures) is uncorrelated with the true edges and does not count.
    ``floor``: each image is floored at this fraction of its own median on ``mask`` before the log, so black
    print does not turn Monte-Carlo specks into huge log gradients, one overall gain (an event camera's unknown
    constant) changes nothing, and a few runaway pixels (events lost to the readout) do not move the floor as
    they would a white level; 0: a floor of 1e-6."""
    import cv2
    m = np.ones(np.shape(ref), bool) if mask is None else mask
    logs = [np.log(np.maximum(a, max(1e-6, floor * float(np.median(a[m]))))).astype(np.float32) for a in (img, ref)]
    g = [cv2.Sobel(a, cv2.CV_32F, dx, dy, ksize=3) for a in logs for dx, dy in ((1, 0), (0, 1))]
    return float(((g[0] * g[2])[m].sum() + (g[1] * g[3])[m].sum()) / ((g[2] ** 2)[m].sum() + (g[3] ** 2)[m].sum()))


def region_scores(img, ref, mask) -> dict:
    """PSNR and SSIM on ``mask`` on the scale of ``evaluation.quality`` (white level of the reference's region;
    SSIM: OpenCV's map on 8-bit codes, averaged over the region), and the edge contrast kept."""
    from ..evaluation.quality import psnr, ssim_map, white_level
    white = white_level(ref[mask])
    codes = [np.rint(np.clip(a / white, 0, 1) * 255).astype(np.uint8) for a in (img, ref)]
    return {"psnr_db": psnr(img[mask], ref[mask], white), "ssim": float(ssim_map(*codes)[mask].mean()),
            "edge_contrast": edge_contrast(img, ref, mask, EDGE_FLOOR)}


@dataclass
class ScanFrequencySweep(AppResult):
    frequencies: list
    planes: dict                 # name -> depth
    rows: list                   # per frequency: rates, and scores[plane][source] -> mean over periods
    cap_ev_s: float | None       # the readout cap on this film (None: no capped run)
    crops: list                  # per frequency: {"t_s", "instant", source -> refocus on the first plane, "region"}
    meta: dict = field(default_factory=dict)

    def score(self, source: str, plane: str | None = None, metric: str = "edge_contrast") -> np.ndarray:
        """One metric per frequency (mean over the periods) of one source on one plane (default: the first)."""
        plane = plane or next(iter(self.planes))
        return np.array([r["scores"][plane][source][metric] if source in r["scores"][plane] else np.nan
                         for r in self.rows])

    def rate_line(self) -> tuple | None:
        """(events per hertz, events per second): the offered rate as a line in the scan frequency (each period
        fires every edge again; the scene's own motion adds a constant); None with fewer than two frequencies."""
        if len(self.rows) < 2:
            return None
        a, b = np.polyfit(self.frequencies, [r["offered_ev_s"] for r in self.rows], 1)
        return float(a), float(b)

    def crossing(self, cap_ev_s: float | None) -> float | None:
        """Scan frequency at which the offered rate reaches ``cap_ev_s``."""
        line = self.rate_line()
        return None if cap_ev_s is None or line is None or line[0] <= 0 else (cap_ev_s - line[1]) / line[0]

    @property
    def crossing_hz(self) -> float | None:
        """Where the offered rate meets this run's cap (None without a cap or with one frequency)."""
        return self.crossing(self.cap_ev_s)

    def report(self) -> str:
        m = self.meta
        limit = (f"readout cap {self.cap_ev_s / 1e6:.1f} Mev/s (IMX636 {IMX636['readout_cap'] / 1e9:.3g} GEPS per "
               f"{IMX636['readout_cap_native_pixels']} px, scaled to {m['width']}x{m['height']} px, "
               f"x{m['cap_scale']:g}); offered rate crosses it at {self.crossing_hz or float('nan'):.0f} Hz"
               if self.cap_ev_s else "no readout cap run")
        lines = [f"scan-frequency sweep of {os.path.basename(m['scene'])}: {m['duration_s'] * 1e3:g} ms of events per "
                 f"frequency, {m['views']} views per period, start image: {m['start_note']}; {limit}",
                 "  scores: mean over the periods, on each plane's pixels (Mitsuba depth), against Mitsuba's "
                 "instantaneous centre view (edge contrast kept, PSNR dB); fidelity: PSNR dB against the rendered "
                 "views refocused alike",
                 "  Hz     periods  offered Mev/s (peak 1 ms)  dropped | plane: edge contrast views/events/capped, "
                 "PSNR events/capped, fidelity events/capped"]
        for r in self.rows:
            parts = []
            for plane in self.planes:
                s = r["scores"][plane]
                cap = s.get("capped", {})
                parts.append(f"{plane}: {s['views']['edge_contrast']:.3f}/{s['events']['edge_contrast']:.3f}/"
                             f"{cap.get('edge_contrast', float('nan')):.3f}, {s['events']['psnr_db']:.2f}/"
                             f"{cap.get('psnr_db', float('nan')):.2f} dB, {s['events']['psnr_vs_views_db']:.2f}/"
                             f"{cap.get('psnr_vs_views_db', float('nan')):.2f} dB")
            lines.append(f"  {r['frequency_hz']:<6g} {r['periods']:>4}     {r['offered_ev_s'] / 1e6:8.1f} "
                         f"({r['peak_1ms_ev_s'] / 1e6:6.1f})       {100 * r['dropped_fraction']:5.1f}% | "
                         + "; ".join(parts))
        lines.append(time_split_line(m["time_split_s"], indent="  "))
        return "\n".join(lines)

    def paper_rows(self) -> list:
        from .scan_frequency_outputs import paper_rows
        return paper_rows(self)

    def write(self, out_dir: str) -> dict:
        from .scan_frequency_outputs import write_outputs
        return write_outputs(self, out_dir)

    def figure(self, path: str) -> str:
        from .scan_frequency_outputs import figure
        return figure(self, path)


def paper_rows(result: ScanFrequencySweep) -> list:
    """The metrics.json "paper" rows of a sweep (Fig. 11), as the other applications' ``paper_rows``."""
    return result.paper_rows()


def _check(frequencies, duration, views, cap_scale, start, region_tolerance, planes, spp=4, margin=4) -> tuple:
    """Every argument checked (one-line ConfigError) before anything is rendered; returns the frequencies (sorted)
    with their whole numbers of periods, and the planes."""
    from .capture import START_METHODS
    from .highspeed import _check_planes
    duration = number(duration, "duration", 0, 1.0, lo_open=True, strict=True)
    try:
        freqs = sorted({float(number(f, "frequency", 0, 1e5, lo_open=True, strict=True)) for f in frequencies})
    except TypeError:
        raise ConfigError(f"frequencies = {frequencies!r}: give a list of scan frequencies (Hz)") from None
    if not freqs:
        raise ConfigError("frequencies: give at least one scan frequency (Hz)")
    periods = []
    for f in freqs:
        n = duration * f
        if round(n) < 1 or abs(n - round(n)) > 1e-6 * max(1.0, n):
            raise ConfigError(f"frequency {f:g} Hz: duration {duration * 1e3:g} ms is not a whole number of its scan "
                             f"periods ({n:.3g}); choose frequencies that are multiples of {1 / duration:g} Hz")
        periods.append(int(round(n)))
    number(views, "views", 2, MAX_VIEWS, integer=True, strict=True)
    number(cap_scale, "cap_scale", 0, 1e6, lo_open=True, strict=True)
    number(region_tolerance, "region_tolerance", 0, 0.99, lo_open=True, strict=True)
    number(spp, "spp", 1, MAX_SPP, integer=True, strict=True)
    number(margin, "margin", 0, 1000, integer=True, strict=True)
    if start not in START_METHODS:
        raise ConfigError(f"start = {start!r}: allowed {', '.join(START_METHODS)}")
    try:
        return freqs, periods, _check_planes(planes)
    except ValueError as e:
        raise ConfigError(str(e)) from None


def _scene(scene_path, defines, frequency):
    """The scene at one scan frequency (its ``frequency`` XML default), checked to scan at that frequency."""
    try:
        timed = load_scene(scene_path, **{**defines, "frequency": frequency})
    except EventFieldError as e:
        if "$frequency" in str(e) and "unused" in str(e):
            raise ConfigError(f"{scene_path}: has no `frequency` XML default, so its scan frequency cannot be swept "
                              '(declare <default name="frequency" .../> and use it in the galvo sensor)') from None
        raise
    optics = timed.sensor.optics_metadata() if hasattr(timed.sensor, "optics_metadata") else {}
    if optics.get("design") != "galvo" or not timed.scan_period:
        raise ConfigError(f"{scene_path}: needs a galvo sensor with a periodic scan (got {optics.get('design')!r})")
    if abs(timed.scan_period * frequency - 1) > 1e-6:
        raise ConfigError(f"{scene_path}: its scan does not follow the `frequency` XML default (period "
                         f"{timed.scan_period * 1e3:g} ms at frequency={frequency:g}); declare "
                         '<default name="frequency" .../> and use it in the sensor')
    return timed


def _score_periods(cap, capped_lfs, planes, tolerance, margin, t_show) -> tuple:
    """Scores of every period's refocus (per plane and source, mean over the periods) and the images of the
    period nearest ``t_show`` for the figure. Events alone fix brightness up to one gain: an events-only
    capture's light fields are scaled by one gain per source, fitted once over every period and plane
    (``quality.fit_gain``; as the designs comparison, and the metrics say so), where its refocus was scored
    as it came (median 2.06 against the reference's 0.545)."""
    from ..evaluation.quality import fit_gain
    from ..evaluation.truth import centre_frame, truth_depth
    from ..focus.refocus import refocus
    from .capture import INPUTS
    periods, shown, first = [], None, next(iter(planes))
    mids = [float(lf.times.mean()) for lf in cap.lightfields]
    pick = int(np.argmin(np.abs(np.array(mids) - t_show)))
    for k, lf in enumerate(cap.lightfields):
        sources = {"views": cap.truth_lightfields[k], "events": lf, **({"capped": capped_lfs[k]} if capped_lfs else {})}
        z = truth_depth(cap.timed, mids[k])
        inner = np.zeros(z.shape, bool)
        inner[margin:z.shape[0] - margin, margin:z.shape[1] - margin] = True
        periods.append({"instant": centre_frame(cap.timed, mids[k], log=False, spp=TRUTH_SPP),
                        "regions": {n: inner & np.isfinite(z) & (np.abs(z / d - 1) < tolerance)
                                    for n, d in planes.items()},
                        "refocused": {n: {s: refocus(l, d, on_motion="ignore") for s, l in sources.items()}   # (scored)
                                      for n, d in planes.items()}})
    gains = {}
    if cap.lightfields and cap.lightfields[0].meta.get("inputs") == INPUTS["events"]:
        for s in ("events", "capped") if capped_lfs else ("events",):
            gains[s] = fit_gain(np.stack([p["refocused"][n][s] for p in periods for n in planes]),
                                np.stack([p["instant"] for p in periods for _ in planes]))
    per_period = []
    for k, p in enumerate(periods):
        scores = {}
        for name in planes:
            refocused = {s: img * gains.get(s, 1.0) for s, img in p["refocused"][name].items()}
            scores[name] = {s: _scores(img, p["instant"], p["regions"][name], refocused)
                            for s, img in refocused.items()}
            if k == pick and name == first:
                shown = {"t_s": mids[k], "instant": p["instant"], "region": p["regions"][name], **refocused}
        per_period.append(scores)
    mean = {name: {s: {m: float(np.nanmean([p[name][s][m] for p in per_period])) for m in per_period[0][name][s]}
                   for s in per_period[0][name]} for name in planes}
    return mean, shown, gains


def _scores(img, instant, region, refocused) -> dict:
    from ..evaluation.quality import psnr, white_level
    if region.sum() < 16:                            # the plane left the view in this period
        return {m: float("nan") for m in ("psnr_db", "ssim", "edge_contrast", "psnr_vs_views_db", "edge_vs_events")}
    out = region_scores(img, instant, region)
    views = refocused["views"]
    out["psnr_vs_views_db"] = psnr(img[region], views[region], white_level(views[region]))
    out["edge_vs_events"] = edge_contrast(img, refocused["events"], region, EDGE_FLOOR)
    return out


def sweep(scene: str | None = None, frequencies=FREQUENCIES, planes: dict | None = None,
          defines: dict | None = None, duration: float = 0.008, views: int = 24, readout_cap: bool = True,
          cap_scale: float = 5.0, start: str = "frame", region_tolerance: float = 0.1, spp: int = 4,
          margin: int = 4, progress: bool = False) -> ScanFrequencySweep:
    """Per scan frequency, ``duration`` seconds of events (a whole number of scan periods, so the frequencies must
    be multiples of 1 / duration) from the scene's own pixel and, with ``readout_cap``, from the same pixel
    behind the IMX636 readout cap x ``cap_scale``; one light field per period refocused on each plane of
    ``planes`` ({name: depth}; default for the fan: fan 0.6, wall 1.5) and scored (module docstring).
    ``scene``: a galvo scene whose scan frequency is its ``frequency`` XML default (default: the bundled fan at
    160 x 120); ``defines``: its other XML defaults."""
    from ..evaluation.truth import check_planes_seen
    from .capture import capture, lightfields, reuse_for
    fan = scene is None
    scene = bundled_scene(SCENE) if fan else scene
    defines = {**({"width": 160, "height": 120} if fan else {}), **(defines or {})}
    if "frequency" in defines:       # each run sets it: a define would be dropped (-D frequency=300 ran 250 Hz)
        raise ConfigError(f"defines: frequency = {defines['frequency']!r}: the sweep sets the scan frequency of each "
                          "run; give the frequencies to sweep (--frequencies) instead")
    planes = PLANES if planes is None and fan else planes
    freqs, periods, planes = _check(frequencies, duration, views, cap_scale, start, region_tolerance, planes or {},
                                    spp, margin)
    timed = _scene(scene, defines, freqs[0])                    # before any rendering: the scene and its planes
    check_planes_seen(timed, planes, duration / 2, region_tolerance, scene)
    width, height = timed.film_size
    pixel = readout_pixel(cap_scale) if readout_cap else None
    rows, crops, seconds = [], [], {"render_events": 0.0, "views_from_events": 0.0, "ground_truth_views": 0.0,
                                    "scoring": 0.0}
    for f, n in zip(freqs, periods):
        cap = capture(scene, {**defines, "frequency": f}, periods=n, views=views, start=start, spp=spp,
                      progress=progress)
        for key in ("render_events", "views_from_events", "ground_truth_views"):
            seconds[key] += cap.seconds[key]
        rates = offered_rates(cap.events, n / f)
        capped_lfs = None
        if pixel:
            t0 = time.perf_counter()
            ev = render_events(cap.timed, n / f, steps=cap.events.meta["stepping"]["steps"], spp=spp, pixel=pixel,
                               progress=progress, reuse=reuse_for(start))
            t1 = time.perf_counter()
            capped_lfs = lightfields(ev, cap.timed, views, start, spp)[0]   # as capture builds its own
            seconds["render_events"] += t1 - t0
            seconds["views_from_events"] += time.perf_counter() - t1
            capped = offered_rates(ev, n / f)
            rates.update(dropped_fraction=capped["dropped_fraction"], kept_ev_s=len(ev) / (n / f),
                         capped_offered_ev_s=capped["offered_ev_s"])
        t0 = time.perf_counter()
        scores, shown, gains = _score_periods(cap, capped_lfs, planes, region_tolerance, margin, duration / 2)
        seconds["scoring"] += time.perf_counter() - t0
        rows.append({"frequency_hz": f, "periods": n, "period_ms": 1e3 / f, **rates, "scores": scores,
                     **({"gains_fitted": gains} if gains else {})})
        crops.append(shown)
    start_note = ("one rendered frame at t = 0 (extra information: a conventional camera beside the event camera)"
                  if start == "frame" else
                  "the events alone (focus.galvo_periods.reconstruct_periods, up to a constant: scored after one "
                  "gain per source and frequency, fitted to the reference, rows' gains_fitted)")
    meta = {"scene": scene, "defines": {k: v for k, v in defines.items() if k != "frequency"}, "width": width,
            "height": height, "duration_s": duration, "views": views, "start": start, "start_note": start_note,
            "readout_cap": bool(readout_cap), "cap_scale": cap_scale, "region_tolerance": region_tolerance,
            "spp": spp, "pixel_model": cap.events.meta["pixel_model"], "readout_pixel": pixel,
            "time_split_s": seconds}
    return ScanFrequencySweep(freqs, planes, rows, film_cap(pixel, width, height) if pixel else None, crops, meta)
