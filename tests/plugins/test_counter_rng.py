"""Counter-based draws (``plugins/counter_rng.py``): the pixel model's random numbers are a hash of (seed, pixel,
the pixel's own event counter, stream), so host and device draw the same bits, and a realisation of the
threshold jitter or the shot noise is the same whatever the step size (the draws follow the events, not the
steps)."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.errors import ConfigError
from mitsuba_eventfield.plugins import counter_rng, pixel_state

SIDE = 32


def _grid(n_pix=256, n_counter=256):
    pixel, counter = np.meshgrid(np.arange(n_pix, dtype=np.uint32), np.arange(n_counter, dtype=np.uint32))
    return pixel.ravel(), counter.ravel()


def _bits_np(pixel, counter, seed, stream):
    with np.errstate(over="ignore"):
        word = np.uint32(counter_rng.stream_word(counter_rng.seed_word(seed), stream) & counter_rng.MASK)
        return counter_rng.bits(pixel, counter, word)


def test_host_and_device_draw_the_same_bits():
    ef.set_variant()
    pixel, counter = _grid()
    word = counter_rng.stream_word(counter_rng.seed_array(mi, 9), counter_rng.NOISE_WAIT)
    device = counter_rng.bits(mi.UInt32(pixel), mi.UInt32(counter), word).numpy()
    assert np.array_equal(device, _bits_np(pixel, counter, 9, counter_rng.NOISE_WAIT))


def test_draws_are_uniform_and_unrelated_across_pixels_counters_streams_and_seeds():
    """65,536 draws: 64-bin chi-square within its 0.1 % bound (df 63: 103), and no correlation above 0.02 (sd of
    a correlation of 65,536 independent pairs: 0.004) between neighbouring pixels, consecutive counters, two
    streams or two seeds."""
    pixel, counter = _grid()
    u = _bits_np(pixel, counter, 0, counter_rng.JITTER_ON) / 2.0**32
    hist = np.bincount((u * 64).astype(np.int64), minlength=64)
    expected = len(u) / 64
    assert np.sum((hist - expected) ** 2 / expected) < 103
    grid = u.reshape(256, 256)                          # [counter, pixel]
    others = {"next pixel": (grid[:, :-1], grid[:, 1:]), "next counter": (grid[:-1], grid[1:]),
              "other stream": (u, _bits_np(pixel, counter, 0, counter_rng.JITTER_OFF) / 2.0**32),
              "other seed": (u, _bits_np(pixel, counter, 1, counter_rng.JITTER_ON) / 2.0**32)}
    for name, (a, b) in others.items():
        assert abs(np.corrcoef(a.ravel(), b.ravel())[0, 1]) < 0.02, name


def _ramp(steps, pixel):
    times = np.linspace(0.0, 1.0, steps + 1)
    frames = np.exp(np.log(0.5) + 4.0 * times)[:, None, None] * np.ones((1, SIDE, SIDE))
    return ef.events_from_frames(frames.astype(np.float32), times, pixel=pixel)


def _sorted(ev):
    key = ev.y.astype(np.int64) * SIDE + ev.x
    order = np.lexsort((ev.t, key))
    return key[order], ev.t[order].astype(np.int64), ev.p[order]


def test_the_jitter_realisation_does_not_depend_on_the_step_size():
    """A ramp of 20 thresholds with jitter 0.04 at 200 and at 2000 steps: every pixel fires the same events
    (the thresholds after its m-th event are draw m), each within 1 us (its crossing's interpolation)."""
    pixel = {"threshold_on": 0.2, "threshold_off": 0.2, "threshold_jitter": 0.04, "seed": 4}
    (ka, ta, pa), (kb, tb, pb) = _sorted(_ramp(200, pixel)), _sorted(_ramp(2000, pixel))
    assert len(ka) > 19 * SIDE * SIDE and np.array_equal(ka, kb) and np.array_equal(pa, pb)
    assert np.abs(ta - tb).max() <= 1
    counts = np.bincount(ka, minlength=SIDE * SIDE)
    assert counts.std() > 0.3                          # the jitter is there: pixels differ


def _dark(steps, rate_hz, seed=3):
    times = np.linspace(0.0, 1.0, steps + 1)
    frames = np.zeros((steps + 1, SIDE, SIDE), np.float32)
    return ef.events_from_frames(frames, times, pixel={"shot_noise_hz": rate_hz, "seed": seed})


def test_the_shot_noise_realisation_does_not_depend_on_the_step_size():
    """Shot noise at 3 Hz for a second, in 100 and in 1000 steps: the same events (pixel, polarity) within 1 us,
    but for the few that the coarse steps delay (a second event of a pixel within one 10 ms step fires at the
    next step's start: P = 1 - e^-0.03 (1 + 0.03), 4.4e-4 a pixel-step, about 45 of ~3,100), and another seed
    gives other events."""
    fine, coarse = _sorted(_dark(1000, 3.0)), _sorted(_dark(100, 3.0))
    n = len(fine[0])
    assert 2800 < n < 3400
    keys = {(k, t, p) for k, t, p in zip(*coarse)}
    near = {(k, t + d, p) for k, t, p in zip(*coarse) for d in (-1, 1)}
    matched = sum((k, t, p) in keys or (k, t, p) in near for k, t, p in zip(*fine))
    assert matched > 0.97 * n and abs(len(coarse[0]) - n) < 0.01 * n, (matched, n, len(coarse[0]))
    other = _sorted(_dark(1000, 3.0, seed=4))
    assert sum((k, t, p) in keys for k, t, p in zip(*other)) < 0.01 * n


def test_a_checkpoint_of_generator_drawn_noise_is_refused():
    integ = mi.load_dict({"type": "eventfield", "shot_noise_hz": 5.0})
    integ.stage_log(mi.Float(np.zeros(16, np.float32)), (4, 4))
    integ.commit(0.0, 1e-3)
    integ.stage_log(mi.Float(np.zeros(16, np.float32)), (4, 4))
    integ.commit(1e-3, 2e-3)
    state = integ.get_state()
    assert {"noise_left", "noise_k"} <= set(state) and "rng_state" not in state
    other = mi.load_dict({"type": "eventfield", "shot_noise_hz": 5.0})
    other.set_state(state)
    assert np.array_equal(other.noise_left.numpy(), integ.noise_left.numpy())
    old = dict(state, rng_state=np.zeros(16, np.uint64), rng_inc=np.ones(16, np.uint64))
    with pytest.raises(ConfigError, match="PCG32"):
        pixel_state.set_state(other, old)
    assert dr.width(integ.noise_k) == 16


def test_a_noise_backlog_is_bounded_when_the_rate_falls():
    """At rate x dt far above 1 a step holds more events than the one it may fire; they are lost, not owed: a
    500 Hz dark pixel (10 events a 20 ms step) that turns bright (5 Hz) fires about 5 Hz after the switch
    (owed without limit, it kept firing one event a step: 23 a pixel in 0.48 s, against 2.4)."""
    steps, side = 50, 16
    times = np.linspace(0.0, 1.0, steps + 1)
    frames = np.where(times[:, None, None] > 0.5, 1.0, 0.0) * np.ones((1, side, side))
    ev = ef.events_from_frames(frames.astype(np.float32), times,
                               pixel={"shot_noise_hz": 500.0, "shot_noise_bright_factor": 0.01, "seed": 2})
    before = np.count_nonzero(ev.t < 500_000) / side ** 2
    after = np.count_nonzero(ev.t > 520_000) / side ** 2
    assert 24 <= before <= 25                      # one a step, the most a step fires (25 steps)
    assert 1.5 < after < 4.0, after                # 5 Hz x 0.48 s = 2.4, plus at most about one owed


def test_no_two_counters_draw_one_row_of_pixels_shifted():
    """The rows of draws (every pixel) of two counters are unrelated. Hashing the counter and then adding the
    pixel's Weyl step made two counters' rows one row shifted wherever their counter hashes differed by a
    multiple of the step smaller than the film (about one pair in 500,000 at 4096 pixels): such a pair is found
    here among the first 4 M counters, and its rows share no more than chance under that shift."""
    n_pix = 4096
    with np.errstate(over="ignore"):
        word = np.uint32(counter_rng.stream_word(counter_rng.seed_word(5), counter_rng.NOISE_WAIT) & counter_rng.MASK)
        inner = counter_rng.finalise(np.arange(1 << 22, dtype=np.uint32) * np.uint32(0x61C88647) + word)
        g_inverse = np.uint32(pow(counter_rng.GOLDEN, -1, 1 << 32))
        d = ((inner - inner[0]) * g_inverse).astype(np.int64)
    d = np.where(d >= 1 << 31, d - (1 << 32), d)
    c2 = int(np.nonzero((np.abs(d) < n_pix // 2) & (np.arange(len(d)) > 0))[0][0])
    shift = int(d[c2])
    pixel = np.arange(n_pix // 2, dtype=np.uint32) + np.uint32(n_pix // 4)
    with np.errstate(over="ignore"):      # the old design: the same row, shifted
        old1 = counter_rng.finalise(pixel * np.uint32(counter_rng.GOLDEN) + inner[0])
        old2 = counter_rng.finalise((pixel - np.uint32(shift & counter_rng.MASK)) * np.uint32(counter_rng.GOLDEN)
                                    + inner[c2])
    assert np.array_equal(old1, old2)
    new1 = _bits_np(pixel, np.zeros_like(pixel), 5, counter_rng.NOISE_WAIT)
    new2 = _bits_np(pixel - np.uint32(shift & counter_rng.MASK), np.full_like(pixel, c2), 5, counter_rng.NOISE_WAIT)
    assert np.count_nonzero(new1 == new2) <= 2


def test_no_two_seeds_draw_one_sensor_of_noise_shifted():
    """Seeds 0 and 902 drew, for a 1280x720 sensor, the same noise shifted by 806,330 pixels (their words were
    902 Weyl steps apart and the pixel was added to the word): 115,270 pixels' draws equal, an eighth of the
    sensor. Now the draws of the two seeds, pixel by pixel at any shift, coincide no more than chance: two sets
    of 921,600 random 32-bit words share about 200."""
    pixel = np.arange(1280 * 720, dtype=np.uint32)
    a, b = (_bits_np(pixel, np.zeros_like(pixel), s, counter_rng.NOISE_WAIT) for s in (0, 902))
    assert len(np.intersect1d(a, b)) < 400


def test_every_bit_of_a_seed_counts_and_seed_and_step_do_not_add():
    """A pixel seed of 2^32 drew seed 0's noise (the words were cut to 32 bits), and the independent-seed
    sampler seed was seed + step (seed 1 at step k was seed 0 at step k + 1)."""
    from mitsuba_eventfield.simulate.stepping import step_seed
    words = {counter_rng.seed_word(s) for s in (0, 1, 1 << 32, (1 << 32) + 1, 1 << 64)}
    assert len(words) == 5
    seeds = {step_seed(s, k) for s in range(40) for k in range(40)}
    assert len(seeds) == 1600 and all(0 <= v < 1 << 32 for v in seeds)
    with pytest.raises(ValueError, match="negative"):
        counter_rng.seed_word(-1)


def test_renders_of_neighbouring_seeds_with_independent_steps_share_no_noise():
    """The helper's measurement, on the demo at 64x48 with 20 independent-seed steps: the events (x, y, p, step)
    of seed 1 at step k and seed 0 at step k + 1 overlapped by 0.63 (the same sampler seed), against 0.08
    for unrelated seeds at one step. Now both pairings are chance alike."""
    from conftest import DEMO

    def keyed(seed, shift=0):
        ev = ef.render_events(ef.load_scene(DEMO, motion=None, width=64, height=48), 0.02, steps=20, seed=seed,
                              seed_mode="independent")
        step = np.ceil(ev.t / 1000.0).astype(np.int64) - shift     # step k ends at (k + 1) ms
        return set(zip(ev.x.tolist(), ev.y.tolist(), ev.p.tolist(), step.tolist()))

    s0, s1, s1_shifted = keyed(0), keyed(1), keyed(1, shift=-1)
    overlap = lambda a, b: len(a & b) / len(a | b)  # noqa: E731
    assert overlap(s0, s1_shifted) < 0.2 and overlap(s0, s1) < 0.2, (overlap(s0, s1_shifted), overlap(s0, s1))


def test_an_independent_seed_render_at_its_default_steps_equals_the_same_steps_asked_for():
    """The default steps' noise probe renders the first frame, which the loop then takes as step 0's: at the
    render's seed, where an independent-seed render samples step 0 at hash_words(seed, 0) (the fan at 64x48:
    185,890 events against another count with the steps given). Now at step 0's own seed."""
    from conftest import ROOT
    fan = f"{ROOT}/scenes/fan/fan.xml"
    chosen = ef.render_events(ef.load_scene(fan, width=64, height=48), 0.008, seed=3, seed_mode="independent")
    steps = chosen.meta["stepping"]["steps"]
    asked = ef.render_events(ef.load_scene(fan, width=64, height=48), 0.008, steps=steps, seed=3,
                             seed_mode="independent")
    assert chosen.meta["stepping"]["mode"] == "uniform" and len(chosen) > 10_000 and chosen.equals(asked)


def test_words_a_weyl_step_apart_draw_unrelated_sequences():
    """With ``finalise(index * GOLDEN + word)`` two words k Weyl steps apart drew one sequence shifted by k
    indices (all but k of 100,000 draws shared); now about as many as chance gives two random sets (2)."""
    index = np.arange(100_000, dtype=np.uint32)
    with np.errstate(over="ignore"):
        for k in (1, 902, 806_330):
            a = counter_rng.mixed_np(index, 12345)
            b = counter_rng.mixed_np(index, np.uint32((12345 + k * counter_rng.GOLDEN) & counter_rng.MASK))
            assert len(np.intersect1d(a, b)) < 20


def test_stream_words_are_no_arithmetic_progression():
    """With ``word + stream * _STREAM_MUL`` seed word w's stream 1 was seed word w + _STREAM_MUL's stream 0."""
    w = counter_rng.seed_word(7)
    for s in range(1, 6):
        shifted = (w + s * counter_rng._STREAM_MUL) & counter_rng.MASK
        assert counter_rng.stream_word(w, s) != counter_rng.stream_word(shifted, 0)
    assert len({counter_rng.stream_word(w, s) for s in range(1000)}) == 1000


def test_the_readout_caps_keys_are_not_the_pixel_models_draws():
    """The readout cap keyed step k by stream number k: its steps 1-4 drew the pixel model's streams (event i's
    key was pixel i's first draw, one hash short). Its words and keys now share nothing with them."""
    from mitsuba_eventfield.plugins import readout
    pixel = np.arange(50_000, dtype=np.uint32)
    for seed in (0, 3):
        w = counter_rng.seed_word(seed)
        pixel_words = {counter_rng.stream_word(w, s) & counter_rng.MASK for s in range(1, 5)}
        steps = {readout.step_word(seed, k) for k in range(1, 200)}
        assert not steps & pixel_words and len(steps) == 199
        for k in range(1, 5):
            keys = counter_rng.finalise(readout.keys_np(len(pixel), readout.step_word(seed, k)))
            draws = _bits_np(pixel, np.zeros_like(pixel), seed, k)
            assert np.count_nonzero(keys == draws) <= 2


def test_neighbouring_counters_and_pixels_flip_half_the_bits():
    """Avalanche: a draw's 32 bits for (pixel, counter) and for (pixel, counter ^ 1), or (pixel ^ 1, counter),
    differ in half their bits on average (16 of 32, +-0.1 over 65,536 pixels: a binomial's spread is 2.8 bits
    a draw, 0.011 over them all), and never in none: the whole-row tests could not see a weak mix."""
    from mitsuba_eventfield.plugins.counter_rng import bits, stream_word
    word = np.uint32(stream_word(np.uint32(12345), 3))
    pixel = np.arange(65536, dtype=np.uint32)
    for c in (0, 6, 1001):
        counter = np.full_like(pixel, c)
        a = bits(pixel, counter, word)
        for other in (bits(pixel, counter ^ np.uint32(1), word), bits(pixel ^ np.uint32(1), counter, word)):
            flipped = np.unpackbits((a ^ other).view(np.uint8)).reshape(-1, 32).sum(axis=1)
            assert abs(flipped.mean() - 16) < 0.1 and flipped.min() > 0
