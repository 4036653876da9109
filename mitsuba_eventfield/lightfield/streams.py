"""Light fields from event streams: one scan period of a galvo stream or one instant of a kaleidoscope's
(:func:`from_events`), the sliding light fields of a galvo stream (:func:`galvo_lightfields`), and the one rule
for the reconstruction when none is named (:func:`default_method`), which the light-field commands share.
Methods solved above this layer (the per-period galvo solver needs depth from focus) register here
(:func:`register_galvo_solver`)."""
from __future__ import annotations

import numpy as np

from ..errors import ConfigError
from ..events.stream import EventStream
from ..optics.galvo import VIEWS_PER_PERIOD
from ..validate import MAX_VIEWS, finite, instance, keywords, number
from . import reconstruct
from .model import LightField, _galvo_scan, from_galvo, from_spatial, galvo_period_starts, galvo_view_times
from .scan_lock import warn_unlocked

PERIODS = "periods"     # the per-period galvo solver, each pixel at its own depth (focus.galvo_periods)
MIN_VIEWS = 2           # one view has no parallax: refocus and depth from it are the image itself
# galvo light fields solved above this layer (they need depth from focus), by method name: maker(events, views,
# period indices, keywords) -> iterator of LightField. focus.galvo_periods registers PERIODS; the package's
# import makes sure it has.
_SOLVERS: dict = {}


def _without_stuck_pixels(events, where: str, kw: dict):
    """``events`` with the ``c_on`` / ``c_off`` of ``kw`` (when given: a recording's, as the commands'
    --contrast) as its contrast thresholds in its metadata, so every reader of the stream takes them (the
    per-period solver's depth-from-focus pass read the metadata's and refused a recording they were given
    for), and without its stuck or hot pixels, with the warning that names them, as the commands read a file
    (``events.stuck_pixels``; one pixel stuck ON at 50 kHz took a script's refocused maximum to 918,620 where
    the command's was 3.18). Without thresholds, or already filtered, the stream is taken as it is."""
    from ..events.stuck_pixels import nonempty, without_stuck_pixels
    pm = events.meta.get("pixel_model") or {}
    on, off = (kw.get(k) if kw.get(k) is not None else pm.get(t)
               for k, t in (("c_on", "threshold_on"), ("c_off", "threshold_off")))
    if on is None or off is None:
        return events
    given = events if (on, off) == (pm.get("threshold_on"), pm.get("threshold_off")) else \
        EventStream(events.x, events.y, events.t, events.p, events.width, events.height,
                    dict(events.meta, pixel_model=dict(pm, threshold_on=on, threshold_off=off)))
    if "stuck_pixels_left_out" in events.meta:
        return given
    kept = without_stuck_pixels(given, where)
    return given if kept is given else nonempty(kept, where)


def register_galvo_solver(name: str, maker, takes) -> None:
    """Make ``maker`` the galvo light fields of method ``name`` (``galvo_lightfields``, ``from_events``); its
    keywords are those of the function ``takes`` (checked at the call)."""
    _SOLVERS[name] = (maker, takes)


def methods(design: str | None) -> tuple:
    """The reconstructions a light field of ``design`` can be made with: ``reconstruct``'s, and for a galvo
    the per-period solver too."""
    return (*reconstruct.methods(), PERIODS) if design == "galvo" else reconstruct.methods()


def default_method(design: str | None, start_frame: bool) -> str:
    """The reconstruction :func:`from_events`, :func:`galvo_lightfields` and the light-field commands use when
    none is named: ``direct`` from a start frame, else for a galvo stream the per-period solver (``periods``:
    each pixel at its own depth; the one-depth ``galvo`` solver read galvo_static's 0.5 m card 0.549 m, the
    per-period one 0.490 m, at 2-7x its time) and ``highpass`` for the others."""
    return "direct" if start_frame else (PERIODS if design == "galvo" else "highpass")


def galvo_lightfields(events, views: int = VIEWS_PER_PERIOD, method: str | None = None, periods=None,
                      **method_kw):
    """Sliding light fields from a galvo stream, one per scan period: reconstruct ``views`` frames per period
    (``method``: one of ``reconstruct``'s, or ``periods``; default :func:`default_method`) and place each at
    its scan position. ``periods`` takes ``focus.galvo_periods.reconstruct_periods``' keywords (``depth_range``,
    ...) and warns (``SolverWarning``) for a period whose events do not fit a static scene. Yields LightField
    objects; bad arguments are refused at the call, before the first one is asked for."""
    instance(events, EventStream, "galvo_lightfields: events", "ef.read_events, ef.render_events")
    _galvo_scan(events.meta.get("optics", {}), "galvo_lightfields")
    return _sliding(_without_stuck_pixels(events, "galvo_lightfields", method_kw), views, method, periods,
                    method_kw)


