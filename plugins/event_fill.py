"""Events of one step, made on the device: count, prefix sum, fill, timestamps and time order in Dr.Jit.

The host twin is ``pixel_model.expand_crossings`` (NumPy, over the compressed firing pixels); this module gives
the same events, bit for bit, without leaving the backend (LLVM or CUDA):

1. count: every pixel's number of crossings ``|n|`` is already known from the step's kernel;
2. prefix sum: an inclusive scan of the counts gives each pixel's slot range in the event array, and its last
   entry is the step's event total (the one scalar the host reads per step, to size the arrays);
3. fill: event ``i`` finds its pixel by a binary search over the scan (the first pixel whose inclusive sum
   exceeds ``i``) and its crossing number ``k = i - start(pixel) + 1``;
4. timestamps: crossing ``k`` sits at level ``ref + sign k C``; its time is where the step's linear segment
   meets that level, computed in float64 in the same operation order as the host twin, then rounded to integer
   microseconds (``dr.round``: ties to even, as ``np.rint``): float32 would lose microseconds after ~16 s;
5. order: a stable sort by timestamp keeps equal times in (pixel, k) order, the host twin's order.

Events stay as Dr.Jit arrays (:class:`DeviceEvents`); the caller decides when they cross to the host, so a
render can keep many steps on the device and move them in one chunk.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np


@dataclass
class DeviceEvents:
    """One or more steps' events on the device, time-sorted: x, y (UInt32), t (Int64 us), p (Int32 +1/-1)."""
    x: object
    y: object
    t: object
    p: object
    count: int

    def numpy(self):
        """(x uint16, y uint16, t int64 us, p int8) NumPy arrays: the one device-to-host copy."""
        if self.count == 0:
            return (np.empty(0, np.uint16), np.empty(0, np.uint16), np.empty(0, np.int64), np.empty(0, np.int8))
        return (self.x.numpy().astype(np.uint16), self.y.numpy().astype(np.uint16), self.t.numpy(),
                self.p.numpy().astype(np.int8))

    @staticmethod
    def concat(parts: list["DeviceEvents"]) -> "DeviceEvents":
        """One chunk from many steps, still on the device. Each part is scattered at an opaque offset: one
        cached kernel whatever the sizes (``dr.concat`` bakes each offset into a new kernel)."""
        parts = [q for q in parts if q.count]
        if len(parts) <= 1:
            return parts[0] if parts else empty()
        total = sum(q.count for q in parts)
        cols = {k: dr.empty(type(getattr(parts[0], k)), total) for k in "xytp"}
        start = 0
        for q in parts:
            index = dr.arange(mi.UInt32, q.count) + _opaque(start, mi.UInt32)
            for k, buf in cols.items():
                dr.scatter(buf, getattr(q, k), index)
            start += q.count
        dr.eval(*cols.values())
        return DeviceEvents(*cols.values(), count=total)


@dataclass
class HostEvents:
    """One step's events made on the host (pixel models with sparse sequential state): the same interface as
    :class:`DeviceEvents`, already NumPy (x uint16, y uint16, t int64 us, p int8)."""
    x: np.ndarray
    y: np.ndarray
    t: np.ndarray
    p: np.ndarray

    @property
    def count(self) -> int:
        return len(self.t)

    def numpy(self):
        return self.x, self.y, self.t, self.p


def time_order(t_us: np.ndarray, step_start_us: int) -> np.ndarray:
    """Stable time order of one step's events on the host. Offsets within a step usually fit 16 bits, where
    NumPy's stable sort is a radix sort (about 8x faster than comparison sorting here)."""
    offset = t_us - step_start_us
    if len(offset) and offset.min() >= 0 and offset.max() < 2**16:
        return np.argsort(offset.astype(np.uint16), kind="stable")
    return np.argsort(t_us, kind="stable")


def empty() -> DeviceEvents:
    return DeviceEvents(mi.UInt32(), mi.UInt32(), mi.Int64(), mi.Int32(), count=0)


def _opaque(value, cls):
    v = cls(value)
    dr.make_opaque(v)       # a literal per step would be baked into the kernel and recompile it every step
    return v


RADIX_BITS = 11      # bits per counting-sort pass (2048 buckets), as Dr.Jit's own radix sort uses on the CPU


