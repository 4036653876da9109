"""LightField: views x H x W (x C) of linear intensity, each view's position and time, and how disparity
depends on depth, so that refocus, focal stacks and depth from focus work alike for both optical designs.

Disparity model: a point at depth z appears in view k displaced from the reference (position 0) by
``alpha(z) * position[k]`` pixels (x right, y down), with ``alpha_axis(z) = A_axis + B_axis / z``:

* kaleidoscope / microlens: position = sub-aperture centre on the main lens (metres); thin-lens geometry gives
  alpha = (w / W) D (1/z - 1/S): A = -(w/W) D / S, B = (w/W) D (image plane W wide mapped to w pixels, lens to
  image plane D, focus distance S);
* galvo: position = optical deflection (2 x mechanical angle, radians); alpha = f (1 - pivot / z) with the
  X mirror's pivot for x and the Y mirror's for y (plugins/galvo_optics.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class LightField:
    views: np.ndarray              # (K, H, W) or (K, H, W, C), linear intensity
    positions: np.ndarray          # (K, 2)
    times: np.ndarray              # (K,) seconds
    A: tuple                       # disparity model alpha(z) = A + B / z, per axis (x, y)
    B: tuple
    kind: str = "generic"
    meta: dict = field(default_factory=dict)
    cache: dict = field(default_factory=dict, repr=False, compare=False)   # derived data (refocus spectra)

    def __post_init__(self):
        self.views = np.asarray(self.views, dtype=np.float64)
        self.positions = np.asarray(self.positions, dtype=np.float64).reshape(-1, 2)
        self.times = np.asarray(self.times, dtype=np.float64).reshape(-1)
        if not (len(self.views) == len(self.positions) == len(self.times)):
            raise ValueError("views, positions and times must have one length")
        if not np.all(np.isfinite(self.views)):
            raise ValueError("light field views contain NaN or infinite values")

    @property
    def shape(self):
        return self.views.shape[1:3]

    def alpha(self, depth):
        """(alpha_x, alpha_y) at depth(s) z: pixels of displacement per unit of view position."""
        inv = 0.0 if np.isinf(depth) else 1.0 / np.asarray(depth, dtype=np.float64)
        return self.A[0] + self.B[0] * inv, self.A[1] + self.B[1] * inv

    def depth_for_alpha(self, alpha_x):
        """Inverse of the x disparity model: the depth at which views align with slope ``alpha_x``."""
        d = (alpha_x - self.A[0])
        return math.inf if d == 0 else self.B[0] / d

    def shifts(self, depth=None, alpha=None) -> np.ndarray:
        """(K, 2) pixel displacement in each view of a point at ``depth``, or for a disparity slope ``alpha``
        (pixels per unit of view position; a number, or (alpha_x, alpha_y))."""
        if alpha is None:
            ax, ay = self.alpha(depth)
        else:
            ax, ay = (alpha, alpha) if np.isscalar(alpha) else alpha
        return np.stack([ax * self.positions[:, 0], ay * self.positions[:, 1]], axis=-1)

    def subset(self, index) -> "LightField":
        return LightField(self.views[index], self.positions[index], self.times[index], self.A, self.B, self.kind,
                          dict(self.meta))


def _exp(log_frames):
    return np.exp(np.asarray(log_frames, dtype=np.float64))


def galvo_disparity_model(optics: dict, width: int):
    f = (width / 2) / math.tan(math.radians(optics["fov_x_deg"]) / 2)
    d1, s = optics["mirror_distance"], optics["mirror_separation"]
    return (f, f), (-f * d1, -f * (d1 + s))


def galvo_field_depth(lf: "LightField", depth, x, y, weight_x=0.5):
    """Metric depth at pixel (x, y) from the depth a constant-shift refocus found sharpest there (numbers or
    arrays that broadcast, e.g. a whole depth map with its pixel grid).

    A mirror turn by e rotates the view, moving an image point at normalised coordinates (tx, ty) by
    f e (1 + tx^2) along its own axis (plus a tx ty cross term that a circular scan averages out), and moves
    the viewpoint by e x pivot, which shifts a point at depth z by f e pivot / z whatever its position. Over a
    full circular scan the fitted shift slope is alpha = f s - f pivot / z with s = 1 + (tx^2 + ty^2) / 2,
    where the constant-shift model assumes s = 1: off-axis points look farther. Galvo depth is hypersensitive
    to this (pivot / z ~ 0.1-0.3), so even 5 degrees off axis biases depth by several percent. The (1 + tx^2)
    and (1 + ty^2) scales differ, so what a focus measure finds also depends on the orientation of the local
    texture: ``weight_x`` (number or per-pixel array in [0, 1]) is the share of the local gradient energy along
    x (vertical edges see the x scale, horizontal edges the y scale; ``galvo_orientation_weight``); 0.5 takes
    their mean. Pivots: lf.B = (-f pivot_x, -f pivot_y), lf.A = (f, f)."""
    if lf.kind != "galvo":
        raise ValueError(f"galvo_field_depth needs a galvo light field, got {lf.kind!r}")
    h, w = lf.shape
    A = lf.A[0]                                   # alpha = A + B / z, A = f
    wx = np.clip(np.asarray(weight_x, np.float64), 0.0, 1.0)
    B = wx * lf.B[0] + (1 - wx) * lf.B[1]         # the constant-shift model the focal stack used, per pixel
    tx, ty = (np.asarray(x, np.float64) + 0.5 - w / 2) / A, (np.asarray(y, np.float64) + 0.5 - h / 2) / A
    with np.errstate(divide="ignore"):
        alpha = A + B / np.asarray(depth, np.float64)
        out = B / (alpha - A * (1 + wx * tx * tx + (1 - wx) * ty * ty))
    out = np.where(out > 0, out, np.inf)          # beyond infinity after the correction: report infinity
    return float(out) if out.ndim == 0 else out


def galvo_orientation_weight(image, window: int = 7) -> np.ndarray:
    """Per pixel, the share of gradient energy along x (Sobel, box-summed over ``window``): the weight of the
    x scan scale in what a focus measure finds there (``galvo_field_depth``). 0.5 where there is no texture."""
    import cv2
    img = np.asarray(image, np.float32)
    gx2 = cv2.boxFilter(cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3) ** 2, -1, (window, window))
    gy2 = cv2.boxFilter(cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3) ** 2, -1, (window, window))
    total = gx2 + gy2
    return np.where(total > 1e-12, gx2 / np.maximum(total, 1e-12), 0.5).astype(np.float64)


def spatial_disparity_model(optics: dict, view_w: int, view_h: int):
    D, S = optics["lens_to_image_plane"], optics["focus_distance"]
    W, H = optics["image_plane_size"]
    kx, ky = view_w / W * D, view_h / H * D
    return (-kx / S, -ky / S), (kx, ky)


def from_galvo(log_frames, times, optics: dict, meta: dict | None = None) -> LightField:
    """A light field from galvo frames (log intensity, e.g. reconstructed) at known times: each frame is the view
    at the scan position (optical angles) of its time."""
    from .scan import curve_from_dict
    curve = curve_from_dict(optics["scan"], where="event metadata")
    ax, ay = curve.angles(np.asarray(times, dtype=np.float64))
    frames = _exp(log_frames)
    A, B = galvo_disparity_model(optics, frames.shape[2])
    return LightField(frames, np.stack([2 * ax, 2 * ay], axis=-1), times, A, B, "galvo", dict(meta or {}))


def galvo_steps_per_period(optics: dict, width: int, px_per_step: float = 1.0) -> int:
    """Render steps per scan period so the scan moves the image by at most ``px_per_step`` pixels per step
    (at infinity, where the shift is largest): the path length of one period over ``px_per_step``."""
    from .reconstruct import galvo_scan_shifts
    from .scan import curve_from_dict
    period = curve_from_dict(optics["scan"]).period
    if period is None:
        raise ValueError("the scan is not periodic")
    shifts = galvo_scan_shifts(optics, np.linspace(0.0, period, 2049), math.inf, width)
    length = float(np.hypot(*np.diff(shifts, axis=0).T).sum())
    return max(1, int(math.ceil(length / px_per_step)))


def galvo_view_times(optics: dict, t_period_start: float, views: int) -> np.ndarray:
    """``views`` instants evenly spread over the scan period that starts at ``t_period_start``."""
    from .scan import curve_from_dict
    period = curve_from_dict(optics["scan"]).period
    if period is None:
        raise ValueError("the scan is not periodic: choose view times explicitly")
    return t_period_start + (np.arange(views) + 0.5) * period / views


def galvo_period_starts(events, periods=None) -> dict:
    """{period index: start time in seconds} for the whole scan periods of a galvo stream (all, or the indices
    ``periods``, each checked against the stream)."""
    from .scan import curve_from_dict
    period = curve_from_dict(events.meta["optics"]["scan"]).period
    if period is None:
        raise ValueError("the scan is not periodic: choose view times explicitly")
    t0 = events.meta.get("t_start_us", 0) * 1e-6
    n_periods = int(math.floor(events.duration_us * 1e-6 / period + 1e-9))   # whole periods only
    wanted = range(n_periods) if periods is None else periods
    for p in wanted:
        if not 0 <= p < n_periods:
            raise ValueError(f"scan period {p} is not in the stream: allowed 0..{n_periods - 1} "
                             f"({n_periods} whole periods of {period * 1e3:g} ms)")
    return {p: t0 + p * period for p in wanted}


def galvo_lightfields(events, views: int = 32, method: str = "direct", periods=None, **method_kw):
    """Sliding light fields from a galvo stream, one per scan period: reconstruct ``views`` frames per period
    (``method`` of ``reconstruct``) and place each at its scan position. Yields LightField objects."""
    from . import reconstruct as rc
    optics = events.meta["optics"]
    starts = galvo_period_starts(events, periods)
    wanted = list(starts)
    all_times = np.concatenate([galvo_view_times(optics, starts[p], views) for p in wanted])
    frames = rc.reconstruct(events, all_times, method, **method_kw)
    for i, p in enumerate(wanted):
        sl = slice(i * views, (i + 1) * views)
        yield from_galvo(frames[sl], all_times[sl], optics, {"period_index": p})


def from_spatial(log_or_linear_frame, optics: dict, time: float = 0.0, log: bool = True) -> LightField:
    """A light field from one kaleidoscope/microlens film image (log or linear): its n x n extracted views."""
    from .views import extract_views
    frame = np.asarray(log_or_linear_frame, dtype=np.float64)
    stack = extract_views(_exp(frame) if log else frame, optics)
    h, w = stack.images.shape[1:3]
    A, B = spatial_disparity_model(optics, w, h)
    return LightField(stack.images, stack.positions, np.full(len(stack.images), time), A, B, optics["design"],
                      {"ij": stack.ij.tolist()})


def from_events(events, period: int = 0, views: int = 32, time: float | None = None, method: str | None = None,
                log_start=None, **method_kw) -> LightField:
    """One light field from an event stream, whatever its optics.

    * galvo: the scan period ``period`` (index from the stream start), ``views`` views. Default method:
      ``direct`` from ``log_start`` when given, else the static-scene ``galvo`` solver;
    * kaleidoscope / microlens: the film at ``time`` seconds (default: stream end), split into its views.
      Default method: ``direct`` from ``log_start`` when given, else ``highpass`` (moving content only).
    """
    from . import reconstruct as rc
    optics = events.meta.get("optics", {})
    design = optics.get("design")
    t0 = events.meta.get("t_start_us", 0) * 1e-6
    if method is None:
        method = "direct" if log_start is not None else ("galvo" if design == "galvo" else "highpass")
    kw = dict(method_kw)
    if method == "direct":
        kw.update(log_start=log_start, t_start=t0)
    if design == "galvo":
        return next(galvo_lightfields(events, views, method, periods=[period], **kw))
    if design in ("kaleidoscope", "microlens"):
        t = t0 + events.duration_us * 1e-6 if time is None else time
        frame = rc.reconstruct(events, [t], method, **kw)[0]
        return from_spatial(frame, optics, time=t, log=True)
    raise ValueError("the stream's metadata describes no light-field optics (optics.design is "
                     f"{design!r}; expected galvo, kaleidoscope or microlens)")
