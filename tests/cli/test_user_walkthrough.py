"""What a new user's walkthrough (2026-11-27, a researcher converting videos and sweeping at scale) found: each
case refused in one line before any work and with its inputs kept, or now doing what the user asked."""
import os

import numpy as np
import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield import cli
from mitsuba_eventfield.evaluation.sweep import grid

DEMO = os.path.join(ROOT, "scenes", "demo", "demo.xml")
TINY = ["-D", "width=24", "-D", "height=18", "--duration", "0.002", "--steps", "4", "--quiet"]


@pytest.fixture
def ramp(tmp_path):
    """A brightening 8x8 frame stack: 1.1 log units over 5 ms (5 events a pixel at C = 0.2)."""
    path = tmp_path / "ramp.npz"
    np.savez(path, frames=np.exp(np.linspace(0, 1.1, 6))[:, None, None] * np.ones((6, 8, 8), np.float32),
             times=np.linspace(0, 0.005, 6))
    return path


def _refused(argv, capsys, *words):
    assert cli.main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and all(w in err for w in words), err
    return err


def test_an_output_that_is_an_input_through_a_link_is_refused_and_the_input_kept(ramp, tmp_path, capsys):
    before = ramp.read_bytes()
    link = tmp_path / "link.npz"
    os.symlink(ramp, link)
    _refused(["convert", link, "-o", ramp], capsys, "the output is the input")
    hard = tmp_path / "hard.npz"
    os.link(ramp, hard)
    with pytest.raises(ef.EventFieldError, match="the output is the input"):
        ef.events_from_frames(str(hard), output=str(ramp))
    times = tmp_path / "times.txt"
    times.write_text("0\n0.001\n0.002\n")
    frames = tmp_path / "imgs"
    frames.mkdir()
    import cv2
    for k in range(3):
        cv2.imwrite(str(frames / f"f{k}.png"), np.full((8, 8), 40 * k + 20, np.uint8))
    _refused(["convert", frames, "-o", times, "--times", times], capsys, "the output is the input")
    assert ramp.read_bytes() == before and times.read_text() == "0\n0.001\n0.002\n"


def test_an_empty_output_path_is_refused_before_any_work(ramp, capsys):
    _refused(["render", DEMO, "-o", "", *TINY], capsys, "empty")
    _refused(["convert", ramp, "-o", ""], capsys, "empty")
    with pytest.raises(ef.EventFieldError, match="empty"):
        ef.events_from_frames(str(ramp), output="")
    with pytest.raises(ef.EventFieldError, match="empty"):
        ef.render_events(ef.load_scene(DEMO, width=24, height=18), 0.002, steps=4, output=" ")


def test_a_negative_pixel_seed_names_the_field(ramp, tmp_path, capsys):
    _refused(["convert", ramp, "-o", tmp_path / "r.h5", "--pixel", "seed=-1"], capsys, "seed = -1", ">= 0")
    assert not (tmp_path / "r.h5").exists()


def test_a_define_given_twice_is_refused(tmp_path, capsys):
    _refused(["render", DEMO, "-o", tmp_path / "a.h5", "-D", "width=32", *TINY], capsys, "-D width given twice")


def test_negative_times_into_aedat4_are_refused_before_any_work(tmp_path, capsys, monkeypatch):
    path = tmp_path / "neg.npz"
    np.savez(path, frames=np.exp(np.linspace(0, 1, 6))[:, None, None] * np.ones((6, 8, 8), np.float32),
             times=np.linspace(0, 0.005, 6) - 0.5)
    from mitsuba_eventfield.simulate import convert
    monkeypatch.setattr(convert, "_feed", lambda *a: pytest.fail("frames converted before the refusal"))
    for out in ("neg.aedat4", "neg.raw"):
        assert cli.main(["convert", str(path), "-o", str(tmp_path / out)]) == 2
        err = capsys.readouterr().err
        assert err.strip().splitlines() == [f"eventfield: error: {tmp_path / out}: {out.split('.')[1]} files hold "
                                            "timestamps >= 0 only (the events start at -0.5 s): choose .h5, .npz "
                                            "or .txt, or shift the times"], err
        assert not (tmp_path / out).exists()


def test_a_render_starting_before_zero_is_refused_for_aedat4_before_rendering(tmp_path):
    with pytest.raises(ef.EventFieldError, match=r"aedat4 files hold timestamps >= 0 only \(the events start at "
                                                 r"-0.001 s\)"):
        ef.render_events(DEMO, 0.002, steps=2, t_start=-0.001, output=str(tmp_path / "e.aedat4"),
                         pixel={"threshold": 0.2})
    assert not (tmp_path / "e.aedat4").exists()


def test_a_source_whose_times_are_known_late_is_still_refused_whole(tmp_path):
    pytest.importorskip("faery")                   # (the AEDAT4 writer; the GPU image lacks it)
    from mitsuba_eventfield.simulate.frame_sources import FrameSource
    frames = [np.full((8, 8), v, np.float32) for v in np.exp(np.linspace(0, 1, 6))]
    src = FrameSource("gen", 8, 8, None, lambda: zip(np.linspace(-0.5, -0.495, 6), frames), {"kind": "generator"})
    with pytest.raises(ef.EventFieldError, match="aedat4 files hold timestamps >= 0 only .the events start at -0.5 s"):
        ef.events_from_frames(src, output=str(tmp_path / "neg.aedat4"))   # (its first frame read first)
    assert not (tmp_path / "neg.aedat4").exists()


