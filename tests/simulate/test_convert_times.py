"""Frames at given times (a reviewer's findings, 2026-11-27): ``times`` was ignored for a path (a folder's or a
video's frames then sat at --fps or the container's rate), an array's ``fps`` beside its ``times`` was dropped
silently, and a bad time was not named. Timestamps here are checked against the log-linear crossings worked by
hand."""
import math

import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.cli.main import main as cli

UNEVEN = [0.0, 0.010, 0.013]          # seconds: the second interval is 3 ms, not 10


def _ramp(dtype=np.float32):
    """One pixel stepping up by 0.5 in ln I over the first interval, then still: with C = 0.2, ON crossings
    at 0.2 / 0.5 and 0.4 / 0.5 of the interval (4 and 8 ms at UNEVEN), none after."""
    return np.array([1.0, math.exp(0.5), math.exp(0.5)], dtype).reshape(3, 1, 1)


def _cli(args, capfd):
    try:
        code = cli(["convert"] + [str(a) for a in args] + ["--quiet"])
    except SystemExit as e:
        code = e.code
    return code, capfd.readouterr().err.strip()


def test_times_place_an_npz_stack_without_its_own(tmp_path):
    np.savez(tmp_path / "s.npz", frames=_ramp())
    ev = ef.events_from_frames(str(tmp_path / "s.npz"), UNEVEN, threshold=0.2)
    assert ev.t.tolist() == [4000, 8000] and ev.p.tolist() == [1, 1]
    assert ev.meta["duration_us"] == 13000


def test_a_folder_at_given_times_equals_the_same_frames_as_an_array(tmp_path, capfd):
    """A timestamps file (seconds, one a line, comments allowed) places a folder's images; the events equal
    those of the same 16-bit frames given as an array with the same times, and differ from the frames at a
    uniform rate."""
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(3)
    frames = (rng.random((6, 12, 16)) * 60000 + 2000).astype(np.uint16)
    (tmp_path / "f").mkdir()
    for i, f in enumerate(frames):
        cv2.imwrite(str(tmp_path / "f" / f"frame_{i}.png"), f)
    times = np.array([0.0, 0.001, 0.0015, 0.004, 0.0041, 0.009])
    (tmp_path / "t.txt").write_text("# seconds\n" + "\n".join(repr(float(t)) for t in times) + "\n")
    code, err = _cli([tmp_path / "f", "-o", tmp_path / "f.h5", "--times", tmp_path / "t.txt"], capfd)
    assert code == 0, err
    from_folder = ef.read_events(str(tmp_path / "f.h5"))
    from_array = ef.events_from_frames(frames, times)
    assert len(from_array) > 100 and from_folder.equals(from_array)
    assert from_folder.t.max() <= 9000
    assert not from_folder.equals(ef.events_from_frames(frames, fps=1000))
    np.save(tmp_path / "t.npy", times)                      # a .npy array works as the text does
    assert ef.events_from_frames(str(tmp_path / "f"), str(tmp_path / "t.npy")).equals(from_array)


def _video(path, frames=30):
    cv2 = pytest.importorskip("cv2")
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 100, (32, 24))
    for k in range(frames):
        img = np.full((24, 32, 3), 40, np.uint8)
        img[:, k] = 220                                     # a bright column sweeping right
        writer.write(img)
    writer.release()
    return str(path)


def test_a_video_at_given_times(tmp_path, capfd):
    path = _video(tmp_path / "v.avi")
    times = np.cumsum(np.r_[0, np.full(29, 0.002)])        # 500 Hz, where the container says 100
    ev = ef.events_from_frames(path, times)
    assert ev.meta["duration_us"] == 58000 and 0 <= ev.t.min() and ev.t.max() <= 58000
    at_rate = ef.events_from_frames(path)
    assert at_rate.meta["duration_us"] == 290000 and len(at_rate) == len(ev)
    np.savetxt(tmp_path / "short.txt", times[:-1])
    code, err = _cli([path, "-o", tmp_path / "o.h5", "--times", tmp_path / "short.txt"], capfd)
    assert code == 2 and err == f"eventfield: error: {path}: times: 29 values for 30 frames: give one time a " \
        "frame", err
    assert not (tmp_path / "o.h5").exists()


