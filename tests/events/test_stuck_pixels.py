"""Stuck and hot pixels of a recording (``events.stuck_pixels``): a pixel whose events integrate to a level
spanning more than any sensor's range (140 dB) within a second is left out, named in a warning; pixels that
see light, noisy ones that fire both ways and a leaky pixel's slow drift are kept (a real camera's helper run,
2026-11-27: five pixels stuck ON at 20 kHz took a galvo refocus's 99th percentile from 1.9 to 12, at 50 kHz to
3.7e6, and wrote +inf into a reconstruction's EXR)."""
import math
import os

import numpy as np
import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield import cli
from mitsuba_eventfield.events.stuck_pixels import MAX_LEVEL_SPAN, stuck_pixels

GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")


def _brute(ev, c_on, c_off, window_us=1_000_000):
    """The largest span of each pixel's running level within each one-second window, one pixel at a time."""
    out = {}
    for x, y in set(zip(ev.x.tolist(), ev.y.tolist())):
        sel = (ev.x == x) & (ev.y == y)
        steps, windows = np.where(ev.p[sel] > 0, c_on, -c_off), (ev.t[sel] - ev.t[0]) // window_us
        for w in np.unique(windows):
            level = np.cumsum(steps[windows == w])
            span = max(level.max(), 0.0) - min(level.min(), 0.0)
            if span > MAX_LEVEL_SPAN and span > out.get((x, y), 0.0):
                out[(x, y)] = span
    return out


def test_stuck_pixels_against_a_pixel_by_pixel_sum():
    """Random walks of every kind (balanced, drifting, stuck ON, stuck OFF) over 3 s: the vectorised spans
    equal a pixel-by-pixel sum, window by window, for unequal ON and OFF thresholds."""
    rng = np.random.default_rng(5)
    n = 60_000
    x, y, t = rng.integers(0, 12, n), rng.integers(0, 8, n), np.sort(rng.integers(0, 3_000_000, n))
    bias = rng.uniform(0.0, 1.0, 96)[y * 12 + x]                    # each pixel's chance of ON
    p = np.where(rng.random(n) < bias, 1, -1)
    ev = ef.EventStream(x, y, t, p, 12, 8)
    found, truth = stuck_pixels(ev, 0.2, 0.3), _brute(ev, 0.2, 0.3)
    assert 5 < len(truth) < 90 and found.keys() == truth.keys()
    assert all(math.isclose(found[k], truth[k], rel_tol=1e-9) for k in truth)


def test_a_leaky_pixels_drift_over_an_hour_is_not_stuck():
    """0.1 Hz ON events for an hour take a pixel's level 72 in log (beyond the range, but over minutes): kept."""
    t = np.arange(360) * 10_000_000
    ev = ef.EventStream(np.zeros(360, int), np.zeros(360, int), t, np.ones(360), 4, 4)
    assert stuck_pixels(ev, 0.2, 0.2) == {}
    fast = ef.EventStream(np.zeros(360, int), np.zeros(360, int), np.arange(360) * 100, np.ones(360), 4, 4)
    assert list(stuck_pixels(fast, 0.2, 0.2)) == [(0, 0)]          # the same events at 10 kHz: stuck


@pytest.fixture(scope="module")
def stuck_recording(tmp_path_factory):
    """One scan period of the static galvo scene at 64x48 with three pixels stuck ON at 40 kHz, as a camera
    recording (RAW, no optics), and the same period clean."""
    d = tmp_path_factory.mktemp("recordings")
    ev = ef.render_events(ef.load_scene(GALVO, width=64, height=48), 0.004, steps=32)
    optics = d / "optics.json"
    import json
    optics.write_text(json.dumps(ev.meta["optics"]))
    hot_t = np.arange(0, 4000, 25)
    hot = [(5, 7), (30, 20), (50, 40)]
    x = np.r_[ev.x, np.repeat([h[0] for h in hot], len(hot_t))]
    y = np.r_[ev.y, np.repeat([h[1] for h in hot], len(hot_t))]
    t = np.r_[ev.t, np.tile(hot_t, len(hot))]
    p = np.r_[ev.p, np.ones(len(hot) * len(hot_t), np.int8)]
    order = np.argsort(t, kind="stable")
    ef.write_events(str(d / "stuck.raw"), ef.EventStream(x[order], y[order], t[order], p[order], 64, 48))
    ef.write_events(str(d / "clean.raw"), ef.EventStream(ev.x, ev.y, ev.t, ev.p, 64, 48))
    return d, hot


def test_a_refocus_of_a_recording_leaves_its_stuck_pixels_out(stuck_recording, capsys, monkeypatch):
    """Refocused, the recording with three stuck pixels is the clean recording's image to 2 % (median; p99 8 %,
    measured: their own scene events go with them, and the galvo solve is global), where keeping them put its
    99th percentile 55 times off; the warning names the three pixels."""
    from mitsuba_eventfield.cli import inputs
    from mitsuba_eventfield.images import read_exr
    d, hot = stuck_recording

    def refocused(name, out):
        assert cli.main(["refocus", str(d / f"{name}.raw"), "--optics", str(d / "optics.json"), "--contrast", "0.2",
                         "--depth", "1", "-o", str(d / f"{out}.png")]) == 0
        return read_exr(str(d / f"{out}.exr"))[0]["Y"], capsys.readouterr().err
    clean, said = refocused("clean", "clean")
    assert "stuck or hot" not in said
    left_out, said = refocused("stuck", "left_out")
    assert "3 stuck or hot pixels left out" in said and all(f"({x}, {y})" in said for x, y in hot), said
    monkeypatch.setattr(inputs, "without_stuck_pixels", lambda ev, where: ev)
    kept, _ = refocused("stuck", "kept")
    off = {name: np.abs(img / clean - 1) for name, img in (("left out", left_out), ("kept", kept))}
    assert np.median(off["left out"]) < 0.04 and np.percentile(off["left out"], 99) < 0.15
    assert np.percentile(off["kept"], 99) > 10


def test_a_reconstruction_beyond_float32_is_clipped_and_said(tmp_path, capsys):
    """A pixel that gains 100 in log over 10 s (not stuck: 10 a second) reconstructs to e^100, +inf in float32:
    clipped at e^80 and said, not written as inf with NumPy's overflow warning."""
    from mitsuba_eventfield.images import read_exr
    t = np.arange(1000) * 10_000
    ev = ef.EventStream(np.zeros(1000, int), np.zeros(1000, int), t, np.ones(1000), 4, 4,
                        {"pixel_model": {"threshold_on": 0.1, "threshold_off": 0.1}})
    ef.write_events(str(tmp_path / "drift.h5"), ev)
    assert cli.main(["reconstruct", str(tmp_path / "drift.h5"), "--times", "9990", "-o", str(tmp_path / "r")]) == 0
    err = capsys.readouterr().err
    assert "1 pixel-frames reconstructed beyond a log level of +-80" in err and "overflow" not in err
    y = read_exr(str(tmp_path / "r" / "frame_0000.exr"))[0]["Y"]
    assert np.isfinite(y).all() and y[0, 0] == pytest.approx(math.exp(80), rel=1e-6)
