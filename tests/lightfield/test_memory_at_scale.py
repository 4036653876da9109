"""Memory that follows what a step needs, not the recording (a scale audit at 1280x720, 2026-11-28): one scan
period of a 5 s recording held 16 bytes of every event of it, the galvo solver's sparse system needed about
8 GiB for one period, and ``reconstruct`` converted its whole stack at once (four more copies of it). Peaks
are measured with tracemalloc, which sees NumPy's allocations; each bound is well under what the old code
took on the same input (stated per test)."""
import math
import os
import tracemalloc

import numpy as np
import pytest
from conftest import ROOT

from mitsuba_eventfield.events.stream import EventStream
from mitsuba_eventfield.lightfield import galvo_solve
from mitsuba_eventfield.lightfield.reconstruct import direct

GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")


def _peak(fn):
    tracemalloc.start()
    tracemalloc.reset_peak()
    try:
        result = fn()
        return result, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_direct_weighs_only_the_events_of_its_window():
    """Two million events after the window cost nothing (they cost 16 bytes each: 32 MB); the frames equal
    those of the window's events alone."""
    rng = np.random.default_rng(0)
    w, h, n_in, n_after = 32, 24, 5000, 2_000_000
    t = np.r_[np.sort(rng.integers(0, 10_000, n_in)), np.sort(rng.integers(20_000, 10_000_000, n_after))]
    n = len(t)
    ev = EventStream(rng.integers(0, w, n), rng.integers(0, h, n), t, rng.choice([-1, 1], n), w, h,
                     {"pixel_model": {"threshold_on": 0.2, "threshold_off": 0.3}})
    times = [0.002, 0.005, 0.01]
    frames, peak = _peak(lambda: direct(ev, times, t_start=0.0))
    alone = EventStream(ev.x[:n_in], ev.y[:n_in], ev.t[:n_in], ev.p[:n_in], w, h, ev.meta)
    assert np.array_equal(frames, direct(alone, times, t_start=0.0))
    assert peak < 2_000_000, peak


def _reference_system(counts, angles, mapper, samples, lags):
    """The pair equations written out one by one (dense): row r of pair (k, k2) and pixel (y, x) is +1 at the
    pixel, minus the bilinear weights at its position in view k; b = the interpolated counts of view k minus
    the pixel's counts in view k2."""
    n, h, w = counts.shape
    rows, rhs = [], []
    for k, k2 in galvo_solve._pairs(samples, lags):
        sx, sy = mapper(angles[k2], angles[k])
        for y in range(h):
            for x in range(w):
                x0, y0 = math.floor(sx[y, x]), math.floor(sy[y, x])
                if not (0 <= x0 and 0 <= y0 and x0 + 1 < w and y0 + 1 < h):
                    continue
                fx, fy = sx[y, x] - x0, sy[y, x] - y0
                row = np.zeros(h * w)
                row[y * w + x] += 1.0
                value = 0.0
                for yy, xx, wt in ((y0, x0, (1 - fx) * (1 - fy)), (y0, x0 + 1, fx * (1 - fy)),
                                   (y0 + 1, x0, (1 - fx) * fy), (y0 + 1, x0 + 1, fx * fy)):
                    row[yy * w + xx] -= wt
                    value += wt * counts[k, yy, xx]
                rows.append(row)
                rhs.append(value - counts[k2, y, x])
    return np.array(rows), np.array(rhs)


@pytest.fixture(scope="module")
def galvo_period():
    import mitsuba_eventfield as ef
    from mitsuba_eventfield.optics.scan import scan_period
    ev = ef.render_events(ef.load_scene(GALVO, width=16, height=12), 0.0125, steps=32)
    return ev, scan_period(ev.meta["optics"]["scan"])


