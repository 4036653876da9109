"""Galvo reconstruction from events alone: the log image at the start of a scan period, with per-pixel
parallax and moving objects, from that period's events and a prior (``focus.galvo_periods`` runs it period
by period, with depth from focus and the previous period as the prior).

Why it works. Under a periodic scan every view is the scene seen through known mirror angles, so the view at
time t_b shows at pixel x what the view at t_a shows at H_ab(x), H_ab the exact view-to-view homography of the
plane at the depth of the point seen at x (``optics.galvo``). With L(x, t) = L_s(x) + C N(x, t) (N: net events
since the period start t_s), each pair of instants gives one linear equation per pixel,

    L_s(x) - L_s(H_ab(x)) = C N(H_ab(x), t_a) - C N(x, t_b)        (bilinear interpolation at H_ab(x)),

a difference of L_s along the scan's displacement: the events fix L_s up to one constant (an event camera
records no absolute brightness). Pairs one sample apart (small shifts) and a quarter period apart (large,
well-conditioned shifts; ``lags``) are compared, solved by sparse least squares (LSQR). With moving objects
only neighbouring samples are paired (``DYNAMIC_LAGS``): an object moves 4x less in one sample than in a
quarter period, and on the fan (scenes/fan, 128x96, 16 samples) refocus PSNR against converged views rose from
25.1 to 27.6 dB; more samples per period (32, 48) shrink the scan's shift per pair as well and were worse.

What breaks the single-depth solver, and what this module does about it:

* **Parallax.** The displacement depends on the depth of each point. ``start_image`` takes a depth map and
  maps each pixel at its own depth (``focus.galvo_periods`` estimates it from the period's own light field:
  depth from focus on the views integrated onto the current estimate, angular-variance measure) (homographies
  interpolated linearly in inverse depth, in which a galvo's displacement is affine); start from one plane,
  then alternate ``depth_iterations`` times. Textureless pixels (flat focus curves) get the median depth: their
  equations barely depend on it.
* **Moving objects.** Their points move between t_a and t_b on top of the scan, so their equations are wrong
  by the object's motion. Iteratively re-weighted least squares (Huber weights on the residuals, scale from the
  residuals' median absolute deviation) lets the consistent majority decide.
* **Continuity.** For every period after the first, the previous period's start image plus its events up to
  t_s is a prediction of L_s (exact for an ideal pixel where the previous estimate was right); the solve pulls
  towards it with weight ``prior_weight`` (Tikhonov on the difference). This carries the unknown constant from
  period to period, fills what the period's equations cannot see, and stops noise from accumulating.

No rendered frame is used anywhere; everything comes from the events and the optics in their metadata.
"""
from __future__ import annotations

import contextlib
import contextvars
import math
import threading

import numpy as np

from ..errors import ConfigError
from ..events.stream import EventStream
from ..optics.galvo import GalvoGeometry
from ..optics.scan import curve_from_dict, scan_period


def geometry_and_angles(events: EventStream, times):
    optics = events.meta.get("optics", {})
    if optics.get("design") != "galvo":
        raise ConfigError("galvo reconstruction needs a galvo event stream (optics.design == 'galvo'), got "
                          f"{optics.get('design')!r}")
    geometry = GalvoGeometry.from_optics(optics, events.width, events.height)
    ax, ay = curve_from_dict(optics["scan"], where="event metadata").angles(np.asarray(times, np.float64))
    return geometry, np.stack([ax, ay], axis=-1)


def _inverse_depth(depth, shape) -> np.ndarray:
    """Inverse depth per pixel from a number (math.inf allowed) or an (H, W) map."""
    d = np.asarray(depth, dtype=np.float64)
    if d.ndim == 0:
        d = np.full(shape, float(d))
    if d.shape != tuple(shape):
        raise ConfigError(f"depth map is {d.shape}, the events are {shape[1]}x{shape[0]} (H, W = {shape})")
    if not np.all(d > 0):
        raise ConfigError("depth must be > 0 everywhere (math.inf allowed)")
    return 1.0 / d


