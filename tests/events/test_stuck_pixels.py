"""Stuck and hot pixels of a recording (``events.stuck_pixels``): a pixel whose events drive its level one way
by more than any sensor's range (140 dB) every second, with its thresholds as favourable as a real sensor's
mismatch allows, is left out and named in a warning; pixels that see light (with mismatched thresholds too),
noisy ones that fire both ways and a leaky pixel's slow drift are kept (a real camera's helper run,
2026-11-27: five pixels stuck ON at 20 kHz took a galvo refocus's 99th percentile from 1.9 to 12, at 50 kHz to
3.7e6, and wrote +inf into a reconstruction's EXR; a review then found a first criterion, the running level's
span at the nominal thresholds, leaving out half the pixels of a realistic-pixel galvo render)."""
import math
import os

import numpy as np
import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield import cli
from mitsuba_eventfield.events.stuck_pixels import MAX_LEVEL_SPAN, stuck_pixels

GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")


def test_the_net_drift_against_a_search_over_threshold_ratios():
    """Pixels with every ON share over 2 s: the flagged ones and their net change equal a brute-force search
    for the ON / OFF ratio (1/3..3 times the nominal one) that keeps each pixel's net change smallest; stuck ON
    and stuck OFF pixels are both found, and a pixel whose ON share a mismatch explains is not."""
    rng = np.random.default_rng(5)
    n = 400_000
    x, y, t = rng.integers(0, 12, n), rng.integers(0, 8, n), np.sort(rng.integers(0, 2_000_000, n))
    share = np.linspace(0.0, 1.0, 96)[y * 12 + x]                  # each pixel's chance of ON
    ev = ef.EventStream(x, y, t, np.where(rng.random(n) < share, 1, -1), 12, 8)
    found = stuck_pixels(ev, 0.2, 0.3)
    ratios = np.geomspace(1 / math.sqrt(3), math.sqrt(3), 20001)
    truth = {}
    for px, py in {(int(a), int(b)) for a, b in zip(x, y)}:
        sel = (x == px) & (y == py)
        n_on, n_off = np.count_nonzero(ev.p[sel] > 0), np.count_nonzero(ev.p[sel] < 0)
        nets = 0.2 * n_on * ratios - 0.3 * n_off / ratios
        best = nets[np.argmin(np.abs(nets))] if (nets.min() > 0 or nets.max() < 0) else 0.0
        if abs(best) > MAX_LEVEL_SPAN * 2.0:
            truth[(px, py)] = best
    assert found.keys() == truth.keys() and 10 < len(truth) < 80
    assert any(v > 0 for v in truth.values()) and any(v < 0 for v in truth.values())
    assert all(math.isclose(found[k], truth[k], rel_tol=1e-3) for k in truth)


def test_a_leaky_pixels_drift_over_an_hour_is_not_stuck():
    """0.1 Hz ON events for an hour take a pixel's level 72 in log (beyond the range, but over an hour): kept;
    the same events at 10 kHz are stuck."""
    t = np.arange(360) * 10_000_000
    ev = ef.EventStream(np.zeros(360, int), np.zeros(360, int), t, np.ones(360), 4, 4)
    assert stuck_pixels(ev, 0.2, 0.2) == {}
    fast = ef.EventStream(np.zeros(360, int), np.zeros(360, int), np.arange(360) * 100, np.ones(360), 4, 4)
    assert list(stuck_pixels(fast, 0.2, 0.2)) == [(0, 0)]


@pytest.mark.parametrize("pixel", [{"preset": "prophesee_gen4"}, {"pixel": {"threshold_sigma": 0.03}},
                                   {"threshold_on": 0.2, "threshold_off": 0.24}])
def test_a_realistic_pixel_under_the_scan_is_not_stuck(pixel):
    """A scanned edge fires hundreds of events a second both ways: with mismatched thresholds (sigma 0.03, or
    ON and OFF 0.2 / 0.24 read as 0.2) its level at the nominal thresholds drifts past the range in a second,
    which left out half the pixels of a prophesee_gen4 galvo render. None is left out now."""
    ev = ef.render_events(ef.load_scene(GALVO, width=48, height=36), 0.5, steps=1000, **pixel)
    assert len(ev) > 100_000 and stuck_pixels(ev, 0.2, 0.2) == {}