@pytest.mark.parametrize("samples, lags, depth", [(8, (1, 2), math.inf), (6, (1,), "map")])
def test_the_sparse_system_is_the_pair_equations_written_out(galvo_period, samples, lags, depth):
    ev, period = galvo_period
    ts = ev.start_s + np.arange(samples + 1) * period / samples
    geometry, angles = galvo_solve.geometry_and_angles(ev, ts)
    counts = direct(ev, ts, None, ev.start_s)
    inv = galvo_solve._inverse_depth(np.linspace(0.4, 3.0, 12 * 16).reshape(12, 16) if depth == "map" else depth,
                                     (12, 16))
    mapper = galvo_solve._Mapper(geometry, inv)
    a, b = galvo_solve._system(counts, angles, mapper, samples, lags)
    ref_a, ref_b = _reference_system(counts, angles, mapper, samples, lags)
    assert a.shape == ref_a.shape and len(ref_b) > 100
    assert np.allclose(a.toarray(), ref_a, rtol=0, atol=1e-12) and np.allclose(b, ref_b, rtol=0, atol=1e-12)
    assert a.has_canonical_format and a.indices.dtype == np.int32


def test_the_sparse_system_takes_about_its_own_size():
    """160x90 at 16 samples, quarter-period lags (29 pairs, 0.42 M equations): the system's arrays take 68
    bytes an equation at most (5 float64 values, 5 int32 columns, the right-hand side); the peak stays within
    1.5x that (the COO lists, their concatenation and the conversion took 150 MB)."""
    from mitsuba_eventfield.optics.galvo import GalvoGeometry
    h, w, samples = 90, 160, 16
    geometry = GalvoGeometry.from_optics(galvo_period_optics(), w, h)
    rng = np.random.default_rng(1)
    counts = rng.normal(size=(samples + 1, h, w))
    phase = 2 * np.pi * np.arange(samples + 1) / samples
    angles = np.stack([0.01 * np.cos(phase), 0.01 * np.sin(phase)], axis=-1)
    mapper = galvo_solve._Mapper(geometry, np.zeros((h, w)))
    (a, b), peak = _peak(lambda: galvo_solve._system(counts, angles, mapper, samples, (1, 4)))
    bound = len(galvo_solve._pairs(samples, (1, 4))) * h * w
    assert a.shape[0] > 0.9 * bound and peak < 1.5 * 68 * bound, (peak, 68 * bound)


def galvo_period_optics():
    from mitsuba_eventfield.scene import load_scene
    from mitsuba_eventfield.simulate.summary import sensor_optics
    return sensor_optics(load_scene(GALVO, width=16, height=12))


def test_static_lags_pair_each_equation_once():
    assert galvo_solve.static_lags(16) == (1, 4) and galvo_solve.static_lags(6) == (1,)
    assert galvo_solve.static_lags(4) == (1,) and galvo_solve.static_lags(8) == (1, 2)


def test_the_solve_does_not_copy_the_system():
    """LSQR took the matrix's transpose as ``a.H``, a copy of it (1.6 GiB for one 1280x720 period), and each
    re-weighting copied it again (``diags(sw) @ a``); the solve now holds vectors only: under 12 float64 values
    an equation at its peak, where one copy alone is 7.5 (five values and five int32 columns). Unweighted, the
    solution is the same to the bit as with the copy."""
    from scipy.sparse.linalg import lsqr
    from mitsuba_eventfield.optics.galvo import GalvoGeometry
    h, w, samples = 90, 160, 16
    geometry = GalvoGeometry.from_optics(galvo_period_optics(), w, h)
    counts = np.random.default_rng(2).normal(size=(samples + 1, h, w))
    phase = 2 * np.pi * np.arange(samples + 1) / samples
    angles = np.stack([0.01 * np.cos(phase), 0.01 * np.sin(phase)], axis=-1)
    a, b = galvo_solve._system(counts, angles, galvo_solve._Mapper(geometry, np.zeros((h, w))), samples, (1, 4))
    args = (np.zeros(h * w), 1e-8, 0, 0.2, 30, 1e-4)
    (x, _), peak = _peak(lambda: galvo_solve._solve(a, b, *args))
    assert peak < 12 * 8 * a.shape[0], peak / (8 * a.shape[0])
    robust = (np.zeros(h * w), 1e-8, 2, 0.2, 30, 1e-4)        # re-weighted twice: the weights on the products
    (_, weights), peak = _peak(lambda: galvo_solve._solve(a, b, *robust))
    assert peak < 12 * 8 * a.shape[0] and weights.min() < 1, peak / (8 * a.shape[0])
    with galvo_solve._one_blas_thread():            # (BLAS's threads would sum the norms in another order)
        assert np.array_equal(x, lsqr(a, b, damp=math.sqrt(1e-8), iter_lim=30, atol=1e-4, btol=1e-4)[0])
