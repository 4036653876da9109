"""Events made on the device: count, prefix sum, fill, timestamps and time order in Dr.Jit, for one step
(:func:`crossing_events`, with the refractory period and shot noise) or many (``event_batch``), through one
fill (:func:`fill`).

The host twin is ``pixel_model.expand_crossings`` (NumPy, over the compressed firing pixels); this module gives
the same events, bit for bit, without leaving the backend (LLVM or CUDA):

1. count: every (step, pixel) lane's number of crossings ``|n|`` is known from the pixel kernel (a refractory
   period keeps a closed-form subset of them: ``event_select``);
2. prefix sum: an inclusive scan of the counts gives each lane's slot range in the event array, and its last
   entry is the chunk's event total (the one scalar the host reads, to size the arrays);
3. fill: one lane a pixel writes its own crossings of each step into its slot range (no event
   searches for its pixel: a binary search per event was 2x slower on the CPU);
4. timestamps: crossing ``k`` sits at level ``ref + sign k C``; its time is where the step's linear segment
   meets that level (times the pixel's 1 / rise, made before its crossings' loop), computed in float64 in the
   host twin's operation order, then rounded to integer microseconds (``dr.round``: ties to even, as
   ``np.rint``): float32 would lose microseconds after ~16 s;
5. order: a stable radix sort by microsecond keeps equal times in slot order: (step, pixel, k, then the
   pixel's noise event).

Events stay as Dr.Jit arrays (:class:`DeviceEvents`); the caller decides when they cross to the host, so a
render can keep many steps on the device and move them in one chunk.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass, replace

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_eventfield.plugins import event_memory, pixel_model
from mitsuba_eventfield.plugins.event_select import Refractory, Selection, crossing_time, inverse_rise, select_events


@dataclass
class DeviceEvents:
    """One or more steps' events on the device, time-sorted: ``xy`` (UInt32, x | y << 16), t (Int64 us), p
    (Int8 +1/-1). x and y share a word so that the host receives them as 16-bit halves without conversion."""
    xy: object
    t: object
    p: object
    count: int
    refractory_dropped: int = 0      # crossings and noise events the refractory period removed in this step
    noise_events: int = 0            # shot-noise events kept in this step

    def numpy(self, owned: bool = False):
        """(x uint16, y uint16, t int64 us, p int8) NumPy arrays. On the CPU these are views of the Dr.Jit
        arrays (no copy; x and y strided halves of ``xy``); from a GPU, one device-to-host copy into Dr.Jit's
        pinned host memory. ``owned``: NumPy's own memory instead, one host copy more, and Dr.Jit's buffers
        released here: for a result that any thread may free later (``DeviceEventStream.numpy``). Dr.Jit returns
        a freed pinned buffer to its cache through the freeing thread's CUDA state; freed elsewhere, it is never
        reused (the background writer, before it borrowed its chunks: events/writer.py, docs/design.md)."""
        if self.count == 0:
            return (np.empty(0, np.uint16), np.empty(0, np.uint16), np.empty(0, np.int64), np.empty(0, np.int8))
        xy = self.xy.numpy()
        if sys.byteorder == "little":
            halves = xy.view(np.uint16)
            x, y = halves[0::2], halves[1::2]
        else:
            x, y = (xy & 0xFFFF).astype(np.uint16), (xy >> 16).astype(np.uint16)
        cols = (x, y, self.t.numpy(), self.p.numpy())
        if owned:
            cols = tuple(np.array(c, copy=True, order="C") for c in cols)
        return cols

    @staticmethod
    def concat(parts: list["DeviceEvents"]) -> "DeviceEvents":
        """One chunk from many steps, still on the device (``concat_arrays`` per column)."""
        parts = [q for q in parts if q.count]
        if len(parts) <= 1:
            return parts[0] if parts else empty()
        cols = [concat_arrays([getattr(q, k) for q in parts], type(getattr(parts[0], k))) for k in ("xy", "t", "p")]
        dr.eval(*cols)
        return DeviceEvents(*cols, count=sum(q.count for q in parts))

    @staticmethod
    def host_columns(parts: list["DeviceEvents"]):
        """The parts joined on the host: (x, y, t, p) NumPy arrays, each one copy of the parts' views (on the
        CPU this skips the device-side join, a copy the host would repeat)."""
        cols = [q.numpy() for q in parts if q.count] or [empty().numpy()]
        return tuple(np.concatenate([c[i] for c in cols]) for i in range(4))


MAX_WIDTH, MAX_HEIGHT = 1 << 16, 1 << 15     # x in 16 bits, y in 15: pack_xy, and the fill keeps bit 31 for ON


def film_limit_error(width: int, height: int) -> str | None:
    """Why a film is too large for device events (None when it fits)."""
    if width > MAX_WIDTH or height > MAX_HEIGHT:
        return f"{width}x{height} pixels: events hold at most {MAX_WIDTH} x {MAX_HEIGHT} (x and y share a word)"
    return None


def pack_xy(x, y):
    """x | y << 16: the ``DeviceEvents.xy`` word (x < 65536; y < 32768, as the fill keeps bit 31 for ON)."""
    return x | (y << 16)


def event_word(xy, on):
    """The fill's event word: ``pack_xy``'s x | y << 16 with bit 31 set for an ON event."""
    return xy | dr.select(on, mi.UInt32(1 << 31), mi.UInt32(0))


def polarity(on):
    """Int8 +1 where ``on``, -1 elsewhere: the ``DeviceEvents.p`` column."""
    i8 = int8_array()
    return dr.select(on, i8(1), i8(-1))


def concat_arrays(arrays: list, cls):
    """The arrays one after the other in one ``cls`` array, each scattered at an opaque offset: one cached
    kernel whatever the sizes (``dr.concat`` bakes each offset into a new kernel)."""
    arrays = [cls(a) for a in arrays if dr.width(a)]
    if len(arrays) <= 1:
        return arrays[0] if arrays else cls()
    out, start = dr.empty(cls, sum(dr.width(a) for a in arrays)), 0
    for a in arrays:
        dr.scatter(out, a, dr.arange(mi.UInt32, dr.width(a)) + _opaque(start, mi.UInt32))
        start += dr.width(a)
    return out


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


def int8_array():
    """The ``DeviceEvents.p`` column's type (Int8 of the active backend)."""
    return dr.int8_array_t(mi.Int32)


