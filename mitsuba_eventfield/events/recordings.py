"""Event-camera recordings through faery (https://github.com/aestream/faery): Prophesee RAW (EVT 2.0, 2.1, 3.0),
Prophesee DAT, and AEDAT4 (iniVation / dv), read and written.

A Prophesee file starts with a text header, lines beginning with ``%`` (``% evt 3.0``, ``% format
EVT3;width=1280;height=720``, ``% geometry 640x480``, ``% Version 2``, ``% Width 640`` ...), then binary
words: EVT 3.0 16-bit, EVT 2.0 32-bit, EVT 2.1 64-bit; DAT has one byte of event type and one of event size
(8) after the header. The header is checked here before faery decodes the body, so an empty, foreign or cut
file is one line (``BadFile``): RAW and DAT have no event count, so a cut is found when it splits a word.

Timestamps are microseconds as the camera counted them (faery adds a header's ``% t0``); the stream's
``t_start_us`` is its first event. Recordings carry no optics: the light-field commands take them from a
calibration file (``--calibration``)."""
from __future__ import annotations

import os
import re

import numpy as np

from ..atomic import atomic_output
from ..errors import EventFieldError
from .disk import HEADER_BYTES, BadFile, check_space, disk_errors
from .stream import EventStream, first_out_of_order

RECORDING_FORMATS = {".raw": "raw", ".evt": "raw", ".dat": "dat"}
EVT_VERSIONS = ("evt2", "evt2.1", "evt3")
WORD_BYTES = {"evt2": 4, "evt2.1": 8, "evt3": 2}
MAX_HEADER = 1 << 20            # a longer "header" is not one (a text file that happens to start with %)
FAERY_PARTIAL = ".write"         # faery writes to <name>.write and renames it when done
RECORDING_BYTES_PER_EVENT = 8   # an upper bound: DAT and EVT 2.1 use 8, EVT 2.0 4 (+ time words), EVT 3.0 2-6


def _header(path: str) -> tuple:
    """(header text, its length in bytes) of a Prophesee file: the leading lines that start with ``%``."""
    size = os.path.getsize(path)
    if size == 0:
        raise BadFile("empty file (0 bytes)")
    with open(path, "rb") as f:
        if f.read(1) != b"%":
            raise BadFile("not a Prophesee file (no '%' header line at its start)")
        lines, pos = [], 0
        while pos < min(size, MAX_HEADER):
            f.seek(pos)
            if f.read(1) != b"%":
                break
            f.seek(pos)
            line = f.readline(MAX_HEADER)
            if not line.endswith(b"\n"):
                raise BadFile(f"truncated Prophesee header (it stops mid-line at byte {size})")
            lines.append(line.decode("latin-1").strip())
            pos = f.tell()
            if lines[-1].lower() == "% end":
                break
    return "\n".join(lines), pos


def _evt_version(header: str, named: str | None) -> str:
    m = re.search(r"^%\s*evt\s+(2\.0|2\.1|3\.0)\s*$", header, re.M | re.I) or \
        re.search(r"^%\s*format\s+EVT(2|21|3)\b", header, re.M | re.I)
    found = {"2.0": "evt2", "2": "evt2", "2.1": "evt2.1", "21": "evt2.1", "3.0": "evt3", "3": "evt3"}.get(
        m[1] if m else None)
    if found and named and found != named:
        raise BadFile(f"its header says {found}, not {named} as asked")
    if not (found or named):
        raise BadFile("its header names no EVT version ('% evt 3.0' or '% format EVT3'): name it, "
                      "read_events(path, 'evt2' | 'evt2.1' | 'evt3')")
    return found or named


