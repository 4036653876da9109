"""The capture stage the galvo applications share: a scene's events over whole scan periods and, per period, the
light field built from them (and, for scoring, the same views rendered directly)."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

from ..errors import ConfigError
from ..scene import load_scene
from ..simulate.render import render_events, render_frames
from ..validate import number

START_METHODS = ("events", "frame")
INPUTS = {"events": "events only", "frame": "events + a rendered frame at t = 0"}


def _check_positive(name, value, integer=False, low=0.0):
    return number(value, name, low, integer=integer, lo_open=True, strict=True)


@dataclass
class Capture:
    timed: object
    events: object
    lightfields: list           # one per period, from events
    periods_solved: list        # start="events": what the solver found per period (depth, outliers); else []
    truth_lightfields: list     # same views rendered directly (for scoring; empty when not asked)
    period_s: float
    seconds: dict


def lightfields(events, timed, views: int, start: str = "events", spp: int = 4, depth_range=None,
                calibration=None) -> tuple:
    """(one LightField per whole scan period of ``events``, what the solver found per period or []), each
    light field's ``meta["inputs"]`` naming its inputs; ``start`` as for ``capture``. ``calibration``: a galvo /
    depth calibration of the events' optics, which the solver then solves with (``calibrated_events``)."""
    from ..focus.galvo_periods import reconstruct_periods
    from ..lightfield.streams import galvo_lightfields
    if calibration is not None:
        from ..calibration import calibrated_events, optics_record
        record = optics_record(events.meta.get("optics", {}), events.width, events.height)
        events = calibrated_events(events, calibration, record)
    solved = []
    if start == "frame":
        log_start = render_frames(timed, [0.0], spp=spp)[0]
        lfs = list(galvo_lightfields(events, views, "direct", log_start=log_start, t_start=0.0))
    else:
        pairs = list(reconstruct_periods(events, views, depth_range=depth_range))
        lfs, solved = [lf for lf, _ in pairs], [s for _, s in pairs]
    for lf in lfs:
        lf.meta["inputs"] = INPUTS[start]
    return lfs, solved


def reuse_for(start: str) -> bool:
    """``render_events(reuse=...)`` for a capture with this ``start``: with ``frame`` the frame at t = 0
    (``render_frames``, Mitsuba's own render) must share the event render's samples, so every pixel is rendered
    that way (the static-pixel split draws other samples: simulate/static_pixels.py). Every event render that
    must match the capture's (``scan_frequency``'s readout-capped one) uses this too."""
    return start != "frame"


def _steps_per_period(timed, periods: int, per_period: int, px_per_step: float) -> int:
    """Steps a scan period: ``per_period`` (the scan's own need), more where the moving objects' image motion
    adds to the scan's beyond ``px_per_step`` a step (as the render's coarse-step check adds them: the runner
    at 80x60 went 1.05 px a step, and the render told the application's user to pass a --steps it takes no
    such option for)."""
    from ..simulate.image_motion import object_px_per_step, scan_px_per_step
    duration = periods * timed.scan_period
    for _ in range(3):               # the motion a step shrinks as the steps grow: one or two rounds
        steps = periods * per_period
        worst = (scan_px_per_step(timed, duration, steps) or 0.0) + \
            (object_px_per_step(timed, 0.0, duration, steps) or 0.0)
        if worst <= px_per_step * (1 + 1e-9):
            break
        per_period = int(math.ceil(per_period * worst / px_per_step))
    return per_period


def capture(scene_path: str, defines: dict | None = None, periods: int | None = None, views: int = 40,
            start: str = "events", px_per_step: float = 1.0, spp: int = 4, progress: bool = False,
            truth_views: bool = True, depth_range=None, truth_spp: int = 64, calibration=None,
            before_render=None) -> Capture:
    """Events of ``periods`` whole scan periods (default: all of the motion file's duration) and, per period,
    the light field from the events; with ``truth_views`` also the ground-truth light field of the same views
    (for scoring only).

    ``start``: where each period's log image comes from: ``events`` (default:
    ``focus.galvo_periods.reconstruct_periods``, period by period from the events alone, per-pixel depth from focus in ``depth_range``, moving objects
    down-weighted; up to one unknown constant, as for any event camera) or ``frame`` (one rendered frame at
    t = 0 that every view integrates onto: a conventional camera beside the event camera, extra information
    the paper's rig does not have; every report says which). Steps: enough that the scan moves the image at
    most ``px_per_step`` pixels per step anywhere in the field. Truth views are rendered at ``truth_spp``
    (converged: the reference is the scene, not one noisy render). ``calibration``: see ``lightfields``.
    ``before_render(timed, periods, period)``: an application's checks of its inputs against the loaded scene,
    run before any event is rendered."""
    from ..lightfield.model import from_galvo, galvo_steps_per_period
    if start not in START_METHODS:
        raise ConfigError(f"start = {start!r}: allowed {', '.join(START_METHODS)}")
    _check_positive("views", views, integer=True, low=1)
    _check_positive("px_per_step", px_per_step)
    timed = load_scene(scene_path, **(defines or {}))
    period = timed.scan_period
    if not period:
        raise ConfigError(f"{scene_path}: needs a galvo sensor with a periodic scan")
    if periods is None:
        duration = timed.motion.duration if timed.motion is not None else None
        if not duration:
            has = "no duration in its motion file" if timed.motion is not None else "no motion file (with a duration)"
            raise ConfigError(f"{scene_path}: {has}: give the scan periods to capture (--periods, periods=)")
        periods = max(1, int(math.floor(duration / period + 1e-9)))
    _check_positive("periods", periods, integer=True)
    if before_render is not None:
        before_render(timed, periods, period)
    optics = timed.sensor.optics_metadata()
    width, height = (int(v) for v in timed.sensor.film().size())
    steps = periods * _steps_per_period(timed, periods, max(2 * views, galvo_steps_per_period(
        optics, width, height, px_per_step)), px_per_step)
    t0 = time.perf_counter()
    events = render_events(timed, periods * period, steps=steps, spp=spp, progress=progress,
                           reuse=reuse_for(start))
    t1 = time.perf_counter()
    lfs, solved = lightfields(events, timed, views, start, spp, depth_range, calibration)
    t2 = time.perf_counter()
    truth = [from_galvo(render_frames(timed, lf.times, spp=truth_spp), lf.times, events.meta["optics"],
                        {"period_index": k}) for k, lf in enumerate(lfs)] if truth_views else []
    t3 = time.perf_counter()
    return Capture(timed, events, lfs, solved, truth, period,
                   {"render_events": t1 - t0, "views_from_events": t2 - t1, "ground_truth_views": t3 - t2})
