"""The Python API and the command line make the same thing from the same input (an audit, 2026-11-27: a script's
depths were up to 3.6 m from the same command's, its refocused image 18 % of the peak off, and arguments the
command refuses were taken or ignored)."""
import os

import numpy as np
import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield.cli.main import main as cli
from mitsuba_eventfield.images import read_exr
from mitsuba_eventfield.lightfield.streams import from_events

GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")
KALEIDO = os.path.join(ROOT, "scenes", "moving_grid", "kaleidoscope.xml")


@pytest.fixture(scope="module")
def streams(tmp_path_factory):
    d = tmp_path_factory.mktemp("agree")
    ev = ef.render_events(ef.load_scene(GALVO, width=64, height=48, amplitude=2), 0.004, steps=24)
    ef.write_events(str(d / "g.h5"), ev)
    kal = ef.render_events(ef.load_scene(KALEIDO, views_px=60), 0.01, steps=4)
    return d, ef.read_events(str(d / "g.h5")), kal


def _exr(path, channel):
    return read_exr(str(path))[0][channel]


@pytest.mark.parametrize("method", [None, "galvo"])
def test_refocus_in_python_is_the_commands(streams, method):
    """The default light field of a galvo stream is the per-period solver's on both sides (Python's was the
    one-depth solver's: 0.54 of a 3.0 peak apart), and a named method is the same method."""
    d, ev, _ = streams
    out = d / f"rf_{method}.png"
    assert cli(["refocus", str(d / "g.h5"), "--depth", "0.5", "--views", "8", "-o", str(out)]
               + ([] if method is None else ["--method", method])) == 0
    mine = ef.refocus(from_events(ev, views=8, **({} if method is None else {"method": method})), 0.5)
    theirs = _exr(out.with_suffix(".exr"), "Y")
    assert np.abs(mine - theirs).max() <= 1e-5 * np.abs(theirs).max()
    if method is None:       # and the two methods differ here, so the comparison can tell them apart
        other = ef.refocus(from_events(ev, views=8, method="galvo"), 0.5)
        assert np.abs(other - theirs).max() > 1e-2 * np.abs(theirs).max()


def test_depth_from_focus_measures_as_the_command(streams):
    d, ev, _ = streams
    out = d / "dp.png"
    assert cli(["depth", str(d / "g.h5"), "--near", "0.4", "--far", "4", "--views", "8", "-o", str(out)]) == 0
    dm = ef.depth_from_focus(from_events(ev, views=8), 0.4, 4.0)
    theirs = _exr(out.with_suffix(".exr"), "depth")
    assert np.abs(dm.depth - theirs).max() <= 1e-5 * np.nanmax(theirs)
    other = ef.depth_from_focus(from_events(ev, views=8), 0.4, 4.0, measure="sml")       # Python's old default
    assert np.abs(other.depth - theirs).max() > 0.05


def test_sliding_light_fields_default_to_the_same_solver(streams):
    """``galvo_lightfields`` integrated the events onto a flat image by default (the command warns that this
    is unreliable: galvo_static's confident depths 0.91 m where the card is at 0.5 m)."""
    _, ev, _ = streams
    assert np.array_equal(next(ef.galvo_lightfields(ev, views=8)).views, from_events(ev, views=8).views)
    with pytest.raises(ef.ConfigError, match="method 'periods' reconstructs from the events alone"):
        ef.galvo_lightfields(ev, views=8, method="periods", log_start=np.zeros((48, 64)))


@pytest.mark.parametrize("kwargs, words", [
    (dict(views=1), r"from_events|galvo_lightfields: views = 1: allowed range is \[2, 4096\]"),
    (dict(time=0.002), "from_events: time is for a kaleidoscope stream; this one is galvo"),
    (dict(period=1.5), r"from_events: period = 1.5: must be a whole number"),
    (dict(period=1), r"scan period 1 is not in the stream: allowed 0..0"),
    (dict(method="flat"), "from_events: method = 'flat'; allowed for a galvo stream: .*periods"),
])
def test_a_galvo_light_field_refuses_what_the_command_refuses(streams, kwargs, words):
    with pytest.raises(ef.ConfigError, match=words):
        from_events(streams[1], **kwargs)


