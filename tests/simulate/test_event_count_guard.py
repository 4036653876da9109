"""A threshold far below any sensor's asks for more events than memory holds: every path that makes events
(batched, a step a commit, the host's NumPy path) refuses in one line before allocating them, where a 64x48
render at 1e-6 crashed on a 32-bit array size (its slot ends wrapped past 2^32) and 1e-9 exhausted the memory.
The guard counts the events a step makes, not the crossings a refractory period drops."""
import contextlib
import os

import drjit as dr
import mitsuba as mi
import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield import cli
from mitsuba_eventfield.plugins import pixel_model
from mitsuba_eventfield.plugins.event_batch import one_frame_a_step
from mitsuba_eventfield.plugins.event_integrator import device_path, host_path

SCENE = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")


@pytest.mark.parametrize("path", [None, one_frame_a_step, host_path])
def test_more_events_than_memory_holds_are_refused_on_every_path(path):
    scene = ef.load_scene(SCENE, width=32, height=24)
    with path() if path else contextlib.nullcontext():
        with pytest.raises(ef.EventFieldError, match=r"events from .* on [0-9]+ (firing )?pixels .*: more than "
                                                     r"memory holds"):
            ef.render_events(scene, 0.004, steps=8, threshold=1e-9)
        # the same scene at a small but sane threshold renders: the guard counts, it does not cap
        small, usual = (len(ef.render_events(scene, 0.004, steps=8, threshold=c)) for c in (0.02, 0.2))
    assert 5 * usual < small < 20 * usual                      # events grow about as 1 / threshold (12x here)


@pytest.mark.parametrize("per_step", [False, True])
def test_a_refractory_period_keeps_what_the_guard_counts(per_step):
    """At 1e-7 a 1 ms refractory period keeps ~2,500 events of billions of crossings: the device's per-step path
    summed the crossings and refused what the batched path rendered. (The host's NumPy path does expand every
    crossing before its refractory filter: there the refusal is right.)"""
    scene = ef.load_scene(SCENE, width=32, height=24)
    with device_path(), one_frame_a_step() if per_step else contextlib.nullcontext():
        events = ef.render_events(scene, 0.004, steps=8, threshold=1e-7, pixel={"refractory_s": 1e-3})
    assert 0 < len(events) < 32 * 24 * 5


def test_a_count_beyond_int32_does_not_wrap():
    """floor(rise / c) of 1e10 crossings became INT_MIN as an Int32; counts are capped at 2^30 (far above any
    real step's), so the guard sees a huge count, not a negative one."""
    n = pixel_model.count_crossings(dr, mi.Int32, mi.Float([20.0, -20.0]), mi.Float(0.0), 1e-9, 1e-9)
    assert n.numpy().tolist() == [2 ** 30, -2 ** 30]
    assert pixel_model.count_crossings(dr, mi.Int32, mi.Float([0.25]), mi.Float(0.0), 0.1, 0.1).numpy().tolist() == [2]


def test_the_command_line_says_it_in_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "e.h5"
    assert cli.main(["render", SCENE, "-D", "width=64", "-D", "height=48", "--duration", "0.004", "--steps", "32",
                     "-o", str(out), "--threshold", "1e-6", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "events from 0 s to 0.004 s on 3072 pixels" in err[0], err
    assert "raise the contrast threshold" in err[0] and not list(tmp_path.iterdir())
