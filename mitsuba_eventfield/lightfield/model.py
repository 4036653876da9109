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
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError
from ..optics.galvo import OPTICAL_PER_MECHANICAL, GalvoGeometry, scan_image_path_px
from ..optics.scan import curve_from_dict, scan_period
from ..validate import MAX_VIEWS, array, finite, instance, number

MAX_SHIFT_VIEWS = 1.0      # the largest refocusing shift of a view, in view sizes (beyond: no overlap at all)
MAX_DEPTH = 1e9            # scene units: farther is infinity (give math.inf), and overflowed the galvo's maps
RECORDING_SLACK = 0.01     # of a scan period: how far a recording's event span may fall short of whole periods
# The log levels a light field (or a reconstructed frame) holds: e^+-40 (1e+-17) is far beyond any sensor's
# range (120-140 dB: e^14-16) and keeps a view's square (the variance focus measure) and sums of thousands of
# views inside float32 (e^88.7). Levels beyond are a wrong contrast threshold or runaway drift, not light.
MAX_LOG_LEVEL = 40.0
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


def radiance_of_levels(log_frames, name: str = "from_galvo: log_frames", linear_below: float | None = None,
                       warn: bool = True):
    """Linear frames of log ones: ``exp``, or the pixel's lin-log inverse where the levels are lin-log
    (``linear_below``: its knee; a reconstruction from events on a start frame through ``linlog_np``), the
    levels clipped first (``clip_log_levels``; ``warn=False``: the caller has said it, ``warn_levels_beyond``,
    and converts a stack a frame at a time). The one home of levels -> radiance: the light fields and
    ``reconstruct``'s frames."""
    from ..plugins.pixel_model import linlog_inverse_np
    frames = clip_log_levels(_floats(log_frames, name), name, warn)
    # (a level below the pixel's response to no light, e.g. after a noise OFF event, is no radiance: 0)
    return np.exp(frames) if linear_below is None else np.maximum(linlog_inverse_np(frames, linear_below), 0.0)


def warn_levels_beyond(log_frames, name: str, stacklevel: int = 3) -> None:
    """A warning naming how many finite levels of ``log_frames``, or infinitely bright ones, lie beyond
    +-``MAX_LOG_LEVEL`` (exponentiated, they overflowed float32 and every focus measure after them); counted a
    frame at a time, so that a long stack is not copied whole."""
    a = np.asarray(log_frames)
    beyond = sum(int(np.count_nonzero((np.isfinite(f) & (np.abs(f) > MAX_LOG_LEVEL)) | (f == np.inf)))
                 for f in (a.reshape(-1, *a.shape[-2:]) if a.ndim >= 2 else [a]))
    if beyond:
        warnings.warn(f"{name}: {beyond} of {a.size} levels beyond a log level of +-{MAX_LOG_LEVEL:g} "
                      f"(a brightness ratio of {math.exp(MAX_LOG_LEVEL):.0e} either way, beyond any sensor: a "
                      "stuck pixel, or a contrast threshold larger than the events' own?): clipped there",
                      stacklevel=stacklevel)


def clip_log_levels(log_frames: np.ndarray, name: str, warn: bool = True) -> np.ndarray:
    """``log_frames`` clipped to +-``MAX_LOG_LEVEL`` (NaN stays NaN), said first (``warn_levels_beyond``).
    Clipped, not refused: one stuck pixel's runaway level should not cost the whole image; a wrong threshold
    shows in every pixel. A level of -inf (no light, in plain log) is 0 either way."""
    if warn:
        warn_levels_beyond(log_frames, name, stacklevel=4)
    return np.clip(log_frames, -MAX_LOG_LEVEL, MAX_LOG_LEVEL)


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
    frames, times = radiance_of_levels(log_frames, linear_below=linear_below), array(times, "from_galvo: times", 1)
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


LEVELS = ("frame", "events")


def from_spatial(log_or_linear_frame, optics: dict, time: float = 0.0, log: bool = True,
                 levels: str = "frame", linear_below: float | None = None) -> LightField:
    """A light field from one kaleidoscope/microlens film image (log or linear): its n x n extracted views.
    ``levels``: where the image's brightness levels come from, a ``frame`` taken through the optics (it holds
    their vignetting, which a flat field divides out) or ``events`` alone (log changes: no gain survives).
    ``linear_below``: a log image holds the lin-log levels of a pixel with this knee (as ``from_galvo``)."""
    frame = _floats(log_or_linear_frame, "from_spatial: frame")
    time = finite(time, "from_spatial: time")
    if levels not in LEVELS:
        raise ConfigError(f"from_spatial: levels = {levels!r}; allowed: {', '.join(LEVELS)}")
    stack = extract_views(radiance_of_levels(frame, "from_spatial: frame", linear_below) if log else frame, optics)
    h, w = stack.images.shape[1:3]
    return LightField(stack.images, stack.positions, np.full(len(stack.images), time),
                      Disparity.for_spatial(optics, w, h), optics["design"],
                      {"ij": stack.ij.tolist(), "levels": levels})
