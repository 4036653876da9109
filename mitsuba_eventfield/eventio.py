"""Event files: HDF5 in the DSEC layout (streamed while rendering), TimeLens npz, E2VID text, AEDAT4.

HDF5 layout (DSEC, plus our metadata)::

    /events/x   uint16        /events/y  uint16
    /events/t   int64  microseconds relative to /t_offset (DSEC uses uint32; int64 never wraps)
    /events/p   uint8  1 = ON, 0 = OFF  (DSEC's convention; in memory we use +1/-1)
    /t_offset   int64  microseconds
    /ms_to_idx  uint64 ms_to_idx[m] = index of the first event with t >= m*1000
    /eventfield         group; attrs: width, height, format_version, meta_json (all metadata as JSON)

Every writer is atomic: the file appears under its name only once complete (``atomic.py``).
"""
from __future__ import annotations

import json
import os

import numpy as np

from ._version import __version__
from .atomic import atomic_output, check_writable, temporary_name
from .errors import EventFieldError
from .events import EventStream

FORMATS = {".h5": "h5", ".hdf5": "h5", ".npz": "npz", ".txt": "txt", ".aedat4": "aedat4"}
H5_FORMAT_VERSION = 1


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


class H5EventWriter:
    """Append time-sorted event chunks to a DSEC-layout HDF5 file; memory stays flat in the stream length.

    Use as a context manager: the file is renamed into place by :meth:`close`, and deleted if an exception
    escapes (so no half-written file is ever visible under the target name).
    """

    def __init__(self, path: str, width: int, height: int, meta: dict | None = None, chunk: int = 1 << 16,
                 compression: str | None = "lzf"):
        import h5py
        self.path = check_writable(path, "event file")
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
        self.f = h5py.File(self.tmp, "w")
        g = self.f.create_group("events")
        kw = dict(maxshape=(None,), chunks=(chunk,), compression=compression)
        self.ds = {k: g.create_dataset(k, shape=(0,), dtype=dt, **kw)
                   for k, dt in (("x", np.uint16), ("y", np.uint16), ("t", np.int64), ("p", np.uint8))}
        self.ms_to_idx = self.f.create_dataset("ms_to_idx", shape=(0,), dtype=np.uint64, maxshape=(None,),
                                               chunks=(4096,))
        self.f.create_dataset("t_offset", data=np.int64(0))

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

    def _flush(self):
        if not self._buffer:
            return
        cols = [np.concatenate([b[i] for b in self._buffer]) for i in range(4)]
        n0, n1 = self.written, self.written + len(cols[2])
        for k, v in zip("xytp", cols):
            self.ds[k].resize((n1,))
            self.ds[k][n0:n1] = v
        self.written, self._buffer = n1, []
        self._flush_ms_index()

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
        self._flush()
        end = end_us if end_us is not None else (self.last_t or 0)
        self._write_ms_index(np.empty(0, np.int64), self.count, int(end))
        self._flush_ms_index()
        if meta:
            self.meta.update(meta)
        g = self.f.create_group("eventfield")
        g.attrs["width"], g.attrs["height"] = self.width, self.height
        g.attrs["format_version"] = H5_FORMAT_VERSION
        g.attrs["polarity"] = "events/p: 1 = ON (brighter), 0 = OFF"
        g.attrs["time_unit"] = "microseconds, relative to t_offset"
        g.attrs["meta_json"] = _json(self.meta)
        self.f.close()
        os.replace(self.tmp, self.path)
        self._closed = True

    def abort(self):
        if self._closed:
            return
        try:
            self.f.close()
        finally:
            if os.path.exists(self.tmp):
                os.remove(self.tmp)
            self._closed = True

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
    elif fmt == "npz":  # TimeLens keys (x, y, timestamp, polarity 0/1) plus ours
        with atomic_output(path, "event file") as tmp, open(tmp, "wb") as f:
            np.savez(f, x=events.x, y=events.y, timestamp=events.t.astype(np.float64),
                     polarity=(events.p > 0).astype(np.uint8), t=events.t, p=events.p,
                     width=events.width, height=events.height, meta_json=_json(meta))
    elif fmt == "txt":  # E2VID: "width height" then "t[s] x y p(0/1)" per line; metadata is not kept
        with atomic_output(path, "event file") as tmp, open(tmp, "w") as f:
            f.write(f"{events.width} {events.height}\n")
            rows = np.column_stack([events.t * 1e-6, events.x, events.y, (events.p > 0).astype(np.int64)])
            np.savetxt(f, rows, fmt=["%.6f", "%d", "%d", "%d"])
    else:
        _write_aedat4(path, events)
    return os.path.abspath(path)


def _write_aedat4(path, events):
    try:
        import dv_processing as dv
    except ImportError:
        raise EventFieldError(f"{path}: AEDAT4 export needs dv-processing (pip install dv-processing)") from None
    with atomic_output(path, "event file") as tmp:
        store = dv.EventStore()
        for t, x, y, p in zip(events.t.tolist(), events.x.tolist(), events.y.tolist(), (events.p > 0).tolist()):
            store.push_back(t, x, y, p)
        writer = dv.io.MonoCameraWriter(tmp, dv.io.MonoCameraWriter.EventOnlyConfig(
            "mitsuba-eventfield", (events.width, events.height)))
        if len(events):
            writer.writeEvents(store)
        del writer  # flushes and closes the file


def read_events(path: str, fmt: str | None = None) -> EventStream:
    if not os.path.isfile(path):
        raise EventFieldError(f"{path}: no such event file")
    fmt = format_of(path, fmt)
    try:
        if fmt == "h5":
            return _read_h5(path)
        if fmt == "npz":
            with np.load(path, allow_pickle=False) as z:
                if "t" in z:
                    t, p = z["t"], z["p"]
                else:  # a TimeLens file written elsewhere
                    t, p = np.rint(z["timestamp"]).astype(np.int64), np.where(z["polarity"] > 0, 1, -1)
                meta = json.loads(str(z["meta_json"])) if "meta_json" in z else {}
                w = int(z["width"]) if "width" in z else int(z["x"].max()) + 1
                h = int(z["height"]) if "height" in z else int(z["y"].max()) + 1
                return EventStream(z["x"], z["y"], t, p, w, h, meta)
        if fmt == "txt":
            with open(path) as f:
                w, h = (int(v) for v in f.readline().split()[:2])
            rows = np.loadtxt(path, skiprows=1, ndmin=2)
            t = np.rint(rows[:, 0] * 1e6).astype(np.int64)
            return EventStream(rows[:, 1], rows[:, 2], t, np.where(rows[:, 3] > 0, 1, -1), w, h, {})
        return _read_aedat4(path)
    except EventFieldError:
        raise
    except Exception as e:  # corrupt or foreign file
        raise EventFieldError(f"{path}: cannot read as {fmt} event file: {e}") from None


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


def _read_aedat4(path):
    import dv_processing as dv
    rec = dv.io.MonoCameraRecording(path)
    w, h = rec.getEventResolution()
    parts = []
    while True:
        batch = rec.getNextEventBatch()
        if batch is None:
            break
        parts.append(batch.numpy())
    arr = np.concatenate(parts) if parts else np.zeros(0, dtype=[("timestamp", "<i8"), ("x", "<i2"), ("y", "<i2"),
                                                                  ("polarity", "i1")])
    return EventStream(arr["x"], arr["y"], arr["timestamp"], np.where(arr["polarity"] > 0, 1, -1), w, h,
                       {"camera": rec.getCameraName()})
