"""Speed against accuracy: the levers of a render (samples, sampler, samples where they matter, steps, seeds,
adaptive steps) on a suite of scenes, each scored by a well-conditioned error against an exact or converged reference.

The suite (``SUITE``; tiny films, so that the default run, 5 seeds per setting, takes about 15 minutes on 2 cores):

* ``analytic``: a sinusoidal emitter sliding past a pinhole (``evaluation/analytic.py``), written as an XML scene
  that names no sampler (so it gets the default one), 64x48 pixels; its exact events are known in closed form.
  Measures: the event count error, and the median and 99th-percentile timestamp error (``analytic_score``);
* ``demo``, ``fan`` (galvo, a spinning fan), ``kaleidoscope`` (the moving grid) and ``cards`` (the off-axis cards
  behind the galvo): the per-pixel event-count error (ON and OFF counts of every pixel, L1, relative to the
  total) against a converged render (``REFERENCE``: 256 multi-jittered spp, 4x the steps). The reference is
  itself a render: two of them with different seeds differ by 7.7 % (demo), 2.6 % (fan) and 3.9 %
  (kaleidoscope) in this measure (measured once at the suite's sizes), the floor below which a setting cannot be
  told from it; 1024 spp moved the demo's by 6.9 %;
* ``fan`` also: the PSNR, on textured pixels (``truth.textured``), of the first scan period refocused at the
  fan's depth from the events (``direct`` reconstruction, started from the converged first frame: extra
  information every setting gets alike) against the same refocus of converged rendered views;
* ``cards`` also: depth from focus on the events' light field (same start) against Mitsuba's depth output, the
  median relative error on textured pixels the method is confident about;
* ``demo_davis346``: the demo through a stochastic pixel (mismatch, refractory, leak, noise), each seed with its
  own noise draws, scored by statistics against the reference of the same model (``stochastic.compare``): the
  event-rate error, the KS distance of the inter-event intervals, and the per-pixel rate error as its count error.

Each setting runs with several seeds (error bars: one standard deviation over seeds of the error; of the wall
time, from the fastest seed's run, which is the one plotted, to the slowest: other processes only ever add time);
wall time is the render's (kernels compiled beforehand, on one thread: ``THREADS``), as a ratio to the fastest
setting of the scene.
The Pareto front of each measure (no other setting both faster and more accurate: fastest seeds' times, mean
errors) and the default (what ``eventfield render`` does unasked: 4 spp, uniform steps as many as the image
motion needs, ``stepping.default_steps``, a fixed seed, the scene's sampler) are marked in the chart;
``bench_chart`` also says which settings beat the default beyond the noise. Settings that name no steps take
the default's rule at their own spp and sampler (as ``--spp 16`` does); the ladder of 25-400 uniform steps
(1/4-4 x ``BenchScene.steps``) holds everything else at the default's. Each scene's ``auto20us`` setting is
planned by ``simulate/auto.py`` (its planning time counts).
"""
from __future__ import annotations

import os
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np

from ..backend import ensure_variant, set_variant
from ..errors import ConfigError, EventFieldError
from ..scene.bundled import bundled_scene
from ..simulate.auto import load_with_sampler, plan
from ..simulate.image_motion import largest_px_per_step
from ..simulate.render import render_events, render_frames
from . import analytic as an
from .analytic_scene import (ANALYTIC_C, ANALYTIC_DURATION, analytic_score,  # noqa: F401 (re-exported)
                             analytic_velocity, write_analytic_scene)

