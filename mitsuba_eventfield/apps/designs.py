"""Kaleidoscope against galvo (paper section 6, "Kaleidoscope vs Galvanometer Designs": Fig. 5, Fig. 6, and the
bandwidth row of Table 1), simulated and scored against the renderer. The kaleidoscope multiplexes views in
space (n x n views on the film, one instant): its events are temporal derivatives, static content fires
nothing. The galvo multiplexes them in time (a periodic mirror scan): its events are angular derivatives, static
content is seen, but a light field takes a scan period and what moves meanwhile blurs.

``compare`` (Fig. 5, Table 1): scenes/designs, two textured cards 1 m away on the kaleidoscope's focus plane,
side by side against a uniform sky; "static" never moves, "moving" slides up. One film size (one event sensor),
one field of view per view. Speeds scale the motion file (1x: about 2.5 galvo pixels per 4 ms scan period, as
the paper's). Per speed, events of both designs over ``periods`` scan periods with the same time steps, then
light fields from the events only:

* kaleidoscope: at the middle of each scan period, every pixel's events integrated from t = 0 (the log change
  since then: ``reconstruct.direct`` from zeros, the start image being unknown), split into views;
* galvo: each period's image solved from its events alone (``focus.galvo_periods``: per-pixel depth from focus
  within a factor 2 of the cards' plane, moving content turned down, the previous period as the prior), its
  ``views`` views integrated onto it; and, for the design's own limit without reconstruction error, the same
  views rendered ("galvo_rendered_views").

Each is refocused on the cards' plane and scored against the instant it stands for (the kaleidoscope's views
rendered then, refocused alike; the galvo's centre view mid-period); views are also scored one by one against
the rendered views of their instant. Regions: Mitsuba's ``shape_index`` AOV (``_regions``). Events fix log
intensity only up to a constant, so an estimate is first scaled by one gain (``gain_aligned``: part of the score,
the method never sees the reference); then PSNR (``quality.psnr``) and the correlation with the reference on
the region (0 for a flat estimate: nothing recovered). Bandwidth (Table 1): events per second of each design,
in all and per static-object pixel.

``grid_experiment`` (Fig. 6): a grid sliding horizontally (scenes/moving_grid), event rates on pixels of
horizontal and of vertical lines (``grid_classes``). Outputs: ``designs_outputs``.
"""
from __future__ import annotations

import copy
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError
from ..optics.galvo import scan_parallax_px
from ..scene import bundled_scene, load_scene
from ..scene.coverage import shape_masks, unseen
from ..simulate.render import render_events, render_frames
from ..validate import MAX_SPP, MAX_VIEWS, number
from .designs_outputs import compare_figure, compare_report, grid_figure, grid_report, write_compare, write_grid
from .result import AppResult

SPEEDS = (1.0, 2.0, 4.0, 8.0)
ROWS = ("kaleidoscope", "galvo", "galvo_rendered_views")      # the light fields scored, per speed
VIEW_ROWS = ROWS[:2]                                          # the rendered views are the views' references
REGIONS = ("static", "moving")


def default_scenes(grid: bool = False) -> tuple:
    """(galvo scene, kaleidoscope scene) bundled for ``compare`` (scenes/designs) or ``grid_experiment``."""
    folder = "moving_grid" if grid else "designs"
    return bundled_scene(f"{folder}/galvo.xml"), bundled_scene(f"{folder}/kaleidoscope.xml")


# ------------------------------------------------------------------------------------------------ helpers

def scaled_motion(scene_path: str, speed: float) -> dict:
    """The motion file next to ``scene_path`` with every object ``speed`` times faster (velocities and spins
    scaled, keyframe times divided), as a dict for ``load_scene(motion=...)``."""
    from ..scene.motion import load_motion, motion_path_for
    path = motion_path_for(scene_path)
    if not os.path.isfile(path):
        raise ConfigError(f"{scene_path}: no motion file {os.path.basename(path)} beside it (the speeds scale it)")
    raw = copy.deepcopy(load_motion(path).raw)
    for obj in raw.get("objects", {}).values():
        if "velocity" in obj:
            obj["velocity"] = [speed * float(v) for v in obj["velocity"]]
        if "spin" in obj and "rpm" in obj["spin"]:
            obj["spin"]["rpm"] = speed * float(obj["spin"]["rpm"])
        for key in obj.get("keyframes", []):
            key["t"] = float(key["t"]) / speed
    return raw