@pytest.fixture(scope="module")
def stuck_recording(tmp_path_factory):
    """One scan period of the static galvo scene at 64x48 with three pixels stuck ON at 100 kHz, as a camera
    recording (RAW, no optics), and the same period clean."""
    pytest.importorskip("faery")                    # (the RAW writer; the GPU image lacks it)
    d = tmp_path_factory.mktemp("recordings")
    ev = ef.render_events(ef.load_scene(GALVO, width=64, height=48), 0.004, steps=32)
    optics = d / "optics.json"
    import json
    optics.write_text(json.dumps(ev.meta["optics"]))
    hot_t = np.arange(0, 4000, 10)
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
    99th percentile 3e8 times off; the warning names the three pixels."""
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
    from mitsuba_eventfield.lightfield import streams       # (the light field leaves them out too: Python's path)
    monkeypatch.setattr(inputs, "without_stuck_pixels", lambda ev, where: ev)
    monkeypatch.setattr(streams, "_without_stuck_pixels", lambda ev, where, kw: ev)
    kept, _ = refocused("stuck", "kept")
    off = {name: np.abs(img / clean - 1) for name, img in (("left out", left_out), ("kept", kept))}
    assert np.median(off["left out"]) < 0.04 and np.percentile(off["left out"], 99) < 0.15
    assert np.percentile(off["kept"], 99) > 10


def test_a_reconstruction_beyond_float32_is_clipped_and_said(tmp_path, capsys):
    """A pixel that gains 100 in log over 10 s (not stuck: 10 a second) reconstructs to e^100, +inf in float32:
    clipped at e^40 (lightfield.model.MAX_LOG_LEVEL) and said, not written as inf with NumPy's overflow warning."""
    from mitsuba_eventfield.images import read_exr
    t = np.arange(1000) * 10_000
    ev = ef.EventStream(np.zeros(1000, int), np.zeros(1000, int), t, np.ones(1000), 4, 4,
                        {"pixel_model": {"threshold_on": 0.1, "threshold_off": 0.1}})
    ef.write_events(str(tmp_path / "drift.h5"), ev)
    assert cli.main(["reconstruct", str(tmp_path / "drift.h5"), "--times", "9990", "-o", str(tmp_path / "r")]) == 0
    err = capsys.readouterr().err
    assert "1 of 16 levels beyond a log level of +-40" in err and "overflow" not in err
    y = read_exr(str(tmp_path / "r" / "frame_0000.exr"))[0]["Y"]
    assert np.isfinite(y).all() and y[0, 0] == pytest.approx(math.exp(40), rel=1e-6)


def test_a_recording_of_stuck_pixels_alone_is_refused_not_written_flat(tmp_path, capsys):
    """One pixel stuck ON for 200 ms and nothing else: reconstruct wrote a flat frame as done. Now one line."""
    pytest.importorskip("faery")                    # (the RAW writer; the GPU image lacks it)
    ev = ef.EventStream(np.zeros(2000, int), np.zeros(2000, int), np.arange(2000) * 100, np.ones(2000), 8, 6)
    ef.write_events(str(tmp_path / "stuck.raw"), ev)
    assert cli.main(["reconstruct", str(tmp_path / "stuck.raw"), "--contrast", "0.2", "-o", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].endswith("stuck.raw: no events once its stuck pixels are left out: nothing to reconstruct")
    assert not (tmp_path / "r").exists()


def test_log_levels_are_clipped_with_a_count_of_those_beyond():
    """``lightfield.model.clip_log_levels``: finite levels beyond +-40 and infinitely bright ones are clipped and
    counted; -inf (no light in plain log) is clipped silently (its radiance is 0 either way); NaN stays NaN."""
    from mitsuba_eventfield.lightfield.model import clip_log_levels
    with pytest.warns(UserWarning, match=r"^x: 2 of 6 levels beyond a log level of \+-40"):
        out = clip_log_levels(np.array([0.0, np.inf, 50.0, -np.inf, np.nan, -39.0]), "x")
    assert out[[0, 1, 2, 3, 5]].tolist() == [0.0, 40.0, 40.0, -40.0, -39.0] and np.isnan(out[4])
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert clip_log_levels(np.array([-np.inf, 1.0]), "x").tolist() == [-40.0, 1.0]