def empty_columns():
    return mi.UInt32(), mi.Int64(), int8_array()()


def empty() -> DeviceEvents:
    return DeviceEvents(*empty_columns(), count=0)


def device_copy(values, cls):
    """NumPy ``values`` as a ``cls`` array in Dr.Jit's own memory. An array made from NumPy memory is read with
    alignment 1, so a kernel reading it is another variant (another compile) of the kernel that reads the same
    state computed on the device; a copy by a scatter kernel is aligned (``dr.gather`` by ``arange`` and
    ``dr.copy`` are folded back to the NumPy memory)."""
    src = cls(values)
    out = dr.empty(cls, dr.width(src))
    dr.scatter(out, src, dr.arange(mi.UInt32, dr.width(src)))
    dr.eval(out)
    return out


def _opaque(value, cls):
    v = cls(value)
    dr.make_opaque(v)       # a literal per step would be baked into the kernel and recompile it every step
    return v


# bits a counting-sort pass takes at most. LLVM: 20 (block_mkperm over 10.5 M keys, 2 threads: 5.2 ms for 2^11
# buckets, 8.5 for 2^16, 15 for 2^20, 110 for 2^22). CUDA: 8, for stability: Dr.Jit's CUDA block_mkperm is
# stable only while a histogram per warp fits in shared memory (2^8 buckets: 32 KiB; 2^11: 256 KiB, beyond any
# GPU), and an LSD radix sort needs every pass stable (docs/design.md, "The time sort on CUDA").
PASS_BITS = {"llvm": 20, "cuda": 8}
SMALL_SORT, SMALL_SORT_BITS = 65_536, 11     # fewer keys than SMALL_SORT on the CPU: 11-bit passes (design.md)