def _regions(masks: dict, moving_ids) -> dict:
    """{"static", "moving"}: the pixels of the shapes the motion file leaves still, and of those it moves."""
    none = np.zeros(next(iter(masks.values())).shape, bool)
    return {"static": np.logical_or.reduce([none] + [m for s, m in masks.items() if s not in moving_ids]),
            "moving": np.logical_or.reduce([none] + [m for s, m in masks.items() if s in moving_ids])}


def region_scores(estimate, reference, regions: dict) -> dict:
    """{region: {"psnr_db", "correlation"}} after one gain (module docstring); NaN for an empty region."""
    from ..evaluation.quality import gain_aligned, psnr, white_level
    est, ref = gain_aligned(estimate, reference), np.asarray(reference, np.float64)
    white = white_level(ref)
    out = {}
    for name, mask in regions.items():
        e, r = est[mask], ref[mask]
        flat = e.size < 2 or e.std() <= 1e-4 * abs(e.mean()) or r.std() == 0
        out[name] = {"psnr_db": psnr(e, r, white) if e.size else float("nan"),
                     "correlation": float("nan") if e.size < 2 else 0.0 if flat else float(np.corrcoef(e, r)[0, 1])}
    return out


def _mean_scores(rows: list) -> dict:
    return {n: {k: float(np.nanmean([r[n][k] for r in rows])) for k in ("psnr_db", "correlation")} for n in REGIONS}


def _append(store: dict, scores: dict) -> None:
    for n, k in ((n, k) for n in REGIONS for k in scores[n]):
        store.setdefault(n, {}).setdefault(k, []).append(scores[n][k])


def _check(film, speeds, periods, views, spp, depth):
    if film is not None:
        # a multiple of the kaleidoscope's n views a side, which its sensor checks (_load_pair): a fixed 3 here
        film = number(film, "film", 30, 4096, integer=True, strict=True)   # refused a 5 x 5 scene's films
    speeds = tuple(number(s, "speeds", 0, 64, lo_open=True, strict=True) for s in speeds)
    if not speeds:
        raise ConfigError("speeds: give at least one speed factor (> 0)")
    twice = sorted({f"{v:g}" for v in speeds if speeds.count(v) > 1})
    if twice:        # each speed's images are named by it: a repeat overwrote them while counted twice
        raise ConfigError(f"speeds: {', '.join(twice)} given more than once; give each speed factor once")
    periods = number(periods, "periods", 1, 100, integer=True, strict=True)
    views = number(views, "views", 4, MAX_VIEWS, integer=True, strict=True)
    spp = number(spp, "spp", 1, MAX_SPP, integer=True, strict=True)
    if depth is not None:
        depth = number(depth, "depth", 0, lo_open=True, strict=True)
    return film, speeds, periods, views, spp, depth


def _load_pair(galvo_scene, kaleidoscope_scene, film, speed=None):
    """Both sensors' scenes (motion scaled by ``speed``; None: as their files say), checked to be a galvo with a
    periodic scan and a kaleidoscope on films of one size."""
    def load(path, sizes):
        motion = "auto" if speed is None else scaled_motion(path, speed)
        return load_scene(path, motion=motion, **(sizes if film is not None else {}))
    g = load(galvo_scene, {"views_px": film})
    k = load(kaleidoscope_scene, {"views_px": film})
    for timed, design, path in ((g, "galvo", galvo_scene), (k, "kaleidoscope", kaleidoscope_scene)):
        got = getattr(timed.sensor, "optics_metadata", lambda: {})().get("design")
        if got != design:
            raise ConfigError(f"{path}: needs a {design} sensor (its sensor is {got or type(timed.sensor).__name__})")
    if not g.scan_period:
        raise ConfigError(f"{galvo_scene}: the galvo needs a periodic scan")
    if g.film_size != k.film_size:
        raise ConfigError(f"films differ: galvo {g.film_size}, kaleidoscope {k.film_size}: one event sensor "
                          "means one film size (set film=)")
    return g, k