@pytest.mark.parametrize("kwargs, words", [
    (dict(period=0), "from_events: period is for a galvo stream; this one is kaleidoscope"),
    (dict(views=8, period=0), "from_events: period and views are for a galvo stream; this one is kaleidoscope"),
    (dict(method="periods"), "method = 'periods'; allowed for a kaleidoscope stream: "),
])
def test_a_kaleidoscope_light_field_refuses_galvo_arguments(streams, kwargs, words):
    with pytest.raises(ef.ConfigError, match=words):
        from_events(streams[2], **kwargs)


def test_a_frame_is_rendered_alike(tmp_path):
    """``eventfield frame`` rendered 16 spp, ``ef.render_frames`` 4: the README's Python start frame refocused
    28 % away from the command's. Both take ``FRAME_SPP`` now."""
    from mitsuba_eventfield.validate import FRAME_SPP
    out = tmp_path / "f.exr"
    assert cli(["frame", GALVO, "-D", "width=32", "-D", "height=24", "--times", "0", "-o", str(out)]) == 0
    mine = ef.render_frames(ef.load_scene(GALVO, width=32, height=24), [0.0], log=False)[0]
    assert np.array_equal(mine.astype(np.float32), _exr(out, "Y"))
    assert read_exr(str(out))[1]["spp"] == FRAME_SPP == 16


@pytest.mark.parametrize("kwargs, words", [
    (dict(seed=2**32), r"seed = 4294967296: allowed range is \[0, 4294967295\]"),   # a Dr.Jit error inside
    (dict(spp=100_000), r"spp = 100000: allowed range is \[1, 65536\]"),            # was rendered
    (dict(spp=0), r"spp = 0: allowed range is \[1, 65536\]"),                       # said (0, inf)
    (dict(steps=0), r"steps = 0: allowed range is \[1, 1e\+07\]"),
])
def test_a_render_refuses_what_the_command_refuses(kwargs, words):
    with pytest.raises(ef.ConfigError, match=words):
        ef.render_events(ef.load_scene(GALVO, width=8, height=6), 0.001, **kwargs)


def test_the_largest_seed_renders(tmp_path):
    """At the default steps too, whose noise probe renders a second seed (the next one was 2^32: a review)."""
    for steps in (None, 2):
        ev = ef.render_events(ef.load_scene(GALVO, width=8, height=6), 0.001, steps=steps, seed=2**32 - 1)
        assert ev.meta["seed"] == 2**32 - 1
    assert cli(["render", GALVO, "-D", "width=8", "-D", "height=6", "--duration", "0.001", "--steps", "4",
                "--seed", str(2**32 - 1), "-o", str(tmp_path / "s.h5")]) == 0


def test_a_stuck_pixel_is_left_out_in_python_as_by_the_command(streams):
    """One pixel firing ON at 250 kHz (a 4 ms capture: 1000 events, past 140 dB): the command leaves it out with
    a warning; a script's refocused image kept it (an audit's 50 kHz pixel over 8 ms: maximum 918,620 against the
    command's 3.18). ``from_events`` now leaves it out too, and says so."""
    d, ev, _ = streams
    n = int(ev.duration_us * 0.25)
    t = np.linspace(ev.start_us, ev.start_us + ev.duration_us - 1, n).astype(np.int64)
    order = np.argsort(np.concatenate([ev.t, t]), kind="stable")
    join = lambda a, b: np.concatenate([a, b])[order]  # noqa: E731
    stuck = ef.EventStream(join(ev.x, np.full(n, 20)), join(ev.y, np.full(n, 10)), join(ev.t, t),
                           join(ev.p, np.ones(n, np.int8)), ev.width, ev.height,
                           dict(ev.meta, t_start_us=ev.start_us, duration_us=ev.duration_us))
    ef.write_events(str(d / "stuck.h5"), stuck)
    out = d / "stuck.png"
    assert cli(["refocus", str(d / "stuck.h5"), "--depth", "0.5", "--views", "8", "--method", "galvo",
                "-o", str(out)]) == 0
    with pytest.warns(UserWarning, match=r"from_events: 1 stuck or hot pixel left out.*\(20, 10\) ON"):
        lf = from_events(ef.read_events(str(d / "stuck.h5")), views=8, method="galvo")
    mine, theirs = ef.refocus(lf, 0.5), _exr(out.with_suffix(".exr"), "Y")
    assert np.abs(mine - theirs).max() <= 1e-5 * np.abs(theirs).max() and np.abs(theirs).max() < 100


