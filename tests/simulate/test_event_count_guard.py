"""A threshold far below any sensor's asks for more events than memory holds: every path that makes events
(batched, a step a commit, the host's NumPy path) refuses in one line before allocating them, where a 64x48
render at 1e-6 crashed on a 32-bit array size (its slot ends wrapped past 2^32) and 1e-9 exhausted the memory."""
import os

import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield import cli
from mitsuba_eventfield.plugins.event_batch import one_frame_a_step
from mitsuba_eventfield.plugins.event_integrator import host_path

SCENE = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")


@pytest.mark.parametrize("path", [None, one_frame_a_step, host_path])
def test_more_events_than_memory_holds_are_refused_on_every_path(path):
    scene = ef.load_scene(SCENE, width=32, height=24)
    context = path() if path else __import__("contextlib").nullcontext()
    with context, pytest.raises(ef.EventFieldError, match=r"events from .* on [0-9]+ pixels .*: more than memory holds"):
        ef.render_events(scene, 0.004, steps=8, threshold=1e-9)
    # the same scene at a small but sane threshold renders (the guard counts, it does not cap)
    small = ef.render_events(scene, 0.004, steps=8, threshold=0.02)
    assert 0 < len(small) < 10 * len(ef.render_events(scene, 0.004, steps=8, threshold=0.2)) * 10


def test_the_command_line_says_it_in_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "e.h5"
    assert cli.main(["render", SCENE, "-D", "width=64", "-D", "height=48", "--duration", "0.004", "--steps", "32",
                     "-o", str(out), "--threshold", "1e-6", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "at least 4e+09 events from 0 s to 0.004 s on 3072 pixels" in err[0], err
    assert "raise the contrast threshold" in err[0] and not list(tmp_path.iterdir())