# ------------------------------------------------------------------------------------- design comparison

@dataclass
class DesignComparison(AppResult):
    speeds: tuple
    per_speed: list              # one dict per speed: events, rates, refocus and view scores per period
    images: list                 # per speed, last period: refocused images and references (linear)
    meta: dict = field(default_factory=dict)

    def summary(self, key: str = "refocus") -> dict:
        """{row: {region: {"psnr_db": [per speed], "correlation": [...]}}}: means over periods."""
        return {row: {n: {k: [float(np.nanmean(s[key][row][n][k])) for s in self.per_speed]
                          for k in ("psnr_db", "correlation")} for n in REGIONS} for row in self.per_speed[0][key]}

    def report(self) -> str:
        return compare_report(self)

    def write(self, out_dir: str) -> dict:
        return write_compare(self, out_dir)

    def figure(self, path: str) -> str:
        return compare_figure(self, path)


def _moving_px_per_period(g, moving_ids, period) -> float:
    """How far the moving objects' centroid moves in the centre view during one scan period (galvo pixels)."""
    from ..evaluation.truth import centre_pinhole
    centres = []
    for t in (0.0, period):
        g.set_time(t)
        yy, xx = np.nonzero(_regions(shape_masks(g, t, centre_pinhole(g)), moving_ids)["moving"])
        if not len(xx):
            raise ConfigError(f"{g.path}: the moving objects are outside the view at t = {t:g} s")
        centres.append(np.array([xx.mean(), yy.mean()]))
    return float(np.hypot(*(centres[1] - centres[0])))


def _galvo_rows(g, events, moving_ids, views, spp, depth, out, images):
    """Galvo light fields per period (events only; rendered views), refocused and scored; view scores;
    static-object film mask of the first period. Fills ``out`` and ``images``; returns the mask."""
    from ..evaluation.truth import centre_frame, centre_pinhole
    from ..focus.refocus import refocus
    from ..focus.galvo_periods import reconstruct_periods
    from ..lightfield.model import from_galvo
    static_film = None
    for lf, _ in reconstruct_periods(events, views, depth_range=(0.5 * depth, 2.0 * depth)):   # events only
        t_mid = float(lf.times.mean())
        rendered = from_galvo(render_frames(g, lf.times, spp=spp), lf.times, events.meta["optics"])
        view_rows = []
        for i, t in enumerate(lf.times):
            regions = _regions(shape_masks(g, float(t)), moving_ids)
            view_rows.append(region_scores(lf.views[i], rendered.views[i], regions))
            if lf.meta["period_index"] == 0:
                static_film = regions["static"] if static_film is None else static_film | regions["static"]
        reference = centre_frame(g, t_mid, log=False, spp=spp)
        g.set_time(t_mid)
        regions = _regions(shape_masks(g, t_mid, centre_pinhole(g)), moving_ids)
        images.update(galvo_reference=reference)
        for row, light_field in (("galvo", lf), ("galvo_rendered_views", rendered)):
            img = refocus(light_field, depth, on_motion="ignore")    # (the moving card's blur is scored, not warned)
            images[row] = img
            _append(out["refocus"][row], region_scores(img, reference, regions))
        _append(out["views"]["galvo"], _mean_scores(view_rows))
    return static_film


def _kaleidoscope_rows(k, events, moving_ids, times, spp, depth, out, images):
    """Kaleidoscope light fields at ``times`` (events only), refocused and scored, and their views."""
    from ..focus.refocus import refocus
    from ..lightfield.model import from_spatial
    from ..lightfield.reconstruct import direct
    from ..lightfield.views import extract_views
    optics = k.sensor.optics_metadata()
    films = direct(events, times, None, 0.0)                     # log change since t = 0 (start unknown)
    truths = render_frames(k, times, spp=spp, log=False)       # radiance (lin-log levels need their inverse)
    for t, film, truth in zip(times, films, truths):
        masks = {sid: extract_views(m.astype(np.float32), optics).images > 0.5
                 for sid, m in shape_masks(k, float(t)).items()}
        lf = from_spatial(film, optics, float(t), levels="events")
        ref = from_spatial(truth, optics, float(t), log=False)
        centre = int(np.argmin(np.hypot(*lf.positions.T)))       # refocus is aligned to the centre view
        per_view = [_regions({sid: m[v] for sid, m in masks.items()}, moving_ids) for v in range(len(lf.views))]
        _append(out["views"]["kaleidoscope"], _mean_scores(
            [region_scores(lf.views[v], ref.views[v], per_view[v]) for v in range(len(lf.views))]))
        img, img_ref = refocus(lf, depth, on_motion="ignore"), refocus(ref, depth, on_motion="ignore")
        _append(out["refocus"]["kaleidoscope"], region_scores(img, img_ref, per_view[centre]))
        images.update(kaleidoscope=img, kaleidoscope_reference=img_ref)


