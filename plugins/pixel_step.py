"""One step of every event pixel's deterministic state: the single definition that the per-step kernel
(``EventIntegrator._pixel_step``) and the many-frames kernel (``event_batch``) both trace, so the two cannot
drift apart. Random parts (threshold jitter, shot noise) stay with the per-step kernel: they draw from the
per-pixel generator around this core."""
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


def advance(integ, log_prev, k_on, k_off, offset, log_in, intensity, dt, c_on, c_off) -> PixelLevels:
    """Every pixel through one step from state (``log_prev``, ``k_on``, ``k_off``, ``offset``) to the staged
    log brightness ``log_in`` over ``dt`` seconds (Float, opaque; None when no part of the model needs it):
    photoreceptor low-pass, leak drift, the exact reference level (``pixel_model.reference_level``) and the
    crossing count against thresholds ``c_on`` / ``c_off`` (the pixel's own, or this step's jittered ones).
    ``intensity`` is needed by the low-pass only. Lazy: the caller evaluates."""
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
    n = pixel_model.count_crossings(dr, mi.Int32, log_now, log_ref, c_on, c_off)
    return PixelLevels(log_now, log_ref, n, k_on + dr.maximum(n, 0), k_off + dr.maximum(-n, 0), offset)