def _sliding(events, views, method, periods, method_kw):
    """:func:`galvo_lightfields` of a stream whose stuck pixels are out already (``from_events`` filters its
    own: the search ran twice)."""
    optics = events.meta.get("optics", {})
    views = int(number(views, "galvo_lightfields: views", MIN_VIEWS, MAX_VIEWS, integer=True, strict=True))
    if method is None:
        method = default_method("galvo", method_kw.get("log_start") is not None)
    if method not in methods("galvo"):
        raise ConfigError(f"galvo_lightfields: method = {method!r}; allowed: {', '.join(methods('galvo'))}")
    if method == PERIODS and method_kw.get("log_start") is not None:
        raise ConfigError("galvo_lightfields: method 'periods' reconstructs from the events alone: a start frame "
                          "(log_start) is used by the direct and complementary methods")
    if method in _SOLVERS:          # (the solver is given the events, views and periods; a method events, times)
        keywords(_SOLVERS[method][1], method_kw, f"galvo_lightfields: method {method!r}", bound=3)
    else:
        keywords(reconstruct.method_function(method), method_kw, f"galvo_lightfields: method {method!r}", bound=2)
    starts = galvo_period_starts(events, periods)
    warn_unlocked(events, "galvo_lightfields")
    if not starts:
        raise ConfigError(f"galvo_lightfields: no scan period to reconstruct (the stream lasts "
                          f"{events.duration_us * 1e-3:g} ms, periods = {periods!r})")
    if method in _SOLVERS:
        return _SOLVERS[method][0](events, views, list(starts), method_kw)
    return _galvo_lightfields(events, optics, starts, views, method, method_kw)


def _galvo_lightfields(events, optics, starts, views, method, method_kw):
    from ..plugins.pixel_model import stream_linlog_threshold
    wanted = list(starts)
    all_times = np.concatenate([galvo_view_times(optics, starts[p], views) for p in wanted])
    frames = reconstruct.reconstruct(events, all_times, method, **method_kw)
    for i, p in enumerate(wanted):
        sl = slice(i * views, (i + 1) * views)
        yield from_galvo(frames[sl], all_times[sl], optics, {"period_index": p},
                         linear_below=stream_linlog_threshold(events.meta))


def from_events(events, period: int | None = None, views: int | None = None, time: float | None = None,
                method: str | None = None, log_start=None, **method_kw) -> LightField:
    """One light field from an event stream, whatever its optics, as the light-field commands make it.

    * galvo: the scan period ``period`` (index from the stream start, default 0), ``views`` views (default
      ``VIEWS_PER_PERIOD``). Default method: ``direct`` from ``log_start`` when given, else ``periods``, the
      events-only solver with each pixel at its own depth (``default_method``; ``depth_range`` and the other
      keywords of ``focus.galvo_periods.reconstruct_periods`` pass through);
    * kaleidoscope / microlens: the film at ``time`` seconds (default: stream end), split into its views.
      Default method: ``direct`` from ``log_start`` when given, else ``highpass`` (moving content only).

    An argument of the other design is refused (it was ignored: ``time`` on a galvo stream, ``period`` or
    ``views`` on a kaleidoscope one).
    """
    instance(events, EventStream, "from_events: events", "ef.read_events, ef.render_events")
    optics = events.meta.get("optics", {})
    design = optics.get("design")
    if design not in ("galvo", "kaleidoscope", "microlens"):
        raise ConfigError("the stream's metadata describes no light-field optics (optics.design is "
                          f"{design!r}; expected galvo, kaleidoscope or microlens)")
    wrong = {"galvo": {"time": time}, "kaleidoscope": {"period": period, "views": views}}
    wrong["microlens"] = wrong["kaleidoscope"]
    given = [k for k, v in wrong.get(design, {}).items() if v is not None]
    if given:
        raise ConfigError(f"from_events: {' and '.join(given)} {'is' if len(given) == 1 else 'are'} for "
                          f"{'a kaleidoscope' if design == 'galvo' else 'a galvo'} stream; this one is {design}")
    events = _without_stuck_pixels(events, "from_events", method_kw)
    t0 = events.start_s
    method = default_method(design, log_start is not None) if method is None else method
    if method not in methods(design):
        raise ConfigError(f"from_events: method = {method!r}; allowed for a {design} stream: "
                          f"{', '.join(methods(design))}")
    kw = dict(method_kw)
    if method == "direct":
        # from the stream's start, its first microsecond's events included (reconstruct's default; t_start = t0
        # took them as already in the frame: a recording, which starts at its first event, lost them)
        kw.update(log_start=log_start)
    elif method == "complementary":          # anchored to the start frame (it needs one)
        if log_start is None:
            raise ConfigError("from_events: method 'complementary' needs log_start, a frame to anchor to")
        kw.update(frames=np.asarray(log_start)[None], frame_times=[t0])
    elif log_start is not None:              # taken and ignored, it was recorded as an input
        raise ConfigError(f"from_events: method {method!r} reconstructs from the events alone: a start frame "
                          "(log_start, --start-frame) is used by the direct and complementary methods")
    if design == "galvo":
        period = 0 if period is None else int(number(period, "from_events: period", 0, integer=True, strict=True))
        views = VIEWS_PER_PERIOD if views is None else views
        _galvo_scan(optics, "galvo_lightfields")
        return next(_sliding(events, views, method, [period], kw))
    if design in ("kaleidoscope", "microlens"):
        t1 = events.end_s
        t = t1 if time is None else finite(time, "from_events: time")
        if not t0 <= t <= t1 + 1e-9:     # past the end a reconstruction runs on no data (a high-pass decays)
            raise ConfigError(f"from_events: time = {t:g} s: the stream covers {t0:g} to {t1:g} s")
        from ..plugins.pixel_model import stream_linlog_threshold
        frame = reconstruct.reconstruct(events, [t], method, **kw)[0]
        from_frame = (method == "direct" and kw.get("log_start") is not None) or method == "complementary"
        return from_spatial(frame, optics, time=t, log=True, levels="frame" if from_frame else "events",
                            linear_below=stream_linlog_threshold(events.meta))