# the levers; "key" names a setting on the command line (--settings)
SETTINGS = [
    {"key": "1spp", "spp": 1},
    {"key": "default", "spp": 4},
    {"key": "16spp", "spp": 16},
    {"key": "64spp", "spp": 64},
    {"key": "steps/4", "spp": 4, "steps_factor": 0.25},
    {"key": "steps/2", "spp": 4, "steps_factor": 0.5},
    {"key": "steps*1", "spp": 4, "steps_factor": 1},            # eventfield render's default until 2026-11
    {"key": "steps*2", "spp": 4, "steps_factor": 2},
    {"key": "steps*4", "spp": 4, "steps_factor": 4},
    {"key": "16spp/2", "spp": 16, "steps_factor": 0.5},
    {"key": "1+16", "spp": 1, "spp_changing": 16},                # samples where they matter
    {"key": "indep4", "spp": 4, "sampler": "independent"},      # Mitsuba's own default sampler (ours until 11/2026)
    {"key": "indep16", "spp": 16, "sampler": "independent"},
    {"key": "seeds", "spp": 4, "seed_mode": "independent"},
    {"key": "adaptive", "spp": 4, "adaptive": True},
    {"key": "motion0.5", "spp": 4, "adaptive": True, "px_per_step": 0.5},   # by image motion alone (else log
    {"key": "motion1", "spp": 4, "adaptive": True, "px_per_step": 1.0},     # change): bench_resolution.py
    {"key": "motion2", "spp": 4, "adaptive": True, "px_per_step": 2.0},
    {"key": "auto20us", "spp": 0, "auto": 20e-6},    # eventfield render --auto --timing-accuracy 20us
]
DEFAULT_KEY = "default"
REFERENCE = {"key": "reference", "spp": 256, "steps_factor": 4, "sampler": "multijitter"}
SEEDS = (1, 2, 3, 4, 5)               # the reference renders with seed 0
MEASURES = {   # key: (label, higher is better)
    "count_error": ("event-count error (L1 per pixel, relative)", False),
    "timing_median_us": ("timestamp error, median (us)", False),
    "timing_p99_us": ("timestamp error, 99th percentile (us)", False),
    "refocus_psnr_db": ("refocus PSNR on textured pixels (dB)", True),
    "depth_error": ("depth error vs Mitsuba's (median, relative)", False),
    "rate_error": ("event-rate error |ratio - 1|", False),
    "interval_ks": ("event intervals, KS distance", False),
}
# the timed renders run on one thread: on the shared 2-core machine, with another process holding a core, two
# threads took 0.82-0.88 s for a render one thread did in 0.44-0.47 s (demo, 48x36, 4 spp, 100 steps), and the
# two-thread times of one setting varied 2x between seeds as other work came and went
THREADS = 1


@dataclass(frozen=True)
class BenchScene:
    name: str
    path: str | None                  # None: the analytic scene (written to a temporary folder)
    duration: float
    steps: int = 100                  # the uniform-step ladder's 1 x (steps*1; 1/4 to 4 x this)
    defines: dict = field(default_factory=dict)
    refocus_depth: float | None = None   # galvo: also score refocus at this depth
    depth_range: tuple | None = None     # galvo: also score depth from focus over (near, far) metres
    preset: str | None = None            # a stochastic pixel preset: scored by its statistics


SUITE = (BenchScene("analytic", None, ANALYTIC_DURATION, defines={"height": 48}),
         BenchScene("demo", "demo/demo.xml", 0.1, defines={"width": 48, "height": 36}),
         BenchScene("fan", "fan/fan.xml", 0.004, defines={"width": 48, "height": 36}, refocus_depth=0.6),
         BenchScene("kaleidoscope", "moving_grid/kaleidoscope.xml", 0.02, defines={"views_px": 60}),
         BenchScene("cards", "offaxis_cards/offaxis_cards.xml", 0.01, defines={"width": 64, "height": 48},
                    depth_range=(0.35, 2.0)),
         BenchScene("demo_davis346", "demo/demo.xml", 0.1, defines={"width": 48, "height": 36}, preset="davis346"))


def label(cfg: dict, base_steps: int) -> str:
    """A setting in words, with its real numbers: '4 spp, 25 steps'; '4 spp, default steps (the default)'."""
    if cfg.get("auto"):
        return f"auto, --timing-accuracy {cfg['auto'] * 1e6:g}us (plan time included)"
    if cfg.get("adaptive"):
        px = cfg.get("px_per_step")
        return f"{cfg['spp']} spp, " + (f"steps by image motion ({px:g} px each)" if px else
                                       f"adaptive (steps no longer than 1/{base_steps})")
    text = f"{cfg['spp']} spp" + (f" {cfg['sampler']}" if cfg.get("sampler") else "")
    if cfg.get("spp_changing"):
        text += f" ({cfg['spp_changing']} where it changes)"
    text += (f", {max(1, round(base_steps * cfg['steps_factor']))} steps" if "steps_factor" in cfg
             else ", default steps")        # stepping.default_steps: by image motion, uniform under a scan
    if cfg.get("seed_mode") == "independent":
        text += ", new seed per step"
    return text + (" (the default)" if cfg["key"] == DEFAULT_KEY else "")


