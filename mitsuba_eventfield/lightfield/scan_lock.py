"""Does a galvo stream follow its scan? (``scan_lock``, ``warn_unlocked``.)

A scanned scene fires the same pixels, with the same polarity, at the same point of every scan period, so the
signed event counts (ON minus OFF) of windows one period apart correlate. A frequency in the optics that is not
the mirror's, or events that are no galvo's, do not: their light fields, and the confident depths from them, are
not the scene's. Three things are read from the correlation of windows a twelfth of the stated period long,
at every lag from a quarter of a period to two periods (one sparse Gram matrix of the windows' counts):

* ``lock``: the correlation one stated period apart;
* ``peak``: the best correlation at any of those lags. A stream is locked when its lock is at least
  ``MIN_LOCK_SHARE`` of the peak and above ``MIN_LOCK``, a share rather than an absolute level because thinning
  the events lowers every correlation alike (galvo_static at 96x72, 5 % of its events kept at random: 0.58);
* ``repeats_every``: 1/2 or 1/3 when the events repeat as well after that fraction of the stated period: a
  stated frequency that is a half or a third of the mirror's, which the lock alone cannot see (the events of a
  mirror at 2f repeat after 1/f too).

Measured (96x72, seven periods; 16 streams: four bundled scenes and galvo_static under a Lissajous 300/200 Hz,
line, raster and Moore scan, each with all its events and with 5 % kept at random): every one locked (lock 1.00,
the spinning fan 0.70; thinned 0.29-0.63, each its own peak); the optics' frequency 0.7x, 0.4x or 2.5x the
mirror's: locks -0.58 to 0.06 against peaks of 0.10-1.00 elsewhere (or both below ``MIN_LOCK``), all unlocked; 0.5x
and 1/3x: the sub-period correlation as high as the lock, all said; 10 % off (galvo_static at 64x48): 0.34-0.42
against peaks of 0.96 a period and 8 % away, unlocked (5 % off: 0.74-0.75, locked); random events: lock -0.01. At
the right frequency the half- and third-period correlations stay well below the lock (at most 0.64 of it: the
raster's half period, where its lines repeat). Signed counts separate these better than unsigned ones did (0.7x on
galvo_static: 0.31 unsigned, -0.25 signed), and 2x2 pooling makes fewer, fuller cells (a thinned stream correlates
higher). A check reads up to eight periods in 2-18 ms.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from ..optics.scan import scan_period

WINDOWS_PER_PERIOD = 12      # a twelfth of a period: lags of a half and a third of it are whole windows
SCAN_LOCK_PERIODS = 8        # stated periods read at most
POOL = 2                     # pixels pooled (per axis) into one cell
MIN_LOCK = 0.05              # below: no repetition at all (random events: 0.00)
MIN_LOCK_SHARE = 0.7         # of the best correlation at any lag a stated period's must reach
SUB_PERIOD_SHARE = 0.9       # a half or third period correlating this share of the lock: the events repeat there
MIN_LAG = WINDOWS_PER_PERIOD // 4
# fewer events a window than this and the correlations are noise: no verdict (galvo_static at 64x48 thinned at
# random: 56 events a window lock 0.17, 17 lock 0.05, 5 lock 0.02, each at its own peak; a warning there said
# the events do not repeat while their best lag was the stated period)
MIN_EVENTS_PER_WINDOW = 50


class ScanLockWarning(UserWarning):
    """A galvo stream whose events do not repeat with its scan period (``scan_lock``)."""


@dataclass(frozen=True)
class ScanLock:
    lock: float                      # correlation of signed counts one stated period apart
    peak: float                      # the best correlation at lags from a quarter period to two periods
    peak_periods: float              # that lag, in stated periods
    repeats_every: float | None      # 1/2 or 1/3: the events repeat after that share of the stated period too

    @property
    def locked(self) -> bool:
        return self.lock >= MIN_LOCK and self.lock >= MIN_LOCK_SHARE * self.peak and self.repeats_every is None


def _window_counts(events, period_us: float, windows: int):
    """(windows x cells) sparse signed counts, pixels pooled ``POOL`` x ``POOL``, window by window: a dense array
    of all windows was 236 MB at 1280x720."""
    from scipy.sparse import csr_matrix
    bounds = np.searchsorted(events.t, events.start_us + np.arange(windows + 1) * (period_us / WINDOWS_PER_PERIOD))
    row_w = -(-events.width // POOL)
    cells = row_w * -(-events.height // POOL)
    indptr, indices, data = [0], [], []
    for j in range(windows):
        s = slice(bounds[j], bounds[j + 1])
        cell = (events.y[s].astype(np.int64) // POOL) * row_w + events.x[s] // POOL
        counts = np.bincount(cell, weights=events.p[s], minlength=cells)
        nz = np.flatnonzero(counts)
        indices.append(nz), data.append(counts[nz])
        indptr.append(indptr[-1] + len(nz))
    return csr_matrix((np.concatenate(data), np.concatenate(indices), np.asarray(indptr)), shape=(windows, cells))


def _lag_correlations(c) -> np.ndarray:
    """Mean Pearson correlation of rows k apart, for every lag k (NaN where no pair has variance)."""
    n = c.shape[1]
    gram = (c @ c.T).toarray()
    sums = np.asarray(c.sum(axis=1)).ravel()
    cov = gram - np.outer(sums, sums) / n
    var = np.diag(cov).copy()
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.sqrt(np.outer(var, var))
    out = np.full(len(var), np.nan)
    for k in range(1, len(var)):
        d = np.diagonal(corr, k)
        d = d[np.isfinite(d)]
        if d.size:
            out[k] = d.mean()
    return out


def scan_lock(events) -> ScanLock | None:
    """How well the events repeat with the scan of their optics (module docstring); None with fewer than two
    whole stated periods or ``MIN_EVENTS_PER_WINDOW`` events a window."""
    from .model import _galvo_scan
    period_us = scan_period(_galvo_scan(events.meta.get("optics", {}), "scan lock")) * 1e6
    w = WINDOWS_PER_PERIOD
    windows = min(int(events.duration_us // (period_us / w)), w * SCAN_LOCK_PERIODS)
    if windows < 2 * w or not len(events):
        return None
    read = int(np.searchsorted(events.t, events.start_us + windows * period_us / w))
    if read < MIN_EVENTS_PER_WINDOW * windows:
        return None
    corr = _lag_correlations(_window_counts(events, period_us, windows))
    lock = corr[w]
    if not np.isfinite(lock):
        return None
    lags = np.arange(MIN_LAG, min(2 * w, windows - 1) + 1)
    values = np.where(np.isfinite(corr[lags]), corr[lags], -np.inf)
    best = int(lags[np.argmax(values)])
    repeats = [m for m in (3, 2) if np.isfinite(corr[w // m]) and lock >= MIN_LOCK
               and corr[w // m] >= SUB_PERIOD_SHARE * lock]
    return ScanLock(float(lock), float(corr[best]), best / w, 1.0 / repeats[0] if repeats else None)


def warn_unlocked(events, where: str) -> None:
    """A ``ScanLockWarning`` when the events do not follow their scan (``ScanLock.locked``)."""
    state = scan_lock(events)
    if state is None or state.locked:
        return
    f = 1.0 / scan_period(events.meta["optics"]["scan"])
    if state.repeats_every is not None:
        m = round(1 / state.repeats_every)
        said = (f"{where}: the events repeat every 1/{m} of the {f:g} Hz scan's period (counts that far apart "
                f"correlate as well as one period apart, {state.lock:.2f}): the mirror runs at {m * f:g} Hz, not "
                "the optics' frequency?")
    else:
        said = (f"{where}: the events do not repeat with the {f:g} Hz scan (signed counts one period apart "
                f"correlate {state.lock:.2f}, {state.peak_periods:.2f} periods apart {state.peak:.2f}; a scanned "
                "scene's are alike): the optics' scan frequency is not the mirror's, or these are not a galvo's "
                "events")
    warnings.warn(said + "; light fields and depths from them are not the scene's", ScanLockWarning, stacklevel=3)
