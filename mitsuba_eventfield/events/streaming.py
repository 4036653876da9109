"""Chunk writers for the event formats besides HDF5: E2VID text, TimeLens npz and AEDAT4, fed time-sorted
chunks while a render runs (by the background writer) or a whole stream at once (``write_events``), with
memory flat in the stream's length.

Each has the interface of ``H5EventWriter``: ``append(x, y, t, p, complete_until_us)``, ``close(end_us,
meta)``, ``abort()``. Each writes to a partial file beside the target (``atomic.temporary_name``), renamed into
place by ``close`` and removed by ``abort``, and checks the free disk space before every chunk (``disk.py``).

npz is a zip of ``.npy`` arrays whose sizes are only known at the end: the columns are appended to raw
partial files while streaming, and ``close`` writes each as one zip member (header, then the bytes copied in
chunks), so no column is ever held in memory whole.
"""
from __future__ import annotations

import contextlib
import os
import zipfile

import numpy as np

from ..atomic import check_writable, publish, remove_stale_partials, temporary_name
from ..errors import EventFieldError
from . import text
from .disk import HEADER_BYTES, check_file_limit, check_room, check_space, disk_errors
from .hdf5 import H5EventWriter, _json
from .stream import chunk_columns, first_out_of_order

NPZ_BYTES_PER_EVENT = 22       # x, y, timestamp (float64), polarity, t, p
AEDAT4_BYTES_PER_EVENT = 17    # dv::Event (int64 t, int16 x, y, uint8 p, padded: 16) and LZ4's worst-case growth
AEDAT4_MAX_SIDE = 32767        # dv::Event's x, y are int16 (and dv refuses a 0-pixel side with a C++ trace)
TXT_BYTES_PER_EVENT = 32       # "t.tttttt x y p\n" for timestamps below 10^5 s and sensors below 10^5 px
COPY_CHUNK = 1 << 20


class _PartialFile:
    """The partial-file discipline shared by the writers: a temporary name, published by :meth:`_publish`,
    removed by :meth:`abort`."""

    def __init__(self, path: str, width: int, height: int, meta: dict | None):
        self.path = check_writable(path, "event file")
        remove_stale_partials(self.path)
        self.tmp = temporary_name(self.path)
        self.width, self.height, self.meta = int(width), int(height), dict(meta or {})
        self.count, self.closed = 0, False
        self.last_t = None

    def _checked(self, x, y, t, p) -> tuple:
        """A chunk to append, checked as ``H5EventWriter.append`` checks one (``stream.chunk_columns``), and in
        time order after the chunks before it: an order checked only within each chunk let a stream whose
        second 65,536 events started before the first ended be written unsorted."""
        if self.closed:
            raise EventFieldError(f"{self.path}: the event writer is closed (or was aborted): nothing more can be "
                                  "appended")
        x, y, t, p = chunk_columns(f"{self.path}: append", self.width, self.height, x, y, t, p)
        if len(t):
            if (self.last_t is not None and t[0] < self.last_t) or first_out_of_order(t) is not None:
                raise ValueError(f"{self.path}: events must be appended in time order")
            self.last_t = int(t[-1])
        return x, y, t, p

    def _publish(self):
        publish(self.tmp, self.path)  # (atomic.publish: the one place outputs appear)
        self.closed = True

    def _remove(self, *paths):
        for p in paths:
            with contextlib.suppress(FileNotFoundError):
                os.remove(p)

    def abort(self):
        """Give the output up: nothing is left at the output path or beside it. Releasing may fail (closing a
        file flushes its buffer, which fails again on a full disk): the partial files go all the same (a
        disk-full render left its .txt / the .npz's column files behind, "nothing was kept" notwithstanding)."""
        if not self.closed:
            self.closed = True
            try:
                self._release()
            except OSError:
                pass
            finally:
                self._remove(self.tmp)

    def _release(self):
        pass

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            if not self.closed:
                self.close()
        else:
            self.abort()
        return False