def pick_settings(keys=None) -> list:
    """The settings named by ``keys`` (all when None), in table order; an unknown key is refused."""
    if keys is None:
        return list(SETTINGS)
    known = {s["key"]: s for s in SETTINGS}
    bad = [k for k in keys if k not in known]
    if bad or not keys:
        raise ConfigError(f"bench settings {','.join(bad) or '(none)'}: choose from {', '.join(known)}")
    return [s for s in SETTINGS if s["key"] in keys]


def pick_scenes(names=None) -> list:
    if names is None:
        return list(SUITE)
    known = {s.name: s for s in SUITE}
    bad = [n for n in names if n not in known]
    if bad or not names:
        raise ConfigError(f"bench scenes {','.join(bad) or '(none)'}: choose from {', '.join(known)}")
    return [s for s in SUITE if s.name in names]


def _pixel_counts(ev) -> np.ndarray:
    index = (ev.y.astype(np.int64) * ev.width + ev.x) * 2 + (ev.p > 0)
    return np.bincount(index, minlength=2 * ev.width * ev.height)


def _refocused(lf, depth) -> np.ndarray:
    """Refocus without motion compensation, for the reference and every setting alike (the spinning fan smears
    both the same way, so refocus's motion-blur warning says nothing about the settings)."""
    import warnings

    from ..focus.refocus import refocus
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return refocus(lf, depth)


