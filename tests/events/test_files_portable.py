"""Files other programs can read (HDF5 with built-in filters, EXR that OpenCV decodes), and files that fail
well: a damaged input or a full disk is one line naming the file, never a stack trace, a crash or a
half-written output."""
import collections
import errno
import json
import os
import re
import subprocess
import sys

import h5py
import numpy as np
import OpenEXR
import pytest
from conftest import AEDAT4

import mitsuba_eventfield as ef
from mitsuba_eventfield.events import disk
from mitsuba_eventfield.events import io as eventio
from mitsuba_eventfield.events import text
from mitsuba_eventfield.images import read_exr, write_exr

FORMATS = [".h5", ".npz", ".txt", AEDAT4]


@pytest.fixture(scope="module")
def stream():
    rng = np.random.default_rng(3)
    n = 20_000
    t = np.sort(rng.integers(0, 50_000, n))
    return ef.EventStream(rng.integers(0, 64, n), rng.integers(0, 48, n), t, rng.choice([-1, 1], n), 64, 48,
                          {"seed": 3, "duration_us": 50_000})


# --- HDF5: deflate + shuffle, which every HDF5 reader has built in -------------------------------------------

def test_h5_event_datasets_use_gzip(tmp_path, stream):
    whole, streamed = str(tmp_path / "whole.h5"), str(tmp_path / "streamed.h5")
    ef.write_events(whole, stream)
    with ef.H5EventWriter(streamed, 64, 48, chunk=4096) as w:
        for k in range(0, len(stream), 3000):
            w.append(stream.x[k:k + 3000], stream.y[k:k + 3000], stream.t[k:k + 3000], stream.p[k:k + 3000])
        w.close()
    for path in (whole, streamed):
        with h5py.File(path, "r") as f:
            for k in "xytp":
                ds = f["events"][k]
                assert (ds.compression, ds.compression_opts, ds.shuffle) == ("gzip", eventio.H5_GZIP_LEVEL, True)
        assert ef.read_events(path).equals(stream)


