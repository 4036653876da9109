"""Event-camera recordings in (Prophesee RAW EVT 2.0 / 3.0 and DAT, through faery), files the cameras' software
reads out (AEDAT4 for faery and dv-processing, RAW / DAT for tonic), and the light-field commands on a
recording, which carries no optics: refused in one line without ``--calibration``, run with it."""
import importlib.util
import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield.images import read_exr

faery = pytest.importorskip("faery")

GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")
KINDS = [("evt2", "x.raw"), ("evt3", "x.raw"), ("dat2", "x.dat")]


@pytest.fixture(scope="module")
def stream():
    rng = np.random.default_rng(11)
    n = 30_000
    t = np.sort(rng.integers(1_000, 2_000_000, n))
    return ef.EventStream(rng.integers(0, 640, n), rng.integers(0, 480, n), t, rng.choice([-1, 1], n), 640, 480)


def _faery_file(path, stream, version):
    """A recording as faery's writer (the camera's format, not ours) makes it."""
    a = np.zeros(len(stream), faery.EVENTS_DTYPE)
    a["t"], a["x"], a["y"], a["on"] = stream.t, stream.x, stream.y, stream.p > 0
    faery.events_stream_from_array(a, (stream.width, stream.height)).to_file(str(path), version=version)
    return str(path)


@pytest.mark.parametrize("version,name", KINDS)
def test_recording_reads_exactly(tmp_path, stream, version, name):
    path = _faery_file(tmp_path / name, stream, version)
    back = ef.read_events(path)
    assert (back.width, back.height) == (640, 480) and len(back) == len(stream)
    for k in "xytp":
        assert np.array_equal(getattr(back, k), getattr(stream, k)), k
    assert back.meta["recording"]["format"] == version and back.meta["t_start_us"] == int(stream.t[0])


@pytest.mark.parametrize("ext,fmt", [(".raw", "evt2"), (".raw", "evt3"), (".raw", None), (".dat", None)])
def test_written_recording_round_trips(tmp_path, stream, ext, fmt):
    path = str(tmp_path / f"w{ext}")
    ef.write_events(path, stream, fmt)
    assert ef.read_events(path).equals(stream)
    assert ef.read_events(path, fmt).equals(stream) if fmt else True


def _times(t):
    t = np.asarray(t, np.int64)
    n = len(t)
    return ef.EventStream(np.full(n, 3), np.full(n, 4), t, np.ones(n, np.int8), 32, 24)


@pytest.mark.parametrize("name, t, raw_version", [
    ("starts after 2^24 us", 20_000_000 + np.arange(0, 1_000_000, 1000), "evt3"),
    ("a 30 s gap", [0, 1_000_000, 30_000_000], "evt2"),
    ("sparse past 2^24 us", np.arange(0, 20_000_000, 1_000_000), "evt2"),
    ("starts after 2^32 us", [100_000_000_000, 100_000_001_000], "evt3"),
])
def test_recording_times_past_the_words_range_round_trip(tmp_path, name, t, raw_version):
    """EVT 3.0 words hold 24 bits of microseconds, DAT 32: such streams went in wrapped and came back wrong
    (20.0 s read back as 12.6 s) with exit 0. Now a start past the words' range goes in relative to the
    header's t0, and a .raw spanning 2^24 us or more is EVT 2.0 (34 bits)."""
    ev = _times(t)
    for ext in ("raw", "dat"):
        path = str(tmp_path / f"w.{ext}")
        ef.write_events(path, ev)
        back = ef.read_events(path)
        assert np.array_equal(back.t, ev.t), (name, ext)
        assert back.meta["recording"]["format"] == (raw_version if ext == "raw" else "dat2")


def test_recording_that_cannot_hold_the_span_is_one_line(tmp_path):
    long = _times([0, 1 << 24])                 # one microsecond past EVT 3.0's words
    with pytest.raises(ef.EventFieldError, match=r"x\.raw: the events span 16\.7772 s: EVT 3\.0 timestamps hold "):
        ef.write_events(str(tmp_path / "x.raw"), long, "evt3")
    with pytest.raises(ef.EventFieldError, match=r"x\.dat: the events span 4294\.97 s: DAT timestamps hold "):
        ef.write_events(str(tmp_path / "x.dat"), _times([0, 1 << 32]))
    assert os.listdir(tmp_path) == []


