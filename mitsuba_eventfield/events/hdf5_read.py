"""Reading DSEC-layout HDF5 event files (``io`` has the layout): whole, a time window, or the little that
``eventfield info`` prints, the last two without holding the columns whole.

A 1280x720 render of a few seconds holds 10^8-10^9 events (13 bytes each in memory, more while converting):
`info` and `preview` of a 10 ms window read all of them, gigabytes for a line of text or one picture. A window
is found by bisection on ``/events/t`` (a few dozen element reads, each decompressing one chunk of HDF5's cache)
and only its rows are read; ``info`` reads the columns a block at a time, checking each as a whole read would. Bisection needs time order, which a file holding ``/ms_to_idx`` has (the DSEC
index is made of sorted events; our writer refuses unsorted chunks); a file without it is read whole and
windowed after its order is checked, as before."""
from __future__ import annotations

import bisect
import json
import warnings

import numpy as np

from ..errors import EventFieldError
from .stream import EventStream

READ_BLOCK = 1 << 22        # rows read at once where the whole file is checked and counted (``info``)


class _Column:
    """A dataset's values as a sequence for ``bisect``: each item one element read."""

    def __init__(self, dataset):
        self.dataset = dataset

    def __len__(self) -> int:
        return self.dataset.shape[0]

    def __getitem__(self, i: int) -> int:
        return int(self.dataset[i])


def _open(f, path: str):
    """(events group, t_offset, metadata, width, height) of an open file; width None for a foreign file."""
    if "events" not in f:
        raise EventFieldError(f"{path}: no /events group (not a DSEC-layout event file)")
    lengths = [f["events"][k].shape[0] for k in "xytp"]       # (before any part is read: a part's would be 0s)
    if len(set(lengths)) > 1:
        raise EventFieldError(f"{path}: event stream: x, y, t, p must have one length (got "
                              f"{', '.join(map(str, lengths))})")
    meta, w, h = {}, None, None
    if "eventfield" in f:
        g = f["eventfield"]
        meta = json.loads(g.attrs["meta_json"])
        w, h = int(g.attrs["width"]), int(g.attrs["height"])
    return f["events"], int(f["t_offset"][()]) if "t_offset" in f else 0, meta, w, h


def _foreign_size(path: str, ev, meta: dict) -> tuple:
    """A foreign DSEC file keeps no sensor size: the data's, said (a crop read as the sensor). The largest
    coordinates of the whole file, read a block at a time, whatever part of it is read."""
    n = ev["x"].shape[0]
    w = max((int(ev["x"][i:i + READ_BLOCK].max()) + 1 for i in range(0, n, READ_BLOCK)), default=0)
    h = max((int(ev["y"][i:i + READ_BLOCK].max()) + 1 for i in range(0, n, READ_BLOCK)), default=0)
    warnings.warn(f"{path}: no sensor size in the file (a DSEC-layout file without /eventfield): taken as {w}x{h} "
                  "from its largest coordinates; light fields need the sensor's own", stacklevel=4)
    meta["sensor_size"] = "from the largest coordinates"
    return w, h


def _rows(path: str, ev, t_offset: int, meta: dict, w, h, rows: slice) -> EventStream:
    from .io import polarity_of
    if w is None:
        w, h = _foreign_size(path, ev, meta)
    t = ev["t"][rows].astype(np.int64) + t_offset
    return EventStream(ev["x"][rows], ev["y"][rows], t, polarity_of(ev["p"][rows]), w, h, meta)


def _whole_span(ev, t_offset: int, meta: dict) -> dict:
    """``meta`` with the whole file's ``t_start_us`` / ``duration_us`` where it records none, from its first and
    last events: what ``EventStream.start_us`` / ``duration_us`` would give on the whole file, kept for a part
    (whose ``time_window`` then records its own span in both)."""
    meta = dict(meta)
    n = ev["t"].shape[0]
    if n:
        first, last = int(ev["t"][0]) + t_offset, int(ev["t"][n - 1]) + t_offset
        whole = EventStream([0, 0], [0, 0], [first, last], [1, 1], 1, 1, meta)
        meta.update(t_start_us=whole.start_us, duration_us=whole.duration_us)
    return meta


def read_h5(path: str, window: tuple | None = None) -> EventStream:
    """The events of ``path``; with ``window`` = (t0_us, t1_us) (either None: open) those with t0 <= t < t1, as
    ``EventStream.time_window`` gives them (its span in the metadata), reading only their rows where the file
    holds ``/ms_to_idx``."""
    import h5py
    window = None if window is None or tuple(window) == (None, None) else tuple(window)
    with h5py.File(path, "r") as f:
        ev, t_offset, meta, w, h = _open(f, path)
        if window is None or "ms_to_idx" not in f:
            stream = _rows(path, ev, t_offset, meta, w, h, slice(None))
            if window is not None:
                from .io import _check_time_order
                _check_time_order(stream)
            return stream if window is None else stream.time_window(*window)
        t0, t1 = window
        column = _Column(ev["t"])
        i0 = 0 if t0 is None else bisect.bisect_left(column, int(np.ceil(t0)) - t_offset)
        i1 = len(column) if t1 is None else bisect.bisect_left(column, int(np.ceil(t1)) - t_offset, lo=i0)
        part = _rows(path, ev, t_offset, _whole_span(ev, t_offset, meta), w, h, slice(i0, i1))
        return part.time_window(t0, t1)


def _checked_on_count(path: str, ev, t_offset: int, w: int, h: int) -> int:
    """The ON events of the whole file, read a block at a time, each block checked as a whole read checks the
    stream (coordinates on the sensor, polarity values, time order, within and across blocks): ``info`` read
    only the first and last events and took an unsorted file's, or one with x past its sensor, as valid."""
    from .io import _check_time_order
    on, last = 0, None
    for i in range(0, ev["t"].shape[0], READ_BLOCK):
        part = _rows(path, ev, t_offset, {}, w, h, slice(i, i + READ_BLOCK))
        _check_time_order(part, offset=i, before=last)
        on += int(np.count_nonzero(part.p > 0))
        last = int(part.t[-1])
    return on


def h5_summary(path: str, count: bool = True) -> tuple[dict | None, EventStream]:
    """(``EventStream.summary`` of the file, an EventStream of its first and last events with its metadata and
    span), reading the columns a block at a time (``_checked_on_count``), none whole; ``count`` False: no
    summary (None), only the two events read."""
    import h5py
    with h5py.File(path, "r") as f:
        ev, t_offset, meta, w, h = _open(f, path)
        n = ev["t"].shape[0]
        ends = _rows(path, ev, t_offset, meta, w, h, slice(0, 0))   # (two events have the whole file's span)
        if n:
            rows = [slice(0, 1)] + ([slice(n - 1, n)] if n > 1 else [])
            ends = EventStream.concatenate([_rows(path, ev, t_offset, ends.meta, ends.width, ends.height, r)
                                            for r in rows])
        if not count:
            return None, ends
        on = _checked_on_count(path, ev, t_offset, ends.width, ends.height)
    return EventStream.summary_of(n, on, ends.width, ends.height, ends.duration_us), ends
