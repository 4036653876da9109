"""Event files: HDF5 in the DSEC layout, TimeLens npz, E2VID text, AEDAT4 (all four streamed while rendering), and the
event cameras' own recordings: Prophesee RAW (EVT 2.0 / 2.1 / 3.0) and DAT (``recordings.py``, through faery).

HDF5 layout (DSEC, plus our metadata)::

    /events/x   uint16        /events/y  uint16
    /events/t   int64  microseconds relative to /t_offset (DSEC uses uint32; int64 never wraps)
    /events/p   uint8  1 = ON, 0 = OFF  (DSEC's convention; in memory we use +1/-1)
    /t_offset   int64  microseconds: the recording's first millisecond (its t_start_us, else its first event)
    /ms_to_idx  uint64 ms_to_idx[m] = index of the first event with t >= m*1000 (t as stored: from t_offset)
    /eventfield         group; attrs: width, height, format_version, meta_json (all metadata as JSON)

The event datasets are deflate (gzip) compressed with the shuffle filter: filters built into every HDF5 library,
so h5dump, MATLAB, Julia or C read the files as they are (LZF, used before, is an h5py plugin; those files
still read here). docs/design.md "Event file compression" has the measurements behind the level.

Every writer is atomic: the file appears under its name only once complete (``atomic.py``), and checks the free
disk space before each chunk, so a full disk is one ``EventFieldError`` rather than a crash in HDF5 (a segfault
on ENOSPC; dv-processing, which wrote AEDAT4 before faery, aborted from its writer thread).
"""
from __future__ import annotations

import json
import os
import re
import warnings

import numpy as np

from .._version import __version__
from ..errors import ConfigError, EventFieldError
from ..validate import file_path, instance, number
from .aedat import read_aedat4, write_aedat4  # noqa: F401  (re-exported)
from .disk import DISK_MARGIN, HEADER_BYTES, WRITE_CHUNK, BadFile, GuardedFile, check_space, disk_errors  # noqa: F401
from .hdf5 import H5_BYTES_PER_EVENT, H5_GZIP_LEVEL, H5EventWriter, _json  # noqa: F401
from .hdf5_read import h5_summary, read_h5
from .recordings import EVT_VERSIONS, RECORDING_FORMATS, read_aedat4_faery, read_recording, write_recording
from .stream import EventStream, first_out_of_order
from .streaming import AEDAT4_BYTES_PER_EVENT, BYTES_PER_EVENT, NPZ_BYTES_PER_EVENT, open_writer  # noqa: F401

FORMATS = {".h5": "h5", ".hdf5": "h5", ".npz": "npz", ".txt": "txt", ".aedat4": "aedat4", **RECORDING_FORMATS}
# formats named by the caller only: a RAW file of a given EVT version (when its header does not say)
NAMED_FORMATS = set(EVT_VERSIONS)


# formats whose timestamps are unsigned: a stream starting before 0 s cannot be written to them
UNSIGNED_TIME_FORMATS = {"aedat4", *RECORDING_FORMATS.values(), *NAMED_FORMATS}


def format_of(path: str, fmt: str | None = None, t_first_s: float | None = None) -> str:
    """The event format of ``path`` (its extension, or ``fmt`` where given and consistent with it). With
    ``t_first_s``, the first instant the events may have (a render's start, a conversion's first frame): a
    format that holds no negative time is refused before any work, not after the events are made."""
    fmt = _format_of(path, fmt)
    if t_first_s is not None and t_first_s < 0 and fmt in UNSIGNED_TIME_FORMATS:
        raise EventFieldError(f"{path}: {fmt} files hold timestamps >= 0 only (the events start at "
                              f"{t_first_s:.6g} s): choose .h5, .npz or .txt, or shift the times")
    return fmt


