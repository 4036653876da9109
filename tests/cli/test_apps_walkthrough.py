"""What an applications user's walkthrough found (2026-11-27), each refused or fixed in one place."""
import os

import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield import cli

FAN = os.path.join(ROOT, "scenes", "fan", "fan.xml")


def _refused(argv, capsys, *words):
    assert cli.main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err and all(w in err[-1] for w in words) and not any("Traceback" in line for line in err), err
    return err[-1]


def test_a_scene_that_is_not_utf8_is_one_line(tmp_path, capsys):
    """A UnicodeDecodeError has no strerror: reading it crashed the error message (exit 3) in every command."""
    scene = tmp_path / "latin.xml"
    scene.write_bytes(b'<?xml version="1.0" encoding="ISO-8859-1"?>\n<scene version="3.0.0"><!-- 90\xb0 --></scene>\n')
    _refused(["render", scene, "-o", tmp_path / "e.h5", "--duration", "0.001", "--steps", "2"], capsys,
             "latin.xml: cannot read the scene: not UTF-8 text", "save it as UTF-8")


@pytest.mark.parametrize("plane", ["../escaped=0.6", "conventional=0.6", "a/b=0.6"])
def test_a_highspeed_plane_name_must_be_a_plain_file_name(tmp_path, capsys, plane):
    """A plane names its files: '../escaped' wrote outside the output folder, 'conventional' overwrote the
    conventional frame's EXR, 'a/b' failed after the whole render."""
    _refused(["highspeed", FAN, "--plane", plane, "-o", tmp_path / "hs"], capsys, "a name of letters, digits")
    assert not (tmp_path / "hs").exists() and not (tmp_path / "escaped.exr").exists()


def test_a_time_window_has_its_own_span():
    """A 1.5 ms cut of a 4 ms stream kept the 4 ms duration: `info` quoted a rate 2.7x low and refocus took the
    cut for a whole scan period."""
    ev = ef.EventStream([1, 2, 3], [1, 1, 1], [100, 1200, 3000], [1, -1, 1], 4, 4,
                        {"t_start_us": 0, "duration_us": 4000})
    cut = ev.time_window(0, 1500)
    assert (cut.start_us, cut.duration_us, len(cut)) == (0, 1500, 2)
    late = ev.time_window(1000, None)
    assert (late.start_us, late.duration_us) == (1000, 3000)
    beyond = ev.time_window(3500, 9000)                     # clipped to the stream's span
    assert (beyond.start_us, beyond.duration_us, len(beyond)) == (3500, 500, 0)
    assert ev.time_window().meta["duration_us"] == 4000    # no window: the stream as it is


def test_options_that_were_ignored_are_refused(tmp_path, capsys):
    _refused(["hdr", "--depths", "0.5", "-o", tmp_path / "h"], capsys, "--depths and --views apply to the light field")
    events = ef.EventStream([1, 2], [1, 1], [100, 200], [1, -1], 4, 4,
                            {"pixel_model": {"threshold_on": 0.2, "threshold_off": 0.2}})
    path = tmp_path / "e.h5"
    ef.write_events(str(path), events)
    _refused(["reconstruct", path, "--cutoff", "3", "-o", tmp_path / "r"], capsys,
             "--cutoff: --method direct filters nothing")
    # --contrast is for a recording without thresholds; on a file with them it replaced them silently
    _refused(["reconstruct", path, "--contrast", "0.5", "-o", tmp_path / "r"], capsys,
             "carries its own contrast thresholds (ON 0.2, OFF 0.2)")
    assert not (tmp_path / "r").exists() and not (tmp_path / "h").exists()


def test_hdr_refuses_a_period_without_events(tmp_path, capsys):
    """One step a period made 0 events, and hdr wrote and scored the start frame as the events' image."""
    _refused(["hdr", "-D", "width=32", "-D", "height=24", "--steps", "1", "-o", tmp_path / "h"], capsys,
             "no events in its scan period (1 steps): nothing to recover the image from")
    assert not os.path.exists(tmp_path / "h" / "metrics.json")


def test_foreign_polarities_have_one_reading(tmp_path):
    """A text file's polarity 2 or 5 was read as ON, and a 0x0 sensor taken; an npz's 0/1 (what text files hold)
    was refused as 'polarity must be +1 or -1'. One rule: -1/+1 or 0/1, anything else named."""
    text = tmp_path / "e.txt"
    text.write_text("4 4\n0.000001 1 1 0\n0.000002 2 1 1\n")
    assert ef.read_events(str(text)).p.tolist() == [-1, 1]
    text.write_text("4 4\n0.000001 1 1 2\n0.000002 2 1 5\n")
    with pytest.raises(ef.EventFieldError, match=r"e.txt: .*polarity values 2, 5: expected -1 / \+1 or 0 / 1"):
        ef.read_events(str(text))
    text.write_text("0 0\n")
    with pytest.raises(ef.EventFieldError, match=r"'width height' \(each >= 1\)"):
        ef.read_events(str(text))
    import numpy as np
    npz = tmp_path / "e.npz"
    np.savez(npz, x=np.array([1, 2]), y=np.array([1, 1]), t=np.array([1, 2]), p=np.array([0, 1]), width=4, height=4)
    assert ef.read_events(str(npz)).p.tolist() == [-1, 1]


