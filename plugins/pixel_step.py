"""One step of every event pixel: the single definition that the per-step kernel (``EventIntegrator._pixel_step``)
and the many-frames kernel (``event_batch``) both trace, so the two cannot drift apart. :func:`advance` is the
deterministic core; :func:`step` wraps it with the random parts (threshold jitter, shot noise), which draw from
the per-pixel PCG32 generator in a fixed order: two jitter draws, then three noise draws a step, made whether
or not they are used. A generator carried through a many-frames loop therefore draws what the per-step kernel
draws, step after step.

Threshold jitter is the reset's noise: a pixel draws its next thresholds when it fires and holds them until it
fires again (the pixel state ``held_on`` / ``held_off``). Drawn afresh every step instead, a slow rise met the
lowest of many draws, so the count depended on the step size, not the sensor (a 4-threshold ramp, C = 0.2,
jitter 0.04: 21, 25, 32 and 40 events a pixel at 20, 200, 2000 and 10,000 steps), and a still pixel kept
firing on its leftover rise (0.14-0.53 events a pixel in a second)."""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from mitsuba_eventfield.plugins import pixel_model


@dataclass
class PixelLevels:
    """What a step leaves: the (low-passed) log brightness at the step's end, the reference level the step
    compared against, the signed crossing count, the updated ON / OFF counts and reference drift."""
    log_now: object
    log_ref: object
    n: object
    k_on: object
    k_off: object
    offset: object


def advance(integ, log_prev, k_on, k_off, offset, log_in, intensity, dt, thresholds) -> tuple:
    """Every pixel through one step from state (``log_prev``, ``k_on``, ``k_off``, ``offset``) to the staged
    log brightness ``log_in`` over ``dt`` seconds (Float, opaque; None when no part of the model needs it):
    photoreceptor low-pass, leak drift, the exact reference level (``pixel_model.reference_level``) and the
    crossing count against ``thresholds``: (c_on, c_off), the pixel's own or the jittered ones it holds
    (:func:`step`). ``intensity`` is needed by the low-pass only. Returns the :class:`PixelLevels` and the
    thresholds counted against. Lazy: the caller evaluates."""
    cfg = integ.config
    log_now = log_in
    if cfg.cutoff_hz:
        alpha = pixel_model.lowpass_alpha(dr, intensity, dt, cfg.cutoff_hz, cfg.bright_intensity,
                                          cfg.cutoff_min_fraction)
        log_now = log_prev + alpha * (log_in - log_prev)
    if cfg.leak_rate_hz:
        offset = offset - integ.leak_rate * integ.c_on * dt      # the reference sinks: ON events
    log_ref = pixel_model.reference_level(dr, mi.Float, integ.anchor, k_on, k_off, integ.c_on, integ.c_off)
    if offset is not None:
        log_ref = log_ref + offset
    c_on, c_off = thresholds
    n = pixel_model.count_crossings(dr, mi.Int32, log_now, log_ref, c_on, c_off)
    return PixelLevels(log_now, log_ref, n, k_on + dr.maximum(n, 0), k_off + dr.maximum(-n, 0), offset), c_on, c_off


@dataclass
class PixelStep:
    """A whole step of the pixel model: the levels, the thresholds the step compared against (the pixel's own,
    or the jittered ones it held), the jittered thresholds it holds for the next step (None without jitter),
    and the shot-noise draws (hit Bool, u_pol, u_t; None without shot noise)."""
    levels: PixelLevels
    c_on: object
    c_off: object
    noise: tuple | None
    held: tuple | None = None


def step(integ, log_prev, k_on, k_off, offset, rng, log_in, intensity, dt, held=None) -> PixelStep:
    """Every pixel through one step with the whole pixel model: :func:`advance` against the thresholds the
    pixel holds (``held``: (on, off), jittered at its last event; None without jitter), the reference moved by
    them, new thresholds drawn where the pixel fired (two draws from ``rng``), shot noise (three draws).
    ``rng``: the per-pixel ``mi.PCG32`` (advanced in place; None when nothing draws). ``intensity``: the linear
    radiance (needed by the low-pass and shot noise). Lazy: the caller evaluates.

    All crossings of one step share the thresholds held at its start (a step is meant to be short next to the
    time between a pixel's events); the normal pair (Box-Muller: a log, a square root, a sine and a cosine) is
    made only where the pixel fired (a symbolic branch: the CPU skips it in every packet of quiet pixels), the
    uniforms drawn either way, so the generator's stream does not depend on the events."""
    cfg = integ.config
    thresholds = held if cfg.threshold_jitter else (integ.c_on, integ.c_off)
    lv, c_on, c_off = advance(integ, log_prev, k_on, k_off, offset, log_in, intensity, dt, thresholds)
    if cfg.threshold_jitter:                # the reference moved by the thresholds the pixel held
        lv.offset = lv.offset + mi.Float(dr.maximum(lv.n, 0)) * (c_on - integ.c_on) \
            - mi.Float(dr.maximum(-lv.n, 0)) * (c_off - integ.c_off)
        u = mi.Point2f(rng.next_float32(), rng.next_float32())
        held = _redrawn(integ, cfg.threshold_jitter, lv.n != 0, u, c_on, c_off)
    noise = None
    if cfg.shot_noise_hz:
        prob = pixel_model.shot_noise_probability(dr, intensity, dt, cfg.shot_noise_hz, cfg.bright_intensity,
                                                  cfg.shot_noise_bright_factor)
        u_hit, u_pol, u_t = rng.next_float32(), rng.next_float32(), rng.next_float32()
        noise = (u_hit < prob, u_pol, u_t)
    return PixelStep(lv, c_on, c_off, noise, held if cfg.threshold_jitter else None)


def jittered(c_on, c_off, jitter: float, u) -> tuple:
    """Thresholds ``c_on``, ``c_off`` with the reset's noise: each plus ``jitter`` times one of the normal pair
    of the uniforms ``u`` (Mitsuba's Box-Muller), floored at a tenth of it."""
    g = mi.warp.square_to_std_normal(u)
    return dr.maximum(c_on + jitter * g.x, c_on * 0.1), dr.maximum(c_off + jitter * g.y, c_off * 0.1)


def _redrawn(integ, jitter: float, fired, u, c_on, c_off) -> tuple:
    """The thresholds each pixel holds after the step: new ones (:func:`jittered`) where it fired, else those it
    held."""
    def draw(base_on, base_off, u, c_on, c_off):
        return jittered(base_on, base_off, jitter, u)

    def keep(base_on, base_off, u, c_on, c_off):
        return c_on, c_off
    return dr.if_stmt((integ.c_on, integ.c_off, u, c_on, c_off), fired, draw, keep)


def needs_intensity(cfg) -> bool:
    """True when the pixel model reads the linear radiance, not only its log (low-pass, shot noise)."""
    return bool(cfg.cutoff_hz or cfg.shot_noise_hz)


def needs_dt(cfg) -> bool:
    """True when the pixel model reads the step's length (low-pass, leak, shot noise)."""
    return bool(cfg.cutoff_hz or cfg.leak_rate_hz or cfg.shot_noise_hz)
