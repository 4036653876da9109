"""Threshold jitter is the reset's noise (``pixel_step``): drawn when a pixel fires, held until it fires again.
So the event count of a brightness ramp is the ramp's height over the mean threshold whatever the step size
(renewal: a rise of 4 log units at C = 0.2 gives 20 events a pixel), and a pixel that stops changing stops
firing. Drawn afresh every step, a slow rise met the lowest of many draws (21, 25, 32 events a pixel at 20,
200, 2000 steps) and a still pixel kept firing on its leftover rise."""
import numpy as np
import pytest

import mitsuba_eventfield as ef

SIDE, C, JITTER = 16, 0.2, 0.04


def _events(log_levels, times):
    frames = np.exp(np.asarray(log_levels, np.float64))[:, None, None] * np.ones((1, SIDE, SIDE))
    return ef.events_from_frames(frames.astype(np.float32), times,
                                 pixel={"threshold_on": C, "threshold_off": C, "threshold_jitter": JITTER, "seed": 4})


@pytest.mark.parametrize("steps", [20, 200, 2000])
def test_a_ramp_fires_its_height_over_the_mean_threshold_at_any_step_size(steps):
    times = np.linspace(0.0, 1.0, steps + 1)
    ev = _events(np.log(0.5) + 4.0 * times, times)
    per_pixel = np.bincount(ev.y.astype(np.int64) * SIDE + ev.x, minlength=SIDE * SIDE)
    assert np.all(ev.p > 0)
    # renewal: 4.0 / E[c] = 20, less the part-threshold left at the end (half a threshold on average), with a
    # per-pixel spread of about sqrt(20) x 0.2 = 0.9 events: the mean of 256 pixels is good to about 0.06
    assert 19.0 < per_pixel.mean() < 20.3, per_pixel.mean()


def test_a_still_pixel_stops_firing():
    """A rise of 1.75 thresholds, then a second of still frames: the pixel fires once for the threshold crossed,
    at most once more at the next reset (when the new draw is below the 0.75 C left), then never."""
    times = np.linspace(0.0, 1.0, 1001)
    levels = np.full(len(times), np.log(0.5))
    levels[1:] += 1.75 * C
    ev = _events(levels, times)
    assert np.all(ev.p > 0) and len(ev) >= SIDE * SIDE
    assert ev.t.max() <= 3000                      # within the first steps after the rise (1 ms each)


def test_each_event_draws_new_thresholds():
    """On a linear ramp every crossing of a pixel is its threshold after the one before, so the log rise between
    consecutive events of a pixel is the threshold it held: spread by the jitter within each pixel (a pixel that
    kept one draw forever, or no jitter, would show none), about C on average."""
    rate = 4.0                                               # log units a second
    times = np.linspace(0.0, 1.0, 2001)
    ev = _events(np.log(0.5) + rate * times, times)
    pixel = ev.y.astype(np.int64) * SIDE + ev.x
    spreads, means = [], []
    for k in range(SIDE * SIDE):
        held = np.diff(np.sort(ev.t[pixel == k])) * 1e-6 * rate
        spreads.append(held.std())
        means.append(held.mean())
    assert 0.8 * JITTER < np.mean(spreads) < 1.2 * JITTER, np.mean(spreads)     # ~0.04 within each pixel
    assert abs(np.mean(means) - C) < 0.01


def test_the_on_and_off_thresholds_are_drawn_independently():
    """A reset draws the ON and the OFF threshold from a normal pair: each with the jitter as its spread around
    its own base, uncorrelated with the other (one draw for both made a pixel's ON and OFF thresholds move
    together: correlation 1), and new for the next reset."""
    import drjit as dr
    import mitsuba as mi
    from conftest import TEST_VARIANT

    from mitsuba_eventfield.plugins import counter_rng
    from mitsuba_eventfield.plugins.pixel_step import _jittered
    ef.set_variant(TEST_VARIANT)
    n = 65536
    pixel, word = dr.arange(mi.UInt32, n), mi.UInt32(counter_rng.seed_word(4))
    on, off = (np.array(a) for a in _jittered(mi.Float(0.2), mi.Float(0.3), JITTER, pixel, mi.UInt32(0), word))
    on2, _ = (np.array(a) for a in _jittered(mi.Float(0.2), mi.Float(0.3), JITTER, pixel, mi.UInt32(1), word))
    # sampling error of a correlation over 65536 pairs: 1 / sqrt(n) = 0.004; of a mean: 0.04 / 256 = 0.00016
    assert abs(np.corrcoef(on, off)[0, 1]) < 0.02 and abs(np.corrcoef(on, on2)[0, 1]) < 0.02
    assert on.mean() == pytest.approx(0.2, abs=0.001) and off.mean() == pytest.approx(0.3, abs=0.001)
    assert on.std() == pytest.approx(JITTER, rel=0.02) and off.std() == pytest.approx(JITTER, rel=0.02)
