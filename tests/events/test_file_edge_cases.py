"""Event files at their edges (a reviewer's findings, 2026-11-26): late starts, values that wrapped around, chunks
that were never checked, foreign files out of order, and writers used after they were closed. Each case is a
file that reads back as what went in, or one line naming the file before anything is written."""
import errno
import os

import h5py
import numpy as np
import pytest
from conftest import AEDAT4

import mitsuba_eventfield as ef
from mitsuba_eventfield.cli.main import main as cli
from mitsuba_eventfield.events.hdf5 import H5EventWriter
from mitsuba_eventfield.events.stream import EventStream


def _stream(t, x=None, width=64, height=48, meta=None):
    t = np.asarray(t, np.int64)
    n = len(t)
    x = np.arange(n) % width if x is None else x
    return EventStream(x, np.arange(n) % height, t, np.where(np.arange(n) % 2, -1, 1), width, height, meta or {})


def _index(t_rel, entries):
    """DSEC's ms_to_idx: the first event at or after each millisecond of the stored (relative) times."""
    return np.searchsorted(t_rel, 1000 * np.arange(entries), side="left")


def test_a_late_start_is_stored_from_t_offset(tmp_path):
    """Three events at t = 1e11 us made an 800 MB file (an index entry for every millisecond since t = 0)."""
    ev = _stream([10**11, 10**11 + 5, 10**11 + 7000])
    path = str(tmp_path / "late.h5")
    ef.write_events(path, ev)
    assert os.path.getsize(path) < 100_000
    with h5py.File(path) as f:
        offset, t_rel, index = int(f["t_offset"][()]), f["events"]["t"][()], f["ms_to_idx"][()]
    assert offset == 10**11 and np.array_equal(t_rel + offset, ev.t)
    assert np.array_equal(index, _index(t_rel, len(index))) and len(index) == 8
    assert ef.read_events(path).equals(ev)
    early = _stream([-2500, -100, 3000])                 # before zero: an offset below the first event
    ef.write_events(str(tmp_path / "early.h5"), early)
    with h5py.File(tmp_path / "early.h5") as f:
        assert int(f["t_offset"][()]) == -3000 and f["events"]["t"][0] == 500
    assert ef.read_events(str(tmp_path / "early.h5")).equals(early)


def test_a_render_from_zero_keeps_a_zero_offset(tmp_path):
    """A stream whose metadata starts at 0 (every render) is stored as before: t_offset 0."""
    ev = _stream([1200, 1500, 2600], meta={"t_start_us": 0, "duration_us": 4000})
    ef.write_events(str(tmp_path / "r.h5"), ev)
    with h5py.File(tmp_path / "r.h5") as f:
        assert int(f["t_offset"][()]) == 0 and list(f["ms_to_idx"][()]) == [0, 0, 2, 3, 3]


def test_the_index_covers_start_plus_duration(tmp_path):
    """``duration_us`` is a duration: a stream from 5 ms for 10 ms is indexed to 15 ms (it stopped at 10)."""
    ev = _stream([5200, 9000, 14100], meta={"t_start_us": 5000, "duration_us": 10000})
    ef.write_events(str(tmp_path / "d.h5"), ev)
    with h5py.File(tmp_path / "d.h5") as f:
        offset, index = int(f["t_offset"][()]), f["ms_to_idx"][()]
    assert offset == 5000 and len(index) == 11 and index[-1] == 3 and index[4] == 1


@pytest.mark.parametrize("columns, message", [
    (([65539], [0], [0], [1]), r"x = 65539: allowed range is \[0, 65535\]"),
    (([1], [0], [0], np.array([255], np.uint8)), r"p = 255: allowed range is \[-128, 127\]"),
    (([1], [0], [1.9], [1]), "t must be whole numbers"),
    (([1.7], [0], [0], [1]), "x must be whole numbers"),
    (([1], [0], [1e19], [1]), r"t = 1e\+19: allowed range"),
    (([1], [0], np.array([2**63 + 1], np.uint64), [1]), "t = 9223372036854775809: allowed range"),
])
def test_values_are_refused_not_wrapped(columns, message):
    with pytest.raises(ef.ConfigError, match=message):
        EventStream(*columns, 640, 480)
    assert EventStream([1.0], [2.0], [3.0], [1.0], 640, 480).x.tolist() == [1]     # whole floats are fine


