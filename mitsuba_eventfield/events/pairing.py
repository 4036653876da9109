"""Two event streams of one sensor against each other, event by event: the k-th event of a pixel and polarity in
one against the k-th of the same pixel and polarity in the other, wherever the two counts agree (the timing
alone; a missing or extra event makes its pixel and polarity unpaired instead of shifting every later pair).

The measure of timing that needs no ground truth: two renders that differ only in their seed hold the same
step error and independent Monte-Carlo noise, so their paired differences are sqrt 2 times one render's noise
timing error (``simulate/accuracy_limit.py`` predicts that error; tests/simulate/test_auto_timing.py and
``./run bench timing_model`` check the prediction against this measure and against a converged render).
"""
from __future__ import annotations

import numpy as np

from ..errors import ConfigError


def _sorted_keys(stream):
    """Each event's key (pixel, polarity) and time, sorted by key and then by time (stable)."""
    key = (stream.y.astype(np.int64) * stream.width + stream.x) * 2 + (stream.p > 0)
    order = np.lexsort((stream.t, key))
    return key[order], stream.t[order]


def paired_time_differences(a, b) -> dict:
    """|t_a - t_b| (us, float64) of the k-th events of every pixel and polarity whose counts agree in ``a`` and
    ``b`` (EventStreams of one sensor size), and the share of each stream's events so paired."""
    if (a.width, a.height) != (b.width, b.height):
        raise ConfigError(f"paired_time_differences: sensors differ ({a.width}x{a.height} against "
                          f"{b.width}x{b.height})")
    ka, ta = _sorted_keys(a)
    kb, tb = _sorted_keys(b)
    n = 2 * a.width * a.height
    same = np.bincount(ka, minlength=n) == np.bincount(kb, minlength=n)
    pa, pb = same[ka], same[kb]                 # (equal counts: the same number of events kept from each)
    dt = np.abs(ta[pa].astype(np.float64) - tb[pb])
    return {"dt_us": dt, "share_a": len(dt) / max(len(ka), 1), "share_b": len(dt) / max(len(kb), 1)}


def two_seed_timing_us(a, b) -> float:
    """One render's Monte-Carlo timing error (us, the median) from two renders ``a`` and ``b`` that differ only
    in their seed: the median paired difference over sqrt 2 (NaN when no event pairs)."""
    dt = paired_time_differences(a, b)["dt_us"]
    return float(np.median(dt) / np.sqrt(2)) if len(dt) else float("nan")