class _Scorer:
    """The reference of one scene (exact events, or a converged render and its refocus) and the scoring of a
    setting's events against it."""

    VIEWS = 16

    def __init__(self, spec: BenchScene, path: str, log):
        self.spec, self.path = spec, path
        if spec.path is None:
            self.truth = an.truth_events(analytic_velocity(spec.duration, spec.steps), spec.duration, ANALYTIC_C)
            self.reference_wall = None
            return
        cfg = dict(REFERENCE)
        ev, self.reference_wall = _render(path, spec, cfg, seed=0)
        log(f"  reference ({label(cfg, spec.steps)}): {len(ev)} events, {self.reference_wall:.1f} s")
        self.reference, self.counts = ev, _pixel_counts(ev)
        if not self.counts.sum():      # every setting's count error would be its own count over 1 (an "error" of 244)
            raise EventFieldError(f"{spec.path}: its reference render ({label(cfg, spec.steps)}) has no events in "
                                  f"{spec.duration:g} s: nothing changes for the event count to be scored against "
                                  "(a longer --duration, or a scene that moves)")
        self.refocus_ref = self.depth_truth = None
        galvo = ev.meta.get("optics", {}).get("design") == "galvo"
        if spec.refocus_depth is not None and galvo:
            self._refocus_reference(ev)
        if spec.depth_range is not None and galvo:
            self._depth_truth(ev)

    def _refocus_reference(self, ev):
        from ..lightfield.model import from_galvo, galvo_view_times
        from .truth import textured
        timed, self.start = self._converged_start()
        optics = ev.meta["optics"]
        times = galvo_view_times(optics, 0.0, self.VIEWS)
        views = render_frames(timed, times, spp=REFERENCE["spp"])
        self.refocus_ref = _refocused(from_galvo(views, times, optics), self.spec.refocus_depth)
        self.mask = textured(np.log(np.maximum(self.refocus_ref, 1e-6)))

    def _converged_start(self):
        """The converged log frame at t = 0: the direct reconstruction's start, extra information every
        setting gets alike (the refocus and depth measures score the events' light field, not the start)."""
        timed = load_with_sampler(self.path, {"type": "multijitter", "sample_count": REFERENCE["spp"]},
                                  **self.spec.defines)
        return timed, render_frames(timed, [0.0], spp=REFERENCE["spp"])[0]

    def _depth_truth(self, ev):
        """Mitsuba's depth output of the centre view, on textured pixels (where focus can be measured)."""
        from .truth import centre_frame, textured, truth_depth
        timed, self.start = self._converged_start()
        self.depth_truth = truth_depth(timed, 0.0)
        self.depth_mask = textured(centre_frame(timed, 0.0, spp=REFERENCE["spp"]), 0.1) & np.isfinite(self.depth_truth)

    def _depth_error(self, ev) -> float:
        """Median relative error of depth from focus (events' light field, 16 views) on confident textured
        pixels; 1.0 when no pixel is confident (the method refused everywhere)."""
        from ..focus.depth import depth_from_focus
        from ..lightfield.streams import from_events
        lf = from_events(ev, period=0, views=self.VIEWS, log_start=self.start)
        near, far = self.spec.depth_range
        d = depth_from_focus(lf, near, far, 24, "tenengrad")
        good = self.depth_mask & (d.confidence >= 0.6)
        return float(np.median(np.abs(d.depth[good] / self.depth_truth[good] - 1))) if good.any() else 1.0

    def score(self, ev) -> dict:
        if self.spec.path is None:
            return analytic_score(ev, self.truth)
        if self.spec.preset is not None:                 # stochastic pixel: statistics, not per-event matches
            from .stochastic import compare
            c = compare(ev, self.reference)
            return {"rate_error": abs(c["rate_ratio"] - 1), "interval_ks": c["interval_ks"],
                    "count_error": c["pixel_rate_error"]}
        counts = _pixel_counts(ev)
        out = {"count_error": float(np.abs(counts - self.counts).sum() / max(self.counts.sum(), 1))}
        if self.depth_truth is not None:
            out["depth_error"] = self._depth_error(ev)
        if self.refocus_ref is not None:
            from ..lightfield.streams import from_events
            from .quality import psnr, white_level
            lf = from_events(ev, period=0, views=self.VIEWS, log_start=self.start)
            img = _refocused(lf, self.spec.refocus_depth)
            out["refocus_psnr_db"] = psnr(img[self.mask], self.refocus_ref[self.mask], white_level(self.refocus_ref))
        return out


def _render(path, spec: BenchScene, cfg: dict, seed: int, warm: bool = False):
    """One setting's events and render wall time (after a 2-step render that compiles the kernels)."""
    sampler = {"type": cfg["sampler"], "sample_count": cfg["spp"]} if cfg.get("sampler") else None
    timed = load_with_sampler(path, sampler, **spec.defines)
    kw = dict(spp=cfg["spp"], seed=seed, seed_mode=cfg.get("seed_mode", "fixed"), spp_changing=cfg.get("spp_changing"))
    if spec.preset is not None:                  # each seed its own noise draws too (the reference: seed 0)
        kw.update(preset=spec.preset, pixel={"seed": seed})
    if cfg.get("adaptive"):          # by image motion alone at px_per_step, or no step longer than 1/spec.steps
        kw.update(adaptive=True, max_log_change=0.5, **({"px_per_step": cfg["px_per_step"]} if "px_per_step" in cfg
                                                         else {"max_step": spec.duration / spec.steps}))
    elif "steps_factor" in cfg:                  # else the render's default steps (stepping.default_steps)
        kw.update(steps=max(1, int(round(spec.steps * cfg["steps_factor"]))))
    import drjit as dr
    previous = dr.thread_count()
    dr.set_thread_count(THREADS)               # only around the renders: Mitsuba's EXR input and output hang on it
    try:
        if warm:
            render_events(timed, spec.duration * 2 / spec.steps, **dict(kw, adaptive=False, steps=2))
        t0 = time.perf_counter()
        ev = render_events(timed, spec.duration, **kw)
        return ev, time.perf_counter() - t0
    finally:
        dr.set_thread_count(previous)


