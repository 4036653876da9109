"""One step of every event pixel: the single definition that the per-step kernel (``EventIntegrator._pixel_step``)
and the many-frames kernel (``event_batch``) both trace, so the two cannot drift apart. :func:`advance` is the
deterministic core; :func:`step` wraps it with the random parts (threshold jitter, shot noise), which draw from
the per-pixel PCG32 generator in a fixed order: two jitter draws, then three noise draws a step. A generator
carried through a many-frames loop therefore draws what the per-step kernel draws, step after step."""
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
    crossing count against ``thresholds``: (c_on, c_off), the pixel's own, or a function of the step's rise
    ``log_now - log_ref`` that returns them (jittered: :func:`step`). ``intensity`` is needed by the low-pass
    only. Returns the :class:`PixelLevels` and the thresholds counted against. Lazy: the caller evaluates."""
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
    c_on, c_off = thresholds(log_now - log_ref) if callable(thresholds) else thresholds
    n = pixel_model.count_crossings(dr, mi.Int32, log_now, log_ref, c_on, c_off)
    return PixelLevels(log_now, log_ref, n, k_on + dr.maximum(n, 0), k_off + dr.maximum(-n, 0), offset), c_on, c_off


# The jitter's normal pair (Mitsuba's Box-Muller, ``warp.square_to_std_normal``) never exceeds 5.77 in magnitude:
# over every uniform a PCG32 float draw can give (2^24 values, checked on LLVM; sqrt(-2 ln 2^-24) = 5.768), so a
# jittered threshold is at least max(c - 6 jitter, c / 10), the clamp (``_jittered``). A step whose rise stays
# below that, less a margin for the float32 division's rounding, crosses nothing whatever the draws.
NORMAL_BOUND = 6.0
QUIET_MARGIN = 0.999


@dataclass
class PixelStep:
    """A whole step of the pixel model: the levels, the thresholds the step compared against (the pixel's own,
    or jittered), and the shot-noise draws (hit Bool, u_pol, u_t; None without shot noise)."""
    levels: PixelLevels
    c_on: object
    c_off: object
    noise: tuple | None


def step(integ, log_prev, k_on, k_off, offset, rng, log_in, intensity, dt) -> PixelStep:
    """Every pixel through one step with the whole pixel model: threshold jitter (two draws from ``rng``),
    :func:`advance`, the reference moved by the jittered thresholds, shot noise (three draws). ``rng``: the
    per-pixel ``mi.PCG32`` (advanced in place; None when nothing draws). ``intensity``: the linear radiance
    (needed by the low-pass and shot noise). Lazy: the caller evaluates.

    The jitter's normal pair (Box-Muller: a log, a square root, a sine and a cosine) is made only where the
    step's rise could cross a jittered threshold, i.e. reach the lowest value the jitter can give it (a symbolic
    branch: the CPU skips it in every packet of pixels that cannot cross): elsewhere the pixel's own thresholds
    stand in, which give the same count (none) and, multiplied by it, the same offset; the draws are made either
    way, so the generator's stream does not change."""
    cfg = integ.config
    thresholds = (integ.c_on, integ.c_off)
    if cfg.threshold_jitter:
        u = mi.Point2f(rng.next_float32(), rng.next_float32())
        thresholds = _jittered(integ, cfg.threshold_jitter, u)
    lv, c_on, c_off = advance(integ, log_prev, k_on, k_off, offset, log_in, intensity, dt, thresholds)
    if cfg.threshold_jitter:                # the reference moved by the jittered thresholds
        lv.offset = lv.offset + mi.Float(dr.maximum(lv.n, 0)) * (c_on - integ.c_on) \
            - mi.Float(dr.maximum(-lv.n, 0)) * (c_off - integ.c_off)
    noise = None
    if cfg.shot_noise_hz:
        prob = pixel_model.shot_noise_probability(dr, intensity, dt, cfg.shot_noise_hz, cfg.bright_intensity,
                                                  cfg.shot_noise_bright_factor)
        u_hit, u_pol, u_t = rng.next_float32(), rng.next_float32(), rng.next_float32()
        noise = (u_hit < prob, u_pol, u_t)
    return PixelStep(lv, c_on, c_off, noise)


def _jittered(integ, jitter: float, u):
    """The function of a step's rise that gives its thresholds (``advance``): the pixel's own jittered by the
    normal pair of uniforms ``u`` where the rise could reach one, the pixel's own elsewhere."""
    def thresholds(rise):
        def jitter_them(c_on, c_off, u):
            g = mi.warp.square_to_std_normal(u)
            return (dr.maximum(c_on + jitter * g.x, c_on * 0.1), dr.maximum(c_off + jitter * g.y, c_off * 0.1))

        def own(c_on, c_off, u):
            return c_on, c_off
        quiet = (rise < _lowest(integ.c_on, jitter)) & (-rise < _lowest(integ.c_off, jitter))
        return dr.if_stmt((integ.c_on, integ.c_off, u), ~quiet, jitter_them, own)
    return thresholds


def _lowest(c, jitter: float):
    """A rise below which no threshold ``c`` jittered by ``jitter`` is crossed: the lowest value the jitter can
    give it (``NORMAL_BOUND``), less the margin (``QUIET_MARGIN``). Not yet run on a GPU, whose float32 log and
    sine are approximations of their own: the bound leaves 4 % above the largest normal, and
    tests/plugins/test_event_batch.py (in gpu_session.sh's known tests) checks the events there."""
    return dr.maximum(c - NORMAL_BOUND * jitter, c * 0.1) * QUIET_MARGIN


def needs_intensity(cfg) -> bool:
    """True when the pixel model reads the linear radiance, not only its log (low-pass, shot noise)."""
    return bool(cfg.cutoff_hz or cfg.shot_noise_hz)


def needs_dt(cfg) -> bool:
    """True when the pixel model reads the step's length (low-pass, leak, shot noise)."""
    return bool(cfg.cutoff_hz or cfg.leak_rate_hz or cfg.shot_noise_hz)
