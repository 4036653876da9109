"""A step's events made on the host (NumPy), the twin of ``event_fill``: the firing pixels are compressed on the
device, gathered to the host, and expanded there (``pixel_model.expand_crossings``), with the refractory period
and shot noise applied to the sparse events. The CPU's choice for pixel models with a refractory period or
shot noise (faster there), and the reference the device path is tested against."""
from __future__ import annotations

import drjit as dr
import numpy as np

from mitsuba_eventfield.plugins import pixel_model


def step_events(integ, step: dict, t0: float, t1: float):
    """The step's events on the host: (pixel index, time s, polarity) of every crossing, linearly
    interpolated in time, then the refractory period and shot-noise events."""
    n, noise = step["n"], step["noise"]
    # one compress over every pixel that produced anything (crossings or noise), one gather kernel
    fired = dr.compress((n != 0) | noise[0]) if noise is not None else dr.compress(n != 0)
    if dr.width(fired) == 0:
        return np.empty(0, np.int64), np.empty(0), np.empty(0, np.int8)
    cols = [n, integ.log_prev, step["log_now"], step["log_ref"], step["c_on"], step["c_off"]]
    if noise is not None:
        cols += [noise[3], noise[1], noise[2]]
    sparse = [dr.gather(type(a), a, fired) for a in cols]
    dr.eval(*sparse)
    arr = [a.numpy() for a in sparse]
    fpix = fired.numpy().astype(np.int64)
    sig = arr[0] != 0
    pix, t, p = pixel_model.expand_crossings(fpix[sig], *(a[sig] for a in arr[:6]), t0, t1)
    hit = arr[6] != 0 if noise is not None else None
    before = integ.last_emit[fpix[hit]] if (noise is not None and integ.config.refractory_s) else None
    crossings = None
    if integ.config.refractory_s:
        keep, crossings = pixel_model.refractory_crossings(pix, t, integ.last_emit, integ.config.refractory_s)
        integ.refractory_dropped += int(len(t) - keep.sum())
        pix, t, p = pix[keep], t[keep], p[keep]
    if noise is None:
        return pix, t, p
    npix, nt, pol = _noise_events(integ, fpix[hit], arr[7][hit], arr[8][hit], before, crossings, t0, t1)
    # each pixel's noise event after its own crossings (both in pixel order): the device's slot order, which
    # the stable time sort keeps for equal times
    at = np.searchsorted(pix, npix, side="right")
    return np.insert(pix, at, npix), np.insert(t, at, nt), np.insert(p, at, pol)

def _noise_events(integ, npix, u_pol, u_t, before, crossings, t0: float, t1: float):
    """Shot-noise events of the pixels ``npix`` (uniform polarity and time within the step), subject to the
    refractory period like the signal's."""
    pol = np.where(u_pol < 0.5, 1, -1).astype(np.int8)
    nt = t0 + u_t.astype(np.float64) * (t1 - t0)
    if integ.config.refractory_s:
        keep = pixel_model.refractory_extra(npix, nt, before, crossings, integ.last_emit,
                                            integ.config.refractory_s)
        integ.refractory_dropped += int(len(nt) - keep.sum())
        npix, nt, pol = npix[keep], nt[keep], pol[keep]
    integ.noise_events += len(npix)
    return npix, nt, pol
