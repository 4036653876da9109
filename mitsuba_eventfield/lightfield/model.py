"""LightField: views x H x W (x C) of linear intensity, each view's position and time, and how a point at a
given depth moves between views, so that refocus, focal stacks and depth from focus work alike for both optical
designs.

How views align (``LightField.alignments``):

* kaleidoscope / microlens: position = sub-aperture centre on the main lens (metres). Thin-lens geometry shifts a
  point at depth z by ``alpha(z) * position`` pixels in every view, the same across the field:
  alpha = (w / W) D (1/z - 1/S) (image plane W wide mapped to w pixels, lens to image plane D, focus distance S);
* galvo: position = optical deflection (2 x mechanical angle, radians). A plane at depth z maps from the
  reference view (both mirrors at rest) to each view by the exact homography of the two-mirror geometry
  (``optics.galvo.GalvoGeometry``): off axis a constant shift per view would be wrong by the factor (1 + t^2).
  The on-axis (paraxial) slope alpha(z) = f (1 - pivot / z) is kept for ``alpha`` refocus and step estimates.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError
from ..events.stream import EventStream
from ..optics.galvo import OPTICAL_PER_MECHANICAL, VIEWS_PER_PERIOD, GalvoGeometry, scan_image_path_px
from ..optics.scan import curve_from_dict, scan_period
from ..validate import MAX_VIEWS, array, finite, instance, number

MAX_SHIFT_VIEWS = 1.0      # the largest refocusing shift of a view, in view sizes (beyond: no overlap at all)
MAX_DEPTH = 1e9            # scene units: farther is infinity (give math.inf), and overflowed the galvo's maps
RECORDING_SLACK = 0.01     # of a scan period: how far a recording's event span may fall short of whole periods
from . import reconstruct
from .views import extract_views


@dataclass(frozen=True)
class Disparity:
    """Shift of a point at depth z per unit of view position, alpha(z) = at_infinity + per_inverse_depth / z,
    per axis (x, y): exact for spatial multiplexing, the on-axis approximation for a galvo."""
    at_infinity: tuple
    per_inverse_depth: tuple

    def alpha(self, depth):
        """(alpha_x, alpha_y) at depth(s) z: pixels of displacement per unit of view position."""
        inv = 0.0 if np.isinf(depth) else 1.0 / np.asarray(depth, dtype=np.float64)
        return (self.at_infinity[0] + self.per_inverse_depth[0] * inv,
                self.at_infinity[1] + self.per_inverse_depth[1] * inv)

    def depth_for_alpha(self, alpha_x):
        """Inverse of the x model: the depth at which views align with slope ``alpha_x``."""
        d = alpha_x - self.at_infinity[0]
        return math.inf if d == 0 else self.per_inverse_depth[0] / d

    @classmethod
    def for_spatial(cls, optics: dict, view_w: int, view_h: int) -> "Disparity":
        """Kaleidoscope / microlens views (thin lens, see the module docstring)."""
        D, S = optics["lens_to_image_plane"], optics["focus_distance"]
        W, H = optics["image_plane_size"]
        kx, ky = view_w / W * D, view_h / H * D
        return cls((-kx / S, -ky / S), (kx, ky))


@dataclass
class LightField:
    views: np.ndarray              # (K, H, W) or (K, H, W, C), linear intensity
    positions: np.ndarray          # (K, 2)
    times: np.ndarray              # (K,) seconds
    disparity: Disparity           # shift per unit of position (galvo: the on-axis approximation)
    kind: str = "generic"
    meta: dict = field(default_factory=dict)
    galvo: GalvoGeometry | None = None   # galvo light fields: the exact view-to-view mapping
    # spatial multiplexing: (K, 2) pixels by which a point on the focus plane (alpha = 0) sits off the centre
    # view's pixel in each view, from the optics' misalignment (a kaleidoscope calibration's registration,
    # ``calibration.apply_to_lightfield``); None: a perfect instrument. Part of every shift (``shifts``)
    view_offsets: np.ndarray | None = None
    cache: dict = field(default_factory=dict, repr=False, compare=False)   # derived data (refocus spectra)

    def __post_init__(self):
        self.views = array(self.views, "LightField: views", (3, 4))
        self.positions = array(self.positions, "LightField: positions", (1, 2), min_len=0)
        if self.positions.size % 2:
            raise ConfigError(f"LightField: positions of shape {self.positions.shape}: expected (K, 2)")
        self.positions = self.positions.reshape(-1, 2)
        self.times = array(self.times, "LightField: times", (0, 1), min_len=0).reshape(-1)
        if not (len(self.views) == len(self.positions) == len(self.times)):
            raise ConfigError(f"LightField: views, positions and times must have one length (got {len(self.views)}, "
                              f"{len(self.positions)}, {len(self.times)})")
        instance(self.disparity, Disparity, "LightField: disparity")
        if self.view_offsets is not None:
            if self.galvo is not None:
                raise ConfigError("LightField: view_offsets are for spatial multiplexing (one shift per view); a "
                                  "galvo light field maps its views by its geometry")
            self.view_offsets = array(self.view_offsets, "LightField: view_offsets", 2)
            if self.view_offsets.shape != self.positions.shape:
                raise ConfigError(f"LightField: view_offsets of shape {self.view_offsets.shape}: expected "
                                  f"{self.positions.shape}, one (dx, dy) per view")
        if self.galvo is not None and (self.galvo.width, self.galvo.height) != tuple(self.shape[::-1]):
            raise ConfigError(f"galvo geometry is for {self.galvo.width}x{self.galvo.height} pixels, the views are "
                              f"{self.shape[1]}x{self.shape[0]}")

    @property
    def shape(self):
        return self.views.shape[1:3]

    @property
    def shift_invariant(self) -> bool:
        """True when a depth moves every pixel of a view by one shift (no galvo geometry)."""
        return self.galvo is None

    def alpha(self, depth):
        return self.disparity.alpha(depth)

    def depth_for_alpha(self, alpha_x):
        return self.disparity.depth_for_alpha(alpha_x)

    def shifts(self, depth=None, alpha=None) -> np.ndarray:
        """(K, 2) pixel displacement in each view of a point at ``depth``, or for a disparity slope ``alpha``
        (pixels per unit of view position; a number, or (alpha_x, alpha_y)), the instrument's ``view_offsets``
        included. For a galvo light field this is the on-axis displacement; ``alignments`` gives the exact one
        everywhere."""
        if alpha is None:
            ax, ay = self.alpha(depth)
        else:
            ax, ay = (alpha, alpha) if np.isscalar(alpha) else alpha
        out = np.stack([ax * self.positions[:, 0], ay * self.positions[:, 1]], axis=-1)
        return out if self.view_offsets is None else out + self.view_offsets

    def alignments(self, depth: float) -> np.ndarray:
        """(K, 3, 3) maps from reference-view array indices to each view's, for points at ``depth``: pure
        translations for spatial multiplexing, the exact homographies for a galvo."""
        if self.galvo is None:
            out = np.tile(np.eye(3), (len(self.views), 1, 1))
            out[:, :2, 2] = self.shifts(depth)
            return out
        mech = self.positions / OPTICAL_PER_MECHANICAL          # the views' optical angles back to the mirrors'
        return np.stack([self.galvo.array_homography(px, py, depth) for px, py in mech])

    def depth_range(self) -> tuple:
        """(nearest, farthest) depths this light field can be refocused at (scene units; inf: no far limit):
        every view shifted by at most ``MAX_SHIFT_VIEWS`` times the view's size (beyond, no two views overlap:
        a kaleidoscope refocused at 1e-5 asked for 1 TiB of padding), and a galvo's depths from its farther
        mirror pivot on (points before the mirrors are not seen through them; at 1e308 its homography
        overflowed into a constant image). From the disparity model alpha = A + K / z on each axis."""
        limit = MAX_SHIFT_VIEWS * max(self.shape)
        if self.view_offsets is not None and self.view_offsets.size:
            limit = max(limit - float(np.abs(self.view_offsets).max()), 1.0)
        near, far = 0.0, math.inf
        for axis in (0, 1):
            reach = float(np.abs(self.positions[:, axis]).max()) if len(self.positions) else 0.0
            a, k = self.disparity.at_infinity[axis], self.disparity.per_inverse_depth[axis]
            if reach == 0.0 or k == 0.0:
                continue
            bound = limit / reach                    # |A + K / z| <= bound, for 1 / z in (0, inf)
            lo_inv, hi_inv = sorted(((-bound - a) / k, (bound - a) / k))
            if hi_inv <= 0:
                return math.inf, math.inf            # no depth keeps the shifts within the views
            near = max(near, 1.0 / hi_inv)
            if lo_inv > 0:
                far = min(far, 1.0 / lo_inv)
        if self.galvo is not None:
            near = max(near, self.galvo.pivot_x, self.galvo.pivot_y)
        return near, far

    def check_depth(self, depth, name: str = "depth") -> float:
        """``depth`` as a float if the light field can be refocused there (:meth:`depth_range`; finite depths at
        most ``MAX_DEPTH``, infinity as ``math.inf``), else a ConfigError naming ``name`` and the range."""
        at_infinity = isinstance(depth, numbers.Real) and depth == math.inf
        z = math.inf if at_infinity else number(depth, name, 0, lo_open=True, strict=True, inf_ok=True)
        near, far = self.depth_range()
        # the ends belong to the range (at a galvo's pivot the views align exactly: a depth search may start there)
        if not (near * (1 - 1e-9) <= z <= far) or (z != math.inf and z > MAX_DEPTH):
            top = f"{far:.6g}" if far < MAX_DEPTH else f"{MAX_DEPTH:g} or inf"
            what = "from its farther mirror pivot on, " if self.galvo is not None else ""
            raise ConfigError(f"{name} = {depth!r}: this {self.kind} light field refocuses at depths {what}in "
                              f"[{near:.6g}, {top}] scene units")
        return z

    def subset(self, index) -> "LightField":
        offsets = None if self.view_offsets is None else self.view_offsets[index]
        return LightField(self.views[index], self.positions[index], self.times[index], self.disparity, self.kind,
                          dict(self.meta), self.galvo, offsets)


def _floats(values, name: str) -> np.ndarray:
    try:
        return np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{name}: expected a numeric array, got {type(values).__name__}") from None


def _exp(log_frames, name: str = "from_galvo: log_frames", linear_below: float | None = None):
    """Linear frames of log ones: ``exp``, or the pixel's lin-log inverse where the levels are lin-log
    (``linear_below``: its knee; a reconstruction from events on a start frame through ``linlog_np``)."""
    from ..plugins.pixel_model import linlog_inverse_np
    frames = _floats(log_frames, name)
    # (a level below the pixel's response to no light, e.g. after a noise OFF event, is no radiance: 0)
    return np.exp(frames) if linear_below is None else np.maximum(linlog_inverse_np(frames, linear_below), 0.0)


def galvo_geometry(optics: dict, width: int, height: int) -> GalvoGeometry:
    """The exact two-mirror geometry of a galvo stream's metadata, for a film of width x height pixels."""
    return GalvoGeometry.from_optics(optics, width, height)