def test_a_text_output_gets_its_preview_up_to_its_last_event(tmp_path, capsys):
    assert cli.main(["render", DEMO, "-o", str(tmp_path / "e.txt"), "--preview", str(tmp_path / "p.png"), *TINY]) == 0
    assert (tmp_path / "p.png").stat().st_size > 0
    ev = ef.read_events(str(tmp_path / "e.txt"))       # a .txt keeps no start: its events span it (start_us)
    assert f"(events of {(int(ev.t[-1]) - int(ev.t[0])) / 1e3:g} ms up to the end)" in capsys.readouterr().out


def test_an_output_named_like_an_option_value_is_not_taken_for_an_input(tmp_path, monkeypatch):
    """`--metadata line` with `--curve line`: the second run found a file named "line" and refused it as the
    curve's "input" (a review)."""
    monkeypatch.chdir(tmp_path)
    argv = ["device", "scan", "--simulate", "--dialect", "rigol", "--freq", "10", "--amplitude-deg", "1",
            "--curve", "line", "--duration", "0.05", "--metadata", "line"]
    assert cli.main(argv) == 0 and cli.main(argv) == 0


def test_info_on_a_frame_stack_points_to_convert(ramp, capsys):
    _refused(["info", ramp], capsys, "a frame stack", "eventfield convert")


def test_a_times_file_with_a_byte_order_mark_is_read(ramp, tmp_path):
    times = tmp_path / "bom.txt"
    times.write_bytes(b"\xef\xbb\xbf" + b"\n".join(str(t).encode() for t in np.linspace(0, 0.005, 6)))
    frames = np.load(ramp)["frames"]
    ev = ef.events_from_frames(frames, str(times))
    assert len(ev) == 8 * 8 * 5 and ev.t.min() > 0 and ev.t.max() <= 5000


def test_a_whole_float_film_size_and_numpy_sweep_values_are_taken():
    timed = ef.load_scene(DEMO, width=24.0, height=np.int64(18))
    assert timed.film_size == (24, 18)
    points = grid({"xml.amplitude": np.linspace(0.1, 0.2, 2), "render.spp": range(1, 3)})
    assert points[-1] == {"xml.amplitude": 0.2, "render.spp": 2} and type(points[0]["xml.amplitude"]) is float
    for bad in ([], "abc", np.zeros((2, 2)), 4, {1, 2}):          # a set: no order for the table's rows
        with pytest.raises(ef.EventFieldError, match="give a non-empty list of values"):
            grid({"render.spp": bad})


def test_a_sweep_checks_every_points_pixel_before_spawning_and_its_workers_log_quietly(tmp_path, capfd):
    base = {"xml.width": 24, "xml.height": 18, "render.duration": 0.002, "render.steps": 4}
    from mitsuba_eventfield.evaluation.sweep import check_pixel
    check_pixel({"pixel.threshold_on": None, "pixel.threshold_sigma": 0.3})   # None: the scene's, maybe C = 1
    with pytest.raises(ef.EventFieldError, match=r"sweep point pixel.refractory_s=-1.0: refractory_s = -1.0"):
        ef.sweep(DEMO, over={"pixel.refractory_s": [0.0, -1.0]}, base=base, out_dir=str(tmp_path / "bad"))
    assert not (tmp_path / "bad").exists() or not os.listdir(tmp_path / "bad")        # no point was run
    was = ef.quiet_mitsuba_log()
    try:
        capfd.readouterr()
        table = ef.sweep(DEMO, over={"render.spp": [1]}, base=base, processes=1)
        # the spawned worker loaded a monochrome scene: Mitsuba's own log printed its warning there
        assert len(table.rows) == 1 and "Monochrome" not in capfd.readouterr().err
    finally:
        ef.quiet_mitsuba_log(was)


def test_convert_takes_a_threshold_for_each_polarity(tmp_path):
    """ON at 0.1 and OFF at 0.3 on a frame stack that brightens by 1.1 and darkens back: 11 ON events a pixel
    (levels 0.1 .. 1.1 within rounding: at least 10) and 3 OFF (1.1 -> 0 falls through 0.8, 0.5, 0.2)."""
    path = tmp_path / "updown.npz"
    logs = np.r_[np.linspace(0, 1.1, 6), np.linspace(1.1, 0, 6)[1:]]
    np.savez(path, frames=np.exp(logs)[:, None, None] * np.ones((len(logs), 4, 4), np.float32),
             times=np.linspace(0, 0.01, len(logs)))
    out = tmp_path / "ud.h5"
    assert cli.main(["convert", str(path), "-o", str(out), "--threshold-on", "0.1", "--threshold-off", "0.3",
                     "--quiet"]) == 0
    ev = ef.read_events(str(out))
    on, off = (np.count_nonzero(ev.p == s) / 16 for s in (1, -1))
    assert 10 <= on <= 11 and off == 3 and ev.meta["pixel_model"]["threshold_on"] == 0.1
    with pytest.raises(ef.EventFieldError, match=r"threshold = 50: allowed range is \(0, 10\]"):   # as given
        ef.events_from_frames(np.load(path)["frames"], np.load(path)["times"], threshold=50)
    # the same value twice is taken, as render takes it
    assert cli.main(["convert", str(path), "-o", str(tmp_path / "same.h5"), "--threshold-on", "0.1", "--pixel",
                     "threshold_on=0.1", "--quiet"]) == 0