def test_h5_chunks_deflated_on_threads_are_what_hdf5_itself_stores(tmp_path, stream, monkeypatch):
    """Whole chunks are shuffled and deflated on a thread pool and stored with write_direct_chunk: the bytes of
    a chunk HDF5 compressed itself decode with our inverse of shuffle + deflate (so ``_shuffled`` is HDF5's
    shuffle), and HDF5's own filters decode ours (a plain read gives the events back), from 1 and 3 threads
    (and 0: HDF5's filters throughout), with the partial last chunk left to HDF5."""
    import zlib

    from mitsuba_eventfield.events import hdf5
    hdf5_deflate = hdf5.deflate_chunk
    values = {"x": stream.x, "t": stream.t, "p": (stream.p > 0).astype(np.uint8)}
    with h5py.File(str(tmp_path / "hdf5_own.h5"), "w") as f:
        for k, v in values.items():
            f.create_dataset(k, data=v, chunks=(4096,), compression="gzip", compression_opts=1, shuffle=True)
        for k, v in values.items():
            _, raw = f[k].id.read_direct_chunk((4096,))
            assert zlib.decompress(raw) == bytes(hdf5._shuffled(v[4096:8192]))
            assert zlib.decompress(hdf5.deflate_chunk(v[4096:8192], 1, True)) == zlib.decompress(raw)
    deflated = []                       # the writer's own deflating, counted: HDF5's filters would pass too
    monkeypatch.setattr(hdf5, "deflate_chunk", lambda v, *a: deflated.append(len(v)) or hdf5_deflate(v, *a))
    for threads in (0, 1, 3):
        deflated.clear()
        path = str(tmp_path / f"threads{threads}.h5")
        with ef.H5EventWriter(path, 64, 48, chunk=4096, threads=threads) as w:
            for k in range(0, len(stream), 7000):
                w.append(stream.x[k:k + 7000], stream.y[k:k + 7000], stream.t[k:k + 7000], stream.p[k:k + 7000])
        assert ef.read_events(path).equals(stream)
        assert deflated == ([] if threads == 0 else [4096] * 4 * (len(stream) // 4096))   # 4 columns
        whole = str(tmp_path / f"one_append{threads}.h5")     # 4 whole chunks in one flush: 2 x threads ahead
        with ef.H5EventWriter(whole, 64, 48, chunk=4096, threads=threads) as w:
            w.append(stream.x, stream.y, stream.t, stream.p)
        assert ef.read_events(whole).equals(stream)
        with h5py.File(path, "r") as f:
            ds = f["events"]["t"]
            mask, raw = ds.id.read_direct_chunk((8192,))     # a whole chunk: deflated here, every filter applied
            assert mask == 0 and np.array_equal(np.frombuffer(zlib.decompress(raw), np.uint8).reshape(8, -1).T
                                                .copy().view(np.int64).ravel(), stream.t[8192:12288])
            assert ds.shape == (len(stream),) and len(stream) % 4096     # and a partial last chunk, HDF5's


@pytest.mark.parametrize("coder", ["isal", "zlib"])
def test_h5_chunks_from_either_deflate_read_back(tmp_path, stream, monkeypatch, coder):
    """ISA-L's deflate (python-isal, levels 1-3) and zlib both make the zlib stream HDF5's deflate filter
    decodes: files written on threads with either read back as the stream at every level; ISA-L takes only the
    levels it has (its 0 compresses where zlib's 0 stores; it has no 4-9)."""
    from mitsuba_eventfield.events import hdf5
    levels = []
    if coder == "isal":
        from isal import isal_zlib       # a dependency (setup.cfg): its absence is a failure, not a skip

        class Counted:
            @staticmethod
            def compress(data, level):
                levels.append(level)
                return isal_zlib.compress(data, level)
        monkeypatch.setattr(hdf5, "_isal", Counted)
    else:
        monkeypatch.setattr(hdf5, "_isal", None)
    for level in (0, 1, 3, 6):
        path = str(tmp_path / f"{coder}{level}.h5")
        with ef.H5EventWriter(path, 64, 48, chunk=4096, threads=2, level=level) as w:
            for k in range(0, len(stream), 7000):
                w.append(stream.x[k:k + 7000], stream.y[k:k + 7000], stream.t[k:k + 7000], stream.p[k:k + 7000])
        assert ef.read_events(path).equals(stream)
        with h5py.File(path) as f:
            assert f["events"]["t"].compression_opts == level
    whole = len(stream) // 4096 * 4                     # whole chunks of the four columns, a level
    assert sorted(levels) == ([1] * whole + [3] * whole if coder == "isal" else [])


@pytest.mark.parametrize("setting, deflating_threads", [("0", 0), ("1", 1), (" 3 ", 3)])
def test_writer_threads_from_the_environment(tmp_path, stream, monkeypatch, setting, deflating_threads):
    """``EVENTFIELD_WRITER_THREADS`` sets how many threads deflate a writer's chunks (0: HDF5's own filters on
    the writing thread): the pool's size, and the threads that deflated by name (a pool starts a thread only
    while none is idle, so under load fewer may take part), and the file reads back."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from mitsuba_eventfield.events import hdf5
    real, names, pools = hdf5.deflate_chunk, set(), []
    monkeypatch.setattr(hdf5, "deflate_chunk", lambda v, *a: names.add(threading.current_thread().name)
                        or real(v, *a))

    class Pool(ThreadPoolExecutor):
        def __init__(self, workers, **kw):
            pools.append(workers)
            super().__init__(workers, **kw)
    monkeypatch.setattr(hdf5, "ThreadPoolExecutor", Pool)
    monkeypatch.setenv("EVENTFIELD_WRITER_THREADS", setting)
    path = str(tmp_path / "env.h5")
    with ef.H5EventWriter(path, 64, 48, chunk=1024) as w:
        for k in range(0, len(stream), 5000):
            w.append(stream.x[k:k + 5000], stream.y[k:k + 5000], stream.t[k:k + 5000], stream.p[k:k + 5000])
    assert ef.read_events(path).equals(stream)
    assert pools == ([deflating_threads] if deflating_threads else [])
    assert (0 < len(names) <= deflating_threads or len(names) == deflating_threads == 0) and all(
        n.startswith("h5-deflate") for n in names)


@pytest.mark.parametrize("setting", ["many", "65", "-1", "2.5"])
def test_bad_writer_threads_setting_is_one_line_before_any_file(tmp_path, monkeypatch, setting):
    monkeypatch.setenv("EVENTFIELD_WRITER_THREADS", setting)
    with pytest.raises(ef.ConfigError, match=r"^environment variable EVENTFIELD_WRITER_THREADS = .*\[0, 64\]"):
        ef.H5EventWriter(str(tmp_path / "bad.h5"), 64, 48)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("sizes", [[100, 3000, 1024, 5000, 7, 10_869], [20_000], [1024] * 19 + [544],
                                   [1500, 18_500], [1023, 1, 1025, 17_951]])
def test_appended_pieces_are_joined_only_up_to_a_chunk_boundary(tmp_path, stream, monkeypatch, sizes):
    """A flush joins the waiting remainder with the new piece only up to the first chunk boundary; the rest of
    the piece is deflated from where it lies (no copy of the whole piece on the writer's thread), and the file
    holds the events in order whatever the piece sizes (under, at and over the chunk size)."""
    from mitsuba_eventfield.events import hdf5
    assert sum(sizes) == len(stream)
    real = hdf5.deflate_chunk
    shared = []                         # per deflated t chunk: does it lie in the appended array itself?
    pieces = []

    def deflate(v, *a):
        if v.dtype == np.int64:
            shared.append(any(np.shares_memory(v, q) for q in pieces))
        return real(v, *a)
    monkeypatch.setattr(hdf5, "deflate_chunk", deflate)
    path = str(tmp_path / "pieces.h5")
    with ef.H5EventWriter(path, 64, 48, chunk=1024, threads=2) as w:
        start = 0
        for n in sizes:
            t = stream.t[start:start + n].copy()           # the writer's own copy of the piece, as a chunk is
            pieces.append(t)
            w.append(stream.x[start:start + n], stream.y[start:start + n], t, stream.p[start:start + n])
            start += n
    assert ef.read_events(path).equals(stream)
    assert len(shared) == len(stream) // 1024
    # every chunk past a piece's first boundary comes from the piece itself: with a 1500-event lead, 18
    # of the 18,500-event piece's chunks; one piece alone: all 19
    expected = {(20_000,): 19, (1500, 18_500): 18}.get(tuple(sizes))
    if expected is not None:
        assert sum(shared) == expected


def test_joined_column_slices():
    from mitsuba_eventfield.events.hdf5 import _Joined
    pieces = [np.arange(0, 5), np.arange(5, 30)]
    j = _Joined.of(pieces, 4)                  # lead 5: joined up to 8, the rest a view of the last piece
    assert len(j) == 30 and j.split == 8 and np.shares_memory(j.body, pieces[1])
    for a, b in [(0, 4), (4, 8), (8, 12), (6, 10), (0, 30), (12, 30), (29, 30)]:
        assert np.array_equal(j[a:b], np.arange(a, b))
    assert np.array_equal(j[13:], np.arange(13, 30)) and np.array_equal(j[3:], np.arange(3, 30))
    assert np.array_equal(_Joined.of([np.arange(3), np.arange(3, 5)], 4)[0:5], np.arange(5))   # ends short


def test_old_lzf_files_still_read(tmp_path, stream):
    """Files written before the switch (LZF, an h5py-only filter) keep reading."""
    path = str(tmp_path / "old.h5")
    with h5py.File(path, "w") as f:
        g = f.create_group("events")
        for k, v in (("x", stream.x), ("y", stream.y), ("t", stream.t), ("p", (stream.p > 0).astype(np.uint8))):
            g.create_dataset(k, data=v, chunks=(4096,), maxshape=(None,), compression="lzf")
        f.create_dataset("t_offset", data=np.int64(0))
        e = f.create_group("eventfield")
        e.attrs["width"], e.attrs["height"], e.attrs["meta_json"] = 64, 48, json.dumps({"seed": 3})
    back = ef.read_events(path)
    assert back.equals(stream) and back.meta == {"seed": 3}


# --- EXR: every kind the package writes opens in OpenCV ------------------------------------------------------

def _image(seed, shape=(12, 17)):
    return np.random.default_rng(seed).random(shape).astype(np.float32) * 10


def _exr_kinds():
    depth = _image(1)
    depth[0, :3] = np.nan                                            # "no depth" pixels stay NaN
    return {
        "image": {"Y": _image(0)},                                     # frame, refocus, reconstruct, regression
        "depth": {"depth": depth, "confidence": _image(2)},          # eventfield depth
        "scanrate": {"depth": depth, "confidence": _image(2), "truth": _image(3)},
        "rgb": {"R": _image(4), "G": _image(5), "B": _image(6)},
        "log": {"log": np.log(_image(7) + 1e-3)},                    # eventfield hdr
        "planes": {"events_p0": _image(8), "truth_p0": _image(9), "events_p1": _image(10)},   # highspeed
    }


@pytest.fixture(scope="module")
def exr_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("exr")
    files = {}
    for kind, channels in _exr_kinds().items():
        files[kind] = write_exr(str(d / f"{kind}.exr"), channels, {"kind": kind})
    return files


@pytest.mark.parametrize("kind", list(_exr_kinds()))
def test_exr_round_trip_keeps_names_and_values(exr_files, kind):
    channels, meta = read_exr(exr_files[kind])
    expected = _exr_kinds()[kind]
    assert meta == {"kind": kind} and set(channels) == set(expected)
    for name, value in expected.items():
        np.testing.assert_array_equal(channels[name], value)


@pytest.mark.parametrize("kind", list(_exr_kinds()))
def test_exr_layout_is_one_opencv_decodes(exr_files, kind):
    """Without running OpenCV: a Y or R/G/B channel, 32-bit float pixels, ZIP compression (OpenCV 4.x's
    OpenEXR 2.3 decodes it; the HTJ2K codecs of OpenEXR 3.4 it does not)."""
    with OpenEXR.File(exr_files[kind], separate_channels=True) as f:
        names = set(f.channels())
        assert names & {"Y", "R", "G", "B"}
        assert all(c.pixels.dtype == np.float32 for c in f.channels().values())
        assert f.header()["compression"] == OpenEXR.ZIP_COMPRESSION


def _opencv_with_exr():
    """A PYTHONPATH under which ``import cv2`` decodes EXR, or None. The project's OpenCV (5.0 wheels) is built
    without OpenEXR; an OpenCV 4 wheel installed aside (EVENTFIELD_CV2_EXR, or <venv>/cv2-exr) is used then."""
    probe = "import cv2, re, sys; sys.exit(0 if re.search(r'OpenEXR:\\s+(?!NO)\\S', cv2.getBuildInformation()) else 1)"
    for extra in (os.environ.get("EVENTFIELD_CV2_EXR"), os.path.join(sys.prefix, "cv2-exr"), ""):
        if extra is None or (extra and not os.path.isdir(extra)):
            continue
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (extra, os.environ.get("PYTHONPATH")) if p))
        if subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True).returncode == 0:
            return env["PYTHONPATH"]
    return None


CV2_READ = """
import json, sys
import cv2, numpy as np
out = {}
for kind, path in json.loads(sys.argv[1]).items():
    img = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    out[kind] = None if img is None else [img.dtype.str, list(img.shape), img.astype(np.float64).tolist()]
print(json.dumps(out))
"""


def test_every_exr_kind_reads_in_opencv(exr_files):
    pythonpath = _opencv_with_exr()
    if pythonpath is None:
        pytest.skip("no OpenCV with OpenEXR here (pip install --target .venv/cv2-exr 'opencv-python-headless<5')")
    env = dict(os.environ, PYTHONPATH=pythonpath, OPENCV_IO_ENABLE_OPENEXR="1")
    r = subprocess.run([sys.executable, "-c", CV2_READ, json.dumps(exr_files)], env=env, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    read = json.loads(r.stdout)
    for kind, channels in _exr_kinds().items():
        assert read[kind] is not None, f"{kind}: OpenCV could not read it"
        dtype, shape, values = read[kind]
        if kind == "rgb":      # OpenCV gives B, G, R
            expected = np.dstack([channels["B"], channels["G"], channels["R"]])
        else:                  # the primary image: Y, or the first channel stored as Y
            expected = channels.get("Y", next(iter(channels.values())))
        assert dtype == "<f4" and shape == list(expected.shape), kind
        np.testing.assert_array_equal(np.array(values, dtype=np.float64), expected.astype(np.float64))


def test_cli_luminance_reader_on_each_kind(exr_files):
    from mitsuba_eventfield.cli.inputs import luminance_channel as _luminance_channel
    np.testing.assert_array_equal(_luminance_channel(exr_files["image"]), _exr_kinds()["image"]["Y"])
    rgb = _exr_kinds()["rgb"]                        # a colour frame: its luminance (it was its red channel)
    np.testing.assert_allclose(_luminance_channel(exr_files["rgb"]),
                               0.212671 * rgb["R"] + 0.715160 * rgb["G"] + 0.072169 * rgb["B"], rtol=1e-6)
    with pytest.raises(ef.EventFieldError, match="needs a Y .* it has confidence, depth"):
        _luminance_channel(exr_files["depth"])       # a depth map is not a frame, Y on disk or not


# --- damaged event files: one line, naming the file ----------------------------------------------------------

def _damaged(tmp_path, stream, ext, damage):
    good = str(tmp_path / f"good{ext}")
    ef.write_events(good, stream)
    data = open(good, "rb").read()
    os.remove(good)
    content = {"empty": b"", "truncated_half": data[: len(data) // 2], "truncated_tenth": data[: len(data) // 10],
               "truncated_16_bytes": data[:16], "garbage": np.random.default_rng(0).bytes(3000),
               "text": b"hello world\nthis is not an event file\n"}[damage]
    path = tmp_path / f"{damage}{ext}"
    path.write_bytes(content)
    return str(path)


@pytest.mark.parametrize("ext", FORMATS)
@pytest.mark.parametrize("damage", ["empty", "truncated_half", "truncated_tenth", "truncated_16_bytes", "garbage",
                                    "text"])
def test_damaged_event_file_is_one_line(tmp_path, stream, ext, damage, capfd):
    path = _damaged(tmp_path, stream, ext, damage)
    capfd.readouterr()
    with pytest.raises(ef.EventFieldError) as err:
        ef.read_events(path)
    message = str(err.value)
    assert message.startswith(path + ": ") and "\n" not in message and len(message) < 300, message
    assert "Stacktrace" not in message and ".hpp(" not in message and "Traceback" not in message
    out, errs = capfd.readouterr()
    assert out == "" and errs == ""             # nothing printed on the side (C++ traces, HDF5 error stacks)


def test_damaged_file_on_the_command_line(tmp_path):
    empty = tmp_path / "empty.aedat4"
    empty.write_bytes(b"")
    r = subprocess.run([sys.executable, "-m", "mitsuba_eventfield.cli", "info", str(empty)], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "empty file (0 bytes)" in r.stderr, r.stderr


def _aedat4_body_damaged(tmp_path, stream, damage):
    """A valid AEDAT4 header and data table, the packets after it damaged (64 bytes overwritten, or cut)."""
    pytest.importorskip("faery")                    # (the AEDAT4 writer; the GPU image lacks it)
    good = str(tmp_path / "good.aedat4")
    ef.write_events(good, stream)
    data = bytearray(open(good, "rb").read())
    os.remove(good)
    body = 18 + int.from_bytes(data[14:18], "little")          # after "#!AER-DAT4.0\r\n", length, header
    at = body + (len(data) - body) // 2
    if damage == "overwritten_ff":
        data[at:at + 64] = b"\xff" * 64
    elif damage == "overwritten_random":
        data[body + 1500:body + 1564] = np.random.default_rng(1).bytes(64)
    else:                                                       # cut in the middle of a packet
        del data[at:]
    path = tmp_path / f"{damage}.aedat4"
    path.write_bytes(bytes(data))
    return str(path)


@pytest.mark.needs("dv_processing", "aedat4")
@pytest.mark.parametrize("damage", ["overwritten_ff", "overwritten_random", "truncated_mid_packet"])
def test_aedat4_with_a_damaged_body_is_one_line_never_a_hang(tmp_path, stream, damage):
    """dv-processing spins forever inside one call on some damaged packets (these two among them): the read
    is refused with one line naming the file, in seconds. In a child process, so a hang fails the test."""
    path = _aedat4_body_damaged(tmp_path, stream, damage)
    try:
        r = subprocess.run([sys.executable, "-m", "mitsuba_eventfield.cli", "info", path], capture_output=True,
                           text=True, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail(f"reading {damage} AEDAT4 hung for 60 s")
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and err[0].startswith(f"eventfield: error: {path}: "), r.stderr
    assert "Traceback" not in r.stderr and "Stacktrace" not in r.stderr


@pytest.mark.parametrize("ext", FORMATS)
def test_stream_without_events_round_trips(tmp_path, ext):
    path = str(tmp_path / f"none{ext}")
    ef.write_events(path, ef.EventStream.empty(8, 6, {"duration_us": 1000}))
    back = ef.read_events(path)
    assert len(back) == 0 and (back.width, back.height) == (8, 6)


# --- full disk: one line, nothing left behind ----------------------------------------------------------------

Usage = collections.namedtuple("Usage", "total used free")


def _disk(monkeypatch, free_after, calls_with_room=0):
    """shutil.disk_usage as the writers see it: room for ``calls_with_room`` calls, then ``free_after`` bytes."""
    calls = {"n": 0}

    def disk_usage(path):
        calls["n"] += 1
        free = 1 << 40 if calls["n"] <= calls_with_room else free_after
        return Usage(1 << 41, (1 << 41) - free, free)

    monkeypatch.setattr(disk.shutil, "disk_usage", disk_usage)
    return calls


@pytest.mark.parametrize("ext", FORMATS)
def test_full_disk_refused_before_writing(tmp_path, stream, ext, monkeypatch):
    _disk(monkeypatch, free_after=10_000)
    with pytest.raises(ef.EventFieldError, match=r"disk full: 9.77 KiB free, need about [\d.]+ [KM]iB$") as err:
        ef.write_events(str(tmp_path / f"ev{ext}"), stream)
    assert str(err.value).startswith(str(tmp_path / f"ev{ext}"))
    assert os.listdir(tmp_path) == []


def test_disk_fills_while_streaming(tmp_path, stream, monkeypatch):
    """The streaming writer checks before every chunk: the disk fills after a few, the file is discarded."""
    calls = _disk(monkeypatch, free_after=50_000, calls_with_room=3)
    with pytest.raises(ef.EventFieldError, match="disk full"):
        with ef.H5EventWriter(str(tmp_path / "s.h5"), 64, 48, chunk=2048) as w:
            for k in range(0, len(stream), 1000):
                w.append(stream.x[k:k + 1000], stream.y[k:k + 1000], stream.t[k:k + 1000], stream.p[k:k + 1000])
    assert calls["n"] == 4 and os.listdir(tmp_path) == []


def test_disk_fills_at_close_stops_the_deflating_threads(tmp_path, stream, monkeypatch):
    """The disk fills when close writes the last chunks: the one-line error, no file, and the writer's
    deflating threads stopped (a failed close used to leave them, and the partial file, behind)."""
    import threading
    path = str(tmp_path / "c.h5")
    w = ef.H5EventWriter(path, 64, 48, chunk=2048, threads=2)
    w.append(stream.x, stream.y, stream.t, stream.p)            # whole chunks written through the threads
    assert w._pool is not None
    _disk(monkeypatch, free_after=10_000)
    with pytest.raises(ef.EventFieldError, match="disk full"):
        w.close()
    assert w._pool is None and os.listdir(tmp_path) == []
    assert not [t for t in threading.enumerate() if t.name.startswith("h5-deflate")]


def test_disk_fills_during_render(tmp_path, demo_small, monkeypatch):
    _disk(monkeypatch, free_after=0, calls_with_room=1)        # room to create the file, none to finish it
    with pytest.raises(ef.EventFieldError, match="out.h5: disk full"):
        ef.render_events(demo_small, 0.004, steps=4, output=str(tmp_path / "out.h5"))
    assert os.listdir(tmp_path) == []


REFUSALS = [(errno.ENOSPC, r"disk full: [\d.]+ [KMG]iB free, need about [\d.]+ [KM]iB$"),
            (errno.EDQUOT, r"disk quota exceeded: the file system refused about [\d.]+ [KM]iB more \(a user or "),
            (errno.EFBIG, r"file too large: the file system or the process's file-size limit")]


@pytest.mark.parametrize("code, says", REFUSALS)
@pytest.mark.parametrize("ext, module, writer", [(".npz", np.lib.format, "write_array_header_1_0"),
                                                (".txt", text, "write_lines")])
def test_enospc_from_a_write_is_one_line(tmp_path, stream, ext, module, writer, code, says, monkeypatch):
    """The disk fills between the check and the write (another program), or a quota or file-size limit
    refuses it: the OSError becomes the one line saying which, and the partial file (and the npz writer's
    column files) are gone (a quota's EDQUOT was a traceback)."""
    def no_space(*a, **k):
        raise OSError(code, os.strerror(code))
    monkeypatch.setattr(module, writer, no_space)
    with pytest.raises(ef.EventFieldError, match=says):
        ef.write_events(str(tmp_path / f"ev{ext}"), stream)
    assert os.listdir(tmp_path) == []


HDF5_ENOSPC = """
import errno, io, os, sys
import numpy as np
import mitsuba_eventfield as ef
from mitsuba_eventfield.events import disk, io as eventio
written = [0]
def write_some(self, view):              # the disk (or a quota: errno argv[2]) is full after 40 kB
    if written[0] > 40_000:
        raise OSError(int(sys.argv[2]), os.strerror(int(sys.argv[2])))
    written[0] += len(view)
    return io.FileIO.write(self, view)
disk.GuardedFile._write_some = write_some
rng = np.random.default_rng(0)
n = 200_000
ev = ef.EventStream(rng.integers(0, 64, n), rng.integers(0, 48, n), np.sort(rng.integers(0, 10**6, n)),
                    rng.choice([-1, 1], n), 64, 48)
try:
    ef.write_events(sys.argv[1], ev)
except ef.EventFieldError as e:
    print(e)
"""


@pytest.mark.parametrize("code, says", REFUSALS[:2])
def test_enospc_inside_hdf5_does_not_crash(tmp_path, code, says):
    """HDF5 crashes (segfault) on closing a file whose write failed, so it must never see the failure, a
    quota's EDQUOT included (it reached HDF5): run in a process of its own, where a crash shows as the exit
    status."""
    path = str(tmp_path / "ev.h5")
    r = subprocess.run([sys.executable, "-c", HDF5_ENOSPC, path, str(code)], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, (r.returncode, r.stderr[-2000:])
    assert re.match(re.escape(f"{path}: ") + says.rstrip("$"), r.stdout) and r.stdout.count("\n") == 1, r.stdout
    assert os.listdir(tmp_path) == []