def stable_order(key, key_bound: int):
    """Stable sorting permutation of UInt32 ``key`` whose values are all below ``key_bound``: a least-
    significant-digit radix sort with only the passes that bound needs. A step of up to 2 ms needs one pass,
    where ``dr.argsort`` on 32 bits always makes three."""
    n = dr.width(key)
    index = dr.arange(mi.UInt32, n)
    shift, bits = 0, max(1, int(key_bound).bit_length())
    while shift < bits:                     # shifts 0, 11, 22 and one mask: at most three kernels, all cached
        digit = (key >> shift) & ((1 << RADIX_BITS) - 1)
        dr.eval(digit)
        perm = dr.detail.block_mkperm(digit, n, 1 << RADIX_BITS)
        key, index = dr.gather(mi.UInt32, key, perm), dr.gather(mi.UInt32, index, perm)
        shift += RADIX_BITS
    return index


def crossing_events(n, log_prev, log_now, log_ref, c_on, c_off, width: int, t0: float, t1: float,
                    base_us: int = 0, resolution_us: float = 0.0) -> DeviceEvents:
    """The step's events from its dense per-pixel arrays (all of the film's length, already evaluated):
    ``n`` signed crossing counts (Int32), brightness at t0 and t1, the reference level and the thresholds.
    Timestamps are ``rint((t0 + frac (t1 - t0)) 1e6) + base_us`` microseconds, floored to ``resolution_us``
    when it is > 0 (the sensor clock). Returns the time-sorted events, still on the device."""
    n_pix = dr.width(n)
    counts = mi.UInt32(dr.abs(n))
    ends = dr.prefix_reduce(dr.ReduceOp.Add, counts, exclusive=False)     # inclusive scan: slot ends
    total = int(dr.gather(mi.UInt32, ends, n_pix - 1)[0]) if n_pix else 0  # the host sync of the step
    if total == 0:
        return empty()
    slot = dr.arange(mi.UInt32, total)
    pixel = dr.binary_search(0, n_pix - 1, lambda i: dr.gather(mi.UInt32, ends, i) <= slot)
    n_p = dr.gather(mi.Int32, n, pixel)
    k = slot - (dr.gather(mi.UInt32, ends, pixel) - dr.gather(mi.UInt32, counts, pixel)) + 1
    sign = dr.select(n_p > 0, mi.Int32(1), mi.Int32(-1))

    def at(a):
        return mi.Float64(dr.gather(mi.Float, a, pixel))

    lp, ln, ref = at(log_prev), at(log_now), at(log_ref)
    step = dr.select(n_p > 0, at(c_on), at(c_off))
    # same operations, same order, same precision as expand_crossings: ((ref + (sign k) C) - lp) / (ln - lp)
    frac = (ref + mi.Float64(mi.Int64(sign) * mi.Int64(k)) * step - lp) / (ln - lp)
    frac = dr.clip(dr.select(dr.isnan(frac), 1.0, frac), 0.0, 1.0)
    t0_d, t1_d = _opaque(t0, mi.Float64), _opaque(t1, mi.Float64)
    t_us = mi.Int64(dr.round((t0_d + frac * (t1_d - t0_d)) * 1e6)) + _opaque(base_us, mi.Int64)
    # stable: equal times keep (pixel, k) order. The key is the offset from the step's first microsecond, so
    # its range is the step's length in microseconds, known here without asking the device
    start_us = int(math.floor(t0 * 1e6)) + int(base_us) - 1
    key = mi.UInt32(t_us - _opaque(start_us, mi.Int64))
    dr.eval(pixel, t_us, sign, key)     # one kernel; left lazy, the gathers below would redo the binary search
    order = stable_order(key, int(math.ceil((t1 - t0) * 1e6)) + 3)
    pixel, t_us, sign = (dr.gather(type(a), a, order) for a in (pixel, t_us, sign))
    if resolution_us:              # the sensor clock, after ordering by true time (as the host's readout)
        res = _opaque(resolution_us, mi.Float64)
        t_us = mi.Int64(dr.floor(mi.Float64(t_us) / res) * res)
    w = _opaque(width, mi.UInt32)
    x, y = pixel % w, pixel // w
    dr.eval(x, y, t_us, sign)
    return DeviceEvents(x, y, t_us, sign, count=total)