class _Mapper:
    """Where each pixel of one view lands in another, each pixel at its own depth: the exact homographies of a
    few planes uniform in inverse depth, interpolated linearly in inverse depth."""

    def __init__(self, geometry: GalvoGeometry, inv_depth: np.ndarray, planes: int = 6):
        self.geometry = geometry
        lo, hi = float(inv_depth.min()), float(inv_depth.max())
        self.inv = np.array([lo]) if hi - lo < 1e-9 else np.linspace(lo, hi, planes)
        pos = (inv_depth - lo) / (self.inv[1] - lo) if len(self.inv) > 1 else np.zeros_like(inv_depth)
        self.j = np.clip(np.floor(pos).astype(np.int64), 0, len(self.inv) - 2) if len(self.inv) > 1 else None
        self.f = pos - self.j if self.j is not None else None
        h, w = inv_depth.shape
        self.yy, self.xx = np.mgrid[0:h, 0:w].astype(np.float64)

    def _plane(self, a_from, a_to, u):
        hom = self.geometry.view_to_view(a_from, a_to, math.inf if u == 0 else 1.0 / u)
        xx, yy = self.xx, self.yy
        den = hom[2, 0] * xx + hom[2, 1] * yy + hom[2, 2]
        return ((hom[0, 0] * xx + hom[0, 1] * yy + hom[0, 2]) / den,
                (hom[1, 0] * xx + hom[1, 1] * yy + hom[1, 2]) / den)

    def __call__(self, a_from, a_to):
        maps = [self._plane(a_from, a_to, u) for u in self.inv]
        if self.j is None:
            return maps[0]
        sx = np.stack([m[0] for m in maps])
        sy = np.stack([m[1] for m in maps])
        rows, cols = np.indices(self.j.shape)
        f = self.f
        return ((1 - f) * sx[self.j, rows, cols] + f * sx[self.j + 1, rows, cols],
                (1 - f) * sy[self.j, rows, cols] + f * sy[self.j + 1, rows, cols])


def _pairs(samples: int, lags) -> list:
    """(k, k + lag) sample pairs, forward in time, up to the state at the period's end (sample ``samples``, the
    mirrors where they were at sample 0). Wrapped to sample 0 instead, pair (S - 1, 0) spanned (S - 1) / S of a
    period backwards, so one equation in S carried S - 1 samples of object motion (fan, 96x72, 16 samples, one
    plane: log error on the blades 0.444 -> 0.356; lags (1, 2): 0.390 -> 0.363); on static scenes, where wrapped
    pairs hold too, leaving them out was no worse (offaxis_cards, quarter-period lags: 0.1026 against 0.1065 at
    0.5 m)."""
    return [(k, k + lag) for lag in lags for k in range(samples) if k + lag <= samples]


def _system(counts, angles, mapper: _Mapper, samples: int, lags):
    """Sparse A (equations x pixels) and right-hand side b of the pair equations (module docstring). Every row
    holds five entries, the pixel's +1 and its four bilinear neighbours in the other view (minus their weights),
    written straight into CSR arrays sized for every pixel of every pair: built as lists of 64-bit COO
    triplets, concatenated, then converted, one 1280x720 period at 16 samples needed about 8 GiB (a scale
    audit, 2026-11-28). Duplicate entries (a neighbour that is the pixel itself) are summed as the conversion
    summed them, so the matrix is the same to the bit."""
    from scipy.sparse import csr_matrix
    h, w = counts.shape[1:]
    pairs = _pairs(samples, lags)
    bound = len(pairs) * h * w                        # equations at most: every pixel of every pair
    index = np.int32 if 5 * bound < 2 ** 31 else np.int64
    cols, vals, rhs = np.empty((bound, 5), index), np.empty((bound, 5)), np.empty(bound)
    n_eq = 0
    pix = np.arange(h * w).reshape(h, w)
    for k, k2 in pairs:
        sx, sy = mapper(angles[k2], angles[k])                 # view k2 pixel -> view k position
        x0, y0 = np.floor(sx).astype(np.int64), np.floor(sy).astype(np.int64)
        fx, fy = sx - x0, sy - y0
        ok = (x0 >= 0) & (y0 >= 0) & (x0 + 1 < w) & (y0 + 1 < h)
        m = int(ok.sum())
        if not m:
            continue
        eq = slice(n_eq, n_eq + m)
        cols[eq, 0], vals[eq, 0] = pix[ok], 1.0
        x0, y0, fx, fy = x0[ok], y0[ok], fx[ok], fy[ok]
        interp = np.zeros(m)
        ck = counts[k].ravel()
        for j, (idx, wt) in enumerate(((y0 * w + x0, (1 - fx) * (1 - fy)), (y0 * w + x0 + 1, fx * (1 - fy)),
                                       ((y0 + 1) * w + x0, (1 - fx) * fy), ((y0 + 1) * w + x0 + 1, fx * fy)), 1):
            cols[eq, j], vals[eq, j] = idx, -wt
            interp += wt * ck[idx]
        rhs[eq] = interp - counts[k2].ravel()[pix[ok]]
        n_eq += m
    if n_eq == 0:
        raise ConfigError("the scan moves the image out of the frame: no equations")
    a = csr_matrix((vals[:n_eq].reshape(-1), cols[:n_eq].reshape(-1), np.arange(0, 5 * n_eq + 1, 5, dtype=index)),
                   shape=(n_eq, h * w))
    a.sum_duplicates()
    return a, rhs[:n_eq]


