"""EventBuffer: events appended chunk by chunk into one set of columns, the in-memory result of a render.

Why not keep the chunks and join them at the end: the chunks of a render on the CPU are views of the event
engine's Dr.Jit arrays, so keeping them keeps every step's memory alive. Then each step's kernels write into
memory the process has never touched, and the final join writes everything a second time: the peak is twice the
events, and on the 2-core CI machine first-touched memory cost ~1.8 ms per MB (a 346x260 fan render of 800
steps, 59 M events: 26.0 ms a step, against 24.5 with this buffer, which lets Dr.Jit reuse the chunks' memory).

The columns are reserved (``np.empty``: address space, no memory until written) for ``reserve_events``, sized
from the available memory, so appending never moves them (growing by ``ndarray.resize`` from a small start
copied: the 100-frame converter bench took 0.25 s instead of 0.16); past that they grow by doubling. Where the
system refuses the reservation (strict overcommit) it is halved until it is granted. ``take`` trims the columns
to the events held (a shrinking ``ndarray.resize``: no copy) and hands them over.

A large chunk's copy is split across threads (``COPY_THREADS``; NumPy releases the GIL while it copies). What
it costs is the kernel faulting in and zeroing the columns' fresh pages, which parallelises: writing 30 M
events (390 MB) in 440 k-event chunks into a fresh reservation took 0.36-0.86 s on one thread and 0.06-0.23 s
on two (2-core VM, a new process per run, alternating; docs/design.md, "The in-memory result").
"""
from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..validate import available_memory, usable_cores

COLUMNS = (("x", np.uint16), ("y", np.uint16), ("t", np.int64), ("p", np.int8))
BYTES_PER_EVENT = sum(np.dtype(d).itemsize for _, d in COLUMNS)      # 13
RESERVE_SHARE = 0.5        # of the available memory, reserved (not touched) for the columns
MIN_RESERVE = 1 << 16
SPLIT_COPY_MIN = 1 << 17   # events in a chunk before its copy is split: a smaller one is not worth a hand-off
COPY_THREADS = 4           # at most, the calling thread included (bounded by the usable cores)
MEMORY_LEFT = 256 << 20    # bytes an in-memory result leaves the system when it takes a chunk
MEMORY_CHECK_BYTES = 16 << 20   # event bytes appended between two reads of the memory available

_pool = None
_pool_lock = threading.Lock()


def _forget_pool() -> None:
    """A forked child has none of the parent's threads: its first large copy makes a pool of its own."""
    global _pool, _pool_lock
    _pool, _pool_lock = None, threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pool)


def _copy_pool() -> tuple:
    """(pool, helpers): the threads that copy a part of a large chunk each (None, 0 on one core); made once,
    on first use."""
    global _pool
    helpers = min(COPY_THREADS, usable_cores()) - 1
    if helpers < 1:
        return None, 0
    with _pool_lock:
        if _pool is None:
            _pool = (ThreadPoolExecutor(helpers, thread_name_prefix="event-copy"), helpers)
    return _pool


def copy_into(columns, start: int, chunk) -> None:
    """``chunk``'s columns into ``columns`` from index ``start``, split into contiguous parts that the copy
    pool's threads and the caller write at once when the chunk is large (the same bytes either way)."""
    n = len(chunk[0])
    pool, helpers = _copy_pool() if n >= SPLIT_COPY_MIN else (None, 0)
    parts = helpers + 1

    def part(k):
        lo, hi = n * k // parts, n * (k + 1) // parts
        for col, values in zip(columns, chunk):
            col[start + lo:start + hi] = values[lo:hi]
    running = [pool.submit(part, k) for k in range(1, parts)]
    part(0)
    for r in running:
        r.result()


def reserve_events() -> int:
    """Events the columns are first reserved for: ``RESERVE_SHARE`` of the available memory."""
    return max(MIN_RESERVE, int(RESERVE_SHARE * available_memory()) // BYTES_PER_EVENT)


class EventBuffer:
    """Columns x (uint16), y (uint16), t (int64 us), p (int8) that chunks are appended to in order."""

    def __init__(self, capacity: int | None = None):
        capacity = reserve_events() if capacity is None else max(1, int(capacity))
        while True:
            try:
                self._cols = [np.empty(capacity, dtype) for _, dtype in COLUMNS]
                break
            except MemoryError:
                if capacity <= MIN_RESERVE:
                    raise
                capacity = max(MIN_RESERVE, capacity // 2)
        self.count, self._unchecked = 0, 0

    def __len__(self) -> int:
        return self.count

    @property
    def capacity(self) -> int:
        return len(self._cols[0])

    def append(self, x, y, t, p) -> None:
        """Copy one chunk's columns in after the events already held; refused in one line where the memory left
        cannot take them (a render into memory grew until the system killed it: a file streams them instead)."""
        end = self.count + len(t)
        self._unchecked += len(t) * BYTES_PER_EVENT     # memory read once per MEMORY_CHECK_BYTES, not per step
        if self._unchecked >= MEMORY_CHECK_BYTES and self._unchecked > available_memory() - MEMORY_LEFT:
            from ..errors import EventFieldError
            self._unchecked -= len(t) * BYTES_PER_EVENT      # (not taken)
            held = self.count * BYTES_PER_EVENT / 2**30
            raise EventFieldError(f"events in memory: {self.count} held ({held:.2f} GiB) and no memory left for "
                                  f"{len(t)} more: write them to a file (an output path, -o events.h5), which "
                                  "streams them")
        if self._unchecked >= MEMORY_CHECK_BYTES:
            self._unchecked = 0
        if end > self.capacity:
            grown = max(end, 2 * self.capacity)
            for col in self._cols:         # the buffer owns its columns and has handed out no view of them
                col.resize(grown, refcheck=False)
        copy_into(self._cols, self.count, (x, y, t, p))
        self.count = end

    def take(self) -> tuple:
        """(x, y, t, p) trimmed to the events held; the buffer is empty afterwards."""
        cols, self._cols = self._cols, [np.empty(0, dtype) for _, dtype in COLUMNS]
        for col in cols:
            col.resize(self.count, refcheck=False)
        self.count = 0
        return tuple(cols)