@pytest.mark.parametrize("times, message", [
    ([0.0, 0.01, 0.01], r"^frames: times\[2\] = 0\.01 is not after times\[1\] = 0\.01: times must be strictly "
                        r"increasing \(seconds\)$"),
    ([0.0, float("nan"), 0.02], r"^frames: times\[1\] = nan: times must be finite \(seconds\)$"),
    ([[0.0], [0.01], [0.02]], r"^frames: times: shape \(3, 1\): expected one value a frame \(a 1-D array\)$"),
    ([0.0, 0.01], r"^frames: times: 2 values for 3 frames: give one time a frame$"),
])
def test_bad_times_are_named(times, message):
    with pytest.raises(ef.EventFieldError, match=message):
        ef.events_from_frames(_ramp(), times)


def test_one_clock_only(tmp_path, capfd):
    """Times and a frame rate together are refused (one of them was ignored), from Python and the command
    line; so are times for a stack that carries its own."""
    with pytest.raises(ef.EventFieldError, match=r"^frames: fps = 100 and times given: give the frames' times or "
                                                 r"their rate, not both$"):
        ef.events_from_frames(_ramp(), UNEVEN, fps=100)
    np.savez(tmp_path / "own.npz", frames=_ramp(), times=UNEVEN)
    with pytest.raises(ef.EventFieldError, match=r"own\.npz: times given: this stack carries its own times"):
        ef.events_from_frames(str(tmp_path / "own.npz"), UNEVEN)
    np.savetxt(tmp_path / "t.txt", UNEVEN)
    code, err = _cli([tmp_path / "own.npz", "-o", tmp_path / "o.h5", "--fps", "10", "--times", tmp_path / "t.txt"],
                     capfd)
    assert code == 2 and "not allowed with argument" in err and len(err.splitlines()) == 1
    (tmp_path / "bad.txt").write_text("0.0\nzero point one\n")
    with pytest.raises(ef.EventFieldError, match=r"bad\.txt: frame times: expected one number \(seconds\) a line"):
        ef.events_from_frames(str(tmp_path / "own.npz"), str(tmp_path / "bad.txt"))
    # the line as an editor counts it, comments and blank lines included (NumPy said "row 1": rows from 0, the
    # comment and blank line left out)
    (tmp_path / "bad.txt").write_text("0.0\n# then\n\n0.1 0.2\n0.3\n")
    with pytest.raises(ef.EventFieldError, match=r"bad\.txt: frame times: expected one number \(seconds\) a line "
                                                 r"\(line 4: '0\.1 0\.2'\)$"):
        ef.events_from_frames(_ramp(), str(tmp_path / "bad.txt"))
    np.savez(tmp_path / "both.npz", frames=_ramp(), times=UNEVEN, timestamps_us=np.asarray(UNEVEN) * 2e6)
    with pytest.raises(ef.EventFieldError, match=r"both\.npz: both 'times' \(seconds\) and 'timestamps_us' are "
                                                 r"given: keep one$"):       # the second was ignored
        ef.events_from_frames(str(tmp_path / "both.npz"))
    assert not (tmp_path / "o.h5").exists()


def test_a_preset_by_name_in_pixel_and_pixel_values_checked(capfd):
    frames = np.random.default_rng(4).random((8, 40, 60)) + 0.05       # large enough for davis346's readout cap
    by_name = ef.events_from_frames(frames, fps=1000, pixel="davis346")
    assert len(by_name) > 10 and by_name.equals(ef.events_from_frames(frames, fps=1000, preset="davis346"))
    with pytest.raises(ef.EventFieldError, match=r"^pixel model: pixel = 3: expected a preset's name or a dict "
                                                 r"of parameters \(allowed presets: ideal, "):
        ef.events_from_frames(frames, fps=1000, pixel=3)
    code, err = _cli(["x.npz", "-o", "o.h5", "--pixel", "seed=1.5"], capfd)
    assert code == 2 and err == "eventfield: error: --pixel seed='1.5': seed takes an integer", err


def test_a_frame_source_keeps_its_own_times():
    from mitsuba_eventfield.simulate.frame_sources import from_array
    source = from_array(_ramp(), UNEVEN)
    assert ef.events_from_frames(source, threshold=0.2).t.tolist() == [4000, 8000]
    with pytest.raises(ef.EventFieldError, match=r"^frames: a FrameSource yields its frames' times"):
        ef.events_from_frames(from_array(_ramp(), UNEVEN), [0.0, 0.1, 0.2])