def _one_speed(g, k, speed, moving_ids, periods, views, spp, depth, split):
    """Events of both designs at one speed, their light fields scored, and their bandwidth."""
    from ..lightfield.model import galvo_steps_per_period, galvo_view_times
    period, optics = g.scan_period, g.sensor.optics_metadata()
    px = _moving_px_per_period(g, moving_ids, period)           # steps: at most ~1 pixel of motion each
    steps = periods * max(2 * views, galvo_steps_per_period(optics, *g.film_size), int(math.ceil(px)))
    t0 = time.perf_counter()
    events = {"galvo": render_events(g, periods * period, steps=steps, spp=spp),
              "kaleidoscope": render_events(k, periods * period, steps=steps, spp=spp)}
    t1 = time.perf_counter()
    out = {"speed": speed, "moving_px_per_period": px, "steps": steps,
           "refocus": {r: {} for r in ROWS}, "views": {r: {} for r in VIEW_ROWS}}
    images = {}
    static = {"galvo": _galvo_rows(g, events["galvo"], moving_ids, views, spp, depth, out, images)}
    mids = np.array([float(galvo_view_times(optics, p * period, views).mean()) for p in range(periods)])
    _kaleidoscope_rows(k, events["kaleidoscope"], moving_ids, mids, spp, depth, out, images)
    static["kaleidoscope"] = _regions(shape_masks(k, 0.0), moving_ids)["static"]
    duration = periods * period
    out["events"] = {d: len(e) for d, e in events.items()}
    out["events_per_s"] = {d: len(e) / duration for d, e in events.items()}
    out["static_events_per_pixel_s"] = {
        d: float(static[d][e.y.astype(np.int64), e.x.astype(np.int64)].sum() / max(static[d].sum(), 1) / duration)
        for d, e in events.items()}
    out["static_pixels"] = {d: int(m.sum()) for d, m in static.items()}
    split["render_events"] = split.get("render_events", 0.0) + t1 - t0
    split["reconstruct_and_score"] = split.get("reconstruct_and_score", 0.0) + time.perf_counter() - t1
    return out, images