def test_named_version_must_match_the_header(tmp_path, stream):
    path = _faery_file(tmp_path / "a.raw", stream, "evt3")
    with pytest.raises(ef.EventFieldError, match=r"a\.raw: .*header says evt3, not evt2"):
        ef.read_events(path, "evt2")


def _cli_info(path):
    r = subprocess.run([sys.executable, "-m", "mitsuba_eventfield.cli", "info", str(path)], capture_output=True,
                       text=True, timeout=120)
    return r.returncode, r.stderr.strip().splitlines()


@pytest.mark.parametrize("version,name", KINDS)
@pytest.mark.parametrize("damage", ["empty", "cut_mid_word", "cut_in_header", "text"])
def test_damaged_recording_is_one_line(tmp_path, stream, version, name, damage):
    data = open(_faery_file(tmp_path / name, stream, version), "rb").read()
    content = {"empty": b"", "cut_mid_word": data[:-1], "cut_in_header": data[:16],
               "text": b"hello world\nnot events\n"}[damage]
    path = tmp_path / f"{damage}{os.path.splitext(name)[1]}"
    path.write_bytes(content)
    code, err = _cli_info(path)
    assert code == 2 and len(err) == 1 and err[0].startswith(f"eventfield: error: {path}: "), err
    assert "Traceback" not in err[0] and "panicked" not in err[0]


# --- our files in the ecosystem's readers ----------------------------------------------------------------------

def test_our_aedat4_reads_in_faery_and_dv(tmp_path, stream):
    path = str(tmp_path / "ours.aedat4")
    ef.write_events(path, stream)                   # written by faery's encoder, read by dv-processing too
    decoder = faery.events_stream_from_file(path)
    a = np.concatenate(list(decoder))
    assert decoder.dimensions() == (640, 480)
    assert np.array_equal(a["t"], stream.t) and np.array_equal(a["x"], stream.x)
    assert np.array_equal(a["y"], stream.y) and np.array_equal(a["on"], stream.p > 0)
    if importlib.util.find_spec("dv_processing") is None:
        pytest.skip("dv-processing not installed")
    script = ("import sys, dv_processing as dv\nr = dv.io.MonoCameraRecording(sys.argv[1])\nn = 0\n"
              "while (b := r.getNextEventBatch()) is not None:\n    n += len(b)\nprint(n, *r.getEventResolution())")
    out = subprocess.run([sys.executable, "-c", script, path], capture_output=True, text=True, timeout=120)
    assert out.stdout.split() == [str(len(stream)), "640", "480"], out.stderr


@pytest.mark.parametrize("ext", [".raw", ".dat", ".aedat4"])
def test_our_recordings_read_in_faery(tmp_path, stream, ext):
    path = str(tmp_path / f"ours{ext}")
    ef.write_events(path, stream)
    a = np.concatenate(list(faery.events_stream_from_file(path)))
    assert np.array_equal(a["t"].astype(np.int64), stream.t) and np.array_equal(a["x"], stream.x)


@pytest.mark.parametrize("ext", [".h5", ".npz", ".txt", ".aedat4", ".raw", ".dat"])
def test_our_files_in_tonic(tmp_path, stream, ext):
    if importlib.util.find_spec("tonic") is None:
        pytest.skip("tonic is not installed (an optional reader, not a dependency)")
    import tonic.io
    path = str(tmp_path / f"ours{ext}")
    ef.write_events(path, stream)
    readers = {".raw": "read_mvs_events" if hasattr(tonic.io, "read_mvs_events") else None,
               ".dat": "read_dvs_red" if hasattr(tonic.io, "read_dvs_red") else None,
               ".aedat4": "read_aedat4" if hasattr(tonic.io, "read_aedat4") else None}
    name = readers.get(ext)
    if name is None:
        pytest.skip(f"tonic {getattr(tonic, '__version__', '?')} has no reader for {ext}")
    events = getattr(tonic.io, name)(path)
    assert len(events) == len(stream)