@pytest.mark.parametrize("columns, message", [
    (([100], [1], [5], [1]), r"coordinates exceed the 4x4 sensor \(x up to 100"),
    (([1, 2], [1], [5, 6], [1, 1]), r"x, y, t, p must have one length \(got 2, 1, 2, 2\)"),
    (([1], [1], [5], [np.nan]), "p contains NaN"),
    (([-1], [1], [5], [1]), "x = -1: coordinates must be >= 0"),
])
def test_a_writer_checks_each_chunk_before_writing_it(tmp_path, columns, message):
    for name in ("a.h5", "a.npz", "a.txt"):
        path = str(tmp_path / name)
        with pytest.raises(ef.ConfigError, match=f"^{path}: append: {message}"):
            with ef.events.io.open_writer(path, ef.events.io.format_of(path), 4, 4) as w:
                w.append(*columns)
    assert os.listdir(tmp_path) == []


def test_order_is_checked_across_chunks(tmp_path):
    """Two chunks each sorted, the second starting before the first ends: refused by every writer."""
    for name in ("a.h5", "a.npz", "a.txt"):
        path = str(tmp_path / name)
        with pytest.raises(ValueError, match="in time order"):
            with ef.events.io.open_writer(path, ef.events.io.format_of(path), 8, 8) as w:
                w.append([1, 2], [1, 2], [100, 200], [1, -1])
                w.append([1, 2], [1, 2], [150, 300], [1, -1])
    assert os.listdir(tmp_path) == []


def test_a_closed_writer_and_a_broken_promise(tmp_path):
    path = str(tmp_path / "w.h5")
    w = H5EventWriter(path, 8, 8)
    w.append([1], [1], [1000], [1], complete_until_us=5000)
    with pytest.raises(ValueError, match="before complete_until_us = 5000 us"):
        w.append([1], [1], [2000], [1])         # the index up to 5 ms was written as final already
    w.append([2], [2], [6000], [-1])
    w.close()
    with pytest.raises(ef.EventFieldError, match=r"w\.h5: the event writer is closed"):
        w.append([1], [1], [7000], [1])
    with h5py.File(path) as f:       # from the first event's millisecond: t_offset 1000 us
        assert int(f["t_offset"][()]) == 1000 and list(f["ms_to_idx"][()]) == [0, 1, 1, 1, 1, 1]
    assert len(ef.read_events(path)) == 2


def test_foreign_files_out_of_order_or_malformed_are_one_line(tmp_path):
    with h5py.File(tmp_path / "unsorted.h5", "w") as f:
        g = f.create_group("events")
        for k, v in (("x", [1, 2, 3]), ("y", [1, 1, 1]), ("t", [3000, 1000, 2000]), ("p", [1, 0, 1])):
            g.create_dataset(k, data=np.asarray(v, np.uint16 if k in "xy" else np.int64 if k == "t" else np.uint8))
    (tmp_path / "nan.txt").write_text("640 480\nnan 5 6 1\n")
    (tmp_path / "noheader.txt").write_text("100 5 6 1\n200 7 8 0\n")
    np.savez(tmp_path / "meta.npz", x=np.array([1], np.uint16), y=np.array([1], np.uint16), t=np.array([5]),
             p=np.array([1], np.int8), width=4, height=4, meta_json="[1, 2]")
    cases = {"unsorted.h5": "events are not in time order: event 1 at t = 1000 us follows 3000 us",
             "nan.txt": "t contains NaN", "noheader.txt": "the first line must be 'width height'",
             "meta.npz": "meta_json holds a JSON list, not an object"}
    for name, message in cases.items():
        path = str(tmp_path / name)
        with pytest.raises(ef.EventFieldError, match=f"^{path}: .*{message}"):
            ef.read_events(path)


