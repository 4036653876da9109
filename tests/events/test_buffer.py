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


@pytest.mark.parametrize("cores", [1, 2, 3, 16])
def test_large_chunks_copied_in_parts_equal_their_join(monkeypatch, cores):
    """A chunk at or above SPLIT_COPY_MIN is copied in parts by several threads (as many as the usable cores,
    at most COPY_THREADS): every part lands where one copy would put it, whatever the part count, chunk length
    (not a multiple of the parts) and offset; on one core there is no pool."""
    monkeypatch.setattr(buffer_mod, "SPLIT_COPY_MIN", 64)
    monkeypatch.setattr(buffer_mod, "usable_cores", lambda: cores)
    monkeypatch.setattr(buffer_mod, "_pool", None)
    chunks = list(_chunks(np.random.default_rng(5), [63, 64, 1001, 0, 97, 4099]))
    buf = EventBuffer(3000)
    for c in chunks:
        buf.append(*c)
    cols = buf.take()
    for i in range(4):
        np.testing.assert_array_equal(cols[i], np.concatenate([c[i] for c in chunks]))
    if cores == 1:
        assert buffer_mod._pool is None
    else:
        assert buffer_mod._pool[1] == min(cores, buffer_mod.COPY_THREADS) - 1


def test_strided_chunk_columns_copied_in_parts(monkeypatch):
    """x and y arrive as strided halves of one 32-bit word (DeviceEvents.numpy): split copies read them right."""
    monkeypatch.setattr(buffer_mod, "SPLIT_COPY_MIN", 8)
    monkeypatch.setattr(buffer_mod, "usable_cores", lambda: 4)
    monkeypatch.setattr(buffer_mod, "_pool", None)
    xy = np.arange(1000, dtype=np.uint32) | (np.arange(1000, dtype=np.uint32) % 7) << 16
    halves = xy.view(np.uint16)
    buf = EventBuffer(10)
    buf.append(halves[0::2], halves[1::2], np.arange(1000, dtype=np.int64), np.ones(1000, np.int8))
    x, y, t, p = buf.take()
    np.testing.assert_array_equal(x, np.arange(1000) & 0xFFFF)
    np.testing.assert_array_equal(y, np.arange(1000) % 7)
    np.testing.assert_array_equal(t, np.arange(1000))


def test_a_chunk_the_memory_left_cannot_take_is_refused_in_one_line(monkeypatch):
    """A render into memory grew until the system killed the process (a review: OOM at 24 GB): a chunk that
    the memory left (less ``MEMORY_LEFT``) cannot take is refused, naming what is held and what to do."""
    from mitsuba_eventfield.errors import EventFieldError
    from mitsuba_eventfield.events import buffer
    monkeypatch.setattr(buffer, "MEMORY_CHECK_BYTES", 1)      # read the memory at every chunk, however small
    buf = buffer.EventBuffer(capacity=16)
    chunk = (np.zeros(1000, np.uint16), np.zeros(1000, np.uint16), np.arange(1000, dtype=np.int64),
             np.ones(1000, np.int8))
    buf.append(*chunk)
    monkeypatch.setattr(buffer, "available_memory", lambda: buffer.MEMORY_LEFT + 999 * buffer.BYTES_PER_EVENT)
    with pytest.raises(EventFieldError, match=r"events in memory: 1000 held \(0.00 GiB\) and no memory left for "
                                              r"1000 more: write them to a file"):
        buf.append(*chunk)
    assert len(buf) == 1000
    monkeypatch.setattr(buffer, "available_memory", lambda: buffer.MEMORY_LEFT + 1000 * buffer.BYTES_PER_EVENT)
    buf.append(*chunk)
    assert len(buf) == 2000