def compare(galvo_scene: str | None = None, kaleidoscope_scene: str | None = None, speeds=SPEEDS,
            periods: int = 2, views: int = 16, film: int | None = None, spp: int = 4, depth: float | None = None,
            progress: bool = False) -> DesignComparison:
    """Both designs on one scene pair at each speed factor (module docstring); ``film``: both films' size
    (square, a multiple of the kaleidoscope's n; default: the scenes' own), ``depth``: the refocus plane (default: the
    kaleidoscope's focus distance, where scenes/designs puts its cards)."""
    film, speeds, periods, views, spp, depth = _check(film, speeds, periods, views, spp, depth)
    default_g, default_k = default_scenes()
    galvo_scene, kaleidoscope_scene = galvo_scene or default_g, kaleidoscope_scene or default_k
    g, k = _load_pair(galvo_scene, kaleidoscope_scene, film)          # bad input: before any rendering
    moving_ids = {n for n, o in (g.motion.objects if g.motion else {}).items() if not o.is_static}
    if not moving_ids or not {s.id() for s in g.scene.shapes()} - moving_ids:
        raise ConfigError(f"{galvo_scene}: needs moving and static shapes (moving: {sorted(moving_ids) or 'none'})")
    hidden = unseen(g, moving_ids)
    if hidden:
        raise ConfigError(f"{galvo_scene}: objects {', '.join(hidden)}: a moving object must be a shape (not an "
                          "instance or the sensor): its pixels are found with the shape-index AOV")
    arguments = {"film": film, "speeds": list(speeds), "periods": periods, "views": views, "spp": spp, "depth": depth}
    depth = depth or float(k.sensor.optics_metadata()["focus_distance"])
    split, per_speed, images = {}, [], []
    for speed in speeds:
        g, k = _load_pair(galvo_scene, kaleidoscope_scene, film, speed)
        out, imgs = _one_speed(g, k, speed, moving_ids, periods, views, spp, depth, split)
        per_speed.append(out)
        images.append(imgs)
        if progress:
            print(f"  speed {speed:g}x: {out['events']['kaleidoscope']} kaleidoscope and {out['events']['galvo']} "
                  f"galvo events ({sum(split.values()):.0f} s so far)", flush=True)
    meta = {"galvo_scene": galvo_scene, "kaleidoscope_scene": kaleidoscope_scene, "default_galvo": default_g,
            "default_kaleidoscope": default_k, "film": list(g.film_size), "periods": periods,
            "views_per_period": views, "period_s": g.scan_period, "spp": spp, "depth": depth,
            "moving_ids": sorted(moving_ids), "arguments": arguments, "inputs": "events only for both designs; the "
            "rendered views and frames are for scoring (and the galvo's design-limit row) only",
            "galvo_optics": g.sensor.optics_metadata(), "kaleidoscope_optics": k.sensor.optics_metadata(),
            "galvo_parallax_px": scan_parallax_px(g.sensor.optics_metadata(), *g.film_size, depth),
            "time_split_s": split}
    return DesignComparison(tuple(speeds), per_speed, images, meta)



# ------------------------------------------------------------------------------------------ grid experiment

@dataclass
class GridExperiment(AppResult):
    rates: dict                  # design -> {"horizontal", "vertical": events per pixel per s, "ratio", "pixels"}
    event_maps: dict             # design -> (H, W) events per pixel per second over the window
    classes: dict                # design -> {"horizontal": bool (H, W), "vertical": bool (H, W)}
    reference: np.ndarray        # the galvo's centre view at the middle of the window (linear)
    meta: dict = field(default_factory=dict)

    def report(self) -> str:
        return grid_report(self)

    def write(self, out_dir: str) -> dict:
        return write_grid(self, out_dir)

    def figure(self, path: str) -> str:
        return grid_figure(self, path)


def line_distances(texture: np.ndarray) -> tuple:
    """(per texel row, per texel column) cyclic distance in texels to the nearest line of a grid texture: a row
    (column) is a line where its mean is darker than midway between the darkest and brightest row (column)."""
    out = []
    for profile in (texture.mean(axis=1), texture.mean(axis=0)):
        lines = np.flatnonzero(profile < 0.5 * (profile.min() + profile.max()))
        if not len(lines):
            raise ConfigError("the grid texture has no lines (uniform rows and columns)")
        d = np.abs(np.arange(len(profile))[:, None] - lines[None, :])
        out.append(np.minimum(d, len(profile) - d).min(axis=1).astype(np.float64))
    return tuple(out)


def _uv_texels(timed, t, shape):
    """Texel coordinates (u, v) every pixel sees at time ``t`` (Mitsuba's ``uv`` AOV; v flipped as the grid
    scenes' ``to_uv`` does) and where a surface is seen at all."""
    from ..backend import mi
    timed.set_time(t)
    a = np.array(mi.render(timed.scene, integrator=mi.load_dict({"type": "aov", "aovs": "uv:uv,d:depth"}), spp=1))
    return np.mod(a[..., 0], 1) * shape[1], np.mod(-a[..., 1], 1) * shape[0], a[..., 2] > 0