def _solve(a, b, prior, prior_weight, robust_iterations, threshold, iterations, tolerance):
    """min sum_i rho(A x - b) + prior_weight |x - prior|^2 by LSQR on the difference from the prior, with
    Huber re-weighting (``robust_iterations`` re-solves). BLAS on one thread: LSQR's vector norms are memory
    bound, and OpenBLAS's threads, spinning against other busy processes, made them 10-45x slower (0.1 against
    4.7 ms for 720 k values); this solve at 173x130 took 2.0-4.5 s against 5.2-10.9 s with two other processes
    on the two cores, and the same 1.5 s on an idle machine."""
    with _one_blas_thread():
        return _solve_robust(a, b, prior, prior_weight, robust_iterations, threshold, iterations, tolerance)


_blas = {"lock": threading.Lock(), "solves": 0, "limiter": None}


@contextlib.contextmanager
def _one_blas_thread():
    """BLAS on one thread while any solve runs. BLAS limits are process-wide: two solves in threads (a Dask
    sweep) each saving and restoring them would leave them at one thread for good when they end out of order,
    so the first solve sets the limit and the last one puts back what was there. (OpenBLAS's count set from a
    worker thread was not always seen from another thread: then a solve there runs on BLAS's own threads, as
    fast on an idle machine.)"""
    from threadpoolctl import threadpool_limits
    with _blas["lock"]:
        if _blas["solves"] == 0:
            _blas["limiter"] = threadpool_limits(limits=1, user_api="blas")
        _blas["solves"] += 1
    try:
        yield
    finally:
        with _blas["lock"]:
            _blas["solves"] -= 1
            if _blas["solves"] == 0:
                _blas["limiter"].restore_original_limits()
                _blas["limiter"] = None     # the next first solve reads the limits afresh


# the progress line of the solves run in this context (``solver_progress``), or None
_PROGRESS = contextvars.ContextVar("galvo_solve_progress", default=None)
PROGRESS_DELAY_S = 2.0      # a solve shorter than this prints nothing (a test's, a small film's)


@contextlib.contextmanager
def solver_progress(desc: str):
    """A progress line on stderr for the galvo solves run inside this block (in this thread): LSQR iterations
    counted as they run, shown once the block has taken ``PROGRESS_DELAY_S``. The solve's iteration count is not
    known ahead (LSQR stops at its tolerance), so the line gives the count and the rate, not a fraction: at
    1280x720 a refocus solves for minutes, which the command line spent silent."""
    from ..simulate.summary import progress_bar
    bar = progress_bar(total=None, desc=f"{desc} (LSQR iterations)", unit="it", delay=PROGRESS_DELAY_S)
    token = _PROGRESS.set(bar)
    try:
        yield bar
    finally:
        _PROGRESS.reset(token)
        bar.close()


