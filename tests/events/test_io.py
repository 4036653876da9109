"""Event files: lossless round trips, the DSEC layout as plain h5py sees it, atomic writes."""
import json
import os

import h5py
import numpy as np
import pytest
from conftest import AEDAT4

import mitsuba_eventfield as ef


@pytest.fixture(scope="module")
def stream():
    rng = np.random.default_rng(1)
    n = 5000
    t = np.sort(rng.integers(0, 25_000, n))
    return ef.EventStream(rng.integers(0, 40, n), rng.integers(0, 30, n), t, rng.choice([-1, 1], n), 40, 30,
                          {"seed": 7, "optics": {"design": "test"}, "duration_us": 25_000})


@pytest.mark.parametrize("ext", [".h5", ".npz", ".txt", AEDAT4])
def test_round_trip(tmp_path, stream, ext):
    path = str(tmp_path / f"ev{ext}")
    ef.write_events(path, stream)
    back = ef.read_events(path)
    assert back.equals(stream)
    if ext in (".h5", ".npz"):
        assert back.meta["seed"] == 7 and back.meta["optics"] == {"design": "test"}
    assert [p for p in os.listdir(tmp_path) if p.startswith(".")] == []   # no temporary left


def test_dsec_layout_with_plain_h5py(tmp_path, stream):
    path = str(tmp_path / "ev.h5")
    ef.write_events(path, stream)
    with h5py.File(path, "r") as f:
        ev = f["events"]
        assert {k: ev[k].dtype for k in "xytp"} == {"x": np.uint16, "y": np.uint16, "t": np.int64, "p": np.uint8}
        t = ev["t"][()] + f["t_offset"][()]
        assert np.array_equal(t, stream.t)
        assert np.array_equal(ev["p"][()], (stream.p > 0).astype(np.uint8))
        ms = f["ms_to_idx"][()]
        assert len(ms) == 26                                  # 0..25 ms inclusive
        assert np.array_equal(ms, np.searchsorted(stream.t, np.arange(26) * 1000, side="left"))
        meta = json.loads(f["eventfield"].attrs["meta_json"])
        assert meta["seed"] == 7 and f["eventfield"].attrs["width"] == 40


def test_streaming_writer_index_matches_whole_file(tmp_path, stream):
    """Chunks appended step by step (as the renderer does) give the same file as one write."""
    path = str(tmp_path / "streamed.h5")
    with ef.H5EventWriter(path, 40, 30, {"a": 1}, chunk=700) as w:
        for t0 in range(0, 25_000, 1_300):
            s = stream.time_window(t0, t0 + 1_300)
            w.append(s.x, s.y, s.t, s.p, complete_until_us=t0 + 1_299)
        w.close(end_us=25_000)
    back = ef.read_events(path)
    assert back.equals(stream)
    with h5py.File(path, "r") as f:
        assert np.array_equal(f["ms_to_idx"][()], np.searchsorted(stream.t, np.arange(26) * 1000))


def test_writer_leaves_nothing_on_error(tmp_path, stream):
    path = tmp_path / "broken.h5"
    with pytest.raises(RuntimeError):
        with ef.H5EventWriter(str(path), 40, 30) as w:
            w.append(stream.x[:10], stream.y[:10], stream.t[:10], stream.p[:10])
            raise RuntimeError("render failed")
    assert os.listdir(tmp_path) == []


def test_render_interrupted_leaves_no_file(tmp_path, demo_small, monkeypatch):
    """A failure in the middle of a streamed render (here in the background writer's thread, raised again in
    the render's) removes the partial file. A tiny event buffer moves every batch's events to the writer."""
    from mitsuba_eventfield.events import hdf5 as render_mod
    calls = {"n": 0}
    real = render_mod.H5EventWriter.append

    def failing_append(self, *a, **k):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real(self, *a, **k)

    monkeypatch.setattr(render_mod.H5EventWriter, "append", failing_append)
    with pytest.raises(KeyboardInterrupt):
        # 200 steps: the render commits its steps in batches of up to 64 (step_batch), each then its own chunk
        ef.render_events(demo_small, 0.005, steps=200, output=str(tmp_path / "out.h5"), event_buffer_mb=1e-6)
    assert calls["n"] == 3 and os.listdir(tmp_path) == []