def _size_of(header: str):
    """(width, height) from a Prophesee header, or None when it gives none. Width and height are read each on
    its own, in either order: Metavision writes ``format EVT3;height=720;width=1280`` and a DAT header
    ``% Height`` before ``% Width`` (read in one order only, such files took the events' extent as the sensor:
    a 96x72 recording read 94x71, and its depth came out 10 % far). A header whose ``geometry`` and width /
    height disagree is refused (the geometry was taken without a word: which one the sensor is, no reader can
    tell)."""
    m = re.search(r"geometry\s+(\d+)x(\d+)", header, re.I)
    geometry = (int(m[1]), int(m[2])) if m else None
    found = {}
    for key in ("width", "height"):
        m = re.search(rf"(?:^%\s*|[;,:\s]){key}(?:\s*=\s*|\s+)(\d+)", header, re.M | re.I)
        if m:
            found[key] = int(m[1])
    named = (found["width"], found["height"]) if len(found) == 2 else None
    if geometry and named and geometry != named:
        raise BadFile(f"its header gives two sensor sizes: geometry {geometry[0]}x{geometry[1]} and width / height "
                      f"{named[0]}x{named[1]}")
    return geometry or named


def check_recording(path: str, fmt: str) -> dict:
    """What ``read_recording`` needs from a RAW / DAT file's header (``fmt``: raw, evt2, evt2.1, evt3, dat),
    its body checked for a cut word; raises ``BadFile``."""
    header, end = _header(path)
    body = os.path.getsize(path) - end
    if fmt == "dat":
        m = re.search(r"^%\s*Version\s+(\d)", header, re.M | re.I)
        version = "dat1" if m and m[1] == "1" else "dat2"
        word = 8
        if body == 1:
            raise BadFile("truncated DAT file (its event type and size bytes are cut)")
        with open(path, "rb") as f:
            f.seek(end)
            kind = f.read(2)
        if len(kind) == 2 and kind[1] != word:
            raise BadFile(f"not a DAT file of CD events (event size {kind[1]} bytes, expected {word})")
        body = max(0, body - 2)
    else:
        version = _evt_version(header, None if fmt == "raw" else fmt)
        word = WORD_BYTES[version]
    if body % word:
        raise BadFile(f"truncated {version.upper()} file ({body} bytes of events after the header, not a whole "
                      f"number of {word}-byte words)")
    return {"version": version, "size": _size_of(header), "header": header}


def _stream(decoder, size, meta, where: str = "the recording") -> EventStream:
    packets = [p for p in decoder if len(p)]
    import faery
    a = np.concatenate(packets) if packets else np.empty(0, faery.EVENTS_DTYPE)
    if size is None:                          # no size in the header: the events' extent, said (as for DSEC)
        size = (int(a["x"].max()) + 1, int(a["y"].max()) + 1) if len(a) else decoder.dimensions()
        meta["sensor_size"] = "from the largest coordinates"
        import warnings
        warnings.warn(f"{where}: no sensor size in its header: taken as {size[0]}x"
                      f"{size[1]} from its largest coordinates; light fields need the sensor's own", stacklevel=3)
    t = a["t"].astype(np.int64)
    if len(t):
        meta.setdefault("t_start_us", int(t[0]))
    return EventStream(a["x"], a["y"], t, np.where(a["on"], 1, -1).astype(np.int8), int(size[0]), int(size[1]),
                       meta)


def read_recording(path: str, fmt: str) -> EventStream:
    """A Prophesee RAW (``fmt`` raw: the version from the header; or evt2, evt2.1, evt3) or DAT (``dat``) file."""
    import faery
    info = check_recording(path, fmt)
    decoder = faery.events_stream_from_file(path, version_fallback=info["version"],
                                            file_type="dat" if fmt == "dat" else "evt")
    return _stream(decoder, info["size"], {"recording": {"format": info["version"], "header": info["header"]}}, path)


def read_aedat4_faery(path: str) -> EventStream:
    """The first event track of an AEDAT4 file (faery decodes in-process, 6x faster than dv-processing, and
    answers a damaged packet with an error where dv-processing can spin forever)."""
    import faery
    decoder = faery.events_stream_from_file(path, file_type="aedat")
    return _stream(decoder, decoder.dimensions(), {})


