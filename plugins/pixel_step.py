"""One step of every event pixel: the single definition that the per-step kernel (``EventIntegrator._pixel_step``)
and the many-frames kernel (``event_batch``) both trace, so the two cannot drift apart. :func:`advance` is the
deterministic core; :func:`step` wraps it with the random parts (threshold jitter, shot noise), whose draws are
counter-based (``counter_rng``): keyed by the pixel and its own event counters, made only where used, and the
same whatever the step size.

Threshold jitter is the reset's noise: a pixel draws its next thresholds when it fires and holds them until it
fires again (the pixel state ``held_on`` / ``held_off``); the thresholds after its m-th crossing are draw m.
Drawn afresh every step instead, a slow rise met the lowest of many draws, so the count depended on the step
size, not the sensor (a 4-threshold ramp, C = 0.2, jitter 0.04: 21, 25, 32 and 40 events a pixel at 20, 200,
2000 and 10,000 steps), and a still pixel kept firing on its leftover rise (0.14-0.53 events a pixel in a
second).

Shot noise is a Poisson process whose rate follows the brightness: each pixel holds the hazard left before
its next noise event (``noise_left``, an exponential draw) and spends ``rate x dt`` of it a step; the event
falls where the hazard runs out, at that fraction of the step (exact for a rate constant over the step). The
j-th noise event's polarity and the wait before it are draws j of their streams (j from 0; ``noise_k`` counts
the events). Until 2026-11-26 it was a Bernoulli draw a step (p = rate x dt, three uniforms a pixel every
step) with a uniform time in the step: the same process in the limit of short steps, but a different
realisation at every step size.
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from mitsuba_eventfield.plugins import counter_rng, pixel_model


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


def lowpassed(integ, log_prev, log_in, intensity, dt):
    """The log brightness a step leaves the pixel at: the staged ``log_in``, or under the photoreceptor
    low-pass (``cutoff_hz``) that frame blended into the state ``log_prev`` by ``pixel_model.lowpass_alpha``
    over ``dt`` (opaque Float), with the linear ``intensity`` (None: recovered from the log). One home for the
    blend: the step's kernel and the accuracy limit's estimate of a step held for a batch
    (``simulate.accuracy_limit``) both call it."""
    cfg = integ.config
    if not cfg.cutoff_hz:
        return log_in
    if intensity is None:
        intensity = pixel_model.linlog_inverse(dr, log_in, integ.linlog_threshold)
    alpha = pixel_model.lowpass_alpha(dr, intensity, dt, cfg.cutoff_hz, cfg.bright_intensity,
                                      cfg.cutoff_min_fraction)
    return log_prev + alpha * (log_in - log_prev)


def advance(integ, log_prev, k_on, k_off, offset, log_in, intensity, dt, thresholds) -> tuple:
    """Every pixel through one step from state (``log_prev``, ``k_on``, ``k_off``, ``offset``) to the staged
    log brightness ``log_in`` over ``dt`` seconds (Float, opaque; None when no part of the model needs it):
    photoreceptor low-pass, leak drift, the exact reference level (``pixel_model.reference_level``) and the
    crossing count against ``thresholds``: (c_on, c_off), the pixel's own or the jittered ones it holds
    (:func:`step`). ``intensity`` is needed by the low-pass only. Returns the :class:`PixelLevels` and the
    thresholds counted against. Lazy: the caller evaluates."""
    cfg = integ.config
    log_now = lowpassed(integ, log_prev, log_in, intensity, dt)
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
    the shot-noise event (hit Bool, u_pol, u_t: its polarity draw and its time as a fraction of the step; None
    without shot noise) and the noise state after the step ((noise_left, noise_k); None without shot noise)."""
    levels: PixelLevels
    c_on: object
    c_off: object
    noise: tuple | None
    held: tuple | None = None
    noise_state: tuple | None = None


def step(integ, pixel, log_prev, k_on, k_off, offset, noise_state, log_in, intensity, dt, held=None) -> PixelStep:
    """Every pixel through one step with the whole pixel model: :func:`advance` against the thresholds the
    pixel holds (``held``: (on, off), jittered at its last event; None without jitter), the reference moved by
    them, new thresholds drawn where the pixel fired, and shot noise from ``noise_state`` = (noise_left,
    noise_k) (None without shot noise). ``pixel``: the pixels' indices (UInt32), which key their draws with
    ``integ.seed_word``. ``intensity``: the linear radiance (needed by the low-pass and shot noise). Lazy: the
    caller evaluates.

    All crossings of one step share the thresholds held at its start (a step is meant to be short next to the
    time between a pixel's events). The draws (and the jitter's Box-Muller normal: a log, a square root, a
    sine and a cosine) are made only where the pixel fired: symbolic branches, which the CPU skips in every
    packet of quiet pixels."""
    cfg = integ.config
    thresholds = held if cfg.threshold_jitter else (integ.c_on, integ.c_off)
    lv, c_on, c_off = advance(integ, log_prev, k_on, k_off, offset, log_in, intensity, dt, thresholds)
    if cfg.threshold_jitter:                # the reference moved by the thresholds the pixel held
        lv.offset = lv.offset + mi.Float(dr.maximum(lv.n, 0)) * (c_on - integ.c_on) \
            - mi.Float(dr.maximum(-lv.n, 0)) * (c_off - integ.c_off)
        resets = mi.UInt32(lv.k_on + lv.k_off)
        held = _redrawn(integ, pixel, resets, lv.n != 0, c_on, c_off)
    noise = None
    if cfg.shot_noise_hz:
        rate_dt = mi.Float64(pixel_model.shot_noise_hazard(dr, intensity, dt, cfg.shot_noise_hz,
                                                           cfg.bright_intensity, cfg.shot_noise_bright_factor))
        noise, noise_state = _shot_noise(integ, pixel, noise_state, rate_dt)
    return PixelStep(lv, c_on, c_off, noise, held if cfg.threshold_jitter else None,
                     noise_state if cfg.shot_noise_hz else None)


