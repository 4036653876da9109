"""The accuracy-limit estimate's step term (``simulate/accuracy_limit.py``) for steps of unequal length: the second
divided difference of three frames, checked on log brightness that is exactly quadratic in time (where
linear interpolation's error bound dt^2 |L''| / (8 |L'|) is known in closed form)."""
import numpy as np
import pytest

from mitsuba_eventfield.simulate.accuracy_limit import RESOLVE, AccuracyLimit, event_median


def _estimate(d1, d2, a=40.0, b=3.0, sigma=1e-3):
    """Frames of L(t) = a t^2 + b t + L0 (every pixel a different L0) at 0, d1, d1 + d2."""
    limit = AccuracyLimit((d1, d2), spp=4)
    l0 = np.linspace(-1.0, 1.0, 64).reshape(8, 8)
    limit.frames = [l0 + a * t * t + b * t for t in (0.0, d1, d1 + d2)]
    limit.sigma = np.full_like(l0, sigma)
    return limit.estimate()


@pytest.mark.parametrize("d1, d2", [(1e-3, 1e-3), (1e-3, 3e-3), (4e-3, 1e-3)])
def test_step_term_uses_the_second_divided_difference(d1, d2):
    est = _estimate(d1, d2)
    rate = 3.0 + 40.0 * d1                  # the first step's mean slope
    dt = (d1 + d2) / 2
    assert est["steps_us"] == pytest.approx(dt ** 2 * 80.0 / (8 * rate) * 1e6, rel=1e-6)
    # the noise term's slope: over d1 + d2, the longer of the two baselines these frames have, over which the
    # error hardly changes (a plateau: event_slopes) and which resolves it (at least RESOLVE x ~300 us)
    baseline = d1 + d2
    assert est["noise_us"] == pytest.approx(1e-3 / (3.0 + 40.0 * baseline) * 1e6, rel=1e-6)
    assert est["slope_baseline_us"] == pytest.approx(baseline * 1e6) and est["slope_resolved"]
    assert baseline >= RESOLVE * est["noise_us"] * 1e-6


def test_equal_steps_reduce_to_the_uniform_formula():
    """Uniform steps: (l2 - 2 l1 + l0) / dt^2, the formula before placed steps."""
    dt = 2e-3
    est = _estimate(dt, dt)
    l0, l1, l2 = (40.0 * t * t + 3.0 * t for t in (0.0, dt, 2 * dt))
    rate = (l1 - l0) / dt
    assert est["steps_us"] == pytest.approx(dt ** 2 * ((l2 - 2 * l1 + l0) / dt ** 2) / (8 * rate) * 1e6, rel=1e-9)
    assert est["limit"] == ("steps" if est["steps_us"] > est["noise_us"] else "Monte-Carlo noise")


def test_the_noise_term_is_the_median_over_events_not_pixels():
    """90 pixels barely change (0.01 log units a second: they seldom fire), 10 change fast (100 a second): the
    events are the fast pixels', so the timing error is theirs, sigma / 100 (100 us), not sigma / 0.01."""
    dt = 1e-3
    limit = AccuracyLimit((dt, dt), spp=4)
    slope = np.r_[np.full(90, 0.01), np.full(10, 100.0)].reshape(10, 10)
    limit.frames = [slope * t for t in (0.0, dt, 2 * dt)]
    limit.sigma = np.full((10, 10), 0.01)
    assert limit.estimate()["noise_us"] == pytest.approx(100.0, rel=1e-9)


def _drifting(jumps=0, stop=3.2e-3, seed=3):
    """Frames of pixels whose log brightness drifts slowly for ``stop`` seconds and then stops (an edge passed),
    each frame with its own noise (a moving image under a frozen sampler) as large as many steps' change;
    ``jumps`` pixels jump by 2 (one sample crossing an edge) in the first step. Returns (limit, exact error s)."""
    rng = np.random.default_rng(seed)
    n, dt, sigma = 20_000, 1e-4, 0.02
    slope = rng.uniform(5.0, 50.0, n)                       # 1-10 x sigma over 4 ms: errors 0.4-4 ms
    times = [dt * k for k in (0, 1, 2, 4, 8, 16, 32, 64, 128)]
    frames = [slope * min(t, stop) + rng.normal(0, sigma, n) + 2.0 * (np.arange(n) < jumps) * (t > 0)
              for t in times]
    limit = AccuracyLimit((dt, dt), spp=4)
    limit.frames, limit.sigma = frames[:3], np.full(n, sigma)
    limit.baselines = list(zip(times[3:], frames[3:]))
    return limit, event_median(np.full(n, sigma) / slope, slope)


def test_slopes_over_one_step_read_the_frames_noise_as_change():
    """Pixels whose log brightness drifts slowly under frame noise as large as a step's change: over one step
    their difference is mostly noise, so they look steep and the error small (the demo at 48x36: 74 us read,
    486 measured). The baseline grows until the median event's slope is resolved, and no further: past 3.2 ms
    the drift has stopped and longer baselines read it slower (the longest: 4x the error). The estimate comes
    within 25 % of sigma / |L'| on the exact slopes, where one step's reads it 9x too small."""
    limit, exact = _drifting()
    first, one_step = limit.frames[0], limit.frames[1]
    d = np.abs(one_step - first)
    est = limit.estimate()
    assert event_median(limit.sigma / (d / 1e-4), d) < exact / 3                # measured 0.11 x
    assert est["noise_us"] * 1e-6 == pytest.approx(exact, rel=0.25) and est["slope_resolved"]   # 0.97 x
    assert est["slope_baseline_us"] == pytest.approx(3200) and est["slope_baseline_us"] >= RESOLVE * est["noise_us"]


