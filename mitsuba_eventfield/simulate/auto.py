"""Model no more than a scene needs: choose colour, sampler, samples and steps from cheap probes, and say why.

    plan = ef.auto.plan("scenes/fan/fan.xml", duration=0.02)                         # or timing_accuracy=20e-6
    print(plan.report())
    events = ef.render_events(plan.load("scenes/fan/fan.xml"), 0.02, **plan.render_kwargs())

Choices (each verified against the full computation in tests/simulate/test_auto.py and, for a requested timing
accuracy, against the analytic scene's exact events in tests/simulate/test_auto_timing.py):

* colour: one tiny RGB probe frame; if every pixel is grey (R = G = B to 1e-6), the luminance the event pixel
  sees is the mono render's, so mono suffices (events identical, about 3x less work per sample);
* samples per pixel: the per-pixel spread of log brightness over 4 seeds at a probe spp, scaled as
  1/sqrt(spp) (Monte-Carlo), gives the smallest power of two whose noise is below ``noise_fraction`` x C
  (default C / 2; with a fixed seed the noise fires nothing on static pixels, it moves event times);
* steps: the rule of an unasked render (``stepping.uniform_default_steps``): the known image motion, scan and
  objects, at most 0.5 px a step, and the pixel model's floors (low-pass, shot noise), uniform;
* reuse: a static scene under a periodic view renders one period (already automatic in render_events).

With ``timing_accuracy`` (seconds: the median timestamp error wanted; ``eventfield render --auto
--timing-accuracy 20us``) the sampler and spp come from the accuracy-limit model instead
(``simulate/accuracy_limit.py``: a crossing moves by about sigma_L / |dL/dt| from Monte-Carlo noise and by
dt^2 |L''| / (8 |L'|) from the time step). Probe frames at 0, dt, 2 dt give |L''|, and with frames at 4, 8, 16 ...
dt a baseline where the error stops growing with it gives |dL/dt| (``event_slopes``); two seeds of one frame
at 1, 4 and 16 x ``probe_spp`` give each candidate sampler's noise and how fast it falls with spp
(independent: 1/sqrt(spp); stratified and multi-jittered samplers faster on smooth pixels). The cheapest
(sampler, spp) whose predicted noise error is at most ``NOISE_SHARE`` of the request (and whose noise stays
under ``noise_fraction`` x C) is chosen, then the fewest steps whose step error, added in quadrature, keeps the
total within the request; never fewer steps than the motion rule above (count accuracy). A request the limits
(``max_spp``, ``max_steps``) cannot meet is refused before anything is rendered.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from ..backend import set_variant
from ..errors import ConfigError
from ..scene.sampler import SAMPLERS, plugin_name   # candidates for a timing request (the scene's own first)
from ..scene.timed import load_scene
from .accuracy_limit import MAX_BASELINES, AccuracyLimit, event_median, longest_baseline, noise_map
from .accuracy_limit import noisy as is_noisy
from .render import render_frames
from .stepping import whole_number, whole_per_period

NOISE_SHARE = 0.6          # of a requested timing accuracy, the part Monte-Carlo noise may take
PROBES = (1, 4, 16)        # a timing request probes each sampler's noise at these multiples of probe_spp
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9}


@dataclass
class Plan:
    color: bool
    spp: int
    steps: int
    static: bool
    reasons: dict = field(default_factory=dict)
    defines: dict = field(default_factory=dict)
    sampler: dict | None = None          # a Mitsuba sampler dict replacing the scene's own; None: the scene's
    timing: dict | None = None           # a timing-accuracy request: the request, the prediction, the candidates

    def render_kwargs(self) -> dict:
        return {"spp": self.spp, "steps": self.steps}

    def load(self, scene_path: str, motion="auto"):
        """The scene as planned: its defines, and the chosen sampler in place of its own."""
        return load_with_sampler(scene_path, self.sampler, motion=motion, **self.defines)

    def report(self) -> str:
        return "\n".join(f"{k}: {v}" for k, v in self.reasons.items())

    def as_dict(self) -> dict:
        return {"color": self.color, "spp": self.spp, "steps": self.steps, "static": self.static,
                "sampler": self.sampler, "timing": self.timing, "reasons": dict(self.reasons)}


def parse_time(text, what: str = "--timing-accuracy", hi: float = 1.0) -> float:
    """Seconds from a time with a unit: ``20us``, ``0.5 ms``, ``1e-5s`` (units s, ms, us or µs, ns), from 1 us (event
    timestamps are whole microseconds) to ``hi`` s."""
    m = re.fullmatch(r"\s*([0-9.eE+-]+)\s*(s|ms|us|µs|ns)\s*", str(text))
    try:
        value = float(m[1]) * TIME_UNITS[m[2]] if m else math.nan
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and 1e-6 <= value <= hi):         # timestamps are whole microseconds
        raise ConfigError(f"{what} {text!r}: expected a time from 1us to {hi:g}s with a unit, e.g. 20us, 0.5ms, "
                          "1e-5s")
    return value


def load_with_sampler(scene_path: str, sampler: dict | None, motion="auto", **defines):
    """``load_scene(scene_path, motion, **defines)`` with the sensor's sampler replaced by ``sampler`` (e.g.
    ``{"type": "multijitter", "sample_count": 16}``; None: the scene's own or the default, ``scene/sampler.py``)."""
    return load_scene(scene_path, motion=motion, sampler=sampler or None, **defines)


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
        declared = set(re.findall(r'<default\s+name="(\w+)"', f.read()))
    if {"width", "height"} <= declared:
        return {"width": size, "height": size * 3 // 4}
    if "views_px" in declared:
        return {"views_px": 3 * (size // 3)}
    return {}


def noise_std(timed, spp: int, seeds=(0, 1, 2, 3), t: float = 0.0) -> float:
    """Median over pixels of the spread of log brightness across seeds (Monte-Carlo noise), in log units."""
    frames = np.stack([render_frames(timed, [t], spp=spp, seed=s)[0] for s in seeds])
    return float(np.median(frames.std(axis=0)))


def _ladder(sampler: str, max_spp: int) -> list:
    """The sample counts a sampler takes exactly: powers of two (independent), else powers of four."""
    base, low = (2, 1) if sampler == "independent" else (4, 4 if sampler == "ldsampler" else 1)
    return [base ** k for k in range(int(math.log(max_spp, base) + 1e-9) + 1) if base ** k >= low]


def _own_sampler(timed) -> str:
    return plugin_name(timed.sensor.sampler().class_name())


def _noise_model(scene, probe, probe_spp) -> dict | None:
    """A sampler's noise measured at ``PROBES`` x ``probe_spp``: the timing error (us) and median sigma (log) at
    each, and between them power laws in spp (below the first and beyond the last, the nearest piece's exponent,
    kept within [0.25, 1.25]: stratified samplers fall faster once their strata are fine).

    ``probe``: ``_slope_frames``, whose slopes every probe divides its noise by. Slopes taken from 4-spp frames
    carried their noise, which made every pixel look steep and the predicted timing error small, the more so the
    finer the probe (the demo at 48x36: 27 us predicted at 64 spp, 5.4 us at 256, where a render's own estimate
    said about 200 us at 16 and at 256); 64-spp frames one step apart still did (74 us predicted at 64 spp, 486
    measured). One slope for every probe (a baseline chosen per probe's noise made the model jump: runner,
    11.6 / 22.7 / 9.41 us at 4 / 16 / 64 spp)."""
    est, slope = probe["estimate"], probe["slope"]
    if est is None:
        return None
    active = slope > 0
    points, noisy = [], False
    for factor in PROBES:
        spp = probe_spp * factor
        sigma = probe["sigma"] if scene is probe["scene"] and spp == probe["spp"] else noise_map(scene, spp, 0, 0.0)
        noise_us = event_median(np.ravel(sigma)[active] / slope[active], slope[active]) * 1e6
        points.append((spp, max(noise_us, 1e-9), float(np.median(sigma)), est["steps_us"]))
        noisy = noisy or is_noisy(sigma)      # (a scene of flat regions: median 0, its edges noisy)
    slopes = [math.log(a[1] / b[1]) / math.log(b[0] / a[0]) for a, b in zip(points, points[1:])]
    return {"points": points, "slopes": slopes, "steps_us": est["steps_us"], "resolved": est["slope_resolved"],
            "slope_baseline_us": est["slope_baseline_us"], "noise_free": not noisy}


def _slope_frames(timed, dt, probe_spp, duration) -> dict:
    """The image's slopes for every sampler probed (the image is the same whichever sampler renders it): frames
    at 0, dt and 2 dt (slopes, curvature) and at 4, 8, 16 ... dt up to half the duration or a quarter of a scan
    period (longer slope baselines), at the finest probe's spp, their noise, and the estimate and per-pixel
    slope ``accuracy_limit`` takes from them (``event_slopes``)."""
    spp = probe_spp * PROBES[-1]
    longest = min(duration / 2, longest_baseline(timed.scan_period))
    later = [dt * 2 ** k for k in range(2, 2 + MAX_BASELINES) if dt * 2 ** k <= longest]
    frames = render_frames(timed, [0.0, dt, 2 * dt] + later, spp=spp)
    lim = AccuracyLimit(dt, spp)
    lim.frames, lim.baselines, lim.sigma = list(frames[:3]), list(zip(later, frames[3:])), noise_map(timed, spp, 0, 0.0)
    lim.longest = longest
    est = lim.estimate()
    return {"scene": timed, "spp": spp, "sigma": lim.sigma, "estimate": est,
            "slope": lim.chosen["slope"] if est is not None else None}


def _predict(model, spp) -> tuple:
    """(timing error in us, median sigma) of a noise model at ``spp``: between probes the measured power law,
    outside them the nearest one's exponent kept within [0.25, 1.25]."""
    points, slopes = model["points"], model["slopes"]
    i = min(sum(spp > p[0] for p in points[1:-1]), len(slopes) - 1)
    slope = slopes[i] if points[0][0] <= spp <= points[-1][0] else min(max(slopes[i], 0.25), 1.25)
    anchor = points[i + 1] if spp > points[-1][0] else points[i]
    f = (anchor[0] / spp) ** slope
    return anchor[1] * f, anchor[2] * f


def _candidate(model) -> bool:
    """A noise model a timing request may rest on: its slopes resolved (else its error is at least its
    prediction), and noise to model (a jitter-free sampler renders the same image for every seed: the runner's
    own stratified sampler read 1e-9 us and was planned at 1 spp; its error is a fixed pattern no seed shows)."""
    return model["resolved"] and not model["noise_free"]


def _timing_choice(scene_path, defines, timed, dt, duration, target_s, sigma_cap, probe_spp, max_spp) -> dict:
    """The cheapest (sampler, spp) whose predicted noise error is within NOISE_SHARE of ``target_s``."""
    own = _own_sampler(timed)
    budget_us = NOISE_SHARE * target_s * 1e6
    models, best = {}, None
    probe = _slope_frames(timed, dt, probe_spp, duration)
    for order, name in enumerate((own,) + tuple(s for s in SAMPLERS if s != own)):
        scene = timed if name == own else load_with_sampler(scene_path, {"type": name, "sample_count": probe_spp},
                                                            **defines)
        m = _noise_model(scene, probe, probe_spp)
        if m is None:
            raise ConfigError("--timing-accuracy: no pixel changes in the probe frames at the start of the render, "
                              "so there is no event timing to predict")
        models[name] = m
        if not _candidate(m):
            continue
        for spp in _ladder(name, max_spp):
            us, sigma = _predict(m, spp)
            if us <= budget_us and sigma <= sigma_cap:
                best = min(best or (spp, order, name, us), (spp, order, name, us))
                break
    if best is None and not any(_candidate(m) for m in models.values()):
        if any(m["resolved"] for m in models.values()):       # every sampler renders one image for all seeds
            raise ConfigError(f"--timing-accuracy {target_s * 1e6:g}us: no sampler shows Monte-Carlo noise in the "
                              "probe frames, so there is no noise timing to predict")
        longest = max(m["slope_baseline_us"] for m in models.values())
        raise ConfigError(f"--timing-accuracy {target_s * 1e6:g}us: the probe frames do not resolve the image's "
                          f"slopes within {longest:.3g} us (half the duration or a quarter scan period at most), so "
                          "no timing error can be promised; render a longer span, or without --timing-accuracy")
    if best is None:
        floor = min(_predict(m, max_spp)[0] for m in models.values() if _candidate(m))
        raise ConfigError(f"--timing-accuracy {target_s * 1e6:g}us cannot be met within {max_spp} spp: Monte-Carlo "
                          f"noise alone is predicted to move event times by {floor:.3g} us at best")
    spp, _, name, noise_us = best
    return {"sampler": name, "own_sampler": own, "spp": spp, "noise_us": noise_us,
            "steps_us_at_probe": models[own]["steps_us"], "models": models}


def _default_steps(timed, duration, spp, threshold, max_steps, preset=None, pixel=None) -> tuple:
    """(steps, why): the known image motion under 0.5 px a step and the pixel model's floors
    (``stepping.uniform_default_steps``, the rule an unasked render takes). It replaced a rule of its own, the
    99th percentile of a probe's per-pixel log change under C a step, which Monte-Carlo noise drove (a moving
    mesh's edges flip whole samples between dark and bright at any step size): the fan at 346x260 asked for
    2405 steps over 20 ms (481 a scan period, 3 minutes) and then noted that more steps do not help."""
    from .pixel_setup import event_integrator
    from .stepping import uniform_default_steps
    integ = event_integrator(timed, threshold, None, None, None, preset, pixel)
    steps, chosen = uniform_default_steps(timed, duration, spp, integ)
    if steps > max_steps:
        raise ConfigError(f"the scene's image motion needs {steps} steps over {duration:g} s, more than "
                          f"max_steps = {max_steps}")
    speed = chosen.get("largest_image_speed_px_per_s")
    return steps, (f"{chosen['by']}" + (f": the image moves up to {speed:.4g} px/s (scan and objects), at most "
                                         f"{chosen['px_per_step']:g} px a step" if speed is not None else ""))


def _reuse(timed, duration, steps, reasons) -> int:
    """Steps rounded up to whole steps per scan period when one period can be reused; the reason recorded."""
    period = timed.scan_period
    if not timed.is_static:
        reasons["reuse"] = "moving scene: every step is rendered"
    elif period == 0.0:
        reasons["reuse"] = "static scene seen by a fixed view: one frame is rendered and reused"
    elif period is None:
        reasons["reuse"] = "static scene, aperiodic scan: every step is rendered"
    else:
        n = whole_number(duration / period)
        if n:
            steps = whole_per_period(steps, duration, period)     # whole steps per period: one period is reused
            per_period = steps // n
            reasons["steps"] += f"; rounded up to {per_period} per scan period ({steps} in all) for reuse"
            reasons["reuse"] = (f"static scene: one scan period ({per_period} steps) is rendered and reused for the "
                                f"other {n - 1}")
        else:
            reasons["reuse"] = (f"static scene, but {duration:g} s is not a whole number of {period * 1e3:g} ms scan "
                                "periods: every step is rendered")
    return steps


def _noise_spp(timed, threshold, noise_fraction, probe_spp, max_spp, reasons) -> int:
    sigma = noise_std(timed, probe_spp)
    target = noise_fraction * threshold
    need = probe_spp * (sigma / target) ** 2 if sigma > 0 else 1
    spp = int(min(max_spp, 2 ** max(0, math.ceil(math.log2(max(need, 1))))))
    reached = sigma * math.sqrt(probe_spp / spp)
    reasons["spp"] = (f"{spp}: Monte-Carlo noise {sigma:.4f} (log) at {probe_spp} spp scales as 1/sqrt(spp); "
                      f"{spp} spp brings it to {reached:.4f}"
                      + (f" <= {target:.4f} ({noise_fraction} x C)" if reached <= target * (1 + 1e-9) else
                         f", still above the target {target:.4f}: capped at max_spp = {max_spp}"))
    return spp


def _timing_steps(choice, duration, dt, target_s, floor_steps, max_steps) -> tuple:
    """Fewest steps whose step error, in quadrature with the noise error, keeps the total within the target."""
    left_us = math.sqrt(max((target_s * 1e6) ** 2 - choice["noise_us"] ** 2, 0.0))
    s_probe = choice["steps_us_at_probe"]                # step error at the probe's dt; grows as dt^2
    need = 1 if s_probe <= 0 else math.ceil(duration / (dt * math.sqrt(left_us / s_probe)) - 1e-9)
    if need > max_steps:
        raise ConfigError(f"--timing-accuracy {target_s * 1e6:g}us needs {need} steps, more than max_steps = "
                          f"{max_steps}")
    steps = max(need, floor_steps)
    steps_us = s_probe * (duration / steps / dt) ** 2
    return steps, need, steps_us


def scene_threshold(timed) -> float:
    """The contrast threshold the scene's own event integrator sets (the smaller of ON and OFF; 0.2 without one)."""
    integ = timed.scene.integrator()
    on, off = getattr(integ, "threshold_on", None), getattr(integ, "threshold_off", None)
    return float(min(on, off)) if on and off else 0.2


def plan(scene_path: str, duration: float, threshold: float | None = None, noise_fraction: float = 0.5,
         probe_spp: int = 4, probe_dt: float | None = None, defines=None,
         max_spp: int = 256, max_steps: int = 100_000, timing_accuracy: float | None = None,
         preset: str | None = None, pixel: dict | None = None) -> Plan:
    """Colour, spp and steps for rendering ``scene_path`` over ``duration`` seconds (module docstring); with
    ``timing_accuracy`` (seconds, median timestamp error) also the sampler, by the accuracy-limit model.
    ``threshold``: the contrast threshold C of the render (default: the scene's own); ``preset`` / ``pixel``:
    the render's pixel model, as for ``render_events`` (its floors: a low-pass pixel's, shot noise's)."""
    defines = dict(defines or {})
    reasons = {}
    grey = _grey(scene_path, defines)
    reasons["colour"] = ("mono: every pixel of an RGB probe is grey, so the luminance the pixel sees equals the mono "
                         "render" if grey else "rgb: the scene has colour, and luminance needs all three channels")
    set_variant(color=not grey)
    timed = load_scene(scene_path, **defines)
    threshold = scene_threshold(timed) if threshold is None else threshold
    dt = probe_dt or duration / 200
    if timing_accuracy is None:
        spp = _noise_spp(timed, threshold, noise_fraction, probe_spp, max_spp, reasons)
        steps, why = _default_steps(timed, duration, spp, threshold, max_steps, preset, pixel)
        reasons["steps"] = f"{steps}: {why}"
        return Plan(color=not grey, spp=spp, steps=_reuse(timed, duration, steps, reasons), static=timed.is_static,
                    reasons=reasons, defines=defines)
    choice = _timing_choice(scene_path, defines, timed, dt, duration, timing_accuracy, noise_fraction * threshold,
                            probe_spp, max_spp)
    floor, why = _default_steps(timed, duration, probe_spp, threshold, max_steps, preset, pixel)
    steps, need, steps_us = _timing_steps(choice, duration, dt, timing_accuracy, floor, max_steps)
    return _timing_plan(grey, timed, choice, steps, need, floor, why, steps_us, timing_accuracy, duration,
                        reasons, defines)


def _timing_plan(grey, timed, choice, steps, need, floor, why, steps_us, target_s, duration, reasons,
                 defines) -> Plan:
    """The plan of a timing request, with the reason of each choice in words and numbers."""
    target_us = target_s * 1e6
    models = choice["models"]
    listed = "; ".join(f"{name}: " + ", ".join(f"{us:.3g} us at {spp}" for spp, us, _, _ in m["points"]) + " spp"
                       + (" (jitter-free: no noise to model, not a candidate)" if m["noise_free"] else "")
                       for name, m in models.items())
    sampler = None if choice["sampler"] == choice["own_sampler"] else {"type": choice["sampler"],
                                                                          "sample_count": choice["spp"]}
    reasons["sampler"] = (f"{choice['sampler']}" + (" (the scene's own)" if sampler is None else
                                                    f" (in place of the scene's {choice['own_sampler']})")
                          + f": Monte-Carlo timing error by sampler ({listed}); it needs the fewest samples to "
                            f"stay under {NOISE_SHARE:g} x {target_us:g} us")
    reasons["spp"] = f"{choice['spp']}: predicted noise timing error {choice['noise_us']:.3g} us"
    total = math.hypot(choice["noise_us"], steps_us)
    reasons["steps"] = (f"{steps}: the time step's error falls as dt^2; {need} steps keep it, in quadrature with the "
                        f"noise, under {target_us:g} us; the image motion needs {floor} (count accuracy: {why})")
    steps = _reuse(timed, duration, steps, reasons)
    chosen = models[choice["sampler"]]
    reasons["timing"] = (f"requested median timestamp error {target_us:g} us; predicted {total:.3g} us "
                         f"(noise {choice['noise_us']:.3g} us, steps {steps_us:.3g} us); the image's slopes over "
                         f"{chosen['slope_baseline_us']:.3g} us of probe frames")
    timing = {"requested_s": target_s, "predicted_us": total, "noise_us": choice["noise_us"], "steps_us": steps_us,
              "slope_baseline_us": chosen["slope_baseline_us"],
              "steps_for_timing": need, "steps_for_motion": floor, "noise_share": NOISE_SHARE,
              "samplers": {name: {"probe_spp": [p[0] for p in m["points"]], "noise_us": [p[1] for p in m["points"]],
                                  "slopes": m["slopes"]} for name, m in models.items()}}
    return Plan(color=not grey, spp=choice["spp"], steps=steps, static=timed.is_static, reasons=reasons,
                defines=defines, sampler=sampler, timing=timing)
