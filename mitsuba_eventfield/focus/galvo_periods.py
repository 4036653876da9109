"""Galvo captures from events alone, period by period: each scan period's log image solved from that period's
events (``lightfield.galvo_solve``, whose docstring explains the equations), each pixel mapped at its own depth
from focus on the period's light field, moving objects turned down by robust weights, and the previous period
carried forward as the prior. No rendered frame is used; the images carry one unknown overall constant.
Lives above ``focus`` because it estimates depth from focus."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError
from ..events.stream import EventStream
from ..lightfield.galvo_solve import DYNAMIC_LAGS, geometry_and_angles, start_image
from ..optics.galvo import VIEWS_PER_PERIOD


# A period whose robust weights turn down more than this share of the equations is flagged (``reliable``):
# its events do not fit a static scene at the depths mapped (moving content, depths beyond the range searched,
# noise). From evaluation.failure's depth-range sweep (a textured card in front of a wall, 96 x 72, 24 views):
# 0.019-0.026 with the card in the range searched (log error 0.015-0.017), 0.093-0.105 with it nearer (log
# error 0.021-0.040, the card's depth read 3.4-7x too far). The same scene with the card moving sideways 4, 8,
# 16, 32 px per period: 0.038, 0.065, 0.092, 0.102 (flagged from between 4 and 8 px). Path-traced
# galvo_static and fan at 4 spp: 0.17-0.20 (log error 0.4: Monte-Carlo noise fires most of their events).
MAX_OUTLIERS = 0.05


@dataclass
class PeriodReconstruction:
    """What the events-only solver found for one scan period."""
    period_index: int
    t_start: float
    log_start: np.ndarray        # (H, W) log image at t_start, up to the capture's one constant
    depth: np.ndarray            # (H, W) depth it mapped each pixel with (from focus)
    confidence: np.ndarray       # (H, W) depth-from-focus confidence in [0, 1]
    outliers: float              # fraction of equations the robust weights turned down (moving content)
    meta: dict = field(default_factory=dict)
    reliable: bool = field(init=False)   # outliers <= MAX_OUTLIERS (see there); False: do not trust this period

    def __post_init__(self):
        self.reliable = bool(self.outliers <= MAX_OUTLIERS)


def _depth_from_views(events, t_start, log_start, views, depth_range, planes, c_on=None, c_off=None):
    """Depth per pixel from focus on the light field integrated onto ``log_start`` at the thresholds ``c_on`` /
    ``c_off`` (default: the stream's); flat pixels -> median."""
    import cv2

    from .depth import depth_from_focus
    from ..lightfield.model import from_galvo, galvo_view_times
    from ..lightfield.reconstruct import direct
    from ..plugins.pixel_model import stream_linlog_threshold
    times = galvo_view_times(events.meta["optics"], t_start, views)
    lf = from_galvo(direct(events, times, log_start, t_start, c_on, c_off), times, events.meta["optics"],
                    linear_below=stream_linlog_threshold(events.meta))
    dm = depth_from_focus(lf, depth_range[0], depth_range[1], planes, measure="variance")
    inv = 1.0 / dm.depth
    # the views are mapped at each pixel's depth: a depth beyond the optics' resolution still aligns them (to
    # within RESOLVABLE_PX), the image's median would not (galvo_static at 120 x 90: log error 0.26 against 0.20)
    sure = dm.focus_confidence > 0.5
    fill = float(np.median(inv[sure])) if sure.any() else float(np.median(inv))
    inv = np.where(sure, inv, fill).astype(np.float32)
    inv = cv2.medianBlur(inv, 5).astype(np.float64)          # one wrong plane in a window does not survive
    return 1.0 / np.maximum(inv, 1e-9), dm.confidence


def default_depth_range(optics: dict, nearest: float | None = None) -> tuple:
    """Depths searched when none are given: from twice the Y mirror's pivot distance (an assumed near limit:
    give ``depth_range`` for nearer scenes) to 1000 (practically infinity; the search is uniform in inverse
    depth, where a galvo's view shift is affine). ``nearest``: a nearer depth a caller needs (the CLI's
    ``--near``), searched too, down to the pivot itself (before it the mirrors show nothing)."""
    from ..optics.galvo import GalvoGeometry
    geometry = GalvoGeometry.from_optics(optics, 1, 1)     # the pivots (calibrated ones too); no film needed
    pivot = max(geometry.pivot_x, geometry.pivot_y)
    near = 2.0 * pivot
    if nearest is not None and math.isfinite(nearest):
        near = min(near, max(float(nearest), pivot))
    return near, 1000.0


def reconstruct_periods(events: EventStream, views: int = VIEWS_PER_PERIOD, periods=None, depth_range=None, samples: int = 16,
                        depth_planes: int = 16, depth_iterations: int = 1, robust_iterations: int = 4,
                        prior_weight: float = 0.05, c_on=None, c_off=None):
    """Per whole scan period (all, or the indices ``periods``, in order): (LightField of ``views`` views,
    PeriodReconstruction), from the events alone (module docstring). ``depth_range``: (near, far) searched for
    each pixel's depth (default ``default_depth_range``)."""
    from ..lightfield.model import from_galvo, galvo_period_starts, galvo_view_times
    from ..lightfield.reconstruct import direct
    from ..plugins.pixel_model import stream_linlog_threshold
    optics = events.meta.get("optics", {})
    geometry_and_angles(events, [])
    depth_range = default_depth_range(optics) if depth_range is None else tuple(map(float, depth_range))
    if not 0 < depth_range[0] < depth_range[1]:
        raise ConfigError(f"depth_range = {depth_range}: need 0 < near < far (scene units)")
    kw = dict(samples=samples, robust_iterations=robust_iterations, lags=DYNAMIC_LAGS, c_on=c_on, c_off=c_off)
    prev = None
    for p, t_s in galvo_period_starts(events, periods).items():
        if prev is None:        # first period: one plane, then alternate depth from focus and the solve
            log_s, weights = start_image(events, t_s, depth=math.sqrt(depth_range[0] * depth_range[1]), **kw)
            for _ in range(depth_iterations):
                depth, conf = _depth_from_views(events, t_s, log_s, views, depth_range, depth_planes, c_on, c_off)
                log_s, weights = start_image(events, t_s, depth=depth, **kw)
        else:                   # later periods: the previous one carried forward is the prior and the depth
            prior = direct(events, [t_s], prev.log_start, prev.t_start, c_on, c_off)[0]
            log_s, weights = start_image(events, t_s, depth=prev.depth, prior=prior, prior_weight=prior_weight,
                                         **kw)
        depth, conf = _depth_from_views(events, t_s, log_s, views, depth_range, depth_planes, c_on, c_off)
        prev = PeriodReconstruction(p, t_s, log_s, depth, conf, float(np.mean(weights < 1)))
        times = galvo_view_times(optics, t_s, views)
        lf = from_galvo(direct(events, times, log_s, t_s, c_on, c_off), times, optics,
                        {"period_index": p, "inputs": "events only"}, linear_below=stream_linlog_threshold(events.meta))
        yield lf, prev


class SolverWarning(UserWarning):
    """A scan period whose events do not fit a static scene at the depths the solver mapped (``reliable``)."""


def solved_lightfields(events: EventStream, views: int, periods: list, solver_kw: dict):
    """``lightfield.galvo_lightfields``' ``periods`` method: the light field of each of ``periods`` (checked
    indices) from :func:`reconstruct_periods` with ``solver_kw`` (its depth range checked here, at the call),
    each with a ``SolverWarning`` where the solver's robust weights turned down more than ``MAX_OUTLIERS`` of
    its equations."""
    near_far = solver_kw.get("depth_range")
    if near_far is not None:
        try:
            near, far = (float(v) for v in near_far)
        except (TypeError, ValueError):
            near = far = math.nan
        if not 0 < near < far:
            raise ConfigError(f"galvo_lightfields: depth_range = {near_far!r}: need (near, far) with 0 < near < far "
                              "(scene units)")
    return _solved(events, views, periods, solver_kw)


def _solved(events, views, periods, solver_kw):
    import warnings
    for lf, solved in reconstruct_periods(events, views, periods=periods, **solver_kw):
        if not solved.reliable:
            warnings.warn(f"scan period {solved.period_index}: the solver turned down {solved.outliers:.0%} of its "
                          "equations as not fitting a static scene at the depths found (moving content, depths "
                          "beyond the range searched, noise)", SolverWarning, stacklevel=2)
        yield lf


def _register():
    from ..lightfield.streams import PERIODS, register_galvo_solver
    register_galvo_solver(PERIODS, solved_lightfields, reconstruct_periods)


_register()