def test_times_against_a_video_read_to_its_end(tmp_path):
    """A Matroska file's frame count is an estimate: given times are checked frame by frame, then at the end,
    with the same message as where the count is exact."""
    path = _video(tmp_path / "v.mkv")
    times = np.arange(30) * 0.002
    assert ef.events_from_frames(path, times).meta["duration_us"] == 58000
    for wrong, frames in ((times[:-1], "more than 29"), (np.arange(31) * 0.002, "30")):
        with pytest.raises(ef.EventFieldError, match=rf"v\.mkv: times: {len(wrong)} values for {frames} frames: "
                                                     r"give one time a frame$"):
            ef.events_from_frames(path, wrong)


def test_times_files_and_clocks_for_every_input(tmp_path):
    """A timestamps file works for an array as for a path; an empty one, an npz's own microseconds beside given
    times, and a folder's rate beside times are each one line."""
    np.savetxt(tmp_path / "t.txt", UNEVEN)
    assert ef.events_from_frames(_ramp(), str(tmp_path / "t.txt"), threshold=0.2).t.tolist() == [4000, 8000]
    (tmp_path / "empty.txt").write_text("# nothing\n")
    with pytest.raises(ef.EventFieldError, match=r"^frames: times: 0 values for 3 frames: give one time a frame$"):
        ef.events_from_frames(_ramp(), str(tmp_path / "empty.txt"))
    np.savez(tmp_path / "us.npz", frames=_ramp(), timestamps_us=[0, 10000, 10000])
    with pytest.raises(ef.EventFieldError, match=r"us\.npz: times given: this stack carries its own times "
                                                 r"\('timestamps_us'\)"):
        ef.events_from_frames(str(tmp_path / "us.npz"), UNEVEN)
    with pytest.raises(ef.EventFieldError, match=r"us\.npz: timestamps_us\[2\] = 10000\.0 is not after "
                                                 r"timestamps_us\[1\] = 10000\.0: timestamps_us must be strictly "
                                                 r"increasing \(microseconds\)$"):
        ef.events_from_frames(str(tmp_path / "us.npz"))
    cv2 = pytest.importorskip("cv2")
    (tmp_path / "f").mkdir()
    for i in range(3):
        cv2.imwrite(str(tmp_path / "f" / f"{i}.png"), np.full((4, 4), 50 * (i + 1), np.uint8))
    with pytest.raises(ef.EventFieldError, match=r"f: fps = 10 and times given: give the frames' times or their "
                                                 r"rate, not both$"):
        ef.events_from_frames(str(tmp_path / "f"), UNEVEN, fps=10)
    with pytest.raises(ef.EventFieldError, match=r"f: give the frame rate \(--fps / fps=\) or the frames' times "
                                                 r"\(--times FILE / times=\)"):
        ef.events_from_frames(str(tmp_path / "f"))


@pytest.mark.parametrize("start", [0.0, 1000.0])
def test_a_converted_file_is_indexed_from_its_first_frame(tmp_path, start):
    """/t_offset came from the first event (6 ms into a clip still for its first frames), so the DSEC slicer's
    first frame window [0, 40 ms) asked ms_to_idx for -6 ms and failed; written from memory the same events
    got t_offset 0. Now both: the first frame's millisecond, and every ms_to_idx entry is the first event at
    or after its millisecond (DSEC's definition), checked on the events read back."""
    import h5py
    frames = np.full((30, 12, 16), 0.3, np.float32)
    frames[6:] = 0.3 * np.exp(0.05 * (np.arange(24)[:, None, None] + 1) * (1 + np.arange(16)[None, None, :] / 16))
    times = start + np.arange(30) / 1000.0
    ef.events_from_frames(frames, times, output=str(tmp_path / "streamed.h5"))
    ef.write_events(str(tmp_path / "kept.h5"), ef.events_from_frames(frames, times))
    for name in ("streamed.h5", "kept.h5"):
        with h5py.File(tmp_path / name) as f:
            offset, t, index = int(f["t_offset"][()]), f["events/t"][()], f["ms_to_idx"][()]
        assert offset == int(start * 1e6) and t[0] >= 6000, name               # the first event 6 ms in
        assert len(index) >= 30 and list(index) == [int(np.searchsorted(t, ms * 1000)) for ms in range(len(index))]
    # a caller's FrameSource that does not say when its first frame is (a review: still the first event's)
    from mitsuba_eventfield.simulate.frame_sources import FrameSource
    source = FrameSource("mine", 16, 12, 30, lambda: iter(zip(times.tolist(), frames)), {"kind": "mine"})
    ef.events_from_frames(source, output=str(tmp_path / "source.h5"))
    with h5py.File(tmp_path / "source.h5") as f:
        assert int(f["t_offset"][()]) == int(start * 1e6) and len(f["events/t"][()]) == len(t)