def test_render_streams_to_h5_same_as_memory(tmp_path, demo_small):
    mem = ef.render_events(demo_small, 0.004, steps=6)
    summary = ef.render_events(demo_small, 0.004, steps=6, output=str(tmp_path / "d.h5"))
    disk = ef.read_events(str(tmp_path / "d.h5"))
    assert summary.events == len(mem) > 0
    assert disk.equals(mem)
    for key in ("width", "height", "optics", "pixel_model", "seed", "spp", "package_version", "stepping"):
        assert key in disk.meta
    assert disk.meta["pixel_model"]["threshold_on"] == 0.2


def test_preview_colours(tmp_path):
    ev = ef.EventStream([1, 2, 2], [0, 0, 0], [0, 1, 2], [1, -1, -1], 4, 1)
    img = ef.event_frame_rgb(ev, saturation=1)
    assert tuple(img[0, 0]) == (255, 255, 255)     # no events: white
    assert tuple(img[0, 1]) == (255, 0, 0)         # ON: red
    assert tuple(img[0, 2]) == (0, 0, 255)         # OFF: blue
    ef.write_preview(str(tmp_path / "p.png"), ev)
    assert os.path.getsize(tmp_path / "p.png") > 0


@pytest.mark.parametrize("ext", [".npz", ".h5"])
def test_rendered_file_keeps_the_scene_metadata(tmp_path, ext):
    """Formats written at the end of a render carry the same metadata as the streamed HDF5."""
    from conftest import ROOT
    scene = ef.load_scene(os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml"), width=24, height=18)
    path = str(tmp_path / f"ev{ext}")
    ef.render_events(scene, 0.004, steps=8, spp=1, output=path)
    meta = ef.read_events(path).meta
    assert meta["optics"]["design"] == "galvo" and meta["duration_us"] == 4000
    assert "pixel_model" in meta and meta["render"]["steps"] == 8


def test_streaming_writer_refuses_out_of_order_chunks(tmp_path):
    path = str(tmp_path / "bad.h5")
    w = ef.H5EventWriter(path, 4, 4, {})
    w.append([0], [0], [500], [1])
    with pytest.raises(ValueError, match=r"bad.h5: .* starts at t = 100 us, before the last written event at 500"):
        w.append([0], [0], [100], [1])
    with pytest.raises(ValueError, match=r"t = 600 us follows 700 us"):
        w.append([0, 1], [0, 1], [700, 600], [1, 1])
    w.abort()
    assert os.listdir(tmp_path) == []                       # nothing half-written left behind


@pytest.mark.parametrize("ext", [".npz", ".txt", AEDAT4])
def test_render_streams_every_chunked_format(tmp_path, demo_small, ext, monkeypatch):
    """npz, text and AEDAT4 are written chunk by chunk while rendering (the sink keeps no events), and read
    back equal to the in-memory render."""
    from mitsuba_eventfield.simulate import sink as sink_mod
    kept = []
    real_add = sink_mod.Sink._add_host

    def add_host(self, *a, **k):       # the device path passes borrowed= and counted= (CUDA's default)
        real_add(self, *a, **k)
        kept.append(0 if self.memory is None else len(self.memory))
    monkeypatch.setattr(sink_mod.Sink, "_add_host", add_host)
    mem = ef.render_events(demo_small, 0.004, steps=200)
    assert max(kept) > 0                          # the in-memory render keeps its events, of course
    kept.clear()
    path = str(tmp_path / f"d{ext}")
    summary = ef.render_events(demo_small, 0.004, steps=200, output=path, event_buffer_mb=1e-6)
    # a chunk per batch of steps (step_batch: up to 64 steps at 48x36)
    assert len(kept) >= 4 and max(kept) == 0 and summary.writer_busy_s > 0
    assert ef.read_events(path).equals(mem) and os.listdir(tmp_path) == [f"d{ext}"]


def test_a_streams_start_and_end_have_one_reading():
    """``start_us`` / ``start_s`` / ``end_s``: the metadata's start, else the first event (the origin the
    duration falls back to). Ten callers took 0 where the metadata had none: a camera recording starting at
    5 s then ended at its span (0.002 s), not at its last event."""
    recording = ef.EventStream([1, 2, 3], [1, 1, 1], [5_000_000, 5_001_000, 5_002_000], [1, -1, 1], 4, 4)
    assert recording.start_us == 5_000_000 and recording.start_s == 5.0 and recording.end_s == pytest.approx(5.002)
    rendered = ef.EventStream([1], [1], [700], [1], 4, 4, meta={"t_start_us": 0, "duration_us": 1000})
    assert rendered.start_us == 0 and rendered.end_s == pytest.approx(0.001)
    assert ef.EventStream.empty(4, 4).start_us == 0
    # a consumer: reconstruct --fps puts its frames over the recording (from 0 s to its span before: blank)
    import tempfile

    from mitsuba_eventfield import cli
    from mitsuba_eventfield.images import read_exr
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "rec.txt")                      # a text file keeps no t_start_us
        ef.write_events(path, recording)
        assert cli.main(["reconstruct", path, "--fps", "1000", "--contrast", "0.2", "-o", os.path.join(d, "f")]) == 0
        frame, meta = read_exr(os.path.join(d, "f", "frame_0001.exr"))
        assert meta["time_s"] == pytest.approx(5.002)
        assert frame["Y"][1, 1:4] == pytest.approx(np.exp([0.2, -0.2, 0.2]), rel=1e-3)