def _format_of(path: str, fmt: str | None) -> str:
    if fmt:
        if fmt not in set(FORMATS.values()) | NAMED_FORMATS:
            allowed = sorted(set(FORMATS.values()) | NAMED_FORMATS)
            raise EventFieldError(f"{path}: unknown event format '{fmt}'; allowed: {', '.join(allowed)}")
        named = FORMATS.get(os.path.splitext(path)[1].lower())
        # a format the extension contradicts made a zip named .h5, which read_events then refused
        if named is not None and named != fmt and not (named == "raw" and fmt in NAMED_FORMATS):
            raise EventFieldError(f"{path}: format '{fmt}' does not match the extension (a '{named}' file)")
        return fmt
    ext = os.path.splitext(path)[1].lower()
    if ext not in FORMATS:
        raise EventFieldError(f"{path}: unknown event file extension '{ext}'; allowed: " + ", ".join(FORMATS))
    return FORMATS[ext]


def write_events(path: str, events: EventStream, fmt: str | None = None) -> str:
    """Write a whole stream; the format follows the extension (.h5/.hdf5, .npz, .txt, .aedat4, .raw = EVT 3.0,
    .dat) or ``fmt`` (evt2, evt2.1, evt3 for a RAW file of that version). RAW, DAT, AEDAT4 and text keep no
    metadata (AEDAT4's reader gives the first event's time as ``t_start_us``). HDF5, npz, text and AEDAT4 go
    through the same chunk writers a render streams to (``streaming.py``)."""
    path = file_path(path, "write_events: path")
    instance(events, EventStream, "write_events: events", "ef.read_events, ef.render_events, ef.EventStream")
    fmt = format_of(path, fmt)
    meta = dict(events.meta)
    meta.setdefault("package_version", __version__)
    if fmt in ("raw", "dat") or fmt in NAMED_FORMATS:
        write_recording(path, events, fmt)
        return os.path.abspath(path)
    if fmt in BYTES_PER_EVENT:       # the whole file's size is known: refuse before writing anything
        check_space(path, BYTES_PER_EVENT[fmt] * len(events) + len(_json(meta)) + HEADER_BYTES)
    with open_writer(path, fmt, events.width, events.height, meta) as w:
        for i in range(0, max(len(events), 1), WRITE_CHUNK):
            s = slice(i, i + WRITE_CHUNK)
            w.append(events.x[s], events.y[s], events.t[s], events.p[s])
        # the recorded span ends at t_start_us + duration_us (a duration, not an end time: a stream starting at
        # 5 ms had its index stop 5 ms early)
        start = events.start_us
        w.close(end_us=max(start + events.duration_us, int(events.t[-1]) if len(events) else start))
    return os.path.abspath(path)


# How each format's files start: checked before a library parses them, since dv-processing answers an empty or
# foreign file with a C++ stack trace and NumPy takes any non-zip file for a pickle
_SIGNATURES = {"h5": (b"\x89HDF\r\n\x1a\n",), "npz": (b"PK\x03\x04", b"PK\x05\x06"), "aedat4": (b"#!AER-DAT4.0",)}
_FORMAT_NAMES = {"h5": "HDF5", "npz": "npz (zip)", "txt": "E2VID text", "aedat4": "AEDAT4"}