def stable_order(key, key_bound: int):
    """Stable sorting permutation of UInt32 ``key`` whose values are all below ``key_bound``: a least-
    significant-digit radix sort with only the passes that bound needs, of equal width up to ``PASS_BITS``
    (fixed shifts and masks for a bound's bit count: the same cached kernels whatever the chunk's length), where
    ``dr.argsort`` on 32 bits always makes three (LLVM) or four (CUDA)."""
    n = dr.width(key)
    bits = max(1, int(key_bound).bit_length())
    cuda = dr.backend_v(key) == dr.JitBackend.CUDA
    width = PASS_BITS["cuda"] if cuda else SMALL_SORT_BITS if n < SMALL_SORT else PASS_BITS["llvm"]
    if bits <= width:                        # one pass: the key is its own digit
        return dr.detail.block_mkperm(key, n, 1 << bits)
    width = -(-bits // -(-bits // width))    # as few passes, of equal width: 2 x 11 bits for 22, not 20 + 2
    index = dr.arange(mi.UInt32, n)
    for shift in range(0, bits, width):
        digit = (key >> shift) & ((1 << width) - 1)
        dr.eval(digit)
        perm = dr.detail.block_mkperm(digit, n, 1 << width)
        key, index = dr.gather(mi.UInt32, key, perm), dr.gather(mi.UInt32, index, perm)
    return index


def _read(values, cls=None) -> list:
    """Up to eight device scalars as Python ints (always eight: zeros past ``values``), in one array of ``cls``
    (default UInt32): one device-to-host copy (the chunk's only sync), made by one kernel selecting among the
    scalars (a scatter each and a memset took 11 launches a read, not 7: 28 against 20 us on the CPU)."""
    cls = cls or mi.UInt32
    index, packed = dr.arange(mi.UInt32, 8), dr.zeros(cls, 8)
    for i, v in enumerate(values):
        packed = dr.select(index == i, cls(v), packed)
    return [int(v) for v in packed.numpy()]


def approximate_sum(counts):
    """Counts summed in Float32, capped at 4e9: no wrap past 2^32, for ``event_memory.check_event_count``."""
    return mi.UInt32(dr.minimum(dr.sum(mi.Float32(counts)), 4.0e9))


def crossing_events(n, log_prev, log_now, log_ref, c_on, c_off, width: int, t0: float, t1: float,
                    base_us: int = 0, resolution_us: float = 0.0, refractory: Refractory | None = None,
                    noise=None) -> DeviceEvents:
    """The step's events from its dense per-pixel arrays (all of the film's length, already evaluated):
    ``n`` signed crossing counts (Int32), brightness at t0 and t1, the reference level and the thresholds.
    ``refractory``: drop crossings closer than its period to the pixel's previous event (updates its
    ``last_emit``). ``noise``: (hit Bool, u_pol, u_t) shot-noise draws, at most one event a pixel, placed after
    the crossings and subject to the same refractory rule. Timestamps are ``rint((t0 + frac (t1 - t0)) 1e6) +
    base_us`` microseconds, floored to ``resolution_us`` when it is > 0 (the sensor clock). Returns the
    time-sorted events, still on the device, with the step's refractory drops and noise events counted."""
    n_pix = dr.width(n)
    t0_d, t1_d = _opaque(t0, mi.Float64), _opaque(t1, mi.Float64)
    period = _opaque(refractory.period, mi.Float64) if refractory is not None else None
    sel = select_events(n, log_prev, log_now, log_ref, c_on, c_off, t0_d, t1_d,
                        refractory.last_emit if refractory is not None else None, period, noise)
    kept, hit = sel.kept, sel.hit
    if refractory is not None or hit is not None:   # one kernel for the plan; lazy, every use would redo it
        dr.eval(*[v for v in (kept, sel.first, sel.stride, hit, sel.noise_t, sel.last_emit) if v is not None])
    # one lane a pixel: its kept crossings, then its noise event (inclusive scan: slot ends); the guard counts these
    kept_events = kept + mi.UInt32(hit) if hit is not None else kept
    ends = dr.prefix_reduce(dr.ReduceOp.Add, kept_events, exclusive=False)
    totals = [dr.gather(mi.UInt32, ends, n_pix - 1), dr.sum(mi.UInt32(dr.abs(n))), approximate_sum(kept_events)] + \
        ([dr.sum(mi.UInt32(hit)), dr.sum(mi.UInt32(noise[0]))] if hit is not None else [])
    if refractory is not None:
        refractory.last_emit = sel.last_emit
    total, raw, approx, noise_kept, noise_hits = _read(totals)[:5]
    event_memory.check_event_count(approx, t0, t1, n_pix)       # before its 32-bit sums are trusted
    stats = dict(refractory_dropped=raw + noise_hits - total, noise_events=noise_kept)
    if total == 0:
        return DeviceEvents(*empty_columns(), count=0, **stats)
    if not noise_kept:        # no noise event this step: the lanes hold crossings only (no masked noise write)
        sel = replace(sel, hit=None)
    crossings = Crossings(n, sel, log_prev, log_now, log_ref, c_on, c_off, np.array([t0, t1]), width, n_pix)
    return fill(crossings, ends, total, base_us, resolution_us, stats)


@dataclass
class Crossings:
    """One step's events for :func:`fill`, one lane a pixel: the signed crossing count ``n`` (Int32) and the
    step's ``sel`` (``event_select.Selection``: the kept crossings, their ranks under a refractory period, the
    noise event), the log brightness ``before`` and ``after`` the step and the reference level ``ref`` it
    compared against (Float), per pixel the thresholds it used, the step's boundaries (t0, t1 seconds), the
    film width and pixel count. Any object with ``times``, ``width``, ``n_pix`` and this ``write`` can be
    filled (``event_batch`` recomputes a chunk's crossings instead of storing them)."""
    n: object
    sel: Selection
    before: object
    after: object
    ref: object
    c_on: object
    c_off: object
    times: np.ndarray
    width: int
    n_pix: int

    def write(self, ends, slots: "Slots") -> None:
        """The lanes into their slots (``ends``: inclusive prefix sum of each lane's events; ``slots``:
        :func:`fill`'s slots)."""
        t0, t1 = (_opaque(float(t), mi.Float64) for t in self.times)
        xy = pixel_xy(dr.arange(mi.UInt32, self.n_pix), self.width)
        write_lane(self.n, self.sel, ends, self.before, self.after, self.ref, self.c_on, self.c_off, t0, t1, xy,
                   slots.put)


def write_lane(n, sel: Selection, end, before, after, ref, c_on, c_off, t0, t1, xy, put) -> None:
    """One step of every lane into the slots that end at ``end`` (its inclusive prefix sum): the ``sel.kept``
    crossings first (:func:`write_crossings`), then the noise event where ``sel.hit``, the slot order of every
    device path (the per-step fill's and ``event_batch``'s chunk writer: this is their one lane writer)."""
    noise = mi.UInt32(sel.hit) if sel.hit is not None else 0
    write_crossings(n, sel.kept, end - sel.kept - noise, before, after, ref, c_on, c_off, t0, t1, xy, put,
                    sel.first, sel.stride)
    if sel.hit is not None:
        put(end - 1, sel.noise_t, event_word(xy, sel.noise_on), sel.hit)


def write_crossings(n, kept, start, before, after, ref, c_on, c_off, t0, t1, xy, put, first=None,
                    stride=None) -> None:
    """One step of every lane: its ``kept`` crossings (signed count ``n``, on the segment ``before`` ->
    ``after`` from level ``ref`` between ``t0`` and ``t1`` seconds) into slots ``start``, ``start + 1``, ...
    through ``put(slot, t, xy | ON << 31)`` (:func:`fill`'s slot writer). Ranks ``first + j stride`` for a
    refractory pixel, else j. A symbolic loop over each lane's crossings (inside a caller's loop: one kernel)."""
    on = n > 0
    sign = dr.select(on, mi.Int32(1), mi.Int32(-1))
    word = event_word(xy, on)
    step = dr.select(on, mi.Float64(c_on), mi.Float64(c_off))
    segment = (lp := mi.Float64(before), inverse_rise(lp, mi.Float64(after)), mi.Float64(ref), step, t0, t1)
    ranked = first is not None

    def crossing_body(j):
        # j = 0 is the first kept rank itself: a lone kept crossing may have an infinite stride (0 x inf)
        rank = dr.select(j == 0, first, first + mi.Float64(j) * stride) if ranked else mi.Float64(j)
        t_s = crossing_time(mi.Int64(rank) + 1, sign, *segment)
        put(start + j, t_s, word)
        return (j + 1,)

    dr.while_loop((dr.zeros(mi.UInt32, dr.width(xy)),), lambda j: j < kept, crossing_body)


@dataclass
class Slots:
    """The event slots :func:`fill` sizes and a crossing writer fills: per slot the sort key (microseconds from
    ``start``, the chunk's first microsecond minus one, with ``base`` added: Int64 opaque scalars) and the
    event word x | y << 16 | ON << 31, both in one UInt64 ``key`` (key above) when the key fits 32 bits, else
    ``key`` (UInt64) and ``word`` (UInt32) apart. Arrays only, so that a frozen writer takes them as
    arguments (``event_batch``); :meth:`put` is the one slot writer."""
    key: object
    word: object
    base: object
    start: object

    @staticmethod
    def allocate(count: int, packed: bool, base, start) -> "Slots":
        """Slots for ``count`` events (allocated when first written), key and word in one array if ``packed``."""
        return Slots(dr.empty(mi.UInt64, count), None if packed else dr.empty(mi.UInt32, count), base, start)

    @property
    def packed(self) -> bool:
        return self.word is None

    def put(self, slot, t_s, word, active=True) -> None:
        """Event ``word`` at ``t_s`` seconds into ``slot`` (where ``active``)."""
        key = mi.Int64(dr.round(t_s * 1e6)) + self.base - self.start
        if self.packed:
            dr.scatter(self.key, (mi.UInt64(mi.UInt32(key)) << 32) | mi.UInt64(word), slot, active)
        else:
            dr.scatter(self.key, mi.UInt64(key), slot, active)
            dr.scatter(self.word, word, slot, active)


def pixel_xy(pixel, width: int):
    """``pack_xy`` of pixel indices (row-major, ``width`` pixels a row): no division per event."""
    w_d = _opaque(width, mi.UInt32)
    y = pixel // w_d
    return pack_xy(pixel - y * w_d, y)


def fill(cr: Crossings, ends, total: int, base_us: int = 0, resolution_us: float = 0.0,
         stats: dict | None = None) -> DeviceEvents:
    """The events of ``cr`` (``ends``: each lane's slot end, its crossings then its noise event; ``total``:
    every event), time-sorted, with timestamps ``rint(t 1e6) + base_us`` microseconds floored to the sensor
    clock ``resolution_us`` when > 0. ``cr.write`` has one lane a pixel write its own events into its slot range (the fill of esim_torch's
    count / prefix-sum / fill) through :class:`Slots`, two words an event: the sort key (microseconds from the
    chunk's first one) and x | y << 16 | ON << 31, so no event searches for its pixel or divides by the width,
    and the sort moves 8 bytes an event. The two words share one 64-bit slot
    (key above): one scatter an event in the fill and one gather after the sort, where two 32-bit arrays took
    two of each (dense 2 kHz converter stack, 346x260: the fill kernel 0.39 -> 0.34 ms a frame, the gather
    0.10 -> 0.09); a 64-bit key (time-lapse spans) keeps two arrays. A pixel's noise event takes the slot
    after its own crossings (:func:`write_lane`: one lane a pixel, one scan for both), so equal times keep
    (pixel, crossing rank, then noise) order."""
    count = total
    if count == 0:
        return DeviceEvents(*empty_columns(), count=0, **(stats or {}))
    start_us = int(math.floor(cr.times[0] * 1e6)) + int(base_us) - 1
    # the key is microseconds from the chunk's first (minus one), so its range is the chunk's length, known
    # here without asking the device
    key_bound = int(math.ceil((cr.times[-1] - cr.times[0]) * 1e6)) + 3
    # a span of 2^32 us (71.6 minutes: time-lapse frames) does not fit the 32-bit key: 64 bits, Dr.Jit's sort
    packed = key_bound < 1 << 32
    # the arrays are made where they are first written (a writer may replace them with longer ones of its own:
    # event_batch's frozen pass; only the first ``count`` slots are read)
    slots = Slots.allocate(count, packed, _opaque(base_us, mi.Int64), _opaque(start_us, mi.Int64))
    cr.write(ends, slots)
    if packed:
        keys = mi.UInt32(_first(slots.key, count, mi.UInt64) >> 32)
        dr.eval(keys)
        both = dr.gather(mi.UInt64, slots.key, stable_order(keys, key_bound))
        key, word = mi.UInt32(both >> 32), mi.UInt32(both & 0xFFFFFFFF)
        t_us = mi.Int64(key) + slots.start
    else:
        first_key = _first(slots.key, count, mi.UInt64)
        dr.eval(first_key)
        order = dr.argsort(first_key)        # stable, as stable_order
        key, word = dr.gather(mi.UInt64, first_key, order), dr.gather(mi.UInt32, slots.word, order)
        t_us = mi.Int64(key) + slots.start
    if resolution_us:              # the sensor clock, after ordering by true time (as the host's readout)
        res = _opaque(resolution_us, mi.Float64)
        t_us = mi.Int64(dr.floor(mi.Float64(t_us) / res) * res)
    xy, p = word & 0x7FFFFFFF, polarity((word >> 31) != 0)
    dr.eval(xy, t_us, p)
    return DeviceEvents(xy, t_us, p, count=count, **(stats or {}))


def slot_capacity(count: int) -> int:
    """Slots to allocate for ``count`` events where the length is baked into a recording (``event_batch``'s
    frozen write pass): ``count`` rounded up to a multiple of a quarter of the power of two above it (at most
    half as much again as the events, and a few lengths, so few recordings, for chunks of similar counts)."""
    quarter = max(1, 1 << max(0, int(count - 1).bit_length() - 2))
    return max(1024, -(-int(count) // quarter) * quarter)


def _first(array, count: int, cls):
    """The first ``count`` entries of ``array`` (itself where it holds no more)."""
    if dr.width(array) == count:
        return array
    return dr.gather(cls, array, dr.arange(mi.UInt32, count))
