"""Event files: HDF5 in the DSEC layout (streamed while rendering), TimeLens npz, E2VID text, AEDAT4.

HDF5 layout (DSEC, plus our metadata)::

    /events/x   uint16        /events/y  uint16
    /events/t   int64  microseconds relative to /t_offset (DSEC uses uint32; int64 never wraps)
    /events/p   uint8  1 = ON, 0 = OFF  (DSEC's convention; in memory we use +1/-1)
    /t_offset   int64  microseconds
    /ms_to_idx  uint64 ms_to_idx[m] = index of the first event with t >= m*1000
    /eventfield         group; attrs: width, height, format_version, meta_json (all metadata as JSON)

The event datasets are deflate (gzip) compressed with the shuffle filter: filters built into every HDF5 library,
so h5dump, MATLAB, Julia or C read the files as they are (LZF, used before, is an h5py plugin; those files
still read here). docs/design.md "Event file compression" has the measurements behind the level.

Every writer is atomic: the file appears under its name only once complete (``atomic.py``), and checks the free
disk space before each chunk, so a full disk is one ``EventFieldError`` rather than a crash in HDF5 or
dv-processing (both can die on ENOSPC: a segfault, an abort from dv's writer thread).
"""
from __future__ import annotations

import contextlib
import errno
import io
import json
import os
import re
import shutil
import warnings

import numpy as np

from .._version import __version__
from ..atomic import atomic_output, check_writable, remove_stale_partials, temporary_name
from ..errors import EventFieldError
from .stream import EventStream

FORMATS = {".h5": "h5", ".hdf5": "h5", ".npz": "npz", ".txt": "txt", ".aedat4": "aedat4"}
H5_FORMAT_VERSION = 1
H5_GZIP_LEVEL = 1   # deflate level: 2-4x faster to write than level 4+, within 15% of their size (docs/design.md)

# Free-space estimates (bytes). They are upper bounds: uncompressed sizes, since the compressed size is not
# known before writing. DISK_MARGIN is kept free on top, for what libraries write when they choose: HDF5's
# metadata and the attributes written at close, dv-processing's packet headers and file table.
DISK_MARGIN = 1 << 20
H5_BYTES_PER_EVENT = 13        # x, y uint16 + t int64 + p uint8
NPZ_BYTES_PER_EVENT = 22       # x, y, timestamp (float64), polarity, t, p
AEDAT4_BYTES_PER_EVENT = 16    # dv::Event: int64 t, int16 x, y, uint8 p, padded
HEADER_BYTES = 64 << 10        # file headers, the JSON metadata aside
WRITE_CHUNK = 1 << 16          # events per write (and per free-space check) of the one-shot writers


def format_of(path: str, fmt: str | None = None) -> str:
    if fmt:
        if fmt not in set(FORMATS.values()):
            raise EventFieldError(f"{path}: unknown event format '{fmt}'; allowed: h5, npz, txt, aedat4")
        return fmt
    ext = os.path.splitext(path)[1].lower()
    if ext not in FORMATS:
        raise EventFieldError(f"{path}: unknown event file extension '{ext}'; allowed: " + ", ".join(FORMATS))
    return FORMATS[ext]


def _json(meta: dict) -> str:
    return json.dumps(meta, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o), sort_keys=True)


def _size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if abs(n) < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.3g} {unit}"
        n /= 1024


def _free_bytes(path: str) -> int | None:
    try:
        return shutil.disk_usage(os.path.dirname(os.path.abspath(path))).free
    except OSError:  # cannot tell (directory gone, odd file system): the write itself will say
        return None


def _disk_full(path: str, free: int | None, need: int) -> EventFieldError:
    have = "unknown" if free is None else _size(free)
    return EventFieldError(f"{path}: disk full: {have} free, need about {_size(need)}")


def check_space(path: str, need: int) -> None:
    """Refuse a write of about ``need`` bytes beside ``path`` unless that much (plus DISK_MARGIN) is free, before
    HDF5 or dv-processing meet ENOSPC: neither recovers from it (segfault, abort)."""
    free, need = _free_bytes(path), int(need) + DISK_MARGIN
    if free is not None and free < need:
        raise _disk_full(path, free, need)


