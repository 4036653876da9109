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
from mitsuba_eventfield.lightfield.model import from_events

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
