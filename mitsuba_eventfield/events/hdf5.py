"""Event files in HDF5, the DSEC layout (``io`` has the layout): a writer that streams time-sorted chunks while
rendering, and the reader."""
from __future__ import annotations

import collections
import contextlib
import json
import os
import zlib
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..atomic import check_writable, publish, remove_stale_partials, temporary_name
from ..errors import ConfigError, EventFieldError
from ..validate import number, usable_cores
from .disk import HEADER_BYTES, GuardedFile, _disk_full, _free_bytes, _no_space, check_space
from .stream import MAX_SENSOR, chunk_columns, first_out_of_order

try:    # ISA-L's deflate: a zlib stream like zlib's, 5.8x its speed at level 1 on the fan's events, same size
    from isal import isal_zlib as _isal
except ImportError:     # no python-isal wheel for the platform: zlib (docs/design.md, "HDF5 chunks deflated")
    _isal = None
ISAL_LEVELS = (1, 2, 3)     # the levels ISA-L has (its 0 compresses, zlib's 0 stores): others go to zlib

H5_FORMAT_VERSION = 1
H5_GZIP_LEVEL = 1   # deflate level: 2-4x faster to write than level 4+, within 15% of their size (docs/design.md)
H5_BYTES_PER_EVENT = 13        # x, y uint16 + t int64 + p uint8
H5_COMPRESSIONS = ("gzip", "lzf", None)
MAX_COMPRESSION_THREADS = 64
MS_INDEX_BLOCK = 1 << 22        # ms_to_idx entries (8 bytes each) made at once: 32 MiB


WRITER_THREADS_ENV = "EVENTFIELD_WRITER_THREADS"


def default_compression_threads() -> int:
    """Threads that deflate an HDF5 writer's chunks: ``EVENTFIELD_WRITER_THREADS`` where it is set (0: HDF5's
    own filters on the writing thread; a shared machine's share of the cores), else every core this process
    may run on. On a GPU machine the host's cores are idle while the GPU renders, and HDF5 itself deflates on
    one thread (~13 M events/s, docs/design.md), far below what a GPU makes; on the CPU the render's own
    threads share the cores, and deflating outside HDF5 is cheaper anyway (one thread 1.08x faster than HDF5's
    filters on the fan's events: benchmarks/results/writer.md)."""
    chosen = os.environ.get(WRITER_THREADS_ENV, "").strip()
    if chosen:
        return int(number(chosen, f"environment variable {WRITER_THREADS_ENV}", 0, MAX_COMPRESSION_THREADS,
                          integer=True))
    return min(MAX_COMPRESSION_THREADS, usable_cores())


def _shuffled(values: np.ndarray) -> np.ndarray:
    """HDF5's shuffle filter: every value's first byte, then every second byte, ... (one-byte values as they
    are), so the slowly varying high bytes of coordinates and timestamps sit together for deflate. Returned as
    a contiguous uint8 array, which the deflaters read as a buffer (no ``bytes`` copy; one-byte columns and
    unshuffled chunks as they lie)."""
    contiguous = np.ascontiguousarray(values)
    if values.dtype.itemsize == 1:
        return contiguous.view(np.uint8)
    return np.ascontiguousarray(contiguous.view(np.uint8).reshape(-1, values.dtype.itemsize).T)


def deflate_chunk(values: np.ndarray, level: int, shuffle: bool) -> bytes:
    """One chunk of a column as HDF5's shuffle + deflate filters store it (a zlib stream at ``level``, made by
    ISA-L where it is installed and has that level), for ``write_direct_chunk``: HDF5 and every reader decode
    it with their own filters. Both deflaters release the GIL while they compress (they scale with threads)."""
    data = _shuffled(values) if shuffle else np.ascontiguousarray(values)
    if _isal is not None and level in ISAL_LEVELS:
        return _isal.compress(data, level)
    return zlib.compress(data, level)


