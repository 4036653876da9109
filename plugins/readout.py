"""The sensor's readout cap: events dropped at random so that no 1 ms window holds more than the cap, applied to
each step's time-sorted events on the host (NumPy, :meth:`ReadoutLimiter.filter`) or on the device (Dr.Jit,
:meth:`ReadoutLimiter.filter_device`, one step or a batch of steps at once, so that a capped pixel model's
events never leave the device a step at a time): the same drops, bit for bit.

Time is cut into bins of 1/9 ms, each allowed 1/10 of the 1 ms budget: any 1 ms window overlaps at most 10 bins,
so the cap holds for every window (saturated throughput is 90 % of the cap). Within an overfull bin the
survivors are the events with the smallest random keys (24 bits; ties: time order), a uniformly random
subset; state carries across steps (a bin may span two steps: the events kept of it in the
earlier step count against it).

The keys are a counter-based hash of (seed, step, the event's index in the step), not a generator's stream, so
that host and device draw the same keys without exchanging any; a step with no overfull bin draws none (and on
the device costs one read of four numbers a batch). Until 2026-11 the host drew them from NumPy's generator: the kept
subsets differ from that version's for the same seed, with the same statistics.
"""
from __future__ import annotations

import numpy as np

from mitsuba_eventfield.plugins import counter_rng

READOUT_BINS_PER_MS = 9

# bits of the random key that order an overfull bin's events: equal keys keep time order, and among 100,000
# events of one bin a few hundred pairs tie at 24 bits (a tie matters only where it straddles the bin's cut);
# with the bin above them, steps of up to 256 bins (28 ms) sort one 32-bit word on the device
KEY_BITS = 24


def step_word(seed: int, step: int) -> int:
    """The 32-bit word that, with an event's index, keys the draws of one step: step ``step`` of the seed's
    ``READOUT`` stream (unrelated to the pixel model's streams)."""
    readout = counter_rng.stream_word(counter_rng.seed_word(seed), counter_rng.READOUT)
    return counter_rng.stream_word(readout, step) & counter_rng.MASK


def keys_np(n: int, word: int) -> np.ndarray:
    """The ``n`` events' keys (uint32) of a step with ``step_word`` ``word`` (``counter_rng.mixed``)."""
    return counter_rng.mixed_np(np.arange(n, dtype=np.uint32), word)


def keys_dr(mi, index, word):
    """:func:`keys_np` on the device for the events numbered ``index`` (UInt32) within their step, whose
    ``step_word`` is ``word`` (one, or one an event); UInt32 arithmetic wraps as NumPy's uint32 does."""
    return counter_rng.mixed(index, word)