@pytest.mark.parametrize("times, kwargs, words", [
    ([0.003, 0.001], {}, r"reconstruct: times = \[0.003 0.001\]: expected a non-empty, non-decreasing"),
    ([0.001], dict(method="highpass", cutoff_hz=0), r"reconstruct: cutoff_hz = 0: allowed range is \(0, 1e\+06\]"),
    ([0.001], dict(method="direct", cutoff_hz=5), r"method 'direct': got an unexpected keyword argument 'cutoff_hz'; "
                                                  "it takes log_start, t_start, c_on, c_off"),
    ([0.001], dict(method="complementary"), r"method 'complementary': missing a required argument: 'frames'"),
])
def test_reconstruct_refuses_in_one_line_naming_the_argument(streams, times, kwargs, words):
    """Decreasing times were a ValueError naming no value, a cutoff for the direct method or the complementary
    filter without frames a raw TypeError from inside the method, and cutoff 0 was taken."""
    with pytest.raises(ef.ConfigError, match=words):
        ef.reconstruct.reconstruct(streams[1], times, **kwargs)


def test_other_refusals_of_the_python_api_are_one_line_errors(streams, tmp_path):
    _, ev, _ = streams
    with pytest.raises(ef.EventFieldError, match=r"p.png: the window t0_us = 10000000, t1_us = 20000000 is outside "
                                                 r"the stream, which covers 0 to 4000 us"):
        ef.write_preview(str(tmp_path / "p.png"), ev, 10**7, 2 * 10**7)      # a blank PNG was written
    assert not os.listdir(tmp_path)
    with pytest.raises(ef.ConfigError, match=r"depth_from_focus: near = 0.001: this galvo light field refocuses"):
        ef.depth_from_focus(from_events(ev, views=8, method="galvo"), 0.001, 4.0)     # said "refocus: depth"
    from mitsuba_eventfield.apps import highspeed, scanrate
    with pytest.raises(ef.ConfigError, match="min_confidence = 2: must be in"):     # a bare ValueError before
        scanrate.run(GALVO, min_confidence=2)
    with pytest.raises(ef.ConfigError, match="need 0 < near < far"):
        highspeed.track_focus_depth(GALVO, (0.1, 0.1, 0.5, 0.5), 1.5, 0.6, 1.6)


def _with_stuck_pixel(ev, x=20, y=10, rate_per_us=0.25):
    n = int(ev.duration_us * rate_per_us)
    t = np.linspace(ev.start_us, ev.start_us + ev.duration_us - 1, n).astype(np.int64)
    order = np.argsort(np.concatenate([ev.t, t]), kind="stable")
    join = lambda a, b: np.concatenate([a, b])[order]  # noqa: E731
    return join(ev.x, np.full(n, x)), join(ev.y, np.full(n, y)), join(ev.t, t), join(ev.p, np.ones(n, np.int8))


def test_a_recordings_stuck_pixel_is_left_out_at_the_thresholds_given(streams):
    """A recording without thresholds in its metadata, given them as c_on / c_off (the commands' --contrast):
    the stuck pixel was kept (refocused to NaN after a float32 overflow: a review). Sliding light fields leave
    it out too."""
    _, ev, _ = streams
    meta = {k: v for k, v in ev.meta.items() if k != "pixel_model"}
    rec = ef.EventStream(*_with_stuck_pixel(ev), ev.width, ev.height,
                         dict(meta, t_start_us=ev.start_us, duration_us=ev.duration_us))
    with pytest.warns(UserWarning, match=r"from_events: 1 stuck or hot pixel left out.*\(20, 10\) ON"):
        lf = from_events(rec, views=8, method="galvo", c_on=0.2, c_off=0.2)
    assert np.isfinite(ef.refocus(lf, 0.5)).all() and "pixel_model" not in lf.meta
    with pytest.warns(UserWarning, match=r"galvo_lightfields: 1 stuck or hot pixel left out"):
        assert next(ef.galvo_lightfields(rec, views=8, method="galvo", c_on=0.2, c_off=0.2)).shape == lf.shape


