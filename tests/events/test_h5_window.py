"""An HDF5 event file read in part (events/hdf5_read.py): a time window or the summary gives what reading the
whole file and cutting it gives, reading only the window's rows."""
import h5py
import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.cli import main as cli
from mitsuba_eventfield.events.io import summarize_events


def _stream(n, start=0, meta=None, seed=0):
    rng = np.random.default_rng(seed)
    t = start + np.sort(rng.integers(0, 50_000, n))
    return ef.EventStream(rng.integers(0, 64, n), rng.integers(0, 48, n), t, rng.choice([-1, 1], n), 64, 48,
                          meta if meta is not None else {"t_start_us": start - 700, "duration_us": 52_000})


def _same(a, b):
    assert a.equals(b) and a.meta == b.meta and (a.start_us, a.duration_us) == (b.start_us, b.duration_us)


WINDOWS = [(None, None), (0, None), (None, 10_000), (12_345, 12_346), (12_345.5, 30_000.2), (-5_000, 1_000),
           (49_000, 90_000), (60_000, 70_000), (-9_000, -8_000), (20_000, 20_000), (0, 52_000)]


@pytest.mark.parametrize("meta", [None, {}], ids=["span recorded", "no span"])
def test_a_window_of_the_file_is_the_window_of_the_stream(tmp_path, meta):
    ev = _stream(20_000, meta=meta)
    path = str(tmp_path / "e.h5")
    ef.write_events(path, ev)
    whole = ef.read_events(path)
    rng = np.random.default_rng(3)
    picks = [tuple(sorted(rng.integers(-2_000, 55_000, 2))) for _ in range(40)]
    for t0, t1 in WINDOWS + picks + [(int(ev.t[k]), int(ev.t[k + 1])) for k in (0, 99, 19_998)]:
        _same(ef.read_events(path, window=(t0, t1)), whole.time_window(t0, t1))


def test_few_events_and_none(tmp_path):
    for n in (0, 1, 2):
        path = str(tmp_path / f"e{n}.h5")
        ef.write_events(path, _stream(n, start=100))
        whole = ef.read_events(path)
        for window in WINDOWS:
            _same(ef.read_events(path, window=window), whole.time_window(*window))
        s, ends = summarize_events(path)
        assert s == whole.summary() and ends.meta == whole.meta and list(ends.t) == list(whole.t)


def test_a_window_reads_only_its_rows(tmp_path, monkeypatch):
    """1 ms of a 2M-event file: a few dozen single elements (the bisection) and the window's rows, not the
    columns (the whole file was read for a preview of 10 ms); the summary reads the columns a block at a time."""
    n = 2_000_000
    rng = np.random.default_rng(1)
    ev = ef.EventStream(rng.integers(0, 64, n), rng.integers(0, 48, n), np.sort(rng.integers(0, 10 ** 7, n)),
                        rng.choice([-1, 1], n), 64, 48)
    path = str(tmp_path / "big.h5")
    ef.write_events(path, ev)
    read = []
    original = h5py.Dataset.__getitem__

    def counting(self, key):
        out = original(self, key)
        read.append(np.size(out))
        return out
    monkeypatch.setattr(h5py.Dataset, "__getitem__", counting)
    part = ef.read_events(path, window=(5_000_000, 5_001_000))
    inside = int(np.count_nonzero((ev.t >= 5_000_000) & (ev.t < 5_001_000)))
    assert len(part) == inside and np.array_equal(part.t, ev.t[(ev.t >= 5_000_000) & (ev.t < 5_001_000)])
    assert sum(read) < 4 * inside + 200, sum(read)
    read.clear()
    from mitsuba_eventfield.events import hdf5_read
    monkeypatch.setattr(hdf5_read, "READ_BLOCK", 1 << 18)
    s, _ = summarize_events(path)
    # every column checked (as a whole read checks it), a block at a time: never more than a block in memory
    assert s == ev.summary() and max(read) <= 1 << 18 and sum(read) < 4 * n + 100