def test_recordings_refuse_what_their_words_cannot_hold(tmp_path):
    pytest.importorskip("faery")
    unsorted = _stream([5, 3])
    with pytest.raises(ef.EventFieldError, match=r"a\.raw: events must be in time order"):
        ef.write_events(str(tmp_path / "a.raw"), unsorted)
    for name, width, side in (("w.raw", 3000, 2048), ("w.dat", 20000, 16384)):
        # EVT 3.0 wrote x modulo 2048 for sensors of 2049 to 4096 pixels: x = 2999 read back as 951
        wide = _stream([1, 2], x=[0, width - 1], width=width)
        with pytest.raises(ef.EventFieldError, match=f"a {width}x48 sensor: .* holds sensors of 1 to {side} pixels"):
            ef.write_events(str(tmp_path / name), wide)
    assert os.listdir(tmp_path) == []


def test_aedat4_refuses_what_the_format_cannot_hold(tmp_path):
    pytest.importorskip("faery")                    # (the AEDAT4 writer; the GPU image lacks it)
    with pytest.raises(ef.EventFieldError, match=r"a 40000x48 sensor: AEDAT4 holds sensors of 1 to 32767"):
        ef.write_events(str(tmp_path / "a.aedat4"), _stream([1], width=40000))
    with pytest.raises(ef.EventFieldError, match="AEDAT4 holds timestamps >= 0 only"):     # a user's data: one line
        ef.write_events(str(tmp_path / "a.aedat4"), _stream([-5, 3]))
    assert os.listdir(tmp_path) == []


def test_stream_helpers_on_odd_arguments(tmp_path, capsys):
    ev = _stream([1, 2, 3])
    assert ev.equals(None) is False and ev.equals("x") is False
    with pytest.raises(ef.ConfigError, match="no streams given"):
        EventStream.concatenate([])
    for bad in ("a", float("nan")):
        with pytest.raises(ef.ConfigError, match="time_window: t0_us"):
            ev.time_window(bad)
    assert _stream([1, 2], meta={"duration_us": "abc"}).summary()["duration_s"] == pytest.approx(1e-6)
    huge = EventStream.empty(65536, 65536)
    with pytest.raises(ef.EventFieldError, match=r"p\.png: a preview of 65536x65536 pixels at scale 1 needs"):
        ef.write_preview(str(tmp_path / "p.png"), huge)
    negative = _stream([-5000, -4000, -1000])
    ef.write_events(str(tmp_path / "n.h5"), negative)
    assert cli(["preview", str(tmp_path / "n.h5"), "-o", str(tmp_path / "n.png"), "--t0", "-4.5"]) == 0
    assert "2 events in the window" in capsys.readouterr().out


def test_partials_left_under_a_writers_own_suffix_are_removed(tmp_path, capsys):
    """A SIGKILLed .npz render leaves its columns as <partial>.npz.x, ...; faery leaves <partial>.raw.write:
    the next write to the same path removes them as it removes our own partial files."""
    dead = 4_000_000           # above the kernel's pid limit: no such process
    left = [f"o.partial-{dead}-abc123.npz.{k}" for k in "xytp"] + [f"r.partial-{dead}-abc123.raw.write"]
    for name in left:
        (tmp_path / name).write_bytes(b"left")
    ef.write_events(str(tmp_path / "o.npz"), _stream([1, 2]))
    pytest.importorskip("faery")
    ef.write_events(str(tmp_path / "r.raw"), _stream([1, 2]))
    assert sorted(os.listdir(tmp_path)) == ["o.npz", "r.raw"]
    assert capsys.readouterr().err.count("left by an interrupted run") == 5


def test_whole_floats_at_the_top_of_a_column_are_taken():
    """x = 65535.0 is a valid coordinate on the largest sensor; t = 2^63 as a float is past int64."""
    ev = EventStream([65535.0], [0.0], [2.0 ** 62], [1.0], 65536, 10)
    assert ev.x.tolist() == [65535] and ev.t.tolist() == [2 ** 62]
    with pytest.raises(ef.ConfigError, match=r"t = 9\.223372036854776e\+18: allowed range"):
        EventStream([1], [0], [2.0 ** 63], [1], 640, 480)


class _FullDiskOnClose:
    """A file whose close flushes into a full disk: it closes, then raises ENOSPC (as io does)."""

    def __init__(self, f):
        self.f = f

    def __getattr__(self, name):
        return getattr(self.f, name)

    def close(self):
        self.f.close()
        raise OSError(28, "No space left on device")