def test_a_few_jumping_pixels_do_not_resolve_a_short_baseline():
    """At fine steps a few pixels where one sample crosses an edge jump by whole contrasts; over a baseline b
    their slope is jump / b, they carry most of the weight, and the error grows as b, "resolved" at every
    short baseline (the demo at 48x36, 16 spp, 400 steps: 3.3 us read, 741 us measured by two seeds; here 1 us
    against 565). Only a plateau, where the error stops growing with the baseline, is taken: 501 us here."""
    limit, exact = _drifting(jumps=400, stop=6.4e-3)
    est = limit.estimate()
    assert est["noise_us"] * 1e-6 == pytest.approx(exact, rel=0.25), (est, exact)
    assert est["slope_resolved"] and est["slope_baseline_us"] >= 1600


def test_the_noise_estimate_does_not_grow_with_the_steps():
    """The fan at 96x72, 4 spp: a noise floor set by the samples. Over the pixels it read 172, 481 and 1312 us at
    16, 55 and 480 steps ("more steps do not help" while the number grew eightfold); over the events 22, 23, 13."""
    import mitsuba_eventfield as ef
    from mitsuba_eventfield.scene import bundled_scene
    noise = [ef.render_events(ef.load_scene(bundled_scene("fan/fan.xml"), width=96, height=72), 0.004,
                              steps=steps).meta["render"]["timing_limit"]["noise_us"] for steps in (16, 55, 480)]
    assert max(noise) < 2.5 * min(noise) and max(noise) < 60, noise


def _median_by_sorting_everything(values, weights):
    order = np.argsort(values, kind="stable")
    cum = np.cumsum(weights[order])
    return values[order][min(int(np.searchsorted(cum, 0.5 * cum[-1])), len(cum) - 1)]


def test_event_median_sorts_only_its_bracket_and_agrees_with_sorting_everything(monkeypatch):
    """A large image's weighted median sorts only the pixels between a random sample's quantiles (7x faster at
    1280x720; a wider bracket where heavy-tailed weights move them), and a bracket that misses falls back to
    sorting every pixel: the same value in every case."""
    from mitsuba_eventfield.simulate import accuracy_limit
    sorted_sizes = []
    real = accuracy_limit._sorted_median
    monkeypatch.setattr(accuracy_limit, "_sorted_median",
                        lambda v, w, *rest: (sorted_sizes.append(len(v)), real(v, w, *rest))[1])
    rng = np.random.default_rng(5)
    n = 300_000
    heavy = rng.lognormal(size=n), rng.lognormal(sigma=2.0, size=n)          # event rates span decades
    tied = np.round(rng.lognormal(size=n), 1), rng.random(n)                   # many equal values
    # nearly all the weight on bright pixels the sample skips: its bracket misses the median
    skipped = np.ones(n, bool)
    skipped[accuracy_limit._sample(n)] = False
    skipped &= rng.random(n) < 0.02
    off_sample = rng.lognormal(size=n) + 1000.0 * skipped, np.where(skipped, 1e6, 1e-3)
    # a value that changes with the image column (every 128th column darker): a regular stride missed here
    columns = rng.lognormal(size=n) + 5.0 * (np.arange(n) % 2048 % 128 != 0), rng.lognormal(size=n)
    for values, weights in (heavy, tied, off_sample, columns):
        sorted_sizes.clear()
        assert accuracy_limit.event_median(values, weights) == _median_by_sorting_everything(values, weights)
        if weights is off_sample[1]:
            assert sorted_sizes == [n]                       # the fallback
        else:
            assert len(sorted_sizes) == 1 and sorted_sizes[0] < n // 2


@pytest.mark.parametrize("steps", [5, 8, 40])
def test_no_slope_baseline_spans_more_than_a_quarter_scan_period(steps):
    """A frame difference across a scan period is no slope: galvo_static (4 ms period) in 5 steps over 8 ms took
    a 6.4 ms baseline, read 145 us and called it resolved, where two seeds' renders differ by 9.2 us. Baselines
    now stop at a quarter period (a first step longer than that is kept, unresolved): 36 / 32 / 31 us against
    11 / 13 / 28 us measured, at 5 / 8 / 40 steps."""
    import mitsuba_eventfield as ef
    from mitsuba_eventfield.events.pairing import two_seed_timing_us
    from mitsuba_eventfield.scene import bundled_scene
    a, b = (ef.render_events(ef.load_scene(bundled_scene("galvo_static/galvo_static.xml"), width=48, height=36),
                             0.008, steps=steps, spp=4, seed=seed) for seed in (0, 1))
    est = a.meta["render"]["timing_limit"]
    assert est["slope_baseline_us"] <= 1000 or (est["slope_baseline_us"] == 1600 and not est["slope_resolved"])
    assert est["noise_us"] < 4 * two_seed_timing_us(a, b), est
