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
"""
from __future__ import annotations

import numpy as np

from ..validate import available_memory

COLUMNS = (("x", np.uint16), ("y", np.uint16), ("t", np.int64), ("p", np.int8))
BYTES_PER_EVENT = sum(np.dtype(d).itemsize for _, d in COLUMNS)      # 13
RESERVE_SHARE = 0.5        # of the available memory, reserved (not touched) for the columns
MIN_RESERVE = 1 << 16


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
        self.count = 0

    def __len__(self) -> int:
        return self.count

    @property
    def capacity(self) -> int:
        return len(self._cols[0])

    def append(self, x, y, t, p) -> None:
        """Copy one chunk's columns in after the events already held."""
        end = self.count + len(t)
        if end > self.capacity:
            grown = max(end, 2 * self.capacity)
            for col in self._cols:         # the buffer owns its columns and has handed out no view of them
                col.resize(grown, refcheck=False)
        for col, values in zip(self._cols, (x, y, t, p)):
            col[self.count:end] = values
        self.count = end

    def take(self) -> tuple:
        """(x, y, t, p) trimmed to the events held; the buffer is empty afterwards."""
        cols, self._cols = self._cols, [np.empty(0, dtype) for _, dtype in COLUMNS]
        for col in cols:
            col.resize(self.count, refcheck=False)
        self.count = 0
        return tuple(cols)
