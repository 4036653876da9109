"""Which of a step's crossings and shot-noise draws become events, one lane a pixel, on the device: the
refractory period's closed-form selection and the noise event's placement and gating. One definition that the
per-step fill (``event_fill.crossing_events``) and the many-frames kernels (``event_batch``) both trace; the
NumPy twin is ``pixel_model.refractory_crossings`` / ``refractory_extra`` (``host_events``), and the crossing
times are ``pixel_model.expand_crossings``'s, operation for operation."""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi


def rounded(product, fusing: bool | None = None):
    """``product`` (Float64) rounded on its own before the add that follows it, as NumPy and LLVM round it.
    Dr.Jit writes a CUDA multiply without a rounding modifier (``mul.f64``), which leaves ptxas free to fuse it
    with the next add into one FMA (one rounding instead of two): on an H100 that moved refractory pixels'
    last-emission times by an ulp against the host path (2026-11-26; docs/design.md). A select between the two,
    on a predicate only the running kernel knows, is an instruction ptxas cannot fold. It is written as
    "NaN where the product is NaN, else the product": the same value for every input, and nothing Dr.Jit
    simplifies away. The first form, a select on an opaque True, made the bits equal on an H100, but with
    it Dr.Jit refused to record the chunk passes there (most likely the opaque value's upload, made inside
    a recording). This form passes both on an H200 (``gpu_session.sh known``, benchmarks/results/
    gpu_h200.md). On LLVM nothing is fused and the product is returned as it is (``fusing`` overrides the
    backend's choice: a test runs the CUDA form on the CPU)."""
    if not (dr.backend_v(product) == dr.JitBackend.CUDA if fusing is None else fusing):
        return product
    return dr.select(dr.isnan(product), dr.nan, product)


def inverse_rise(lp, ln):
    """1 / (ln - lp) (Float64), a pixel's step made once for all of its crossings (``crossing_time``)."""
    return 1.0 / (ln - lp)


def crossing_time(k, sign, lp, inv_rise, ref, step, t0, t1):
    """Seconds (Float64) of crossing ``k`` (1-based) of a pixel: where its step's linear segment from ``lp``
    meets level ``ref + sign k C``, ``inv_rise`` = ``inverse_rise(lp, ln)``; the same operations, order,
    precision and roundings as ``pixel_model.expand_crossings`` (``rounded``). A multiply by the pixel's
    reciprocal, not a division an event: the converter (640x480 2 kHz stack, CPU, events left on the device)
    took 3.23-3.47 against 3.37-4.26 ms a frame, faster in each of four alternating pairs; the timestamps,
    rounded to 1 us, move only where a crossing sits within an ulp of a half microsecond."""
    frac = (ref + rounded(mi.Float64(mi.Int64(sign) * mi.Int64(k)) * step) - lp) * inv_rise
    frac = dr.clip(dr.select(dr.isnan(frac), 1.0, frac), 0.0, 1.0)
    return t0 + rounded(frac * (t1 - t0))


@dataclass
class Refractory:
    """Refractory state for ``event_fill.crossing_events``: ``last_emit`` (Float64 seconds per pixel, -inf
    before a pixel's first event; replaced by the updated array) and the period in seconds."""
    last_emit: object
    period: float


def _refractory_plan(size, tk, last, period):
    """Per pixel with more than one crossing (:func:`_single_crossing_plan` takes the others), the closed-form
    refractory selection of ``pixel_model.refractory_crossings`` on the device: crossings are evenly spaced
    within a step, so the kept ones are ranks first, first + stride, ... Returns (first, stride, kept count,
    updated last emission, first kept time), all Float64 per pixel."""
    size_f = mi.Float64(size)
    t_a, t_b = tk(1), tk(2)
    spacing = t_b - t_a
    wait = last + period - t_a                                  # > 0: the first crossing is too early
    first = dr.ceil(wait / spacing - 1e-9)
    first = dr.maximum(dr.select(dr.isnan(first), 0.0, first), 0.0)
    stride = dr.maximum(1.0, dr.ceil(period / spacing - 1e-9))
    any_kept = first < size_f
    runs = dr.floor((size_f - 1 - first) / stride)
    kept = dr.select(any_kept, runs + 1, 0.0)
    rank_last = dr.select(dr.isinf(stride), first, first + stride * runs)
    new_last = dr.select(any_kept, tk(mi.Int64(dr.select(any_kept, rank_last, 0.0)) + 1), last)
    first_kept = dr.select(any_kept, tk(mi.Int64(dr.select(any_kept, first, 0.0)) + 1), dr.inf)
    return first, stride, kept, new_last, first_kept