@pytest.mark.parametrize("suffix", [".txt", ".npz"])
def test_abort_on_a_full_disk_leaves_nothing(tmp_path, suffix):
    """A disk-full render said "nothing was kept" but left its .txt, or the .npz's four column files: closing
    the partial file flushed into the full disk again and the error skipped their removal."""
    from mitsuba_eventfield.events.streaming import NpzEventWriter, TxtEventWriter
    path = str(tmp_path / f"out{suffix}")
    w = (TxtEventWriter if suffix == ".txt" else NpzEventWriter)(path, 8, 6)
    w.append(np.array([1, 2], np.uint16), np.array([3, 4], np.uint16), np.array([5, 6], np.int64),
             np.array([1, -1], np.int8))
    if suffix == ".txt":
        w.f = _FullDiskOnClose(w.f)
    else:
        w.columns = {k: _FullDiskOnClose(f) for k, f in w.columns.items()}
    assert len(os.listdir(tmp_path)) >= 1
    w.abort()
    assert os.listdir(tmp_path) == []


def test_an_aedat4_past_the_file_size_limit_is_one_line_not_an_abort(tmp_path):
    """Under ``ulimit -f`` (a file-size limit; a quota behaves alike but cannot be seen) dv-processing's writer
    thread met EFBIG and aborted the whole process (exit 134, a partial file left). The limit is checked with
    the free space before each chunk: one line, no file; under no limit the same write is taken."""
    pytest.importorskip("faery")                    # (the AEDAT4 writer; the GPU image lacks it)
    import resource
    import subprocess
    import sys
    script = tmp_path / "write.py"
    script.write_text(
        "import sys, numpy as np, mitsuba_eventfield as ef\n"
        "n = int(sys.argv[2]) if len(sys.argv) > 2 else 300_000\n"
        "rng = np.random.default_rng(0)\n"
        "ev = ef.EventStream(rng.integers(0, 64, n), rng.integers(0, 48, n), np.sort(rng.integers(0, 10**6, n)),\n"
        "                    rng.choice([-1, 1], n), 64, 48)\n"
        "try:\n"
        "    ef.write_events(sys.argv[1], ev)\n"
        "    print('written')\n"
        "except ef.EventFieldError as e:\n"
        "    print('refused:', e)\n")
    out = tmp_path / "out"
    out.mkdir()

    def limited():
        resource.setrlimit(resource.RLIMIT_FSIZE, (2 << 20, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
    r = subprocess.run([sys.executable, str(script), str(out / "o.aedat4")], capture_output=True, text=True,
                       preexec_fn=limited, timeout=300)
    assert r.returncode == 0, (r.returncode, r.stderr[-2000:])
    assert "refused:" in r.stdout and "file-size limit (ulimit -f) is 2097152 bytes" in r.stdout, r.stdout
    assert os.listdir(out) == []
    r = subprocess.run([sys.executable, str(script), str(out / "o.aedat4")], capture_output=True, text=True,
                       timeout=300)
    assert "written" in r.stdout and os.listdir(out) == ["o.aedat4"]
    # a file far below the limit is taken (the free-space margin, 1 MiB, refused ten events under 1 MiB)
    def one_mib():
        resource.setrlimit(resource.RLIMIT_FSIZE, (1 << 20, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
    r = subprocess.run([sys.executable, str(script), str(out / "small.aedat4"), "10"], capture_output=True,
                       text=True, preexec_fn=one_mib, timeout=300)
    assert "written" in r.stdout and os.path.getsize(out / "small.aedat4") < 4096, (r.stdout, r.stderr[-500:])


def test_a_quota_refuses_an_aedat4_chunk_before_the_encoder_sees_it(tmp_path, monkeypatch):
    """A user quota (a cluster's home) is not in the free-space figure: dv-processing's writer thread (the
    AEDAT4 writer before faery's) met EDQUOT and aborted the process. Each chunk's bytes are reserved first; a
    refusal is the one line, in this process, with nothing left beside the output (no partial file, no probe)."""
    pytest.importorskip("faery")                    # (the AEDAT4 writer; the GPU image lacks it)
    from mitsuba_eventfield.events import disk
    reserved = []

    def reserve(fd, size):              # the quota grants the header, then refuses the first chunk
        reserved.append(size)
        return 0 if len(reserved) == 1 else errno.EDQUOT
    monkeypatch.setattr(disk, "_reserve", reserve)
    n = 3 * disk.WRITE_CHUNK
    rng = np.random.default_rng(0)
    ev = ef.EventStream(rng.integers(0, 64, n), rng.integers(0, 48, n), np.sort(rng.integers(0, 10**6, n)),
                        rng.choice([-1, 1], n), 64, 48)
    path = str(tmp_path / "o.aedat4")
    with pytest.raises(ef.EventFieldError) as err:
        ef.write_events(path, ev)
    assert str(err.value).startswith(f"{path}: disk quota exceeded: the file system refused about ")
    assert "\n" not in str(err.value) and len(reserved) == 2 and reserved[1] > 16 * disk.WRITE_CHUNK
    assert os.listdir(tmp_path) == []


def test_the_aedat4_encoders_own_refusal_is_the_one_line(tmp_path):
    """Past the checks (a limit they could not see), faery's encoder meets EFBIG and says it in words only
    ("File too large (os error 27)", no errno): the line says file too large, not "disk full" with 40 GiB
    free, and nothing is left."""
    pytest.importorskip("faery")                    # (the AEDAT4 writer; the GPU image lacks it)
    import subprocess
    import sys
    script = ("import resource, sys, numpy as np, mitsuba_eventfield as ef\n"
              "from mitsuba_eventfield.events import streaming\n"
              "for k in ('check_space', 'check_room', 'check_file_limit'):\n"
              "    setattr(streaming, k, lambda *a, **kw: None)\n"
              "resource.setrlimit(resource.RLIMIT_FSIZE, (1 << 20, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))\n"
              "n = 300_000\n"
              "rng = np.random.default_rng(0)\n"
              "ev = ef.EventStream(rng.integers(0, 64, n), rng.integers(0, 48, n), np.sort(rng.integers(0, 10**6, n)),\n"
              "                    rng.choice([-1, 1], n), 64, 48)\n"
              "try:\n"
              "    ef.write_events(sys.argv[1], ev)\n"
              "except ef.EventFieldError as e:\n"
              "    print(e)\n")
    out = tmp_path / "out"
    out.mkdir()
    r = subprocess.run([sys.executable, "-c", script, str(out / "o.aedat4")], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.startswith(f"{out / 'o.aedat4'}: file too large: ") and "disk full" not in r.stdout, r.stdout
    assert os.listdir(out) == []


def test_the_room_probe_meets_the_kernels_refusal(tmp_path):
    """The reservation is the real system call: under a 2 MiB file-size limit the kernel refuses a 4 MiB
    reservation (EFBIG) and grants a 100 kB one; the probe file is gone either way."""
    import subprocess
    import sys
    script = ("import resource, sys\n"
              "from mitsuba_eventfield.events import disk\n"
              "resource.setrlimit(resource.RLIMIT_FSIZE, (2 << 20, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))\n"
              "out, part = sys.argv[1], sys.argv[1] + '.partial'\n"
              "disk.check_room(out, part, 100_000)\n"
              "print('granted')\n"
              "try:\n"
              "    disk.check_room(out, part, 4 << 20)\n"
              "except Exception as e:\n"
              "    print(type(e).__name__, e)\n")
    path = str(tmp_path / "o.aedat4")
    r = subprocess.run([sys.executable, "-c", script, path], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.splitlines() == ["granted", f"EventFieldError {path}: file too large: the file system or the "
                                     "process's file-size limit (ulimit -f) refused about 4 MiB more"], r.stdout
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("ext", [".npz", ".txt", ".h5"])
def test_a_refused_write_names_what_it_needed(tmp_path, ext):
    """100 events (a few kB) under a 1000-byte file-size limit: the line said "refused about 1.06 MiB more",
    the free-space margin added to what the write needed. Now the write's own size, headers included."""
    import resource
    import subprocess
    import sys
    script = ("import sys, numpy as np, mitsuba_eventfield as ef\n"
              "ev = ef.EventStream(np.arange(100) % 64, np.arange(100) % 48, np.arange(100) * 10,\n"
              "                    np.where(np.arange(100) % 2, 1, -1), 64, 48)\n"
              "try:\n"
              "    ef.write_events(sys.argv[1], ev)\n"
              "except ef.EventFieldError as e:\n"
              "    print(e)\n")

    def limited():
        resource.setrlimit(resource.RLIMIT_FSIZE, (1000, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
    out = tmp_path / "out"
    out.mkdir()
    r = subprocess.run([sys.executable, "-c", script, str(out / f"e{ext}")], capture_output=True, text=True,
                       preexec_fn=limited, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "file too large" in r.stdout and "KiB more" in r.stdout and "MiB" not in r.stdout, r.stdout
    assert os.listdir(out) == []


def test_each_aedat4_chunk_is_in_the_file_when_append_returns_and_its_room_was_asked_first(tmp_path, monkeypatch):
    """dv-processing wrote on a thread of its own, so a chunk's reservation had to hold the one before it too.
    faery's encoder writes each packet before ``append`` returns: the file has grown by the chunk (LZ4 keeps
    these dense events under their 16 bytes, never above the 17 reserved), and each reservation is the chunk's
    own bytes plus a header's."""
    pytest.importorskip("faery")                    # (the AEDAT4 writer; the GPU image lacks it)
    from mitsuba_eventfield.events import disk
    from mitsuba_eventfield.events.streaming import AEDAT4_BYTES_PER_EVENT, open_writer
    reserved = []
    monkeypatch.setattr(disk, "_reserve", lambda fd, size: reserved.append(size) or 0)
    n = disk.WRITE_CHUNK
    sizes = []
    with open_writer(str(tmp_path / "o.aedat4"), "aedat4", 64, 48) as w:
        for k in range(3):
            t = np.arange(k * n, (k + 1) * n)
            w.append(t % 64, t % 48, t, np.where(t % 2, 1, -1))
            sizes.append(os.path.getsize(w.tmp))
    need = AEDAT4_BYTES_PER_EVENT * n + disk.HEADER_BYTES
    assert reserved == [disk.HEADER_BYTES, need, need, need]
    grown = np.diff([0] + sizes)
    assert all(n < g < 16 * n for g in grown), grown          # the packet (compressed), not a buffer's share
    assert len(ef.read_events(str(tmp_path / "o.aedat4"))) == 3 * n


def test_a_timelens_npz_is_read_with_its_size_said(tmp_path):
    """A TimeLens-style npz (``timestamp`` in microseconds, ``polarity`` 0 / 1, no sensor size): times rounded
    to the microsecond, the sensor taken from the largest coordinates (x up to 5, y up to 3: 6x4) with a
    warning, as the DSEC reader says it; without events and size, one line."""
    path = tmp_path / "tl.npz"
    np.savez(path, x=np.array([0, 5], np.uint16), y=np.array([0, 3], np.uint16), timestamp=np.array([10.6, 20.4]),
             polarity=np.array([0, 1]))
    with pytest.warns(UserWarning, match=r"tl\.npz: no sensor size in the file \(no width / height\): taken as 6x4"):
        ev = ef.read_events(str(path))
    assert (ev.width, ev.height) == (6, 4) and list(ev.t) == [11, 20] and list(ev.p) == [-1, 1]
    assert ev.meta["sensor_size"] == "from the largest coordinates"
    np.savez(path, x=np.zeros(0, np.uint16), y=np.zeros(0, np.uint16), timestamp=np.zeros(0), polarity=np.zeros(0))
    with pytest.raises(ef.EventFieldError, match=r"tl\.npz: .*no events and no width / height"):
        ef.read_events(str(path))


@pytest.mark.parametrize("ext", [".txt", ".npz", AEDAT4, ".h5"])
def test_closing_twice_or_after_abort_does_nothing(tmp_path, ext):
    """As H5EventWriter: a second close, or a close after abort, is a no-op (the AEDAT4 writer raised KeyError,
    the npz writer FileNotFoundError, leaving its partial file beside the output)."""
    from mitsuba_eventfield.events.streaming import open_writer
    t = np.arange(10)
    for ending in ("close", "abort"):
        path = tmp_path / f"{ending}{ext}"
        w = open_writer(str(path), ext[1:], 64, 48)
        w.append(t % 64, t % 48, t, np.where(t % 2, 1, -1))
        w.close() if ending == "close" else w.abort()
        w.close()
        assert [n for n in os.listdir(tmp_path) if n.startswith(ending)] == ([path.name] if ending == "close" else [])