class TxtEventWriter(_PartialFile):
    """E2VID text: "width height", then "t[s] x y p(0/1)" per event; no metadata (the format has none)."""

    def __init__(self, path, width, height, meta=None):
        super().__init__(path, width, height, meta)
        check_space(self.path, HEADER_BYTES)
        self.f = open(self.tmp, "wb")
        self.f.write(f"{self.width} {self.height}\n".encode())

    def append(self, x, y, t, p, complete_until_us=None):
        x, y, t, p = self._checked(x, y, t, p)
        need = TXT_BYTES_PER_EVENT * len(t)
        check_space(self.path, need)
        with disk_errors(self.path, need):
            text.write_lines(self.f, t, x, y, p)         # (np.savetxt's bytes, 17-23x faster: text.py)
        self.count += len(t)

    def close(self, end_us=None, meta=None):
        if self.closed:             # closed or aborted already: nothing to do (as H5EventWriter)
            return
        with disk_errors(self.path, HEADER_BYTES):
            self.f.close()
        self._publish()

    def _release(self):
        self.f.close()


NPZ_COLUMNS = {"x": np.uint16, "y": np.uint16, "t": np.int64, "p": np.int8}


class NpzEventWriter(_PartialFile):
    """TimeLens npz (x, y, timestamp float64, polarity 0/1) plus ours (t, p, width, height, meta_json)."""

    def __init__(self, path, width, height, meta=None):
        super().__init__(path, width, height, meta)
        check_space(self.path, HEADER_BYTES)
        self.columns = {k: open(f"{self.tmp}.{k}", "wb") for k in NPZ_COLUMNS}

    def append(self, x, y, t, p, complete_until_us=None):
        x, y, t, p = self._checked(x, y, t, p)
        p = np.where(p > 0, 1, -1).astype(np.int8)       # +1 / -1 whichever convention came in
        need = 2 * NPZ_BYTES_PER_EVENT * len(t)          # the raw columns now, the zip at close
        check_space(self.path, need)
        with disk_errors(self.path, need):
            for key, values in zip("xytp", (x, y, t, p)):
                self.columns[key].write(np.asarray(values).astype(NPZ_COLUMNS[key]).tobytes())
        self.count += len(t)

    def _member(self, zf, name, dtype, n, chunks):
        with zf.open(f"{name}.npy", "w", force_zip64=True) as f:
            np.lib.format.write_array_header_1_0(f, {"descr": np.dtype(dtype).str, "fortran_order": False,
                                                     "shape": (n,)})
            for chunk in chunks:
                f.write(np.ascontiguousarray(chunk, dtype).tobytes())

    def _chunks(self, key, convert=None):
        dtype = NPZ_COLUMNS[key]
        with open(f"{self.tmp}.{key}", "rb") as f:
            while True:
                raw = f.read(COPY_CHUNK * np.dtype(dtype).itemsize)
                if not raw:
                    return
                values = np.frombuffer(raw, dtype)
                yield convert(values) if convert else values

    def close(self, end_us=None, meta=None):
        if self.closed:             # closed or aborted already: nothing to do (as H5EventWriter)
            return
        for f in self.columns.values():
            f.close()
        self.meta.update(meta or {})
        meta_json, n = _json(self.meta), self.count
        need = NPZ_BYTES_PER_EVENT * n + len(meta_json) + HEADER_BYTES
        check_space(self.path, need)
        with disk_errors(self.path, need), zipfile.ZipFile(self.tmp, "w", zipfile.ZIP_STORED, allowZip64=True) as zf:
            self._member(zf, "x", np.uint16, n, self._chunks("x"))
            self._member(zf, "y", np.uint16, n, self._chunks("y"))
            self._member(zf, "timestamp", np.float64, n, self._chunks("t", lambda v: v.astype(np.float64)))
            self._member(zf, "polarity", np.uint8, n, self._chunks("p", lambda v: (v > 0).astype(np.uint8)))
            self._member(zf, "t", np.int64, n, self._chunks("t"))
            self._member(zf, "p", np.int8, n, self._chunks("p"))
            for name, value in (("width", self.width), ("height", self.height), ("meta_json", meta_json)):
                with zf.open(f"{name}.npy", "w") as f:
                    np.lib.format.write_array(f, np.asarray(value))
        self._remove(*(f"{self.tmp}.{k}" for k in NPZ_COLUMNS))
        self._publish()

    def _release(self):
        for f in self.columns.values():
            with contextlib.suppress(OSError):     # each closed (and its file removed) even when one fails
                f.close()
        self._remove(*(f"{self.tmp}.{k}" for k in NPZ_COLUMNS))