class ReadoutLimiter:
    """The readout cap of one sensor: its budget per bin and its state across steps (the open bin, the events
    kept of it, the steps seen, the events dropped)."""

    def __init__(self, cap_ev_s: float, seed: int = 0):
        self.bin_us = 1000.0 / READOUT_BINS_PER_MS
        self.budget = int(cap_ev_s * 1e-3 / (READOUT_BINS_PER_MS + 1))
        self.seed = int(seed)
        self.open_bin, self.used = -1, 0
        self.steps = 0
        self.dropped = 0

    def state(self) -> dict:
        return {"open_bin": self.open_bin, "used": self.used, "steps": self.steps, "dropped": self.dropped}

    def set_state(self, saved: dict) -> None:
        self.open_bin, self.used, self.steps, self.dropped = (int(saved[k]) for k in ("open_bin", "used", "steps",
                                                                                     "dropped"))

    def _next_word(self) -> int:
        self.steps += 1
        return step_word(self.seed, self.steps)

    def _carry(self, first: int) -> int:
        """Events already kept of the step's first bin (when an earlier step left it open)."""
        return self.used if first == self.open_bin else 0

    def _close(self, first: int, last_rel: int, last_count: int) -> None:
        """After a step: its last bin is the open one, holding ``last_count`` kept events (the carry included)."""
        self.used, self.open_bin = last_count, first + last_rel

    def filter(self, t_us: np.ndarray) -> np.ndarray:
        """Keep mask (bool) for one step's time-sorted timestamps (int64 us)."""
        word = self._next_word()
        if len(t_us) == 0:
            return np.zeros(0, bool)
        b = np.floor(t_us / self.bin_us).astype(np.int64)
        first = int(b[0])
        counts = np.bincount(b - first)
        carry = self._carry(first)
        counts[0] += carry
        last = len(counts) - 1
        if counts.max() <= self.budget:                  # nothing overflows: keep all, no key needed
            self._close(first, last, int(counts[last]))
            return np.ones(len(t_us), bool)
        order = np.lexsort((keys_np(len(t_us), word) >> (32 - KEY_BITS), b))   # bin, key, time order
        b_s = b[order]
        start = np.r_[0, np.nonzero(np.diff(b_s))[0] + 1]
        rank = np.arange(len(b_s)) - np.repeat(start, np.diff(np.r_[start, len(b_s)]))
        rank = rank + np.where(b_s == self.open_bin, self.used, 0)   # budget already used in a carried bin
        keep = np.zeros(len(t_us), bool)
        keep[order] = rank < self.budget
        self._close(first, last, int(np.count_nonzero(keep[order][b_s == first + last])) +
                    (carry if last == 0 else 0))
        self.dropped += int(len(t_us) - keep.sum())
        return keep

    def _kept_in_last(self, last_count: int, last_rel: int, carry: int) -> int:
        """Kept events of the step's last bin, with the carry (``last_count`` holds it where that bin is the
        first): the first ``budget`` ranks of a bin survive, the carry's among them."""
        carried = carry if last_rel == 0 else 0
        return min(last_count - carried, max(self.budget - carried, 0)) + carried

    def filter_device(self, events, step_counts, t0: float, t1: float, resolution_us: float = 0.0):
        """:meth:`filter` on the ``event_fill.DeviceEvents`` of ``len(step_counts)`` consecutive steps between
        ``t0`` and ``t1`` seconds (their clock ``resolution_us``), on the device: time-sorted, each step's
        ``step_counts[s]`` events contiguous and in order (a chunk of ``event_batch``, or one step). Returns
        the kept events, time order kept, as ``DeviceEvents``: those :meth:`filter` keeps step by step.

        Why one pass serves many steps: an event of step ``s`` in bin ``b`` survives when its rank among
        step ``s``'s events of ``b`` (ordered by key, then time) plus what earlier steps kept of ``b`` is below
        the budget, and earlier steps kept ``min(budget, carry + their events of b)``. Ranking every event of
        ``b`` over the chunk ordered by (step, key, time), after the bin's carry, keeps the same events: an
        event ranked past the budget there is past it step by step too, and below it the two ranks agree."""
        import drjit as dr
        import mitsuba as mi
        from mitsuba_eventfield.plugins import event_fill
        words = [self._next_word() for _ in step_counts]     # every step draws its word, empty ones too
        n = events.count
        if n == 0:
            return events
        # an opaque divisor: Dr.Jit turns a division by a literal into a product with its reciprocal, which
        # moved 92 of 200,000 integer timestamps to the neighbouring bin
        b = mi.Int64(dr.floor(mi.Float64(events.t) / event_fill._opaque(self.bin_us, mi.Float64)))
        first_d = dr.gather(mi.Int64, b, mi.UInt32(0))
        rel = mi.UInt32(b - first_d)
        bins = int(((t1 - t0) * 1e6 + resolution_us + 2) / self.bin_us) + 4    # a bound on the steps' bins
        counts = dr.zeros(mi.UInt32, bins)
        dr.scatter_reduce(dr.ReduceOp.Add, counts, mi.UInt32(1), rel, rel < bins)     # never out of bounds
        last_rel_d = dr.gather(mi.UInt32, rel, mi.UInt32(n - 1))
        open_d, used_d = event_fill._opaque(self.open_bin, mi.Int64), event_fill._opaque(self.used, mi.UInt32)
        carry_d = dr.select(first_d == open_d, used_d, 0)
        counts0 = counts + dr.select(dr.arange(mi.UInt32, bins) == 0, carry_d, 0)
        head = event_fill._read([dr.max(counts0), first_d, last_rel_d, dr.gather(mi.UInt32, counts0, last_rel_d)],
                                mi.Int64)
        most, first, last_rel, last_count = head[:4]
        if last_rel >= bins:
            raise ValueError(f"readout: events span {last_rel + 1} bins, more than their steps ({t0} s, {t1} s) "
                             f"allow ({bins})")
        carry = self._carry(first)
        if most <= self.budget:
            self._close(first, last_rel, last_count)
            return events
        kept, keep, ends = self._keep_device(rel, counts, carry_d, last_rel, step_counts, words, n)
        self._close(first, last_rel, self._kept_in_last(last_count, last_rel, carry))
        self.dropped += n - kept
        stats = dict(refractory_dropped=events.refractory_dropped, noise_events=events.noise_events)
        if kept == 0:
            return event_fill.DeviceEvents(*event_fill.empty_columns(), count=0, **stats)
        slot, mask = ends - 1, keep != 0
        cols = []
        for col in (events.xy, events.t, events.p):
            out = dr.empty(type(col), kept)
            dr.scatter(out, col, slot, mask)
            cols.append(out)
        dr.eval(*cols)
        return event_fill.DeviceEvents(*cols, count=kept, **stats)

    def _keep_device(self, rel, counts, carry_d, last_rel: int, step_counts, words, n: int):
        """(kept count, keep flags, their inclusive prefix sum) of steps with an overfull bin: their events
        ordered by (bin, step, key, time), the first ``budget`` ranks of each bin kept (the carry counted in
        bin 0). (bin, step) never decreases along time-sorted events, so each distinct pair is a group
        numbered in time order, and a stable sort by key, then by group, gives that order."""
        import drjit as dr
        import mitsuba as mi
        from mitsuba_eventfield.plugins import event_fill
        step_counts = np.asarray(step_counts, np.int64)
        index = dr.arange(mi.UInt32, n)
        if len(step_counts) == 1:
            step, in_step = None, index
            word = event_fill._opaque(words[0], mi.UInt32)
            group, groups = rel, last_rel + 1
        else:
            starts = np.r_[0, np.cumsum(step_counts)[:-1]]
            # each event's step: +1 at every later step's first slot (empty steps share it), summed
            marks = dr.zeros(mi.UInt32, n)
            later = starts[1:][starts[1:] < n]
            if len(later):
                dr.scatter_reduce(dr.ReduceOp.Add, marks, mi.UInt32(1), mi.UInt32(later.astype(np.uint32)))
            step = dr.prefix_reduce(dr.ReduceOp.Add, marks, exclusive=False)
            in_step = index - dr.gather(mi.UInt32, mi.UInt32(starts.astype(np.uint32)), step)
            word = dr.gather(mi.UInt32, mi.UInt32(np.asarray(words, np.uint32)), step)
            previous = index - 1
            changed = (index > 0) & ((rel != dr.gather(mi.UInt32, rel, previous, index > 0))
                                     | (step != dr.gather(mi.UInt32, step, previous, index > 0)))
            group = dr.prefix_reduce(dr.ReduceOp.Add, mi.UInt32(changed), exclusive=False)
            groups = last_rel + len(step_counts)     # a bound: each step after the first opens one more at most
        key = keys_dr(mi, in_step, word) >> (32 - KEY_BITS)
        if groups <= 1 << (32 - KEY_BITS):      # group above key in one word: one sort (two passes on the CPU)
            combined = (group << KEY_BITS) | key
            dr.eval(combined)
            order = event_fill.stable_order(combined, (groups << KEY_BITS) - 1)     # group, key, time
        else:                                    # many groups: by key, then stably by group
            dr.eval(key, group)
            by_key = event_fill.stable_order(key, (1 << KEY_BITS) - 1)
            order = dr.gather(mi.UInt32, by_key,
                              event_fill.stable_order(dr.gather(mi.UInt32, group, by_key), groups))
        b_s = dr.gather(mi.UInt32, rel, order)
        start = dr.prefix_reduce(dr.ReduceOp.Add, counts, exclusive=True)
        rank = index - dr.gather(mi.UInt32, start, b_s) + dr.select(b_s == 0, carry_d, 0)
        keep = dr.zeros(mi.UInt32, n)
        dr.scatter(keep, mi.UInt32(rank < self.budget), order)
        ends = dr.prefix_reduce(dr.ReduceOp.Add, keep, exclusive=False)
        return event_fill._read([dr.gather(mi.UInt32, ends, mi.UInt32(n - 1))])[0], keep, ends