def _deflate_columns(columns: dict, level: int, shuffle: bool) -> dict:
    """One chunk of every column (:func:`deflate_chunk` each), as one task of the writer's pool: a task a
    column made four futures a chunk for the writer thread to submit and collect."""
    return {k: deflate_chunk(v, level, shuffle) for k, v in columns.items()}


def _json(meta: dict) -> str:
    return json.dumps(meta, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o), sort_keys=True)


def _check_options(width, height, chunk, compression, level, threads=None) -> None:
    """The writer's arguments, refused (ConfigError naming them) before any file is created."""
    for name, value in (("width", width), ("height", height)):
        number(value, f"event file: {name}", 0, MAX_SENSOR, integer=True, strict=True)
    if threads is not None:
        number(threads, "event file: threads", 0, MAX_COMPRESSION_THREADS, integer=True, strict=True)
    number(chunk, "event file: chunk", 1, 10_000_000, integer=True, strict=True)
    if compression not in H5_COMPRESSIONS:
        raise ConfigError(f"event file: compression = {compression!r}: allowed "
                          + ", ".join(map(repr, H5_COMPRESSIONS)))
    if compression == "gzip" and level is not None:
        number(level, "event file: level", 0, 9, integer=True, strict=True)


class _Joined:
    """The buffered pieces of one column as one array for ``_flush``, copied only up to the first HDF5 chunk
    boundary at or past the end of all but the last piece. A render hands over chunks of many HDF5 chunks
    (millions of events) while a remainder of less than one waits from the last flush: joining them whole
    copied 13 bytes an event on the writer's thread, which sets the pace of a GPU render to HDF5. Slices
    ``[a:b]`` on the chunk grid come from one part without a copy; any other slice is joined."""

    def __init__(self, head: np.ndarray, body: np.ndarray):
        self.head, self.body, self.split = head, body, len(head)

    @classmethod
    def of(cls, pieces: list, chunk: int) -> "_Joined":
        lead = sum(len(piece) for piece in pieces[:-1])
        split = -(-lead // chunk) * chunk                  # the first chunk boundary at or past the lead
        last = pieces[-1]
        if len(pieces) == 1 or split - lead >= len(last):  # one piece, or the last ends before that boundary
            return cls(pieces[0] if len(pieces) == 1 else np.concatenate(pieces), last[:0])
        return cls(np.concatenate(pieces[:-1] + [last[:split - lead]]), last[split - lead:])

    def __len__(self) -> int:
        return self.split + len(self.body)

    def __getitem__(self, part: slice) -> np.ndarray:
        start, stop, _ = part.indices(len(self))
        if stop <= self.split:
            return self.head[start:stop]
        if start >= self.split:
            return self.body[start - self.split:stop - self.split]
        return np.concatenate([self.head[start:], self.body[:stop - self.split]])


class H5EventWriter:
    """Append time-sorted event chunks to a DSEC-layout HDF5 file; memory stays flat in the stream length.

    Use as a context manager: the file is renamed into place by :meth:`close`, and deleted if an exception
    escapes (so no half-written file is ever visible under the target name). ``compression``: "gzip" (deflate,
    readable everywhere; ``level`` 0-9) or None; "lzf" is accepted but only h5py reads it. ``threads``: how many
    threads deflate whole chunks at once (default :func:`default_compression_threads`; ISA-L's deflate for
    levels 1-3 where python-isal is installed); they are stored with ``write_direct_chunk`` in the form HDF5's
    own shuffle + deflate filters store them (a zlib stream), so every reader decodes them with its own
    filters. The last, partial chunk goes through HDF5's own filters; ``threads=0`` sends every chunk through
    them, on the writing thread.
    """

    def __init__(self, path: str, width: int, height: int, meta: dict | None = None, chunk: int = 1 << 16,
                 compression: str | None = "gzip", level: int | None = H5_GZIP_LEVEL, shuffle: bool = True,
                 threads: int | None = None):
        _check_options(width, height, chunk, compression, level, threads)
        self.path = check_writable(path, "event file")
        remove_stale_partials(self.path)
        self.tmp = temporary_name(self.path)
        self.width, self.height, self.meta = int(width), int(height), dict(meta or {})
        self.count = 0             # events appended (written or buffered)
        self.written = 0           # events already in the file
        self.chunk = int(chunk)
        self._buffer = []          # small appends are gathered into chunk-sized writes
        self._ms_buffer = []       # ms_to_idx entries waiting for the next flush
        self.last_t = None
        # /t_offset: the first millisecond of the recording (the declared t_start_us, else the first event or
        # the first complete_until_us), which /events/t and /ms_to_idx count from. It was always 0, and the
        # index held an entry for every millisecond since t = 0: 800 MB for three events at t = 1e11 us
        self.t_offset = None
        self._complete_until = None     # no later event may come before this (a caller's promise, checked)
        self._ms_written = 0
        self._closed = False
        self.f = self._io = None
        self._deflate = (level if level is not None else 4, shuffle and bool(compression)) \
            if compression == "gzip" else None          # (level, shuffle) of chunks deflated here
        self._threads = int(threads) if threads is not None else default_compression_threads()
        self._pool = None          # made at the first whole chunk
        try:
            with self._writing(HEADER_BYTES):
                self._create(compression, level if compression == "gzip" else None, shuffle and bool(compression))
        except BaseException:
            self.abort()
            raise

    def _create(self, compression, level, shuffle):
        import h5py
        self._io = GuardedFile(self.tmp, "w+")
        # no chunk cache: HDF5 would hold megabytes of compressed chunks in it and write them at close,
        # unaccounted for by the free-space checks; _flush writes whole chunks, so the cache saves nothing
        self.f = h5py.File(self._io, "w", rdcc_nbytes=0)
        g = self.f.create_group("events")
        kw = dict(maxshape=(None,), chunks=(self.chunk,), compression=compression, compression_opts=level,
                  shuffle=shuffle)
        self.ds = {k: g.create_dataset(k, shape=(0,), dtype=dt, **kw)
                   for k, dt in (("x", np.uint16), ("y", np.uint16), ("t", np.int64), ("p", np.uint8))}
        self.ms_to_idx = self.f.create_dataset("ms_to_idx", shape=(0,), dtype=np.uint64, maxshape=(None,),
                                               chunks=(4096,))
        self.f.create_dataset("t_offset", data=np.int64(0))

    @contextlib.contextmanager
    def _writing(self, need: int):
        """One write step of about ``need`` bytes: refused up front when the disk has no room for it, and any
        full disk met during it (recorded by GuardedFile, or raised) ends it as the one-line error."""
        check_space(self.path, need)
        cause = None
        try:
            yield
        except Exception as e:
            # after a swallowed failed write HDF5 may trip over what it then reads back: still a full disk
            if not (self._io is not None and self._io.failed) and not _no_space(e):
                raise
            cause = e
        else:
            if not (self._io is not None and self._io.failed):
                return
        cause = (self._io.failed if self._io is not None else None) or cause    # the write the disk refused
        raise _disk_full(self.path, _free_bytes(self.path), int(need), cause)

    def _offset(self, first_us: int) -> int:
        """/t_offset, fixed by the first event or promise (``first_us``): events and promises never go back."""
        if self.t_offset is None:
            start = self.meta.get("t_start_us")
            start = min(int(start), first_us) if isinstance(start, (int, np.integer)) else first_us
            self.t_offset = (start // 1000) * 1000
            self.f["t_offset"][()] = np.int64(self.t_offset)
        return self.t_offset

    def append(self, x, y, t, p, complete_until_us: int | None = None):
        """Append events sorted by t (int64 us; x, y, t, p checked as an EventStream checks them, before any is
        written). ``complete_until_us``: no later chunk holds an event before it, so ms_to_idx entries up to it
        can be written now (a later event before it is refused)."""
        if self._closed:
            raise EventFieldError(f"{self.path}: the event writer is closed (or was aborted): nothing more can be "
                                  "appended")
        x, y, t, p = chunk_columns(f"{self.path}: append", self.width, self.height, x, y, t, p)
        if len(t):
            if self.last_t is not None and t[0] < self.last_t:
                raise ValueError(f"{self.path}: events must be appended in time order: this chunk starts at "
                                 f"t = {int(t[0])} us, before the last written event at {self.last_t} us")
            if self._complete_until is not None and t[0] < self._complete_until:
                raise ValueError(f"{self.path}: events must be appended in time order: this chunk starts at "
                                 f"t = {int(t[0])} us, before complete_until_us = {self._complete_until} us")
            back = first_out_of_order(t)
            if back is not None:
                raise ValueError(f"{self.path}: events must be appended in time order: t = {int(t[back])} us "
                                 f"follows {int(t[back - 1])} us within the chunk")
        if complete_until_us is not None:
            complete_until_us = int(complete_until_us)
            self._complete_until = max(self._complete_until or complete_until_us, complete_until_us)
        if not len(t) and complete_until_us is None:
            return
        offset = self._offset(int(t[0]) if len(t) else complete_until_us)
        stored = t - offset if offset else t       # the file's t counts from /t_offset
        if len(t):
            self._buffer.append((x, y, stored, (p > 0).astype(np.uint8)))
            self.count, self.last_t = self.count + len(t), int(t[-1])
            if self.count - self.written >= self.chunk:
                self._flush()
        # boundaries up to the last timestamp are final (later events are not earlier), and so are those up
        # to complete_until_us when the caller knows no earlier event will come
        until = max(v for v in (complete_until_us, int(t[-1]) if len(t) else None) if v is not None) - offset
        if until >= 0:
            self._write_ms_index(stored, self.count - len(t), until)

    def _pending_bytes(self, events: int) -> int:
        """What writing ``events`` buffered events and the buffered index entries takes at most: their
        uncompressed size (HDF5 keeps no chunk cache here, so it writes them now, not at close)."""
        return H5_BYTES_PER_EVENT * events + 8 * sum(len(i) for i in self._ms_buffer)

    def _flush(self, final: bool = False):
        """Write the buffered events in whole chunks (all of them when ``final``), checking the free space
        before each: a chunk is compressed and written once, and the rest waits for the next flush."""
        pending = self.count - self.written
        n = pending if final else pending - pending % self.chunk
        if n == 0:
            return
        cols = [_Joined.of([b[i] for b in self._buffer], self.chunk) for i in range(4)]
        deflated = self._deflated_chunks(cols, n)
        end = self.written + n
        for i in range(0, n, self.chunk):
            m = min(self.chunk, n - i)
            with self._writing(self._pending_bytes(m)):
                n0, n1 = self.written, self.written + m
                stored = next(deflated) if deflated is not None and m == self.chunk else None
                for k, v in zip("xytp", cols):
                    if i == 0:       # the extent once a flush (a resize a chunk and column cost 22 us each:
                        self.ds[k].resize((end,))    # 0.2 s of a GPU render's 161 M events on the writer)
                    if stored is not None:
                        self.ds[k].id.write_direct_chunk((n0,), stored[k], 0)
                    else:
                        self.ds[k][n0:n1] = v[i:i + m]
                self.written = n1
                self._flush_ms_index()
        self._buffer = [tuple(c[n:] for c in cols)] if n < pending else []

    def _deflated_chunks(self, cols, n):
        """The whole chunks among the first ``n`` buffered events, in order, each as {column: its bytes as
        HDF5's filters store them}, deflated on the thread pool a few chunks ahead of the writes (so that a
        single large append holds only those in memory, not the whole compressed stream); None where HDF5's own
        filters write them (no gzip, ``threads=0``, or a writer not on the chunk grid)."""
        whole = n // self.chunk
        if self._deflate is None or not self._threads or whole == 0 or self.written % self.chunk:
            return None
        if self._pool is None:
            self._pool = ThreadPoolExecutor(self._threads, thread_name_prefix="h5-deflate")
        level, shuffle, ahead = *self._deflate, 2 * self._threads

        def submit(j):
            return self._pool.submit(_deflate_columns, {k: v[j * self.chunk:(j + 1) * self.chunk]
                                                        for k, v in zip("xytp", cols)}, level, shuffle)

        def in_order():
            window = collections.deque(submit(j) for j in range(min(ahead, whole)))
            for j in range(whole):
                done = window.popleft()
                if j + ahead < whole:
                    window.append(submit(j + ahead))
                yield done.result()
        return in_order()

    def _stop_pool(self):
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def _flush_ms_index(self):
        if not self._ms_buffer:
            return
        idx = np.concatenate(self._ms_buffer)
        m0 = self.ms_to_idx.shape[0]
        self.ms_to_idx.resize((m0 + len(idx),))
        self.ms_to_idx[m0:] = idx
        self._ms_buffer = []

    def _write_ms_index(self, t_chunk, chunk_start, until_us):
        """Index entries up to ``until_us``, buffered until the next flush; a long quiet span (hours of
        time-lapse frames between two chunks) is made and written in blocks of ``MS_INDEX_BLOCK``, so memory
        holds at most about two blocks of entries, not the whole span at once."""
        last_ms = until_us // 1000
        while self._ms_written <= last_ms:
            end = min(last_ms + 1, self._ms_written + MS_INDEX_BLOCK)
            bounds = np.arange(self._ms_written, end, dtype=np.int64) * 1000
            self._ms_buffer.append((chunk_start + np.searchsorted(t_chunk, bounds, side="left")).astype(np.uint64))
            self._ms_written = end       # entries decided (buffered until the next flush)
            if end <= last_ms:
                with self._writing(self._pending_bytes(0)):
                    self._flush_ms_index()

    def close(self, end_us: int | None = None, meta: dict | None = None):
        """Finish the index up to ``end_us`` (default: last event), write the metadata and publish the file."""
        if self._closed:
            return
        try:
            self._close(end_us, meta)
        except BaseException:
            self.abort()       # the deflating threads stopped and no partial file left (a full disk at close)
            raise

    def _close(self, end_us, meta):
        self._flush(final=True)
        self._stop_pool()
        end = int(end_us) if end_us is not None else (self.last_t if self.last_t is not None else 0)
        end -= self._offset(end)
        if end >= 0:
            self._write_ms_index(np.empty(0, np.int64), self.count, end)
        if meta:
            self.meta.update(meta)
        meta_json = _json(self.meta)
        with self._writing(self._pending_bytes(0) + len(meta_json) + HEADER_BYTES):
            self._flush_ms_index()
            g = self.f.create_group("eventfield")
            g.attrs["width"], g.attrs["height"] = self.width, self.height
            g.attrs["format_version"] = H5_FORMAT_VERSION
            g.attrs["polarity"] = "events/p: 1 = ON (brighter), 0 = OFF"
            g.attrs["time_unit"] = "microseconds, relative to t_offset"
            g.attrs["meta_json"] = meta_json
            self.f.close()
            self._io.close()
        publish(self.tmp, self.path)  # (atomic.publish: the one place outputs appear)
        self._closed = True

    def abort(self):
        if self._closed:
            return
        self._closed = True
        self._stop_pool()
        try:
            for handle in (self.f, self._io):   # HDF5 first: it writes its last bytes through _io
                with contextlib.suppress(Exception):
                    if handle is not None:
                        handle.close()
        finally:
            with contextlib.suppress(FileNotFoundError):
                os.remove(self.tmp)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            self.abort()
        return False