# Bits of microseconds a format's words hold: EVT 3.0 24 (TIME_HIGH and TIME_LOW words, 12 bits each), EVT 2.0
# 34 (TIME_HIGH's 28 bits above an event's 6), DAT 32. Times past that wrap, and a reader must count the wraps.
# faery's EVT 3.0 round trip lost them wherever events were sparse (1 s apart over 20 s read back 16.0 s for
# 19.0 s; a 30 s gap; checked 2026-11-26 with faery's own reader), and no reader can count the wraps before a
# stream's first event: times then go in relative to the header's t0 (which faery's reader adds back).
TIME_BITS = {"evt3": 24, "evt2": 34, "dat2": 32}
VERSION_NAMES = {"evt3": "EVT 3.0", "evt2": "EVT 2.0", "dat2": "DAT"}
# The largest sensor side each format's words hold: EVT 2.0 and 3.0 keep x and y in 11 bits, DAT in 14. faery
# refuses larger sensors, except EVT 3.0 from 2049 to 4096 pixels, where it wrote x modulo 2048 (checked
# 2026-11-26: x = 4094 read back as 2046).
SENSOR_LIMIT = {"evt3": 2048, "evt2": 2048, "dat2": 16384}


def recording_version(path: str, events: EventStream, fmt: str) -> str:
    """The faery version that holds ``events``' timestamps exactly: ``raw`` is EVT 3.0 for streams spanning less
    than 2^24 us (16.8 s) and EVT 2.0 for longer ones; an explicit version (or DAT) that cannot hold the span is
    one line."""
    version = "dat2" if fmt == "dat" else ("evt3" if fmt == "raw" else fmt)
    if version == "evt2.1":
        raise EventFieldError(f"{path}: writing EVT 2.1 is not supported (faery reads it, writes evt2 and evt3)")
    span = int(events.t.max()) - int(events.t.min()) if len(events) else 0
    if span >= 1 << TIME_BITS[version]:
        if fmt == "raw":
            return "evt2"
        hold = (1 << TIME_BITS[version]) / 1e6
        raise EventFieldError(f"{path}: the events span {span / 1e6:.6g} s: {VERSION_NAMES[version]} timestamps hold "
                              f"less than {hold:.6g} s; write .raw (EVT 2.0 for long streams) or .h5")
    return version


def write_recording(path: str, events: EventStream, fmt: str) -> None:
    """RAW (``fmt`` raw: EVT 3.0, or EVT 2.0 past its span, :func:`recording_version`; or evt2, evt3) or DAT
    (dat2) through faery. Timestamps go into the words as they are where they fit them, so readers that ignore
    the header's t0 see the same times; past that, relative to the header's t0 (``TIME_BITS``). Metadata is
    not kept."""
    import faery
    if len(events) and int(events.t.min()) < 0:
        raise EventFieldError(f"{path}: {fmt} files hold timestamps >= 0 only (the stream starts at "
                              f"{int(events.t.min())} us)")
    version = recording_version(path, events, fmt)
    side = SENSOR_LIMIT[version]
    if not (0 < events.width <= side and 0 < events.height <= side):
        raise EventFieldError(f"{path}: a {events.width}x{events.height} sensor: {VERSION_NAMES[version]} holds "
                              f"sensors of 1 to {side} pixels a side")
    if first_out_of_order(events.t) is not None:
        raise EventFieldError(f"{path}: events must be in time order to be written as {VERSION_NAMES[version]}")
    relative = len(events) > 0 and int(events.t.max()) >= 1 << TIME_BITS[version]
    a = np.zeros(len(events), faery.EVENTS_DTYPE)
    a["t"], a["x"], a["y"], a["on"] = events.t, events.x, events.y, events.p > 0
    need = RECORDING_BYTES_PER_EVENT * len(events) + HEADER_BYTES
    check_space(path, need)
    with atomic_output(path, "event file") as tmp, disk_errors(path, need):
        try:
            faery.events_stream_from_array(a, (events.width, events.height)).to_file(
                tmp, version=version, zero_t0=relative, file_type="dat" if fmt == "dat" else "evt")
        except Exception as e:       # whatever faery still refuses: one line, and its own partial file gone
            if os.path.exists(tmp + FAERY_PARTIAL):
                os.remove(tmp + FAERY_PARTIAL)
            raise EventFieldError(f"{path}: cannot write {VERSION_NAMES[version]}: {' '.join(str(e).split())[:200]}") \
                from None