def _no_space(e: BaseException) -> bool:
    # h5py and Python set errno; dv-processing only says it in the message text
    return getattr(e, "errno", None) == errno.ENOSPC or "No space left on device" in str(e)


@contextlib.contextmanager
def disk_errors(path: str, need: int):
    """Turn ENOSPC raised inside (the disk filled between our check and the write) into the one-line error."""
    try:
        yield
    except EventFieldError:
        raise
    except Exception as e:
        if not _no_space(e):
            raise
        raise _disk_full(path, _free_bytes(path), int(need) + DISK_MARGIN) from None


class _GuardedFile(io.FileIO):
    """The HDF5 file as HDF5 sees it (h5py's file-object driver). HDF5 must never see a failed write: after one
    it crashes the process when it closes the dataset or the file (segfault, even at exit), and it then can
    neither finish nor discard the file. So a write that meets a full disk is recorded in ``failed`` and
    reported to HDF5 as done; the writer checks ``failed`` after each step and throws the file away."""

    failed: OSError | None = None
    _write_some = io.FileIO.write   # the system call (tests replace it to fill the disk)

    def write(self, data) -> int:
        view = memoryview(data).cast("B")
        done = 0
        while self.failed is None and done < len(view):   # h5py ignores short writes: finish them here
            try:
                done += self._write_some(view[done:]) or 0
            except OSError as e:
                if not _no_space(e):
                    raise
                self.failed = e
        return len(view)

    def readinto(self, buffer) -> int:
        view = memoryview(buffer).cast("B")
        n = super().readinto(view) or 0
        view[n:] = bytes(len(view) - n)    # past the end of the file reads as zeros, as in HDF5's own driver
        return len(view)