def grid_classes(timed, times, texture: np.ndarray) -> dict:
    """{"horizontal", "vertical"}: pixels within one pixel of a line of that orientation at some instant of
    ``times`` and never within two pixels of a line of the other one (so a scan or the motion cannot carry an
    edge of the other orientation onto them)."""
    row_d, col_d = line_distances(texture)
    near = dict.fromkeys(("h1", "h2", "v1", "v2"), False)
    tpp = None
    for t in times:
        u, v, ok = _uv_texels(timed, float(t), texture.shape)
        if tpp is None:                                   # texels per pixel (median over neighbouring pixels)
            du = np.abs(np.diff(u, axis=1))[ok[:, 1:] & ok[:, :-1]]
            tpp = float(np.median(du[du < 0.5 * texture.shape[1]])) if du.size else 1.0
        rd = row_d[np.clip(v.astype(np.int64), 0, len(row_d) - 1)]
        cd = col_d[np.clip(u.astype(np.int64), 0, len(col_d) - 1)]
        for k, dist, px in (("h1", rd, 1), ("h2", rd, 2), ("v1", cd, 1), ("v2", cd, 2)):
            near[k] = near[k] | (ok & (dist <= px * tpp))
    return {"horizontal": near["h1"] & ~near["v2"], "vertical": near["v1"] & ~near["h2"]}


def grid_experiment(galvo_scene: str | None = None, kaleidoscope_scene: str | None = None, periods: int = 1,
                    film: int | None = None, spp: int = 4, texture: str | None = None,
                    progress: bool = False) -> GridExperiment:
    """Events of both designs watching a grid slide horizontally (scenes/moving_grid), over ``periods`` galvo
    scan periods, scored by their rate on horizontal-line and vertical-line pixels (module docstring).
    ``texture``: the grid's texture (default: grid.png beside the galvo scene)."""
    import cv2

    from ..evaluation.truth import centre_frame
    from ..lightfield.model import galvo_steps_per_period
    film, _, periods, _, spp, _ = _check(film, (1.0,), periods, 4, spp, None)
    default_g, default_k = default_scenes(grid=True)
    galvo_scene, kaleidoscope_scene = galvo_scene or default_g, kaleidoscope_scene or default_k
    g, k = _load_pair(galvo_scene, kaleidoscope_scene, film)                # bad input: before any rendering
    texture = texture or os.path.join(os.path.dirname(os.path.abspath(galvo_scene)), "grid.png")
    tex = cv2.imread(texture, cv2.IMREAD_GRAYSCALE) if os.path.isfile(texture) else None
    if tex is None:
        raise ConfigError(f"grid texture {texture}: missing or not an image")
    period, optics = g.scan_period, g.sensor.optics_metadata()
    duration = periods * period
    steps = periods * max(64, galvo_steps_per_period(optics, *g.film_size))
    split, rates, maps, classes = {}, {}, {}, {}
    for design, timed in (("kaleidoscope", k), ("galvo", g)):
        t0 = time.perf_counter()
        ev = render_events(timed, duration, steps=steps, spp=spp)
        t1 = time.perf_counter()
        w, h = ev.width, ev.height
        maps[design] = np.bincount(ev.y.astype(np.int64) * w + ev.x, minlength=w * h).reshape(h, w) / duration
        classes[design] = grid_classes(timed, np.linspace(0.0, duration, 9), tex.astype(np.float64))
        r = {c: float(maps[design][m].mean()) if m.any() else float("nan") for c, m in classes[design].items()}
        r["ratio"] = r["horizontal"] / r["vertical"] if r["vertical"] > 0 else float("nan")
        r["pixels"] = {c: int(m.sum()) for c, m in classes[design].items()}
        r["events"], r["events_per_s"] = len(ev), len(ev) / duration
        rates[design] = r
        split[f"render_{design}"], split[f"score_{design}"] = t1 - t0, time.perf_counter() - t1
        if progress:
            print(f"  {design}: {len(ev)} events", flush=True)
    reference = centre_frame(g, 0.5 * duration, log=False, spp=spp)
    meta = {"galvo_scene": galvo_scene, "kaleidoscope_scene": kaleidoscope_scene, "default_galvo": default_g,
            "default_kaleidoscope": default_k, "texture": texture, "film": list(g.film_size), "periods": periods,
            "duration_s": duration, "steps": steps, "spp": spp, "arguments": {"film": film, "periods": periods,
            "spp": spp}, "galvo_optics": optics, "kaleidoscope_optics": k.sensor.optics_metadata(),
            "time_split_s": split}
    return GridExperiment(rates, maps, classes, reference, meta)