class Aedat4EventWriter(_PartialFile):
    """AEDAT4 (iniVation's dv format) through faery's encoder, a core dependency: each chunk becomes one
    LZ4-compressed packet of the events track, written before ``append`` returns; ``close`` adds the file's
    data table. 40-50 ns an event (2 threads), where dv-processing's writer needed a Python call per event
    (0.5-0.8 us: ``EventStore.push_back``, no array constructor); faery and dv-processing both read the files.
    Free space, the process's file-size limit and the room the file system grants (a quota) are checked for
    every chunk before it is handed over."""

    def __init__(self, path, width, height, meta=None):
        if not (0 < int(width) <= AEDAT4_MAX_SIDE and 0 < int(height) <= AEDAT4_MAX_SIDE):
            raise EventFieldError(f"{path}: a {width}x{height} sensor: AEDAT4 holds sensors of 1 to "
                                  f"{AEDAT4_MAX_SIDE} pixels a side (16-bit signed coordinates)")
        super().__init__(path, width, height, meta)
        try:
            import faery
            from faery.extension import aedat
        except ImportError:
            raise EventFieldError(f"{path}: AEDAT4 export needs faery (pip install faery)") from None
        self.dtype = faery.EVENTS_DTYPE
        check_space(self.path, HEADER_BYTES)
        check_room(self.path, self.tmp, HEADER_BYTES)
        with disk_errors(self.path, HEADER_BYTES):
            self.encoder = aedat.Encoder(self.tmp, _aedat4_description(self.width, self.height), aedat.LZ4_DEFAULT)
            self.encoder.__enter__()

    def append(self, x, y, t, p, complete_until_us=None):
        x, y, t, p = self._checked(x, y, t, p)
        if len(t) and t[0] < 0:
            raise EventFieldError(f"{self.path}: AEDAT4 holds timestamps >= 0 only (this chunk starts at "
                                  f"{int(t[0])} us): choose .h5, .npz or .txt, or shift the times")
        need = AEDAT4_BYTES_PER_EVENT * len(t) + HEADER_BYTES
        check_space(self.path, need)
        check_file_limit(self.path, self.tmp, need)      # a quota is not in the free space (check_room)
        check_room(self.path, self.tmp, need)
        packet = np.empty(len(t), self.dtype)
        packet["t"], packet["x"], packet["y"], packet["on"] = t, x, y, p > 0
        with disk_errors(self.path, need):
            self.encoder.write(0, packet)
        self.count += len(t)

    def close(self, end_us=None, meta=None):
        if self.closed:             # closed or aborted already: nothing to do (as H5EventWriter)
            return
        encoder = self.__dict__.pop("encoder")
        with disk_errors(self.path, HEADER_BYTES):
            encoder.__exit__(None, None, None)             # writes the data table and closes the file
        self._publish()

    def _release(self):
        encoder = self.__dict__.pop("encoder", None)
        if encoder is not None:
            with contextlib.suppress(Exception):           # the partial file is removed whatever faery says
                encoder.__exit__(None, None, None)


def _aedat4_description(width: int, height: int) -> list:
    """The AEDAT4 header's stream table (dv's XML tree): one events stream (type EVTS, LZ4) of the sensor's
    size, its source (the camera's name to dv-processing) this package."""
    from faery.extension import aedat

    def node(name, path, attributes, nodes=()):
        return aedat.DescriptionNode(name, path, {k: aedat.DescriptionAttribute(*v) for k, v in attributes.items()},
                                     list(nodes))
    info = node("info", "/mainloop/Recorder/outInfo/0/info/",
                {"sizeX": ("int", width), "sizeY": ("int", height), "source": ("string", "mitsuba-eventfield")})
    stream = node("0", "/mainloop/Recorder/outInfo/0/", {"compression": ("string", "LZ4"), "typeIdentifier":
                                                         ("string", "EVTS"), "originalOutputName": ("string", "events")},
                  [info])
    return [node("outInfo", "/mainloop/Recorder/outInfo/", {}, [stream])]


STREAMED = {"h5": H5EventWriter, "npz": NpzEventWriter, "txt": TxtEventWriter, "aedat4": Aedat4EventWriter}
BYTES_PER_EVENT = {"npz": NPZ_BYTES_PER_EVENT, "txt": TXT_BYTES_PER_EVENT, "aedat4": AEDAT4_BYTES_PER_EVENT}


def open_writer(path: str, fmt: str, width: int, height: int, meta: dict | None = None):
    """The chunk writer of format ``fmt`` (h5, npz, txt, aedat4) for ``path``."""
    return STREAMED[fmt](path, width, height, meta)