def _planned(path, spec: BenchScene, cfg: dict, log):
    """An ``auto`` setting resolved by ``auto.plan`` (its sampler, spp and steps, and the planning time); other
    settings as they are. (None, {"refused": why}) when the plan refuses the request."""
    if not cfg.get("auto"):
        return cfg, {}
    t0 = time.perf_counter()
    try:
        p = plan(path, spec.duration, defines=spec.defines, timing_accuracy=cfg["auto"])
    except ConfigError as e:
        log(f"  {label(cfg, spec.steps)}: refused ({e})")
        return None, {"refused": str(e)}
    finally:
        if "mono" not in ensure_variant():         # the plan picks colour for coloured scenes; the bench is mono
            set_variant(color=False)
    chosen = dict(cfg, spp=p.spp, steps_factor=p.steps / spec.steps,
                  sampler=p.sampler["type"] if p.sampler else None)
    what = f"{chosen['sampler'] or 'own sampler'} {p.spp} spp, {p.steps} steps"
    return chosen, {"plan_s": time.perf_counter() - t0, "chosen": what}


def run_scene(spec: BenchScene, settings=None, seeds=SEEDS, log=print) -> list:
    """One row per setting and seed: the scene, setting, seed, wall time, events, steps and every measure.
    Renders in the active variant when it is a mono one (else the default mono variant)."""
    if "mono" not in ensure_variant():
        set_variant(color=False)
    with tempfile.TemporaryDirectory() as folder:
        path = spec.path if spec.path is None or os.path.isfile(spec.path) else bundled_scene(spec.path)
        if spec.path is None:
            path = write_analytic_scene(folder, analytic_velocity(spec.duration, spec.steps), spec.duration)
        log(f"{spec.name}: {path}")
        scorer = _Scorer(spec, path, log)
        rows, planned = [], []
        for cfg in settings or SETTINGS:
            resolved, extra = _planned(path, spec, cfg, log)
            if resolved is None:
                rows.append({"scene": spec.name, "setting": cfg["key"], "label": label(cfg, spec.steps), **extra})
            else:
                planned.append((resolved, extra))
        runs = {}
        for seed in seeds:                        # seeds outermost: a slow spell of the machine hits every setting
            for cfg, extra in planned:
                # every run warmed on its own freshly loaded scene: a new scene's first render costs ~150 ms more
                # (analytic scene), which a warm-up on the first seed only left in every later seed's time, so the
                # fastest seed was always the first and the "fastest of five" one sample (+-10 %)
                ev, wall = _render(path, spec, cfg, seed, warm=True)
                runs.setdefault(cfg["key"], []).append(
                    {"scene": spec.name, "setting": cfg["key"], "label": label(cfg, spec.steps), "seed": seed,
                     "wall_s": wall + extra.get("plan_s", 0.0), "events": len(ev), "steps": ev.meta["render"]["steps"],
                     "spp": cfg["spp"], "px_per_step": largest_px_per_step(ev.meta), **extra, **scorer.score(ev)})
        for cfg, _ in planned:
            rows += runs[cfg["key"]]
            last = runs[cfg["key"]][-1]
            log(f"  {last['label']:44s} {min(r['wall_s'] for r in runs[cfg['key']]):6.2f} s  " + "  ".join(
                f"{k} {last[k]:.4g}" for k in MEASURES if k in last))
    if scorer.reference_wall is not None:
        for r in rows:
            r["reference_wall_s"] = scorer.reference_wall
    return rows


def run(specs=None, settings=None, seeds=SEEDS, log=print) -> list:
    """Every scene of ``specs`` (default: the suite) with every setting and seed: the raw rows."""
    rows = []
    for spec in specs or SUITE:
        rows += run_scene(spec, settings, seeds, log)
    return rows


def single(scene_path: str, duration: float, steps: int = 100, defines: dict | None = None,
           refocus_depth: float | None = None) -> BenchScene:
    """A bench scene from any scene file (``eventfield bench SCENE``)."""
    name = os.path.splitext(os.path.basename(scene_path))[0]
    return BenchScene(name, scene_path, duration, steps, dict(defines or {}), refocus_depth)