class H5EventWriter:
    """Append time-sorted event chunks to a DSEC-layout HDF5 file; memory stays flat in the stream length.

    Use as a context manager: the file is renamed into place by :meth:`close`, and deleted if an exception
    escapes (so no half-written file is ever visible under the target name). ``compression``: "gzip" (deflate,
    readable everywhere; ``level`` 0-9) or None; "lzf" is accepted but only h5py reads it.
    """

    def __init__(self, path: str, width: int, height: int, meta: dict | None = None, chunk: int = 1 << 16,
                 compression: str | None = "gzip", level: int | None = H5_GZIP_LEVEL, shuffle: bool = True):
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
        self._ms_written = 0
        self._closed = False
        self.f = self._io = None
        try:
            with self._writing(HEADER_BYTES):
                self._create(compression, level if compression == "gzip" else None, shuffle and bool(compression))
        except BaseException:
            self.abort()
            raise

    def _create(self, compression, level, shuffle):
        import h5py
        self._io = _GuardedFile(self.tmp, "w+")
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
        full disk met during it (recorded by _GuardedFile, or raised) ends it as the one-line error."""
        check_space(self.path, need)
        try:
            yield
        except Exception as e:
            # after a swallowed failed write HDF5 may trip over what it then reads back: still a full disk
            if not (self._io is not None and self._io.failed) and not _no_space(e):
                raise
        else:
            if not (self._io is not None and self._io.failed):
                return
        raise _disk_full(self.path, _free_bytes(self.path), int(need) + DISK_MARGIN)

    def append(self, x, y, t, p, complete_until_us: int | None = None):
        """Append events sorted by t (int64 us). ``complete_until_us``: no later chunk holds an event before it,
        so ms_to_idx entries up to it can be written now."""
        t = np.asarray(t, dtype=np.int64)
        if len(t):
            if self.last_t is not None and t[0] < self.last_t:
                raise ValueError(f"{self.path}: events must be appended in time order: this chunk starts at "
                                 f"t = {int(t[0])} us, before the last written event at {self.last_t} us")
            back = np.flatnonzero(np.diff(t) < 0)
            if len(back):
                raise ValueError(f"{self.path}: events must be appended in time order: t = {int(t[back[0] + 1])} us "
                                 f"follows {int(t[back[0]])} us within the chunk")
            self._buffer.append((np.asarray(x, np.uint16), np.asarray(y, np.uint16), t,
                                 (np.asarray(p) > 0).astype(np.uint8)))
            self.count, self.last_t = self.count + len(t), int(t[-1])
            if self.count - self.written >= self.chunk:
                self._flush()
        # boundaries up to the last timestamp are final (later events are not earlier), and so are those up
        # to complete_until_us when the caller knows no earlier event will come
        until = max(int(complete_until_us) if complete_until_us is not None else -1,
                    int(t[-1]) if len(t) else -1)
        if until >= 0:
            self._write_ms_index(t, self.count - len(t), until)

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
        cols = [np.concatenate([b[i] for b in self._buffer]) for i in range(4)]
        for i in range(0, n, self.chunk):
            m = min(self.chunk, n - i)
            with self._writing(self._pending_bytes(m)):
                n0, n1 = self.written, self.written + m
                for k, v in zip("xytp", cols):
                    self.ds[k].resize((n1,))
                    self.ds[k][n0:n1] = v[i:i + m]
                self.written = n1
                self._flush_ms_index()
        self._buffer = [tuple(c[n:] for c in cols)] if n < pending else []

    def _flush_ms_index(self):
        if not self._ms_buffer:
            return
        idx = np.concatenate(self._ms_buffer)
        m0 = self.ms_to_idx.shape[0]
        self.ms_to_idx.resize((m0 + len(idx),))
        self.ms_to_idx[m0:] = idx
        self._ms_buffer = []

    def _write_ms_index(self, t_chunk, chunk_start, until_us):
        last_ms = until_us // 1000
        if last_ms < self._ms_written:
            return
        bounds = np.arange(self._ms_written, last_ms + 1, dtype=np.int64) * 1000
        self._ms_buffer.append((chunk_start + np.searchsorted(t_chunk, bounds, side="left")).astype(np.uint64))
        self._ms_written = last_ms + 1   # entries decided (buffered until the next flush)

    def close(self, end_us: int | None = None, meta: dict | None = None):
        """Finish the index up to ``end_us`` (default: last event), write the metadata and publish the file."""
        if self._closed:
            return
        self._flush(final=True)
        end = end_us if end_us is not None else (self.last_t or 0)
        self._write_ms_index(np.empty(0, np.int64), self.count, int(end))
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
        os.replace(self.tmp, self.path)
        self._closed = True

    def abort(self):
        if self._closed:
            return
        self._closed = True
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


def write_events(path: str, events: EventStream, fmt: str | None = None) -> str:
    """Write a whole stream; the format follows the extension (.h5/.hdf5, .npz, .txt, .aedat4)."""
    fmt = format_of(path, fmt)
    meta = dict(events.meta)
    meta.setdefault("package_version", __version__)
    if fmt == "h5":
        with H5EventWriter(path, events.width, events.height, meta) as w:
            w.append(events.x, events.y, events.t, events.p)
            w.close(end_us=max(events.duration_us, int(events.t[-1]) if len(events) else 0))
    elif fmt == "npz":
        _write_npz(path, events, _json(meta))
    elif fmt == "txt":
        _write_txt(path, events)
    else:
        _write_aedat4(path, events)
    return os.path.abspath(path)


def _write_npz(path, events, meta_json):
    """TimeLens keys (x, y, timestamp, polarity 0/1) plus ours; np.savez writes it in one go, so one check."""
    need = NPZ_BYTES_PER_EVENT * len(events) + len(meta_json) + HEADER_BYTES
    check_space(path, need)
    with atomic_output(path, "event file") as tmp, disk_errors(path, need), open(tmp, "wb") as f:
        np.savez(f, x=events.x, y=events.y, timestamp=events.t.astype(np.float64),
                 polarity=(events.p > 0).astype(np.uint8), t=events.t, p=events.p,
                 width=events.width, height=events.height, meta_json=meta_json)


def _write_txt(path, events):
    """E2VID: "width height" then "t[s] x y p(0/1)" per line; metadata is not kept."""
    t_max = int(events.t.max()) if len(events) else 0
    line = len(f"{t_max * 1e-6:.6f} {events.width} {events.height} 1\n") + 1   # + a minus sign
    check_space(path, line * len(events) + HEADER_BYTES)
    with atomic_output(path, "event file") as tmp, disk_errors(path, line * len(events)), open(tmp, "w") as f:
        f.write(f"{events.width} {events.height}\n")
        for i in range(0, len(events), WRITE_CHUNK):
            s = slice(i, i + WRITE_CHUNK)
            check_space(path, line * (len(events) - i))
            rows = np.column_stack([events.t[s] * 1e-6, events.x[s], events.y[s], (events.p[s] > 0).astype(np.int64)])
            np.savetxt(f, rows, fmt=["%.6f", "%d", "%d", "%d"])


def _write_aedat4(path, events):
    try:
        import dv_processing as dv
    except ImportError:
        raise EventFieldError(f"{path}: AEDAT4 export needs dv-processing (pip install dv-processing)") from None
    # the whole file is checked first: dv-processing writes on a thread of its own and aborts the process
    # on a write error there, so a full disk must never be reached
    need = AEDAT4_BYTES_PER_EVENT * len(events) + HEADER_BYTES
    check_space(path, need)
    with atomic_output(path, "event file") as tmp, disk_errors(path, need):
        writer = dv.io.MonoCameraWriter(tmp, dv.io.MonoCameraWriter.EventOnlyConfig(
            "mitsuba-eventfield", (events.width, events.height)))
        for i in range(0, len(events), WRITE_CHUNK):
            check_space(path, AEDAT4_BYTES_PER_EVENT * (len(events) - i) + HEADER_BYTES)
            store = dv.EventStore()
            s = slice(i, i + WRITE_CHUNK)
            for t, x, y, p in zip(events.t[s].tolist(), events.x[s].tolist(), events.y[s].tolist(),
                                  (events.p[s] > 0).tolist()):
                store.push_back(t, x, y, p)
            writer.writeEvents(store)
        del writer  # flushes and closes the file


class _BadFile(Exception):
    """What is wrong with an event file, found by our own checks (read_events adds the path and format)."""


# How each format's files start: checked before a library parses them, since dv-processing answers an empty or
# foreign file with a C++ stack trace and NumPy takes any non-zip file for a pickle
_SIGNATURES = {"h5": (b"\x89HDF\r\n\x1a\n",), "npz": (b"PK\x03\x04", b"PK\x05\x06"), "aedat4": (b"#!AER-DAT4.0",)}
_FORMAT_NAMES = {"h5": "HDF5", "npz": "npz (zip)", "txt": "E2VID text", "aedat4": "AEDAT4"}


def _check_file(path: str, fmt: str) -> None:
    size = os.path.getsize(path)
    name = _FORMAT_NAMES[fmt]
    if size == 0:
        raise _BadFile("empty file (0 bytes)")
    with open(path, "rb") as f:
        head = f.read(18)
        if fmt == "h5" and not head.startswith(_SIGNATURES["h5"]):
            # HDF5 allows a user block before the signature, at 512, 1024, 2048, ... bytes
            offsets = [512 << k for k in range(32) if (512 << k) < size]
            if not any(f.seek(o) == o and f.read(8) == _SIGNATURES["h5"][0] for o in offsets):
                raise _BadFile("not an HDF5 file (no HDF5 signature)")
    if fmt in ("npz", "aedat4") and not head.startswith(_SIGNATURES[fmt]):
        raise _BadFile(f"not an {name} file (it does not start with {_SIGNATURES[fmt][0]!r})")
    if fmt == "aedat4":  # "#!AER-DAT4.0\r\n", the header's length (int32), the header
        header_end = 18 + int.from_bytes(head[14:18], "little") if len(head) == 18 else None
        if header_end is None or not 18 < header_end <= size:
            raise _BadFile(f"truncated or damaged AEDAT4 file (its header needs "
                           f"{header_end if header_end is not None else 18} bytes, the file has {size})")


def _one_line(e: BaseException) -> str:
    """A library's error as one readable line: dv-processing's messages carry the C++ source line and a stack
    trace, HDF5's a timestamp on a line of its own."""
    import zipfile
    if isinstance(e, UnicodeDecodeError):
        return f"not text (undecodable byte at offset {e.start})"
    text = str(e).split("Stacktrace:")[0]
    lines = [s.strip() for s in text.splitlines() if s.strip() and not re.match(r"\S+\.(h|hpp|cpp)\(\d+\):", s.strip())]
    text = " ".join(lines)
    eof = re.search(r"truncated file: eof = (\d+).*stored_eof = (\d+)", text)
    if eof:
        return f"truncated ({eof[1]} of {eof[2]} bytes)"
    if "End-Of-File" in text:
        return "truncated (unexpected end of file)"
    columns = re.search(r"number of columns changed from (\d+) to (\d+) at row (\d+)", text)
    if columns:  # NumPy's loadtxt; its advice (usecols) does not apply
        return f"truncated or malformed: data row {columns[3]} has {columns[2]} columns, not {columns[1]}"
    opened = re.match(r"Unable to (?:synchronously )?open file \((.*)\)$", text)
    if opened:
        return f"damaged or truncated HDF5 file ({opened[1]})"
    if isinstance(e, zipfile.BadZipFile):
        return f"truncated or damaged zip archive ({text})"
    if isinstance(e, KeyError):
        return f"missing entry {text}"
    return text or type(e).__name__