@pytest.mark.parametrize("kwargs, words", [
    (dict(cutoff_hz=5), r"method 'periods': cutoff_hz: not a keyword it takes \(depth_range, samples, "),
    (dict(method="galvo", bogus=1), r"method 'galvo': bogus: not a keyword it takes \(t_start, samples, depth"),
    (dict(depth_range=(4, 0.4)), r"depth_range = \(4, 0.4\): need \(near, far\) with 0 < near < far"),
])
def test_sliding_light_fields_refuse_bad_keywords_at_the_call(streams, kwargs, words):
    """The solver runs when the first light field is asked for: a keyword it does not take was a TypeError
    there (and a reversed depth range refused only then)."""
    with pytest.raises(ef.ConfigError, match=words):
        ef.galvo_lightfields(streams[1], views=8, **kwargs)


def test_the_commands_say_a_solvers_warning_after_their_checks(streams, capsys):
    """The per-period solver's warning (this stream's moving-free scene still turns down a fifth of its
    equations at 64x48) is said once the command's own checks pass, with the file's name; a refused command
    does not say it (it ends with its one-line error)."""
    d, _, _ = streams
    assert cli(["refocus", str(d / "g.h5"), "--depth", "0.5", "--views", "8", "-o", str(d / "w.png")]) == 0
    err = capsys.readouterr().err
    assert f"eventfield: warning: {d / 'g.h5'}: scan period 0: the solver turned down" in err, err
    try:
        code = cli(["refocus", str(d / "g.h5"), "--depth", "0.001", "--views", "8", "-o", str(d / "x.png")])
    except SystemExit as e:
        code = e.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and "solver turned down" not in err and "--depth = 0.001" in err.splitlines()[-1], err


def test_a_colour_start_frame_is_read_as_its_luminance(streams, tmp_path):
    """A colour camera's EXR (R, G, B, no Y) was read as its red channel alone (a kaleidoscope rig's depth 3.9 %
    off against 1.8 % with its luminance). Now its luminance, with the event pixel's weights: the refocus from
    it is the one from the same frame stored as Y."""
    from mitsuba_eventfield.images import LUMA, write_exr
    d, ev, _ = streams
    rng = np.random.default_rng(1)
    rgb = rng.uniform(0.05, 1.0, (3, ev.height, ev.width)).astype(np.float32)
    write_exr(str(tmp_path / "rgb.exr"), dict(zip("RGB", rgb)))
    write_exr(str(tmp_path / "y.exr"), {"Y": np.tensordot(LUMA, rgb, 1).astype(np.float32)})
    for name in ("rgb", "y"):
        assert cli(["refocus", str(d / "g.h5"), "--depth", "0.5", "--views", "8", "--start-frame",
                    str(tmp_path / f"{name}.exr"), "-o", str(tmp_path / f"rf_{name}.png")]) == 0
    a, b = _exr(tmp_path / "rf_rgb.exr", "Y"), _exr(tmp_path / "rf_y.exr", "Y")
    assert np.abs(a - b).max() <= 1e-5 * np.abs(b).max()
    red = ef.refocus(from_events(ev, views=8, log_start=np.log(rgb[0])), 0.5)       # what the red alone gave
    assert np.abs(red - b).max() > 0.05 * np.abs(b).max()


def test_a_black_flat_frame_is_named(tmp_path, capsys):
    """`calibrate kaleidoscope --flat` refused a black frame without naming it (a rig user's walkthrough)."""
    from mitsuba_eventfield.images import write_exr
    frame = tmp_path / "target.exr"
    assert cli(["frame", KALEIDO, "-D", "views_px=60", "-o", str(frame)]) == 0
    write_exr(str(tmp_path / "black.exr"), {"Y": np.zeros_like(_exr(frame, "Y"))})
    try:
        code = cli(["calibrate", "kaleidoscope", str(frame), "--flat", str(tmp_path / "black.exr"),
                    "-o", str(tmp_path / "k.json")])
    except SystemExit as e:
        code = e.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1].endswith(f"{tmp_path / 'black.exr'}: the flat-field frame is black"), err
    assert not (tmp_path / "k.json").exists()