def test_a_foreign_file_without_the_index_is_checked_whole(tmp_path):
    """No /ms_to_idx (a foreign DSEC-like file): its order is not known, so it is read whole and its order
    checked before the window is cut: an unsorted one is refused, not bisected into a wrong window."""
    path = tmp_path / "foreign.h5"
    with h5py.File(path, "w") as f:
        f["events/t"] = np.array([10, 30, 20, 40], np.int64)
        f["events/x"] = np.array([0, 1, 2, 3], np.uint16)
        f["events/y"] = np.zeros(4, np.uint16)
        f["events/p"] = np.array([1, 0, 1, 1], np.uint8)
    with pytest.warns(UserWarning, match="no sensor size"), \
            pytest.raises(ef.EventFieldError, match="foreign.h5: events are not in time order"):
        ef.read_events(str(path), window=(15, 35))
    with h5py.File(path, "a") as f:
        f["events/t"][...] = [10, 20, 30, 40]
    with pytest.warns(UserWarning, match=r"taken as 4x1"):
        part = ef.read_events(str(path), window=(15, 35))
    assert list(part.t) == [20, 30] and (part.width, part.height) == (4, 1)
    with pytest.warns(UserWarning, match=r"taken as 4x1"):
        s, ends = summarize_events(str(path))
    assert (s["events"], s["on"], s["width"]) == (4, 3, 4) and list(ends.t) == [10, 40]


def test_bad_windows_are_one_line(tmp_path):
    path = str(tmp_path / "e.h5")
    ef.write_events(path, _stream(10))
    for window, says in (((5,), "expected .t0_us, t1_us."), (("a", 1), "window t0_us"), ((9, 3), "t1_us is before"),
                         ((float("nan"), None), "window t0_us")):
        with pytest.raises(ef.ConfigError, match=f"read_events: .*{says}"):
            ef.read_events(path, window=window)


def test_info_and_preview_of_a_file_read_in_part(tmp_path, capsys):
    """The command line's info and preview on HDF5 (read in part) say what they say of the same events in npz
    (read whole)."""
    ev = _stream(5_000, start=2_000)
    outputs = {}
    for ext in (".h5", ".npz"):
        path = str(tmp_path / f"e{ext}")
        ef.write_events(path, ev)
        assert cli(["info", path]) == 0
        assert cli(["preview", path, "-o", str(tmp_path / f"p{ext}.png"), "--t0", "10", "--t1", "20"]) == 0
        assert cli(["preview", path, "-o", str(tmp_path / f"q{ext}.png"), "--t0", "90"]) == 2
        out, err = capsys.readouterr()
        outputs[ext] = (out.replace(path, "FILE").replace(f"p{ext}", "P"), err.replace(path, "FILE"))
    assert outputs[".h5"] == outputs[".npz"] and "events in the window" in outputs[".h5"][0]
    assert "covers 1.3 to 53.3 ms" in outputs[".h5"][1]
    import cv2
    assert np.array_equal(cv2.imread(str(tmp_path / "p.h5.png")), cv2.imread(str(tmp_path / "p.npz.png")))


@pytest.mark.parametrize("case", ["unsorted", "polarity", "off the sensor", "lengths"])
def test_info_checks_the_whole_file_a_block_at_a_time(tmp_path, case, monkeypatch):
    """``info`` read only the first and last events: an unsorted file, polarity values 2 and 5 or x past the
    sensor were summarised as valid (a whole read refuses them), and a /events/t one row longer was said as
    "(got 0, 0, 1, 0)". Blocks of 2 rows here, so the faults fall within a block and across blocks."""
    from mitsuba_eventfield.events import hdf5_read
    monkeypatch.setattr(hdf5_read, "READ_BLOCK", 2)
    t, x, p = [1, 2, 3, 4, 5], [0, 1, 2, 3, 0], [1, 0, 1, 1, 0]
    says = {"unsorted": "events are not in time order: event 2 at t = 1 us follows 2 us",
            "polarity": "polarity values (0, 1, )?2, 5", "off the sensor": "coordinates exceed the 4x4 sensor",
            "lengths": r"x, y, t, p must have one length \(got 5, 5, 6, 5\)"}[case]
    if case == "unsorted":
        t = [1, 2, 1, 4, 5]
    elif case == "polarity":
        p = [0, 1, 2, 5, 1]
    elif case == "off the sensor":
        x = [0, 1, 2, 9, 0]
    path = tmp_path / "bad.h5"
    with h5py.File(path, "w") as f:
        f["events/t"] = np.array(t + ([6] if case == "lengths" else []), np.int64)
        f["events/x"], f["events/y"] = np.array(x, np.uint16), np.zeros(5, np.uint16)
        f["events/p"] = np.array(p, np.uint8)
        g = f.create_group("eventfield")
        g.attrs.update(width=4, height=4, meta_json="{}", format_version=1)
    with pytest.raises(ef.EventFieldError, match=says):
        summarize_events(str(path))
    with pytest.raises(ef.EventFieldError, match=says):
        ef.read_events(str(path))                                   # the whole read says the same