def read_events(path: str, fmt: str | None = None) -> EventStream:
    """Read an event file (format by extension). A missing, empty, truncated or foreign file raises
    ``EventFieldError`` with one line naming the file and the problem."""
    if not os.path.isfile(path):
        raise EventFieldError(f"{path}: no such event file")
    fmt = format_of(path, fmt)
    try:
        _check_file(path, fmt)
        if fmt == "h5":
            return _read_h5(path)
        if fmt == "npz":
            return _read_npz(path)
        if fmt == "txt":
            return _read_txt(path)
        return _read_aedat4(path)
    except EventFieldError:
        raise
    except Exception as e:  # corrupt or foreign file
        raise EventFieldError(f"{path}: cannot read as {fmt} event file: {_one_line(e)}") from None


def _read_npz(path):
    with np.load(path, allow_pickle=False) as z:
        if "t" in z:
            t, p = z["t"], z["p"]
        else:  # a TimeLens file written elsewhere
            t, p = np.rint(z["timestamp"]).astype(np.int64), np.where(z["polarity"] > 0, 1, -1)
        meta = json.loads(str(z["meta_json"])) if "meta_json" in z else {}
        w = int(z["width"]) if "width" in z else int(z["x"].max()) + 1
        h = int(z["height"]) if "height" in z else int(z["y"].max()) + 1
        return EventStream(z["x"], z["y"], t, p, w, h, meta)


