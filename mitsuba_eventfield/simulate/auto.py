"""Model no more than a scene needs: choose colour, samples and steps from cheap probes, and say why.

    plan = ef.auto.plan("scenes/fan/fan.xml", duration=0.02)
    print(plan.report())
    events = ef.render_events(ef.load_scene(path, **plan.defines), 0.02, **plan.render_kwargs())

Choices (each verified against the full computation in tests/simulate/test_auto.py):

* colour: one tiny RGB probe frame; if every pixel is grey (R = G = B to 1e-6), the luminance the event pixel
  sees is the mono render's, so mono suffices (events identical, about 3x less work per sample);
* samples per pixel: the per-pixel spread of log brightness over 4 seeds at a probe spp, scaled as
  1/sqrt(spp) (Monte-Carlo), gives the smallest power of two whose noise is below ``noise_fraction`` x C
  (default C / 2; with a fixed seed the noise fires nothing on static pixels, it moves event times);
* steps: a probe of two instants ``probe_dt`` apart measures the per-pixel log change per unit time; the 99th
  percentile (not the maximum: hard edges crossing a pixel would demand ~100x more steps for a few pixels) sets
  steps so that change stays below ``change_fraction`` x C per step (default one threshold: several
  crossings in a step are interpolated exactly, the linearisation error is second order);
* reuse: a static scene under a periodic view renders one period (already automatic in render_events).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..backend import set_variant
from ..scene.timed import load_scene
from .render import render_frames


@dataclass
class Plan:
    color: bool
    spp: int
    steps: int
    static: bool
    reasons: dict = field(default_factory=dict)
    defines: dict = field(default_factory=dict)

    def render_kwargs(self) -> dict:
        return {"spp": self.spp, "steps": self.steps}

    def report(self) -> str:
        return "\n".join(f"{k}: {v}" for k, v in self.reasons.items())

    def as_dict(self) -> dict:
        return {"color": self.color, "spp": self.spp, "steps": self.steps, "static": self.static,
                "reasons": dict(self.reasons)}


def _grey(scene_path, defines, size=24) -> bool:
    import mitsuba as mi

    previous = mi.variant()
    set_variant(color=True)
    try:
        timed = load_scene(scene_path, **dict(defines, **_tiny(scene_path, size)))
        img = np.array(mi.render(timed.scene, spp=4, seed=0))
    finally:
        set_variant(previous)
    rgb = img[..., :3]
    return bool(np.abs(rgb - rgb.mean(-1, keepdims=True)).max() <= 1e-6 * max(float(rgb.max()), 1e-12))


def _tiny(scene_path, size):
    """XML defaults that shrink the film, when the scene has them."""
    with open(scene_path) as f:
        xml = f.read()
    if 'name="width"' in xml and 'name="height"' in xml:
        return {"width": size, "height": size * 3 // 4}
    if 'name="views_px"' in xml:
        return {"views_px": 3 * (size // 3)}
    return {}


def noise_std(timed, spp: int, seeds=(0, 1, 2, 3), t: float = 0.0) -> float:
    """Median over pixels of the spread of log brightness across seeds (Monte-Carlo noise), in log units."""
    frames = np.stack([render_frames(timed, [t], spp=spp, seed=s)[0] for s in seeds])
    return float(np.median(frames.std(axis=0)))


def plan(scene_path: str, duration: float, threshold: float = 0.2, noise_fraction: float = 0.5,
         change_fraction: float = 1.0, probe_spp: int = 4, probe_dt: float | None = None, defines=None,
         max_spp: int = 256, max_steps: int = 100_000) -> Plan:
    defines = dict(defines or {})
    reasons = {}
    grey = _grey(scene_path, defines)
    reasons["colour"] = ("mono: every pixel of an RGB probe is grey, so the luminance the pixel sees equals the mono "
                         "render" if grey else "rgb: the scene has colour, and luminance needs all three channels")
    set_variant(color=not grey)
    timed = load_scene(scene_path, **defines)
    sigma = noise_std(timed, probe_spp)
    target = noise_fraction * threshold
    need = probe_spp * (sigma / target) ** 2 if sigma > 0 else 1
    spp = int(min(max_spp, 2 ** max(0, math.ceil(math.log2(max(need, 1))))))
    reached = sigma * math.sqrt(probe_spp / spp)
    reasons["spp"] = (f"{spp}: Monte-Carlo noise {sigma:.4f} (log) at {probe_spp} spp scales as 1/sqrt(spp); "
                      f"{spp} spp brings it to {reached:.4f}"
                      + (f" <= {target:.4f} ({noise_fraction} x C)" if reached <= target * (1 + 1e-9) else
                         f", still above the target {target:.4f}: capped at max_spp = {max_spp}"))
    dt = probe_dt or duration / 200
    f0, f1 = render_frames(timed, [0.0, dt], spp=spp)
    rate = float(np.percentile(np.abs(f1 - f0), 99)) / dt
    steps = int(min(max_steps, max(1, math.ceil(duration * rate / (change_fraction * threshold)))))
    reasons["steps"] = (f"{steps}: the 99th-percentile log change is {rate:.3g} per second; {steps} steps keep it "
                        f"under {change_fraction} x C per step")
    static = timed.is_static
    period = timed.scan_period
    if not static:
        reasons["reuse"] = "moving scene: every step is rendered"
    elif period == 0.0:
        reasons["reuse"] = "static scene seen by a fixed view: one frame is rendered and reused"
    elif period is None:
        reasons["reuse"] = "static scene, aperiodic scan: every step is rendered"
    else:
        n_periods = duration / period
        if abs(n_periods - round(n_periods)) <= 1e-6 * max(n_periods, 1) and round(n_periods) >= 1:
            n = int(round(n_periods))
            per_period = math.ceil(steps / n)              # whole steps per period, so one period can be reused
            steps = per_period * n
            reasons["steps"] += f"; rounded up to {per_period} per scan period ({steps} in all) for reuse"
            reasons["reuse"] = (f"static scene: one scan period ({per_period} steps) is rendered and reused for the "
                                f"other {n - 1}")
        else:
            reasons["reuse"] = (f"static scene, but {duration:g} s is not a whole number of {period * 1e3:g} ms scan "
                                "periods: every step is rendered")
    return Plan(color=not grey, spp=spp, steps=steps, static=static, reasons=reasons, defines=defines)