def galvo_paraxial_disparity(geometry: GalvoGeometry) -> Disparity:
    """The on-axis approximation of ``geometry``, per unit of optical angle (the views' positions)."""
    return Disparity(*geometry.paraxial_disparity())


def from_galvo(log_frames, times, optics: dict, meta: dict | None = None,
               linear_below: float | None = None) -> LightField:
    """A light field from galvo frames (log intensity, e.g. reconstructed) at known times: each frame is the view
    at the scan position (optical angles) of its time. ``linear_below``: the frames are the lin-log levels of a
    pixel with this knee (``pixel_model.stream_linlog_threshold`` of the events they were reconstructed from),
    else plain log."""
    frames, times = _exp(log_frames, linear_below=linear_below), array(times, "from_galvo: times", 1)
    if frames.ndim not in (3, 4) or len(times) != len(frames):
        raise ConfigError(f"from_galvo: log_frames of shape {frames.shape} and {len(times)} times: expected "
                          "(K, H, W) or (K, H, W, C) frames, one time per frame")
    curve = curve_from_dict(_galvo_scan(optics, "from_galvo"), where="event metadata")
    geometry = galvo_geometry(optics, frames.shape[2], frames.shape[1])
    meta = dict(meta or {})
    if optics.get("calibrated"):          # optics a calibration placed (calibration.calibrated_optics)
        meta.setdefault("calibrated", sorted(optics["calibrated"]))
    return LightField(frames, np.stack(curve.optical_angles(times), axis=-1), times,
                      galvo_paraxial_disparity(geometry), "galvo", meta, geometry)


