"""The converter's inputs a user gets wrong, or that are damaged (a reviewer's findings, 2026-11-26): each is one
line naming the file and the field, exit 2 from the command line, and no output file; never a partial
conversion that exits 0."""
import os

import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.cli.main import main as cli


def _video(path, frames=30, fps=100):
    cv2 = pytest.importorskip("cv2")
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (32, 24))
    for k in range(frames):
        img = np.full((24, 32, 3), 40, np.uint8)
        img[:, k % 32] = 220                                  # a bright column sweeping right
        writer.write(img)
    writer.release()
    return str(path)


def _cli(args, capfd):
    """Exit code and the whole of stderr, OpenCV's and FFmpeg's own lines included (they write to the file
    descriptor, not to Python's sys.stderr)."""
    try:
        code = cli(["convert"] + [str(a) for a in args] + ["--quiet"])
    except SystemExit as e:
        code = e.code
    return code, capfd.readouterr().err.strip()


def test_a_cut_video_is_refused_not_converted_in_part(tmp_path, capfd):
    whole = _video(tmp_path / "whole.avi")
    data = open(whole, "rb").read()
    cut = tmp_path / "cut.avi"
    cut.write_bytes(data[:len(data) * 6 // 10])            # the container still says 30 frames
    ok, _ = _cli([whole, "-o", tmp_path / "whole.h5"], capfd)
    assert ok == 0 and len(ef.read_events(str(tmp_path / "whole.h5"))) > 100
    code, err = _cli([cut, "-o", tmp_path / "cut.h5"], capfd)
    assert code == 2 and len(err.splitlines()) == 1, err
    assert err.startswith(f"eventfield: error: {cut}: frame ") and "of 30 unreadable" in err
    assert not (tmp_path / "cut.h5").exists()


def test_an_unreadable_video_is_one_line_without_decoder_noise(tmp_path, capfd):
    """A video OpenCV cannot open printed FFmpeg's and OpenCV's parser lines (raw bytes among them) first."""
    whole = open(_video(tmp_path / "whole.avi"), "rb").read()
    for name, data in (("head.avi", whole[:4000]), ("garbage.mp4", b"garbage" * 100)):
        (tmp_path / name).write_bytes(data)
        code, err = _cli([tmp_path / name, "-o", tmp_path / "o.h5"], capfd)
        assert code == 2 and err == f"eventfield: error: {tmp_path / name}: OpenCV cannot open this video", err
    assert not (tmp_path / "o.h5").exists()


def test_frames_spanning_more_than_a_day_are_refused_before_any_file(tmp_path, capfd):
    """--fps 1e-9 asked the HDF5 index for 36 TiB (a MemoryError with a traceback); a few frames an hour
    apart are a time-lapse and convert."""
    from mitsuba_eventfield.validate import MAX_CONVERT_S
    frames = np.full((6, 8, 8), 0.1, np.float32)
    frames[:, 2, 3] = [0.01 * 2 ** k for k in range(6)]
    with pytest.raises(ef.EventFieldError, match=r"^frames: the frames span 5e\+09 s: allowed up to 86400 s"):
        ef.events_from_frames(frames, fps=1e-9, output=str(tmp_path / "a.h5"))
    np.savez(tmp_path / "us.npz", frames=frames, times=np.arange(6) * 1e6)      # microseconds given as seconds
    code, err = _cli([tmp_path / "us.npz", "-o", tmp_path / "b.h5"], capfd)
    assert code == 2 and "the frames span 5e+06 s" in err and len(err.splitlines()) == 1
    assert os.listdir(tmp_path) == ["us.npz"]
    from mitsuba_eventfield.simulate.frame_times import FrameTimesWarning
    with pytest.warns(FrameTimesWarning, match="3600 s apart"):      # converted, and the spacing said
        hourly = ef.events_from_frames(frames, fps=1 / 3600.0)
    assert len(hourly) == 17 and hourly.t[-1] > 3600e6 and 5 * 3600 <= MAX_CONVERT_S


def test_a_long_quiet_span_writes_its_index_in_blocks(tmp_path, monkeypatch):
    """Hours between two frames: the DSEC index (an entry a millisecond) is made a block at a time, and equals
    the one made at once."""
    from mitsuba_eventfield.events import hdf5
    frames = np.full((3, 4, 4), 0.1, np.float32)
    frames[:, 1, 1] = [0.1, 0.5, 0.05]
    times = [0.0, 7.3, 12.9]
    whole, blocked = str(tmp_path / "whole.h5"), str(tmp_path / "blocked.h5")
    from mitsuba_eventfield.simulate.frame_times import FrameTimesWarning
    with pytest.warns(FrameTimesWarning, match="7.3 s apart"):
        ef.events_from_frames(frames, times, output=whole)
        monkeypatch.setattr(hdf5, "MS_INDEX_BLOCK", 1000)
        ef.events_from_frames(frames, times, output=blocked)
    import h5py
    with h5py.File(whole) as a, h5py.File(blocked) as b:
        offset_ms = int(a["t_offset"][()]) // 1000          # from the first frame's millisecond
        assert offset_ms == 0 and len(a["ms_to_idx"]) == 12_901 and a["events"]["t"][0] > 0
        assert np.array_equal(a["ms_to_idx"][()], b["ms_to_idx"][()])
        t = a["events"]["t"][()]
        for ms in (offset_ms, 7300, 7301, 12_900):
            assert a["ms_to_idx"][ms - offset_ms] == np.searchsorted(t, 1000 * (ms - offset_ms))


@pytest.mark.parametrize("members, message", [
    ({"frames": np.ones((3, 4, 4)), "times": np.array(list("abc"))}, "times: expected numbers (seconds)"),
    ({"frames": np.zeros((3, 0, 4), np.float32), "times": [0, 0.01, 0.02]}, "with T >= 2, H, W >= 1"),
    ({"frames": np.ones((3, 4, 4), np.int64), "times": [0, 0.01, 0.02]}, "pixel type int64: integer frames must be"),
])
def test_npz_contents_are_checked(tmp_path, capfd, members, message):
    np.savez(tmp_path / "s.npz", **members)
    code, err = _cli([tmp_path / "s.npz", "-o", tmp_path / "o.h5"], capfd)
    assert code == 2 and message in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "o.h5").exists()


def test_damaged_or_pickled_npz_is_one_line(tmp_path, capfd):
    np.savez(tmp_path / "good.npz", frames=np.random.default_rng(0).random((8, 24, 32)), times=np.arange(8) / 100)
    data = bytearray((tmp_path / "good.npz").read_bytes())
    data[2000:2400] = bytes(400)                                 # inside the frames member: a bad CRC
    (tmp_path / "crc.npz").write_bytes(bytes(data))
    frames = np.empty(2, object)
    frames[0], frames[1] = np.ones((4, 4)), np.ones((4, 4))
    np.savez(tmp_path / "obj.npz", frames=frames, times=[0.0, 1.0])
    for name in ("crc.npz", "obj.npz"):
        code, err = _cli([tmp_path / name, "-o", tmp_path / "o.h5"], capfd)
        assert code == 2 and err.startswith(f"eventfield: error: {tmp_path / name}: not a readable .npz ("), err
        assert len(err.splitlines()) == 1
    assert not (tmp_path / "o.h5").exists()


def test_python_arguments_are_checked():
    ones = np.ones((3, 4, 4), np.float32)
    cases = [(dict(frames=ones, fps="abc"), r"^frames: fps = 'abc': must be a number \(0, inf\)$"),
             (dict(frames=ones, fps=100, threshold="x"), r"^threshold = 'x': must be a number"),
             (dict(frames=[np.ones((24, 32)), np.ones((20, 30))], fps=100), r"^frames: the frames differ in size"),
             (dict(frames=np.ones((3, 4, 4), np.int32), fps=100), r"^frames\[0\]: pixel type int32: integer frames")]
    for kwargs, message in cases:
        with pytest.raises(ef.EventFieldError, match=message):
            ef.events_from_frames(**kwargs)
    # 8-bit frames are scaled by 255: 1 -> 101 -> 201 DN fire floor(ln 201 / C) = 26 ON events in each pixel
    eight_bit = (np.arange(3)[:, None, None] * 100 + np.ones((3, 4, 4))).astype(np.uint8)
    ev = ef.events_from_frames(eight_bit, fps=100, threshold=0.2)
    assert len(ev) == 16 * 26 and (ev.p == 1).all()


def test_output_that_is_the_input_or_fps_given_twice(tmp_path, capfd):
    np.savez(tmp_path / "s.npz", frames=np.random.default_rng(1).random((4, 6, 8)), times=[0, 0.01, 0.02, 0.03])
    before = (tmp_path / "s.npz").read_bytes()
    code, err = _cli([tmp_path / "s.npz", "-o", tmp_path / "s.npz"], capfd)
    assert code == 2 and "the output is the input" in err and (tmp_path / "s.npz").read_bytes() == before
    code, err = _cli([tmp_path / "s.npz", "-o", tmp_path / "o.h5", "--fps", "50"], capfd)
    assert code == 2 and "carries its own times ('times')" in err and not (tmp_path / "o.h5").exists()


def test_pixel_preset_on_the_command_line(tmp_path, capfd):
    """``--pixel preset=NAME`` (the error for an unknown --pixel name lists it) works as ``--preset NAME``."""
    np.savez(tmp_path / "s.npz", frames=np.random.default_rng(2).random((10, 12, 16)) + 0.05,
             times=np.arange(10) / 1000)
    out = {k: tmp_path / f"{k}.h5" for k in ("preset", "pixel")}
    assert _cli([tmp_path / "s.npz", "-o", out["preset"], "--preset", "davis346"], capfd)[0] == 0
    assert _cli([tmp_path / "s.npz", "-o", out["pixel"], "--pixel", "preset=davis346"], capfd)[0] == 0
    a, b = (ef.read_events(str(p)) for p in out.values())
    assert len(a) > 10 and a.equals(b) and a.meta["pixel_model"]["preset"] == "davis346"


def test_a_virtual_file_system_is_not_called_a_full_disk():
    from mitsuba_eventfield.atomic import check_writable
    if not os.path.isdir("/proc"):
        pytest.skip("no /proc on this system")
    with pytest.raises(ef.EventFieldError, match=r"^event file path /proc/e\.h5: directory /proc is not writable$"):
        check_writable("/proc/e.h5", "event file")


def test_a_stack_larger_than_memory_is_not_called_damaged(tmp_path, monkeypatch):
    """Reading a valid .npz's frames past the memory left said "not a readable .npz": it names the memory."""
    path = str(tmp_path / "big.npz")
    np.savez(path, frames=np.ones((4, 6, 8), np.float32), times=np.arange(4) * 1e-3)

    def no_memory(self, key):
        raise MemoryError("Unable to allocate 103. MiB")
    monkeypatch.setattr(np.lib.npyio.NpzFile, "__getitem__", no_memory)
    with pytest.raises(ef.EventFieldError, match=r"big.npz: its frames \(0 MiB\) do not fit in the memory"):
        ef.events_from_frames(path)


def test_what_each_input_holds_reaches_the_pixel(tmp_path):
    """Each input's own conventions, against what the pixel must see:
    - a folder of colour PNGs (OpenCV reads BGR) is the luminance of its RGB: a red image's level times the red
      weight, a blue one's times the blue weight (a log pixel is scale-free, so the events alone could not tell);
    - an npz's ``timestamps_us`` are microseconds (its span is 20 ms, not 20 s or 20 us);
    - a start time off the millisecond grid in binary (1.001 s) is its microsecond rounded (1001000), not
      truncated (1000999), so the file's index starts at its millisecond."""
    import cv2

    from mitsuba_eventfield.images import LUMA
    from mitsuba_eventfield.simulate.frame_sources import from_folder
    for channel, weight in ((2, LUMA[0]), (0, LUMA[2])):           # OpenCV's BGR order: 2 is red, 0 is blue
        folder = tmp_path / f"c{channel}"
        folder.mkdir()
        for k, level in enumerate((50, 200)):
            img = np.zeros((4, 6, 3), np.uint8)
            img[..., channel] = level
            cv2.imwrite(str(folder / f"f{k}.png"), img)
        frames = [f for _, f in from_folder(str(folder), fps=1000).frames()]
        assert np.allclose(frames, [np.full((4, 6), weight * level / 255) for level in (50, 200)], rtol=1e-6)
    ramp = (np.exp(np.linspace(0, 1, 3))[:, None, None] * np.full((3, 4, 6), 0.2)).astype(np.float32)
    np.savez(tmp_path / "us.npz", frames=ramp, timestamps_us=np.array([0, 10_000, 20_000]))
    ev = ef.events_from_frames(str(tmp_path / "us.npz"), threshold=0.2)
    assert ev.duration_us == 20_000 and len(ev) > 0
    times = 1.001 + np.arange(3) * 1e-3
    assert int(1.001 * 1e6) == 1000999                                   # the float's own truncation
    ef.events_from_frames(ramp, times, threshold=0.2, output=str(tmp_path / "late.h5"))
    back = ef.read_events(str(tmp_path / "late.h5"))
    assert back.start_us == 1_001_000 and back.meta["t_start_us"] == 1_001_000