def test_a_crop_keeps_the_window_and_says_where_it_was():
    """``EventStream.crop``: exactly the events inside the window, from its corner, against a brute-force
    selection; a crop of a crop is the composed window on the whole sensor, which ``crop_frame`` cuts a
    frame of the sensor to (a frame of the window's size is taken as it is, any other refused)."""
    from mitsuba_eventfield.events.stream import EventStream
    rng = np.random.default_rng(3)
    n = 5000
    ev = EventStream(rng.integers(0, 64, n), rng.integers(0, 48, n), np.sort(rng.integers(0, 10_000, n)),
                     rng.choice([-1, 1], n), 64, 48, {"duration_us": 10_000})
    cut = ev.crop(10, 5, 30, 20).crop(4, 3, 16, 12)            # the window 14..29 x 8..19 of the sensor
    inside = [(x - 14, y - 8, t, p) for x, y, t, p in zip(ev.x, ev.y, ev.t, ev.p) if 14 <= x < 30 and 8 <= y < 20]
    assert (cut.width, cut.height) == (16, 12) and len(cut) == len(inside) > 100
    assert list(zip(cut.x, cut.y, cut.t, cut.p)) == inside
    assert cut.meta["crop"] == {"window": [14, 8, 16, 12], "sensor": [64, 48]} and cut.duration_us == 10_000
    frame = np.arange(64 * 48).reshape(48, 64)
    assert np.array_equal(cut.crop_frame(frame), frame[8:20, 14:30])
    assert np.array_equal(cut.crop_frame(frame[8:20, 14:30]), frame[8:20, 14:30])
    with pytest.raises(ef.ConfigError, match=r"^f\.exr: a frame of 30x20; the stream's sensor is 16x12 or the "
                                             r"whole 64x48 sensor it was cropped from$"):
        cut.crop_frame(frame[:20, :30], "f.exr")
    for window, message in (((0, 0, 65, 48), r"crop = 0,0,65,48: the window .* inside the 64x48 sensor"),
                            ((-1, 0, 4, 4), r"crop x0 = -1: allowed range is \[0, inf\)"),
                            ((0, 0, 0, 4), r"crop width = 0: allowed range is \[1, inf\)"),
                            ((0.5, 0, 4, 4), r"crop x0 = 0\.5: must be a whole number")):
        with pytest.raises(ef.ConfigError, match=message):
            ev.crop(*window)
    with pytest.raises(ef.ConfigError, match=r"^crop: the stream carries galvo optics, which describe its whole"):
        EventStream(ev.x, ev.y, ev.t, ev.p, 64, 48, {"optics": {"design": "galvo"}}).crop(0, 0, 8, 8)