def galvo_steps_per_period(optics: dict, width: int, height: int | None = None, px_per_step: float = 1.0) -> int:
    """Render steps per scan period so the scan moves the image by at most ``px_per_step`` pixels per step
    (``optics.galvo.scan_image_path_px`` over ``px_per_step``)."""
    height = width if height is None else height
    return max(1, int(math.ceil(scan_image_path_px(optics, width, height) / px_per_step)))


def galvo_view_times(optics: dict, t_period_start: float, views: int) -> np.ndarray:
    """``views`` instants evenly spread over the scan period that starts at ``t_period_start``."""
    scan = _galvo_scan(optics, "galvo_view_times")
    t_period_start = finite(t_period_start, "galvo_view_times: t_period_start")
    views = int(number(views, "galvo_view_times: views", 1, MAX_VIEWS, integer=True, strict=True))
    return t_period_start + (np.arange(views) + 0.5) * scan_period(scan) / views


def _galvo_scan(optics, where: str) -> dict:
    """The scan record of galvo optics metadata (``events.meta["optics"]``); ConfigError for anything else."""
    instance(optics, dict, f"{where}: optics", "an event stream's meta['optics']")
    if optics.get("design") != "galvo" or not isinstance(optics.get("scan"), dict):
        raise ConfigError(f"{where}: the optics metadata describes no galvo scan (optics.design is "
                          f"{optics.get('design')!r}; expected 'galvo' with a scan record)")
    return optics["scan"]