def _read_txt(path):
    with open(path) as f:
        size = f.readline().split()
    if len(size) < 2 or not (size[0].isdigit() and size[1].isdigit()):
        raise _BadFile(f"not an E2VID text event file: the first line must be 'width height', got "
                       f"{' '.join(size)[:40]!r}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)   # "input contained no data": a stream without events
        rows = np.loadtxt(path, skiprows=1, ndmin=2)
    rows = rows.reshape(0, 4) if rows.size == 0 else rows
    if rows.shape[1] != 4:
        raise _BadFile(f"truncated or malformed: expected 4 columns 't x y p' per line, got {rows.shape[1]}")
    t = np.rint(rows[:, 0] * 1e6).astype(np.int64)
    return EventStream(rows[:, 1], rows[:, 2], t, np.where(rows[:, 3] > 0, 1, -1), int(size[0]), int(size[1]), {})


def _read_h5(path):
    import h5py
    with h5py.File(path, "r") as f:
        if "events" not in f:
            raise EventFieldError(f"{path}: no /events group (not a DSEC-layout event file)")
        ev = f["events"]
        t = ev["t"][()].astype(np.int64) + int(f["t_offset"][()]) if "t_offset" in f else ev["t"][()]
        p = np.where(ev["p"][()] > 0, 1, -1).astype(np.int8)
        meta, w, h = {}, None, None
        if "eventfield" in f:
            g = f["eventfield"]
            meta = json.loads(g.attrs["meta_json"])
            w, h = int(g.attrs["width"]), int(g.attrs["height"])
        x, y = ev["x"][()], ev["y"][()]
        if w is None:  # a foreign DSEC file: size from the data
            w, h = (int(x.max()) + 1, int(y.max()) + 1) if len(x) else (0, 0)
        return EventStream(x, y, t, p, w, h, meta)


# AEDAT4 is decoded by dv-processing in a child process: on some damaged packets (a valid header and data
# table, bytes of a packet overwritten) its decoder spins forever inside one C++ call, which no thread of ours
# could stop. The child sends each batch as it decodes it; no batch for AEDAT4_STALL_S (a healthy packet takes
# milliseconds) means it is stuck, and it is killed.
AEDAT4_STALL_S = 10.0
_AEDAT4_DTYPE = np.dtype([("timestamp", "<i8"), ("x", "<i2"), ("y", "<i2"), ("polarity", "i1")])
_AEDAT4_READER = r"""
import json, sys
import numpy as np
out = sys.stdout.buffer
try:
    import dv_processing as dv
    dtype = np.dtype([("timestamp", "<i8"), ("x", "<i2"), ("y", "<i2"), ("polarity", "i1")])
    rec = dv.io.MonoCameraRecording(sys.argv[1])
    w, h = rec.getEventResolution()
    out.write((json.dumps({"width": int(w), "height": int(h), "camera": rec.getCameraName()}) + "\n").encode())
    out.flush()
    while True:
        batch = rec.getNextEventBatch()
        if batch is None:
            break
        a = batch.numpy()
        b = np.empty(len(a), dtype)
        for k in dtype.names:
            b[k] = a[k]
        out.write(b.tobytes())
        out.flush()
except BaseException as e:
    sys.stderr.write(str(e) or type(e).__name__)
    sys.exit(1)
"""


def _read_aedat4(path):
    import importlib.util
    import queue
    import signal
    import subprocess
    import sys
    import threading
    if importlib.util.find_spec("dv_processing") is None:
        raise EventFieldError(f"{path}: reading AEDAT4 needs dv-processing (pip install dv-processing)")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))   # the same dv-processing
    proc = subprocess.Popen([sys.executable, "-c", _AEDAT4_READER, path], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    chunks, errors = queue.Queue(), []

    def pump():
        while True:
            data = proc.stdout.read1(1 << 20)
            chunks.put(data)
            if not data:
                return
    readers = [threading.Thread(target=pump, daemon=True),
               threading.Thread(target=lambda: errors.append(proc.stderr.read()), daemon=True)]
    for r in readers:
        r.start()
    stuck = _BadFile(f"damaged AEDAT4 file: dv-processing stopped making progress decoding it (nothing for "
                     f"{AEDAT4_STALL_S:g} s; a corrupt packet?)")
    received = bytearray()
    try:
        while True:
            try:
                data = chunks.get(timeout=AEDAT4_STALL_S)
            except queue.Empty:
                raise stuck from None
            if not data:
                break
            received += data
        try:
            rc = proc.wait(timeout=AEDAT4_STALL_S)
        except subprocess.TimeoutExpired:
            raise stuck from None
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for r in readers:
            r.join(timeout=5)
    if rc < 0:
        try:
            name = signal.Signals(-rc).name
        except ValueError:
            name = f"signal {-rc}"
        raise _BadFile(f"damaged AEDAT4 file: dv-processing crashed decoding it ({name})")
    if rc != 0:
        raise RuntimeError((errors[0] if errors else b"").decode("utf-8", "replace") or f"exit status {rc}")
    head, _, body = bytes(received).partition(b"\n")
    info = json.loads(head)
    if len(body) % _AEDAT4_DTYPE.itemsize:
        raise _BadFile("damaged AEDAT4 file: an incomplete event from dv-processing")
    arr = np.frombuffer(body, _AEDAT4_DTYPE)
    return EventStream(arr["x"], arr["y"], arr["timestamp"], np.where(arr["polarity"] > 0, 1, -1), info["width"],
                       info["height"], {"camera": info["camera"]})