def _check_file(path: str, fmt: str) -> None:
    size = os.path.getsize(path)
    name = _FORMAT_NAMES[fmt]
    if size == 0:
        raise BadFile("empty file (0 bytes)")
    with open(path, "rb") as f:
        head = f.read(18)
        if fmt == "h5" and not head.startswith(_SIGNATURES["h5"]):
            # HDF5 allows a user block before the signature, at 512, 1024, 2048, ... bytes
            offsets = [512 << k for k in range(32) if (512 << k) < size]
            if not any(f.seek(o) == o and f.read(8) == _SIGNATURES["h5"][0] for o in offsets):
                raise BadFile("not an HDF5 file (no HDF5 signature)")
    if fmt in ("npz", "aedat4") and not head.startswith(_SIGNATURES[fmt]):
        raise BadFile(f"not an {name} file (it does not start with {_SIGNATURES[fmt][0]!r})")
    if fmt == "aedat4":  # "#!AER-DAT4.0\r\n", the header's length (int32), the header
        header_end = 18 + int.from_bytes(head[14:18], "little") if len(head) == 18 else None
        if header_end is None or not 18 < header_end <= size:
            raise BadFile(f"truncated or damaged AEDAT4 file (its header needs "
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
    if "End-Of-File" in text or "failed to fill whole buffer" in text:   # dv-processing; faery (Rust's read_exact)
        return "truncated (unexpected end of file)"
    if text.startswith("LZ4 error") or text.startswith("Zstd error"):   # faery on a damaged AEDAT4 packet
        return f"damaged packet ({text})"
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


def read_events(path: str, fmt: str | None = None, window: tuple | None = None) -> EventStream:
    """Read an event file (format by extension, or ``fmt``: evt2 / evt2.1 / evt3 names a RAW file's version when
    its header does not). A missing, empty, truncated or foreign file raises ``EventFieldError`` with one line
    naming the file and the problem. AEDAT4 is decoded by faery (in-process; dv-processing when faery is not
    installed), RAW and DAT by faery. ``window`` = (t0_us, t1_us), either None for an open end: only the events
    with t0 <= t < t1, as ``EventStream.time_window`` gives them; an HDF5 file's other rows are not read
    (``hdf5_read``), other formats are read whole first."""
    path, fmt = _event_file(path, fmt)
    if window is not None:
        window = tuple(window) if isinstance(window, (tuple, list)) else (window,)
        if len(window) != 2:
            raise ConfigError(f"read_events: window = {window!r}: expected (t0_us, t1_us), either None")
        window = tuple(None if v is None else number(v, f"read_events: window {name}", strict=True)
                       for v, name in zip(window, ("t0_us", "t1_us")))
        if None not in window and window[1] < window[0]:
            raise ConfigError(f"read_events: window = {window!r}: t1_us is before t0_us")
    return _reading(path, fmt, lambda: _read(path, fmt, window))


def summarize_events(path: str, fmt: str | None = None, count: bool = True) -> tuple[dict | None, EventStream]:
    """(``EventStream.summary`` of an event file, an EventStream whose first and last events, span and metadata
    are the file's): an HDF5 file's columns are never held whole (read and checked a block at a time; only its
    first and last events when ``count`` is False, which gives no summary), other formats are read whole."""
    path, fmt = _event_file(path, fmt)
    if fmt == "h5":
        return _reading(path, fmt, lambda: _checked(path, fmt, lambda: h5_summary(path, count)))
    stream = read_events(path, fmt)
    return (stream.summary() if count else None), stream


def _event_file(path, fmt) -> tuple:
    path = file_path(path, "read_events: path")
    if not os.path.isfile(path):
        raise EventFieldError(f"{path}: a folder, not an event file (image frames become events through "
                              "'eventfield convert')" if os.path.isdir(path) else f"{path}: no such event file")
    return path, format_of(path, fmt)


def _checked(path, fmt, read):
    _check_file(path, fmt)
    return read()


def _read(path, fmt, window):
    if fmt in ("raw", "dat") or fmt in NAMED_FORMATS:
        stream = read_recording(path, fmt)
    elif fmt == "h5":
        stream = _checked(path, fmt, lambda: read_h5(path, window))
        window = None                                       # (read_h5 windowed it, its order checked)
    else:
        stream = _checked(path, fmt, lambda: _read_npz(path) if fmt == "npz" else _read_txt(path) if fmt == "txt"
                          else _read_aedat4(path))
    if fmt not in ("raw", "dat") and fmt not in NAMED_FORMATS:
        _check_time_order(stream)
    return stream if window is None else stream.time_window(*window)


def _reading(path, fmt, read):
    """``read()``, its failures as the one line naming the file."""
    try:
        return read()
    except ConfigError as e:         # the stream's own checks, which know no file name
        raise EventFieldError(f"{path}: {e}") from None
    except EventFieldError:
        raise
    except Exception as e:  # corrupt or foreign file
        raise EventFieldError(f"{path}: cannot read as {fmt} event file: {_one_line(e)}") from None


def _check_time_order(stream, offset: int = 0, before: int | None = None) -> None:
    """Files are read as they are, and everything downstream (time windows, the index, light fields) takes the
    events in time order: an unsorted foreign file's window [1000, 2500) held its event at 3000. ``offset``,
    ``before``: ``stream`` is a block of a file read in blocks, starting at event ``offset``, after an event at
    ``before`` us."""
    t, i = stream.t, first_out_of_order(stream.t)
    if before is not None and len(t) and t[0] < before:
        i, previous = 0, before
    elif i is not None:
        previous = int(t[i - 1])
    if i is not None:
        raise ConfigError(f"events are not in time order: event {offset + i} at t = {int(t[i])} us follows "
                          f"{previous} us (sort the file by t)")


def _read_aedat4(path):
    import importlib.util
    if importlib.util.find_spec("faery") is None:
        return read_aedat4(path)
    return read_aedat4_faery(path)


def polarity_of(values) -> np.ndarray:
    """+1 / -1 polarities from a file's column: -1/+1, or 0/1 (0: OFF, as E2VID text files and many tools write
    them); anything else refused (the text reader took 2 and 5 as ON; the npz reader refused the 0/1 that text
    files hold)."""
    v = np.asarray(values)
    if v.size:               # min / max and one pass each: np.unique sorted every event of a large file
        lo, hi = v.min(), v.max()
        whole = v.dtype.kind in "iub" or bool(np.all(v == np.rint(v)))
        if not (whole and ((lo >= 0 and hi <= 1) or (lo >= -1 and hi <= 1 and not np.any(v == 0)))):
            odd = ", ".join(f"{x:g}" for x in np.unique(v)[:5])       # (the error's words only)
            raise BadFile(f"polarity values {odd}: expected -1 / +1 or 0 / 1 (0: OFF)")
    return np.where(v > 0, 1, -1).astype(np.int8)


def _read_npz(path):
    with np.load(path, allow_pickle=False) as z:
        if "frames" in z and "x" not in z:      # a frame stack ("missing entry 'timestamp'" said nothing of it)
            raise BadFile("a frame stack ('frames'), not events: convert it first (eventfield convert "
                          f"{os.path.basename(path)} -o EVENTS.h5)")
        if "t" in z:
            t, p = z["t"], polarity_of(z["p"])
        else:  # a TimeLens file written elsewhere
            t, p = np.rint(z["timestamp"]).astype(np.int64), polarity_of(z["polarity"])
        meta = json.loads(str(z["meta_json"])) if "meta_json" in z else {}
        if not isinstance(meta, dict):
            raise BadFile(f"meta_json holds a JSON {type(meta).__name__}, not an object")
        w, h = (int(z[k]) if k in z else None for k in ("width", "height"))
        if w is None or h is None:    # a TimeLens / foreign npz: the data's, said (as the DSEC reader says it)
            x, y = z["x"], z["y"]
            if not len(x):
                raise BadFile("no events and no width / height: the sensor's size is unknown")
            w, h = (int(x.max()) + 1 if w is None else w), (int(y.max()) + 1 if h is None else h)
            warnings.warn(f"{path}: no sensor size in the file (no width / height): taken as {w}x{h} from its "
                          "largest coordinates; light fields need the sensor's own", stacklevel=3)
            meta["sensor_size"] = "from the largest coordinates"
        return EventStream(z["x"], z["y"], t, p, w, h, meta)


def _read_txt(path):
    with open(path) as f:
        size = f.readline().split()
    if len(size) != 2 or not (size[0].isdigit() and size[1].isdigit()) or min(int(size[0]), int(size[1])) < 1:
        raise BadFile(f"not an E2VID text event file: the first line must be 'width height' (each >= 1), got "
                       f"{' '.join(size)[:40]!r}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)   # "input contained no data": a stream without events
        rows = np.loadtxt(path, skiprows=1, ndmin=2)
    rows = rows.reshape(0, 4) if rows.size == 0 else rows
    if rows.shape[1] != 4:
        raise BadFile(f"truncated or malformed: expected 4 columns 't x y p' per line, got {rows.shape[1]}")
    t = np.rint(rows[:, 0] * 1e6)          # as floats: EventStream refuses NaN, inf and out-of-range times
    return EventStream(rows[:, 1], rows[:, 2], t, polarity_of(rows[:, 3]), int(size[0]), int(size[1]), {})