def galvo_period_starts(events, periods=None) -> dict:
    """{period index: start time in seconds} for the whole scan periods of a galvo stream (all, or the indices
    ``periods``, each checked against the stream)."""
    period = scan_period(_galvo_scan(events.meta.get("optics", {}), "scan periods"))
    t0 = events.start_s
    # whole periods only; the stream's duration is rounded to the microsecond, so two periods of 150 Hz
    # (13,333.3 us) are 13,333 us long and must still count as two
    # A camera recording has no recorded duration: its span runs from its first event to its last, short of
    # the capture by the quiet ends, so a one-period capture counted no whole period. There a period may fall
    # short by RECORDING_SLACK of itself
    slack = 0.0 if "duration_us" in events.meta else RECORDING_SLACK
    n_periods = int(math.floor((events.duration_us + 0.5) * 1e-6 / period + slack + 1e-9))
    if periods is not None and (isinstance(periods, (str, bytes)) or not np.iterable(periods)):
        raise ConfigError(f"periods = {periods!r}: expected a list of scan period indices")
    if n_periods == 0:
        raise ConfigError(f"the stream spans {events.duration_us / 1e3:g} ms, less than one whole scan period of "
                          f"{period * 1e3:g} ms")
    wanted = range(n_periods) if periods is None else periods
    for p in wanted:
        if isinstance(p, bool) or not isinstance(p, numbers.Integral) or not 0 <= p < n_periods:
            raise ConfigError(f"scan period {p} is not in the stream: allowed 0..{n_periods - 1} "
                              f"({n_periods} whole periods of {period * 1e3:g} ms)")
    return {p: t0 + p * period for p in wanted}