def _weighted(a, sw, bar=None):
    """The rows of ``a`` scaled by ``sw``, for LSQR, as an operator that copies nothing: its transpose is a view
    (``a.T``; scipy's own wrapper took it as ``a.H``, a copy of the whole matrix: 1.6 GiB for one 1280x720
    period), and the weights are applied to the products (``diags(sw) @ a`` copied the matrix at every
    re-weighting). With unit weights the products are those of ``a`` to the bit. ``bar``: a progress line
    ticked once an iteration (LSQR takes one product with ``a`` each)."""
    from scipy.sparse.linalg import LinearOperator

    def matvec(v):
        if bar is not None:
            bar.update()
        return sw * (a @ v)
    return LinearOperator(a.shape, matvec=matvec, rmatvec=lambda v: a.T @ (sw * v), dtype=a.dtype)


def _solve_robust(a, b, prior, prior_weight, robust_iterations, threshold, iterations, tolerance):
    from scipy.sparse.linalg import lsqr
    r0 = b - a @ prior
    damp = math.sqrt(prior_weight)
    weights = np.ones(len(b))
    delta = np.zeros(a.shape[1])
    for it in range(robust_iterations + 1):
        sw = np.sqrt(weights)
        delta = lsqr(_weighted(a, sw, _PROGRESS.get()), sw * r0, damp=damp, iter_lim=iterations, atol=tolerance,
                     btol=tolerance, x0=delta if it else None)[0]
        if it == robust_iterations:
            break
        res = np.abs(a @ delta - r0)
        scale = max(1.4826 * float(np.median(res)), 0.5 * threshold)    # never finer than the quantisation
        weights = np.minimum(1.0, 2.0 * scale / np.maximum(res, 1e-12))  # Huber, k = 2 scales
    return prior + delta, weights


DYNAMIC_LAGS = (1,)


def static_lags(samples: int) -> tuple:
    """Pairs one sample and a quarter period apart: the best conditioned set for a static scene."""
    return tuple(sorted({1, max(1, samples // 4)}))   # one lag below 8 samples: (1, 1) built every equation twice


def start_image(events: EventStream, t_start: float, samples: int = 16, depth=math.inf, prior=None,
                prior_weight: float = 1e-8, robust_iterations: int = 0, lags=None, c_on=None, c_off=None,
                iterations: int = 1000, tolerance: float = 1e-4):
    """Log image at ``t_start`` from the events of the scan period that starts there (module docstring).

    ``depth``: one depth for the whole scene or an (H, W) map (scene units, math.inf allowed); ``prior``: a
    predicted log image (e.g. the previous period carried forward), pulled towards with ``prior_weight``
    (without one, zeros: the tiny default weight then only fixes the free constant); ``robust_iterations``:
    Huber re-weighted re-solves (moving objects); ``lags``: sample distances paired (default
    ``static_lags``). ``tolerance``: LSQR's relative stopping tolerance; 1e-4
    instead of scipy's 1e-6 took 72 iterations instead of 106 on scenes/hdr_leds with the same log error to
    0.001 (the threshold's quantisation, C = 0.2, dominates). Returns (log image, per-equation weights)."""
    from .reconstruct import direct, thresholds
    geometry_and_angles(events, [])                                       # a galvo stream, or one line
    c_on, c_off = thresholds(events, c_on, c_off)
    h, w = events.height, events.width
    ts = t_start + np.arange(samples + 1) * (scan_period(events.meta["optics"]["scan"]) / samples)
    geometry, angles = geometry_and_angles(events, ts)
    counts = direct(events, ts, None, t_start, c_on, c_off)                # C N(x, t_k), N(t_0) = 0
    lags = static_lags(samples) if lags is None else tuple(int(v) for v in lags)
    a, b = _system(counts, angles, _Mapper(geometry, _inverse_depth(depth, (h, w))), samples, lags)
    x0 = np.zeros(h * w) if prior is None else np.asarray(prior, np.float64).reshape(-1)
    sol, weights = _solve(a, b, x0, prior_weight, robust_iterations, min(c_on, c_off), iterations, tolerance)
    return sol.reshape(h, w), weights