def test_a_foreign_dsec_file_says_its_sensor_size_is_a_guess(tmp_path):
    """A DSEC-layout file without /eventfield keeps no sensor size: the largest coordinates gave 3x3 for two
    events and a crop's size for a cropped recording, silently; now said, and its 0/1 polarity read as -1/+1."""
    import h5py
    import numpy as np
    path = tmp_path / "dsec.h5"
    with h5py.File(path, "w") as f:
        g = f.create_group("events")
        for name, values, dtype in (("x", [1, 59], np.uint16), ("y", [2, 47], np.uint16), ("t", [5, 9], np.int64),
                                    ("p", [0, 1], np.uint8)):
            g.create_dataset(name, data=np.array(values, dtype))
    with pytest.warns(UserWarning, match=r"no sensor size in the file .* taken as 60x48 from its largest coordinates"):
        ev = ef.read_events(str(path))
    assert (ev.width, ev.height, ev.p.tolist()) == (60, 48, [-1, 1])
    assert ev.meta["sensor_size"] == "from the largest coordinates"


def test_a_capture_without_a_duration_names_the_option(tmp_path, capsys):
    """It said "no duration in its motion file: give periods" of a scene with no motion file at all."""
    _refused(["highspeed", os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml"), "--plane", "card=0.5",
              "-D", "width=32", "-D", "height=24", "-o", tmp_path / "hs"], capsys,
             "galvo_static.xml: no motion file (with a duration): give the scan periods to capture (--periods")


def test_a_highspeed_plane_where_nothing_lies_is_refused_before_the_render(tmp_path, capsys):
    """--plane fan=0.05 rendered the whole capture and then scored NaN; the planes are checked against Mitsuba's
    depth first (the one check scan-frequency used: evaluation.truth.check_planes_seen)."""
    _refused(["highspeed", FAN, "-D", "width=48", "-D", "height=36", "--plane", "fan=0.05", "-o", tmp_path / "hs"],
             capsys, "plane 'fan' at 0.05: no part of", "lies within 0.15 (relative) of that depth")
    assert not (tmp_path / "hs").exists()


def test_hdr_lightfield_depths_must_hold_part_of_the_scene(tmp_path, capsys):
    """hdr --lightfield on another scene refocused at hdr_depth's 0.6 and 1.5 m and reported NaN ("focus check
    FAILED (xnan)") after the render: the depths are checked against Mitsuba's depth first."""
    _refused(["hdr", "--lightfield", os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml"), "-D",
              "width=32", "-D", "height=24", "-o", tmp_path / "h"], capsys,
             "plane '--depths 0.6' at 0.6: no part of", "galvo_static.xml lies within 0.1")
    assert not (tmp_path / "h").exists()


def test_a_flat_light_field_is_said_before_its_constant_refocus(tmp_path, capsys):
    """A kaleidoscope stream refocused at --time 0 (no event integrated yet) wrote an all-white image silently."""
    events = tmp_path / "k.h5"
    scene = ef.load_scene(os.path.join(ROOT, "scenes", "moving_grid", "kaleidoscope.xml"), views_px=30)
    ef.write_events(str(events), ef.render_events(scene, 0.004, steps=8))
    assert cli.main(["refocus", str(events), "--depth", "1", "--time", "0", "-o", str(tmp_path / "r.png")]) == 0
    assert "the light field's views are flat" in capsys.readouterr().err
    assert cli.main(["refocus", str(events), "--depth", "1", "--time", "4", "-o", str(tmp_path / "r4.png")]) == 0
    assert "views are flat" not in capsys.readouterr().err


def test_a_track_focus_roi_too_small_is_refused_before_the_render(tmp_path, capsys):
    """--roi 0.01 0.01 0.02 0.02 (a few pixels) was refused only after the whole capture."""
    _refused(["track-focus", "--roi", "0.01", "0.01", "0.02", "0.02", "-o", tmp_path / "tf"], capsys,
             "roi = (0.01, 0.01, 0.02, 0.02) is 3 x 2 pixels at 240 x 180: needs at least 3 x 3")
    assert not (tmp_path / "tf").exists()


def test_track_focus_past_the_object_is_refused_before_the_render(tmp_path, capsys, monkeypatch):
    """The dart leaves the view after eight 4 ms periods: --periods 14 rendered 56 ms of events, then failed on
    "the object was lost". Mitsuba's depth at each period's middle says so first; the default 6 periods pass
    that check and go on to the render."""
    from mitsuba_eventfield.apps import capture

    rendered = []

    def no_render(timed, duration, **k):
        rendered.append(duration)
        raise ef.EventFieldError("stopped before the render")
    monkeypatch.setattr(capture, "render_events", no_render)
    _refused(["track-focus", "-D", "width=64", "-D", "height=48", "--periods", "14", "-o", tmp_path / "tf"], capsys,
             "periods = 14: no part of the scene is nearer than object_far = 1.6 in periods [8, 9, 10, 11, 12, 13]")
    assert rendered == []
    _refused(["track-focus", "-D", "width=64", "-D", "height=48", "-o", tmp_path / "tf6"], capsys, "stopped before")
    assert rendered == [pytest.approx(0.024)]