# --- the light-field commands on a recording -------------------------------------------------------------------

@pytest.fixture(scope="module")
def galvo_recording(tmp_path_factory):
    """Two scan periods of the static galvo scene, written as an EVT 3.0 recording (which keeps no optics), and a
    calibration file made for its optics."""
    from mitsuba_eventfield.calibration import fit_depth, optics_record, save_calibration
    from mitsuba_eventfield.optics import galvo as galvo_optics
    d = tmp_path_factory.mktemp("recording")
    scene = ef.load_scene(GALVO, width=64, height=48, amplitude=0.5)
    events = ef.render_events(scene, 2 / 250.0, steps=64, threshold=0.1)
    raw = str(d / "g.raw")
    ef.write_events(raw, events)
    record = optics_record(events.meta["optics"], events.width, events.height)
    z = np.array([0.4, 0.7, 1.0, 1.6, 2.5])
    scales = 2 * galvo_optics.focal_length_px(64, record["fov_x_deg"]) * (1 - 0.1 / z)
    cal = str(d / "cal.json")
    save_calibration(cal, record, depth=fit_depth(z, scales))
    return d, raw, cal


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "mitsuba_eventfield.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=600)


def test_a_contrast_far_above_the_recordings_is_said_not_overflowed(galvo_recording):
    """The recording was made at C = 0.1; told 10, its galvo solve reaches log levels near 400 (exponentiated:
    beyond float32, and NumPy's overflow lines came before the image): now clipped at +-40 with one warning that
    names the likely cause, and no NumPy line."""
    d, raw, cal = galvo_recording
    r = _cli("refocus", raw, "-o", d / "c10.png", "--depth", "1", "--views", "8", "--calibration", cal,
             "--contrast", "10")
    assert r.returncode == 0, r.stderr
    assert "beyond a log level of +-40" in r.stderr and "contrast threshold larger" in r.stderr, r.stderr
    assert "overflow" not in r.stderr and "invalid value" not in r.stderr, r.stderr
    assert np.isfinite(read_exr(str(d / "c10.exr"))[0]["Y"]).all()
    r = _cli("refocus", raw, "-o", d / "c01.png", "--depth", "1", "--views", "8", "--calibration", cal,
             "--contrast", "0.1")                  # the recording's own threshold: nothing near the limit
    assert r.returncode == 0 and "log level" not in r.stderr, r.stderr


def test_recording_without_optics_needs_a_calibration(galvo_recording):
    d, raw, cal = galvo_recording
    assert "optics" not in ef.read_events(raw).meta
    r = _cli("info", raw)                                       # says what the other commands will need
    assert r.returncode == 0 and "optics: none recorded" in r.stdout and "--contrast ON[,OFF]" in r.stdout, r.stdout
    r = _cli("refocus", raw, "-o", d / "rf.png", "--depth", "1", "--views", "8")
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and "carries no contrast thresholds" in err[0], err
    r = _cli("refocus", raw, "-o", d / "rf.png", "--depth", "1", "--views", "8", "--contrast", "0.1")
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and "carries no optics" in err[0] and "--calibration" in err[0], err
    r = _cli("refocus", raw, "-o", d / "rf.png", "--depth", "1", "--views", "8", "--calibration", cal,
             "--contrast", "0.1")
    assert r.returncode == 0, r.stderr
    assert os.path.getsize(d / "rf.png") > 0 and os.path.exists(d / "rf.exr")
    r = _cli("depth", raw, "-o", d / "dp.png", "--near", "0.3", "--far", "4", "--planes", "4", "--views", "8",
             "--calibration", cal, "--contrast", "0.1,0.1")
    assert r.returncode == 0, r.stderr


def test_calibration_without_the_fields_a_light_field_needs(galvo_recording, tmp_path):
    import json
    d, raw, cal = galvo_recording
    data = json.load(open(cal))
    del data["depth"]["optics"]["mirror_separation"]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(data))
    r = _cli("refocus", raw, "-o", tmp_path / "rf.png", "--depth", "1", "--views", "8", "--calibration", bad,
             "--contrast", "0.1")
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and "lacks mirror_separation" in err[0], err