def test_convert_takes_a_seed_as_render_does(tmp_path, capfd):
    """``convert --seed N`` is the pixel model's seed (``--pixel seed=N``), as ``render --seed`` is: the same
    davis346 events for the same seed, others for another; the two spellings naming two seeds are refused."""
    frames = np.random.default_rng(4).random((8, 40, 60)) + 0.05
    np.savez(tmp_path / "s.npz", frames=frames, times=np.arange(8) / 1000.0)
    runs = {}
    for name, extra in (("seed3", ["--seed", "3"]), ("pixel3", ["--pixel", "seed=3"]), ("seed4", ["--seed", "4"])):
        code, err = _cli([tmp_path / "s.npz", "-o", tmp_path / f"{name}.npz", "--preset", "davis346", *extra], capfd)
        assert code == 0, err
        runs[name] = ef.read_events(str(tmp_path / f"{name}.npz"))
    assert runs["seed3"].equals(runs["pixel3"]) and runs["seed3"].meta["pixel_model"]["seed"] == 3
    assert not runs["seed3"].equals(runs["seed4"])
    code, err = _cli([tmp_path / "s.npz", "-o", tmp_path / "x.npz", "--seed", "3", "--pixel", "seed=4"], capfd)
    assert code == 2 and err == "eventfield: error: --seed 3 and --pixel seed=4: give the seed once", err
    assert not (tmp_path / "x.npz").exists()


def test_frame_times_in_the_wrong_unit_are_said(tmp_path, capfd):
    """Milliseconds read as seconds (a 100 fps stack 10 'seconds' apart) and seconds read as microseconds
    (an .npz's 'timestamps_us' of 0.01 apart) are warned, naming the file and the likely slip; the conversion
    still runs (a time-lapse may mean it), and times in seconds are not warned."""
    from mitsuba_eventfield.simulate.frame_times import FrameTimesWarning
    np.savez(tmp_path / "ms.npz", frames=_ramp(), times=np.array(UNEVEN) * 1e3)
    with pytest.warns(FrameTimesWarning, match=r"ms\.npz: the first two frames are 10 s apart \(milliseconds"):
        ev = ef.events_from_frames(str(tmp_path / "ms.npz"), threshold=0.2)
    # taken as given: 1000x the seconds' timestamps (to 1 us: a float32 fraction of a 10 s interval)
    assert np.abs(ev.t - [4_000_000, 8_000_000]).max() <= 1
    np.savez(tmp_path / "us.npz", frames=_ramp(), timestamps_us=np.array(UNEVEN))
    with pytest.warns(FrameTimesWarning, match=r"us\.npz: .* 1e-08 s apart \(seconds read as microseconds"):
        ef.events_from_frames(str(tmp_path / "us.npz"), threshold=0.2)
    code, err = _cli([tmp_path / "ms.npz", "-o", tmp_path / "ms.h5"], capfd)
    assert code == 0 and "milliseconds read as seconds?" in err
    import warnings
    np.savez(tmp_path / "s.npz", frames=_ramp(), times=np.array(UNEVEN))
    for interval in (1e-6, 1.0):          # the bounds themselves are likely
        with warnings.catch_warnings():
            warnings.simplefilter("error", FrameTimesWarning)
            ef.events_from_frames(_ramp(), [0.0, interval, 2 * interval], threshold=0.2)
            ef.events_from_frames(str(tmp_path / "s.npz"), threshold=0.2)