def _jittered(base_on, base_off, jitter: float, pixel, resets, seed_word) -> tuple:
    """The thresholds a pixel holds after its ``resets``-th crossing (UInt32; 0: before its first): each of
    ``base_on``, ``base_off`` plus ``jitter`` times one of a normal pair (Mitsuba's Box-Muller of two
    counter-based uniforms), floored at a tenth of it."""
    g = mi.warp.square_to_std_normal(mi.Point2f(counter_rng.draw(mi, pixel, resets, seed_word, counter_rng.JITTER_ON),
                                                counter_rng.draw(mi, pixel, resets, seed_word, counter_rng.JITTER_OFF)))
    return dr.maximum(base_on + jitter * g.x, base_on * 0.1), dr.maximum(base_off + jitter * g.y, base_off * 0.1)


def _redrawn(integ, pixel, resets, fired, c_on, c_off) -> tuple:
    """The thresholds each pixel holds after the step: new ones (:func:`_jittered`) where it fired, else those it
    held."""
    jitter = integ.config.threshold_jitter

    def draw(base_on, base_off, pixel, resets, seed, c_on, c_off):
        return _jittered(base_on, base_off, jitter, pixel, resets, seed)

    def keep(base_on, base_off, pixel, resets, seed, c_on, c_off):
        return c_on, c_off
    return dr.if_stmt((integ.c_on, integ.c_off, pixel, resets, integ.seed_word, c_on, c_off), fired, draw, keep)


def start_draws(integ, n_pix: int) -> None:
    """The random part of a new sensor's state (keyed by ``integ.seed_word``): with jitter, the thresholds of
    the pixels' last reset before the first step (draw 0); with shot noise, the hazard each pixel spends before
    its first noise event, an exponential draw (the process is memoryless, so this is also the steady state at
    any start). Float64: the hazard left is a sum over every step, and in float32 its rounding moved a 3 Hz
    pixel's events by up to tens of microseconds over a second of 1 ms steps."""
    cfg, pixel = integ.config, dr.arange(mi.UInt32, n_pix)
    if cfg.threshold_jitter:
        integ.held_on, integ.held_off = _jittered(integ.c_on, integ.c_off, cfg.threshold_jitter, pixel,
                                                  mi.UInt32(0), integ.seed_word)
    if cfg.shot_noise_hz:
        integ.noise_left = mi.Float64(_exponential(pixel, mi.UInt32(0), integ.seed_word))
        integ.noise_k = dr.zeros(mi.UInt32, n_pix)


def _exponential(pixel, counter, seed_word):
    u = counter_rng.draw(mi, pixel, counter, seed_word, counter_rng.NOISE_WAIT)
    return -dr.log(1.0 - u)                 # u < 1: finite (at most 16.6)


MAX_OWED = 1.0     # hazard (mean waits) the shot noise's clock may be overdue by: at most about one owed event


def _shot_noise(integ, pixel, noise_state, rate_dt) -> tuple:
    """One step of shot noise: ((hit, u_pol, u_t Float64), (noise_left Float64, noise_k) after the step). The
    hazard is one clock: the waits add up, and ``noise_left`` is where the next event sits on it relative to the
    step's start. At most one event a pixel a step: a second one the clock places in the same step is overdue
    (``noise_left`` below zero) and fires at the next step's start, the wait after it still counted from where
    the clock put it, so no event is lost and none shifts the ones after it. About rate x dt / 2 of the events
    are delayed (1 in 2,000 at 1 Hz and 1 ms steps). The clock owes at most one mean wait (``MAX_OWED``): at
    rate x dt near 1 or above, where a step would hold more than one event, the rest are lost, not owed (owed
    without limit, a 500 Hz dark pixel kept firing one event a step long after it turned bright and its rate
    fell to 5 Hz: 23 events a pixel in 0.5 s, against 2.5)."""
    left, k = noise_state
    hit = left <= rate_dt

    def fire(pixel, left, k, rate_dt, seed):
        u_pol = counter_rng.draw(mi, pixel, k, seed, counter_rng.NOISE_POLARITY)
        u_t = dr.select(left > 0, dr.minimum(left / rate_dt, 1.0), 0.0)     # left > 0: rate_dt >= left > 0
        return u_pol, u_t, dr.maximum(left + mi.Float64(_exponential(pixel, k + 1, seed)) - rate_dt, -MAX_OWED), k + 1

    def wait(pixel, left, k, rate_dt, seed):
        return mi.Float(0.5), mi.Float64(0.0), left - rate_dt, k
    u_pol, u_t, left, k = dr.if_stmt((pixel, left, k, rate_dt, integ.seed_word), hit, fire, wait)
    return (hit, u_pol, u_t), (left, k)


def needs_intensity(cfg) -> bool:
    """True when the pixel model reads the linear radiance, not only its log (low-pass, shot noise)."""
    return bool(cfg.cutoff_hz or cfg.shot_noise_hz)


def needs_dt(cfg) -> bool:
    """True when the pixel model reads the step's length (low-pass, leak, shot noise)."""
    return bool(cfg.cutoff_hz or cfg.leak_rate_hz or cfg.shot_noise_hz)