def test_a_recording_with_its_nominal_optics(galvo_recording, tmp_path):
    """Without a calibration, the set-up's nominal optics (``--optics``) give a recording its light field and
    its galvo reconstruction (which reads the scan); a file with optics of its own refuses them."""
    import json
    d, raw, cal = galvo_recording
    optics = json.load(open(cal))["depth"]["optics"]
    nominal = tmp_path / "optics.json"
    nominal.write_text(json.dumps({k: optics[k] for k in ("design", "fov_x_deg", "mirror_distance",
                                                          "mirror_separation", "scan")}))
    r = _cli("refocus", raw, "-o", tmp_path / "rf.png", "--depth", "1", "--views", "8", "--optics", nominal,
             "--contrast", "0.1")
    assert r.returncode == 0, r.stderr
    r = _cli("reconstruct", raw, "-o", tmp_path / "rc", "--method", "galvo", "--times", "2,4", "--contrast", "0.1")
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and "carries no optics" in err[0] and "pass --optics" in err[0], err
    r = _cli("reconstruct", raw, "-o", tmp_path / "rc", "--method", "galvo", "--times", "2,4", "--contrast", "0.1",
             "--optics", nominal)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in (tmp_path / "rc").glob("*.exr")) == ["frame_0000.exr", "frame_0001.exr"]
    h5 = tmp_path / "g.h5"
    recording = ef.read_events(raw)
    recording.meta["optics"] = optics                     # the same events, now carrying optics
    ef.write_events(str(h5), recording)
    r = _cli("refocus", h5, "-o", tmp_path / "x.png", "--depth", "1", "--optics", nominal, "--contrast", "0.1")
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and "carries its own (galvo) optics" in err[0], err


@pytest.mark.parametrize("name, version, header, size", [
    ("mv.raw", "evt3", "% evt 3.0\n% format EVT3;height=480;width=640\n% t0 5", (640, 480)),     # Metavision's order
    ("mv.dat", "dat2", "% Version 2\n% Height 480\n% Width 640\n% T0 5", (640, 480)),
    ("bare.raw", "evt3", "% evt 3.0\n% t0 5", (50, 20)),                                      # no size: said
    ("both.raw", "evt3", "% evt 3.0\n% format EVT3;width=640;height=480\n% geometry 640x480", (640, 480)),
    ("two.raw", "evt3", "% evt 3.0\n% format EVT3;width=64;height=64\n% geometry 640x480", None),   # refused
])
def test_the_sensor_size_is_read_in_either_order_and_a_guess_is_said(tmp_path, name, version, header, size):
    """Headers that give the height before the width (Metavision's ``format EVT3;height=..;width=..``, a DAT's
    ``% Height`` line first) were read in one order only, and the sensor became the events' extent without a
    word (a 96x72 recording read 94x71 and its depths came out 10 % far). A header without a size still takes
    the extent, with a warning."""
    import warnings
    corner = ef.EventStream(np.arange(100) % 50, np.arange(100) % 20, np.arange(100) * 10 + 5, np.ones(100), 640, 480)
    from mitsuba_eventfield.events.recordings import _header
    written = _faery_file(tmp_path / f"faery_{name}", corner, version)
    _, end = _header(written)
    with open(written, "rb") as f:
        body = f.read()[end:]
    (tmp_path / name).write_bytes(header.encode() + b"\n" + body)
    if size is None:          # a header that contradicts itself: which size the sensor is, no reader can tell
        with pytest.raises(ef.EventFieldError, match=r"two.raw.*two sensor sizes: geometry 640x480 and width / "
                                                     r"height 64x64"):
            ef.read_events(str(tmp_path / name))
        return
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        back = ef.read_events(str(tmp_path / name))
    assert (back.width, back.height) == size and len(back) == 100 and np.array_equal(back.x, corner.x)
    guessed = [str(w.message) for w in said if "no sensor size" in str(w.message)]
    assert guessed == ([f"{tmp_path / name}: no sensor size in its header: taken as 50x20 from its largest "
                        "coordinates; light fields need the sensor's own"] if size == (50, 20) else [])