def _single_crossing_plan(tk, last, period):
    """:func:`_refractory_plan` of a pixel with one crossing, the same values with one crossing time instead of
    four and none of the plan's other divisions: at 0.5 ms steps most firing pixels cross once, and a packet
    of 16 pixels whose firing ones all do skips the general plan."""
    t_a = tk(1)
    kept = last + period - t_a <= 0                              # not too early after the pixel's last event
    zero, one = mi.Float64(0.0), mi.Float64(1.0)
    return (dr.select(kept, zero, one), one, dr.select(kept, one, zero), dr.select(kept, t_a, last),
            dr.select(kept, t_a, mi.Float64(dr.inf)))


@dataclass
class Selection:
    """Which of a step's crossings and noise draws become events, per pixel lane (:func:`select_events`):
    ``kept`` crossings (UInt32), their ranks ``first + j stride`` (Float64; None without a refractory period:
    every crossing, rank j), the kept noise event (``hit`` Bool, time ``noise_t`` Float64 s, ``noise_on``; None
    without shot noise) and the pixel's last emission after the step (None without a refractory period)."""
    kept: object
    first: object = None
    stride: object = None
    hit: object = None
    noise_t: object = None
    noise_on: object = None
    last_emit: object = None


def select_events(n, log_prev, log_now, log_ref, c_on, c_off, t0_d, t1_d, last_emit=None, period=None,
                  noise=None) -> Selection:
    """A step's selection of events, one lane a pixel, lazily (the per-step path evaluates it in one kernel,
    ``event_batch`` traces it inside its loop over steps): the closed-form refractory plan
    (``_refractory_plan``) when ``last_emit`` (Float64 s per pixel) is given with ``period``, and the shot-noise
    event of ``noise`` = (hit, u_pol, u_t) at ``t0 + u_t (t1 - t0)``, kept only where the refractory period
    allows it around the pixel's previous and this step's kept crossings."""
    size = mi.UInt32(dr.abs(n))
    sel = Selection(kept=size)
    if last_emit is not None:
        sign_d = dr.select(n > 0, mi.Int32(1), mi.Int32(-1))
        lp_d, ln_d, ref_d = (mi.Float64(a) for a in (log_prev, log_now, log_ref))
        step_d = dr.select(n > 0, mi.Float64(c_on), mi.Float64(c_off))

        def plan(size, last):
            segment = (lp_d, inverse_rise(lp_d, ln_d), ref_d)     # in the branch: still pixels skip the division

            def tk(k):
                return crossing_time(k, sign_d, *segment, step_d, t0_d, t1_d)
            return dr.if_stmt((size, last), size > 1, lambda size, last: _refractory_plan(size, tk, last, period),
                              lambda size, last: _single_crossing_plan(tk, last, period))

        def still(size, last):    # the plan of a pixel without crossings: nothing kept, nothing changes
            return mi.Float64(0.0), mi.Float64(1.0), mi.Float64(0.0), last, dr.full(mi.Float64, dr.inf, dr.width(last))
        # a symbolic branch: the CPU skips the plan's float64 divisions in every packet of still pixels
        sel.first, sel.stride, kept_f, new_last, first_kept = dr.if_stmt((size, last_emit), size > 0, plan, still)
        sel.kept, sel.last_emit = mi.UInt32(kept_f), new_last
    if noise is not None:
        hit, u_pol, u_t = noise[:3]
        if last_emit is None:
            nt = t0_d + rounded(mi.Float64(u_t) * (t1_d - t0_d))
        else:
            def placed(hit, u_t, last, new_last, first_kept, t0, t1):
                nt = t0 + rounded(mi.Float64(u_t) * (t1 - t0))
                keep = hit & (nt >= last + period) & (~dr.isfinite(first_kept) | (nt <= first_kept - period)
                                                      | (nt >= new_last + period))
                return keep, nt, dr.select(keep, dr.maximum(new_last, nt), new_last)

            def quiet(hit, u_t, last, new_last, first_kept, t0, t1):    # no noise event: nothing to place
                return hit, mi.Float64(0.0), new_last
            # a symbolic branch: noise is rare, and its placement's float64 tests ran for every pixel-step
            hit, nt, sel.last_emit = dr.if_stmt((hit, u_t, last_emit, new_last, first_kept, t0_d, t1_d), hit,
                                                placed, quiet)
        sel.hit, sel.noise_t, sel.noise_on = hit, nt, u_pol < 0.5
    return sel