PERIODS = "periods"     # the per-period galvo solver, each pixel at its own depth (focus.galvo_periods)
MIN_VIEWS = 2           # one view has no parallax: refocus and depth from it are the image itself
# galvo light fields solved above this layer (they need depth from focus), by method name: maker(events, views,
# period indices, keywords) -> iterator of LightField. focus.galvo_periods registers PERIODS; the package's
# import makes sure it has.
_SOLVERS: dict = {}


def register_galvo_solver(name: str, maker) -> None:
    """Make ``maker`` the galvo light fields of method ``name`` (``galvo_lightfields``, ``from_events``)."""
    _SOLVERS[name] = maker


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
    optics = events.meta.get("optics", {})
    _galvo_scan(optics, "galvo_lightfields")
    views = int(number(views, "galvo_lightfields: views", MIN_VIEWS, MAX_VIEWS, integer=True, strict=True))
    if method is None:
        method = default_method("galvo", method_kw.get("log_start") is not None)
    if method not in methods("galvo"):
        raise ConfigError(f"galvo_lightfields: method = {method!r}; allowed: {', '.join(methods('galvo'))}")
    if method == PERIODS and method_kw.get("log_start") is not None:
        raise ConfigError("galvo_lightfields: method 'periods' reconstructs from the events alone: a start frame "
                          "(log_start) is used by the direct and complementary methods")
    starts = galvo_period_starts(events, periods)
    if not starts:
        raise ConfigError(f"galvo_lightfields: no scan period to reconstruct (the stream lasts "
                          f"{events.duration_us * 1e-3:g} ms, periods = {periods!r})")
    if method in _SOLVERS:
        return _SOLVERS[method](events, views, list(starts), method_kw)
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


LEVELS = ("frame", "events")


def from_spatial(log_or_linear_frame, optics: dict, time: float = 0.0, log: bool = True,
                 levels: str = "frame") -> LightField:
    """A light field from one kaleidoscope/microlens film image (log or linear): its n x n extracted views.
    ``levels``: where the image's brightness levels come from, a ``frame`` taken through the optics (it holds
    their vignetting, which a flat field divides out) or ``events`` alone (log changes: no gain survives)."""
    frame = _floats(log_or_linear_frame, "from_spatial: frame")
    time = finite(time, "from_spatial: time")
    if levels not in LEVELS:
        raise ConfigError(f"from_spatial: levels = {levels!r}; allowed: {', '.join(LEVELS)}")
    stack = extract_views(np.exp(frame) if log else frame, optics)
    h, w = stack.images.shape[1:3]
    return LightField(stack.images, stack.positions, np.full(len(stack.images), time),
                      Disparity.for_spatial(optics, w, h), optics["design"],
                      {"ij": stack.ij.tolist(), "levels": levels})




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
    t0 = events.start_s
    method = default_method(design, log_start is not None) if method is None else method
    if method not in methods(design):
        raise ConfigError(f"from_events: method = {method!r}; allowed for a {design} stream: "
                          f"{', '.join(methods(design))}")
    kw = dict(method_kw)
    if method == "direct":
        kw.update(log_start=log_start, t_start=t0)
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
        return next(galvo_lightfields(events, views, method, periods=[period], **kw))
    if design in ("kaleidoscope", "microlens"):
        t1 = events.end_s
        t = t1 if time is None else finite(time, "from_events: time")
        if not t0 <= t <= t1 + 1e-9:     # past the end a reconstruction runs on no data (a high-pass decays)
            raise ConfigError(f"from_events: time = {t:g} s: the stream covers {t0:g} to {t1:g} s")
        frame = reconstruct.reconstruct(events, [t], method, **kw)[0]
        from_frame = (method == "direct" and kw.get("log_start") is not None) or method == "complementary"
        return from_spatial(frame, optics, time=t, log=True, levels="frame" if from_frame else "events")
