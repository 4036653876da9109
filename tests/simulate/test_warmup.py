"""A render with a warm-up (``render_events(warmup=)``, ``render --warmup``): the pixel runs before the start and
the warm-up's events are dropped. Oracles: the same render started earlier, cut at the start (identical events,
in memory and streamed to a file); a running photoreceptor low-pass fires as many ON as OFF events under a
periodic scan (a settled start fired 3.4 times as many ON in its first 4 ms)."""
import os

import numpy as np
import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield.cli.main import main as cli

GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")
FAN = os.path.join(ROOT, "scenes", "fan", "fan.xml")


def test_a_warm_up_is_the_earlier_start_cut_at_the_start(tmp_path):
    """The fan (moving, scanned) with 20 uniform steps over 4 ms after a 2 ms warm-up equals 30 steps from -2 ms
    cut at 0, event for event, in memory and in an HDF5 file; the recorded start, duration and counts are the
    kept window's."""
    timed = ef.load_scene(FAN, width=48, height=36)
    warm = ef.render_events(timed, 0.004, steps=20, warmup=0.002)
    early = ef.render_events(timed, 0.006, steps=30, t_start=-0.002)
    cut = early.time_window(0, None)
    assert len(cut) > 1000 and len(cut) < len(early)              # the warm-up fired events, and they went
    assert np.array_equal(warm.t, cut.t) and np.array_equal(warm.x, cut.x) and np.array_equal(warm.p, cut.p)
    assert warm.t.min() >= 0 and warm.meta["t_start_us"] == 0 and warm.meta["duration_us"] == 4000
    assert warm.meta["warmup_s"] == 0.002
    render = warm.meta["render"]
    assert render["events"] == len(cut) and render["on"] == int((cut.p > 0).sum())
    # the metadata describe the kept span: its 20 steps (the warm-up's 10 beside them), its duration and rate
    assert warm.meta["stepping"]["steps"] == 20 and warm.meta["stepping"]["warmup_steps"] == 10
    assert render["duration_s"] == 0.004 and render["rate_ev_per_s"] == pytest.approx(len(cut) / 0.004)
    summary = ef.render_events(timed, 0.004, steps=20, warmup=0.002, output=str(tmp_path / "w.h5"))
    assert summary.events == len(cut) and ef.read_events(str(tmp_path / "w.h5")).equals(warm)


def test_the_pixel_counters_are_the_kept_spans():
    """Shot noise at a steady rate: the summary's noise events of 4 ms kept after a 2 ms warm-up are 4/6 of those
    of the 6 ms rendered (measured 0.67), not all of them: the counters are read again where the warm-up ends."""
    timed = ef.load_scene(FAN, width=48, height=36)
    pixel = {"shot_noise_hz": 500.0, "seed": 1}
    warm = ef.render_events(timed, 0.004, steps=20, warmup=0.002, pixel=pixel).meta["render"]["noise_events"]
    early = ef.render_events(timed, 0.006, steps=30, t_start=-0.002, pixel=pixel).meta["render"]["noise_events"]
    assert early > 2000 and warm / early == pytest.approx(4 / 6, abs=0.04), (warm, early)
    # exactly: the 6 ms render's, less those of its first 2 ms (the same 10 steps, the same draws)
    first = ef.render_events(timed, 0.002, steps=10, t_start=-0.002, pixel=pixel).meta["render"]["noise_events"]
    assert warm == early - first, (warm, early, first)


def test_a_warm_up_under_a_scan_is_whole_periods_and_said_in_the_stepping():
    """Without given steps a scanned scene's warm-up is rounded up to whole scan periods (the default and adaptive
    steps keep the scan's phase grid): 2 ms on the 250 Hz fan is 4 ms; adaptive stepping's metadata say their
    step count includes it."""
    timed = ef.load_scene(FAN, width=48, height=36)
    ev = ef.render_events(timed, 0.004, adaptive=True, warmup=0.002)
    assert ev.meta["warmup_s"] == pytest.approx(0.004) and ev.t.min() >= 0
    assert ev.meta["stepping"]["includes_warmup_s"] == pytest.approx(0.004)


def test_a_running_lowpass_fires_as_many_on_as_off_events():
    """davis346's low-pass (cutoff proportional to brightness: slow on the dark side of each edge) started
    settled on the first frame drifts for a few hundred ms under the scan, firing ON events: the render says
    so and how long (265 ms: five time constants at the darkest tenth's 3 Hz). After a warm-up that long the
    4 ms windows hold as many ON as OFF events (measured 54 / 53 ... 59 / 57, against 2470 / 735 ... 444 / 341
    from the settled start) and the note is gone."""
    timed = ef.load_scene(GALVO, width=64, height=48)
    pixel = {"readout_cap": 0, "shot_noise_hz": 0, "leak_rate_hz": 0}       # the low-pass alone drifts

    def windows(ev):
        bins = np.minimum(ev.t // 4000, 4)
        return np.bincount(bins[ev.p > 0], minlength=5), np.bincount(bins[ev.p < 0], minlength=5)
    settled = ef.render_events(timed, 0.02, preset="davis346", pixel=pixel)
    on, off = windows(settled)
    assert on[0] > 2.5 * off[0]                              # measured 2470 / 735
    notes = [n for n in settled.meta["render"]["notes"] if "photoreceptor low-pass" in n]
    assert len(notes) == 1 and "about 265 ms" in notes[0], notes
    running = ef.render_events(timed, 0.02, preset="davis346", pixel=pixel, warmup=0.3)
    on, off = windows(running)
    assert off.min() > 20 and np.all(np.abs(on / off - 1) < 0.3), (on, off)
    assert not [n for n in running.meta["render"]["notes"] if "photoreceptor low-pass" in n]
    ideal = ef.render_events(timed, 0.02)                      # no low-pass: nothing to settle, nothing said
    assert not [n for n in ideal.meta["render"]["notes"] if "photoreceptor low-pass" in n]


def test_render_takes_a_warm_up_with_a_unit(tmp_path):
    """``render --warmup 4ms`` reaches the render (recorded as ``warmup_s``); up to 10 s, where other times with a
    unit stop at 1 s."""
    from mitsuba_eventfield.simulate.auto import parse_time
    out = tmp_path / "w.h5"
    assert cli(["render", GALVO, "-D", "width=16", "-D", "height=12", "--duration", "0.004", "--warmup", "4ms",
                "--quiet", "-o", str(out)]) == 0
    assert ef.read_events(str(out)).meta["warmup_s"] == pytest.approx(0.004)
    assert parse_time("2s", "--warmup", 10.0) == 2.0
    with pytest.raises(ef.EventFieldError, match="from 1us to 1s"):
        parse_time("2s")


def test_a_bad_warm_up_is_one_named_error(tmp_path, capfd):
    timed = ef.load_scene(GALVO, width=16, height=12)
    with pytest.raises(ef.EventFieldError, match=r"^warmup \(s\) = -1"):
        ef.render_events(timed, 0.004, warmup=-1)
    with pytest.raises(ef.EventFieldError, match=r"^warmup: not with on_device"):
        ef.render_events(timed, 0.004, warmup=0.001, on_device=True)
    with pytest.raises(SystemExit):
        cli(["render", GALVO, "-D", "width=16", "-D", "height=12", "--duration", "0.004", "--warmup", "5",
             "-o", str(tmp_path / "x.h5")])
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--warmup: '5': expected a time from 1us to 10s with a unit" in err[0], err
    assert not (tmp_path / "x.h5").exists()
