"""The ideal event pixel, as pure functions the integrator and the tests share.

An event fires each time the pixel's log brightness ``L`` moves by a contrast threshold from its reference
level; the reference then moves by exactly one threshold (so several events can fire in one step, and no
residual is lost). Between two rendered instants ``L`` is taken as linear in time, which fixes the timestamp of
every crossing (the ESIM model).

Dr.Jit side (per pixel, dense): :func:`linlog`, :func:`count_crossings`.
NumPy side (sparse, only pixels that fired): :func:`expand_crossings` turns the per-pixel counts into events.
"""
from __future__ import annotations

import math

import numpy as np


def linlog(dr, intensity, linear_below: float):
    """Log brightness with a linear segment below ``linear_below`` (C1-continuous), so zero radiance is finite.

    For I >= I_l: log(I); below: log(I_l) + (I - I_l) / I_l, the tangent of log at I_l. Real photoreceptors
    behave alike (dark current), and it keeps Monte-Carlo zeros from producing -inf.
    """
    il = float(linear_below)
    return dr.select(intensity >= il, dr.log(dr.maximum(intensity, il)), math.log(il) + (intensity - il) / il)


def linlog_np(intensity, linear_below: float):
    """NumPy twin of :func:`linlog` (used by oracles and offline tools)."""
    i = np.asarray(intensity, dtype=np.float64)
    il = float(linear_below)
    return np.where(i >= il, np.log(np.maximum(i, il)), math.log(il) + (i - il) / il)


def count_crossings(dr, Int, log_now, log_ref, c_on, c_off):
    """Signed number of threshold crossings per pixel: n > 0 means n ON events (L rose by n*c_on from the
    reference), n < 0 means |n| OFF events."""
    rise = log_now - log_ref
    n_on = dr.maximum(dr.floor(rise / c_on), 0.0)
    n_off = dr.maximum(dr.floor(-rise / c_off), 0.0)
    return Int(n_on) - Int(n_off)


def reference_level(dr, Float, anchor, k_on, k_off, c_on, c_off):
    """Reference level from the pixel's initial level and its integer ON/OFF event counts.

    Kept exact by construction instead of accumulated (``ref += C`` drifts by a rounding error per event):
    with equal thresholds it depends on ``k_on - k_off`` only, so a pixel whose counts return to the same net
    value is back in bit-identical state, which is what makes periodic scans provably periodic in events.
    """
    symmetric = Float(k_on - k_off) * c_on
    general = Float(k_on) * c_on - Float(k_off) * c_off
    return anchor + dr.select(c_on == c_off, symmetric, general)


def expand_crossings(pixel, n, log_prev, log_now, log_ref, c_on, c_off, t0: float, t1: float):
    """Events of the pixels that fired during (t0, t1].

    All inputs are 1-D arrays over the *firing* pixels (``n != 0``). Crossing k (1-based) of a pixel sits at
    level ``ref + k*C*sign``; its time is where the linear segment from ``log_prev`` (at t0) to ``log_now`` (at
    t1) meets that level. Returns (pixel index, time in seconds float64, polarity int8), unsorted.
    """
    n = np.asarray(n, dtype=np.int64)
    counts = np.abs(n)
    if len(n) == 0:
        return np.empty(0, np.int64), np.empty(0, np.float64), np.empty(0, np.int8)
    pixel = np.asarray(pixel, dtype=np.int64)
    lp, ln, ref = (np.asarray(a, dtype=np.float64) for a in (log_prev, log_now, log_ref))
    step = np.where(n > 0, np.asarray(c_on, dtype=np.float64), np.asarray(c_off, dtype=np.float64))
    sign = np.sign(n)
    if counts.max() > 1:  # repeat each firing pixel once per crossing; k = 1..n within the pixel
        idx = np.repeat(np.arange(len(n)), counts)
        k = np.arange(len(idx), dtype=np.int64) - (np.cumsum(counts) - counts)[idx] + 1
        pixel, lp, ln, ref, step, sign = pixel[idx], lp[idx], ln[idx], ref[idx], step[idx], sign[idx]
    else:                 # the common case with short steps: one crossing per pixel
        k = 1
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = (ref + sign * k * step - lp) / (ln - lp)
    frac = np.clip(np.nan_to_num(frac, nan=1.0), 0.0, 1.0)
    return pixel, t0 + frac * (t1 - t0), sign.astype(np.int8)
