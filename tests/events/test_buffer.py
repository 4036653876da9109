"""EventBuffer: the in-memory result's columns, appended chunk by chunk (events/buffer.py)."""
import numpy as np
import pytest

from mitsuba_eventfield.events import buffer as buffer_mod
from mitsuba_eventfield.events.buffer import EventBuffer


def _chunks(rng, sizes):
    t0 = 0
    for n in sizes:
        t = t0 + np.sort(rng.integers(0, 1000, n)).astype(np.int64)
        t0 = int(t[-1]) if n else t0
        yield (rng.integers(0, 346, n).astype(np.uint16), rng.integers(0, 260, n).astype(np.uint16), t,
               rng.choice(np.array([-1, 1], np.int8), n))


@pytest.mark.parametrize("capacity", [None, 1, 7, 1000])
def test_chunks_in_equal_their_join_out(capacity):
    """Whatever the reservation (past it the columns grow), the columns taken are the chunks joined, with their
    dtypes; the buffer is empty afterwards."""
    chunks = list(_chunks(np.random.default_rng(3), [5, 0, 40, 1, 300, 17]))
    buf = EventBuffer(capacity)
    for c in chunks:
        buf.append(*c)
    assert len(buf) == 363 and buf.capacity >= 363
    cols = buf.take()
    for i, dtype in enumerate((np.uint16, np.uint16, np.int64, np.int8)):
        assert cols[i].dtype == dtype and cols[i].flags["OWNDATA"] and cols[i].flags["C_CONTIGUOUS"]
        np.testing.assert_array_equal(cols[i], np.concatenate([c[i] for c in chunks]))
    assert len(buf) == 0 and [len(c) for c in buf.take()] == [0, 0, 0, 0]


def test_reservation_halves_until_granted(monkeypatch):
    """Under strict overcommit a large np.empty raises MemoryError: the reservation halves until it is granted
    (never below MIN_RESERVE, where the error is the system's)."""
    real_empty = np.empty
    limit = 5 * buffer_mod.MIN_RESERVE

    def empty(n, dtype):
        if n > limit:
            raise MemoryError(f"cannot allocate {n}")
        return real_empty(n, dtype)
    monkeypatch.setattr(buffer_mod.np, "empty", empty)
    buf = EventBuffer(64 * buffer_mod.MIN_RESERVE)
    assert buf.capacity == 4 * buffer_mod.MIN_RESERVE
    limit = 0
    with pytest.raises(MemoryError):
        EventBuffer(4 * buffer_mod.MIN_RESERVE)


def test_default_reservation_follows_available_memory(monkeypatch):
    monkeypatch.setattr(buffer_mod, "available_memory", lambda: 26 * 10**9)
    assert buffer_mod.reserve_events() == 10**9          # half of it, 13 bytes an event
    monkeypatch.setattr(buffer_mod, "available_memory", lambda: 1000)
    assert buffer_mod.reserve_events() == buffer_mod.MIN_RESERVE
