"""Accuracy of a stochastic pixel model as statistics, not per-event matches.

With shot noise, threshold mismatch or jitter on, two renders of the same scene with different seeds share no
event one-to-one, yet both are right; what must agree is the distribution. ``statistics`` summarises a stream
(event rate per pixel, ON fraction, inter-event intervals per pixel), ``compare`` scores one stream against a
reference of the same model (e.g. a converged render, or another seed):

* ``rate_ratio``: total event rate over the reference's (1 = same bandwidth);
* ``pixel_rate_error``: mean |rate - reference rate| per pixel over the reference's mean rate (where the events
  are, not only how many);
* ``on_fraction_diff``: difference of the ON fractions;
* ``interval_ks``: the two-sample Kolmogorov-Smirnov distance between the inter-event interval distributions
  (0: the same; shot noise at twice the rate halves the intervals and gives ~0.3 or more), with its p-value.
"""
from __future__ import annotations

import numpy as np

from ..errors import ConfigError


def _intervals(events) -> np.ndarray:
    """Time between consecutive events of the same pixel (seconds), all pixels together."""
    pix = events.y.astype(np.int64) * events.width + events.x
    order = np.lexsort((events.t, pix))
    p, t = pix[order], events.t[order].astype(np.float64) * 1e-6
    same = p[1:] == p[:-1]
    return np.diff(t)[same]


def statistics(events) -> dict:
    """Rate per pixel (events/s, (H, W)), total rate, ON fraction and inter-event intervals of a stream."""
    duration = events.duration_us * 1e-6
    if not duration > 0:
        raise ConfigError("statistics: the stream has no duration (t_start/t_end metadata or events)")
    counts = np.bincount(events.y.astype(np.int64) * events.width + events.x, minlength=events.width * events.height)
    return {"rate_map": counts.reshape(events.height, events.width) / duration, "rate": len(events) / duration,
            "on_fraction": float(np.mean(events.p > 0)) if len(events) else float("nan"),
            "intervals": _intervals(events)}


def compare(events, reference) -> dict:
    """``events`` against ``reference`` (same film) by the statistics above."""
    from scipy.stats import ks_2samp
    if (events.width, events.height) != (reference.width, reference.height):
        raise ConfigError(f"compare: films differ ({events.width}x{events.height} vs "
                          f"{reference.width}x{reference.height})")
    a, b = statistics(events), statistics(reference)
    if not b["rate"] > 0:
        raise ConfigError("compare: the reference has no events")
    mean_ref = float(b["rate_map"].mean())
    ks = ks_2samp(a["intervals"], b["intervals"]) if len(a["intervals"]) and len(b["intervals"]) else None
    return {"rate_ratio": a["rate"] / b["rate"],
            "pixel_rate_error": float(np.abs(a["rate_map"] - b["rate_map"]).mean() / mean_ref),
            "on_fraction_diff": a["on_fraction"] - b["on_fraction"],
            "interval_ks": float(ks.statistic) if ks else float("nan"),
            "interval_ks_p": float(ks.pvalue) if ks else float("nan")}
