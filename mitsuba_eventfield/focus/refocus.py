"""Post-capture refocus by align-and-add, focal stacks, and focus tracking over time.

Refocusing at depth z maps every view back onto the reference view for points at z (``LightField.alignments``)
and averages in linear intensity, which is what a lens with the synthetic aperture would integrate.

* Spatial multiplexing (one shift per view): the shifts are exact Fourier phase ramps on reflect-padded views,
  so no resampling blur biases focus measures.
* Galvo: each view is warped by its exact homography (``optics.galvo``) with Lanczos interpolation (reflected
  borders, as the Fourier path). Bicubic is 6x faster (0.10 against 0.61 ms a 120 x 90 warp) and found the
  same depths on scenes/offaxis_cards, but its blur hides detail: the scan-frequency test's edge contrast kept
  under a readout cap read 0.71 with bicubic, 0.45 with Lanczos and 0.55 with exact Fourier shifts. A
  constant shift per view is right only on the optical axis: off axis the scan moves the image (1 + t^2) times
  more, and a shift-only refocus read a card 9.6 degrees off axis 54-68 % too far. ``alpha`` refocus (a
  disparity slope rather than a depth) keeps the on-axis shifts.

Moving content. The views of a galvo light field are taken one after another over a scan period, so content
that moves by d pixels during it is smeared over d pixels in the refocused image (the paper's motion blur of
the galvo design). ``view_motion`` measures d from the views themselves and ``refocus`` flags it
(``MotionBlurWarning``, or a refusal with ``on_motion="raise"``) above ``MOTION_LIMIT_PX`` = 2 px. From
``evaluation.failure``'s speed sweep (a textured card at 0.5 m, exact views, 96 x 72, 24 views): refocus PSNR
on the card 37.9 dB static, 35.8 dB at 1 px of motion per period, 30.8 dB at 2 px, 24.9 dB at 4 px; the
measure read 0.2 px on the static card (0.7 px on views from events, 0.3-1.6 px on the static bundled scenes
with 16-32 views) and 1.0 / 2.0 / 4.0 / 8.0 px for 1 / 2 / 4 / 8 px of motion (16 px read 4.9: the flow
under-reads past ~8 px, still flagged). Blocks need a log gradient of ``TEXTURE_GRADIENT`` = 0.05 per pixel:
on views from events a weaker one moves by a threshold step per event, and the static card read 1.5-2.0 px.
"""
from __future__ import annotations

import math
import numbers
import warnings

import cv2
import numpy as np

from ..errors import ConfigError
from ..lightfield.model import LightField
from ..validate import MAX_PLANES, finite, number
from .measures import IMAGE_MEASURES, focus_measure, refine_peak

MOTION_LIMIT_PX = 2.0       # module docstring: content moving more than this over the views is flagged
MOTION_MIN_VIEWS = 12       # fewer views: motion is not measured (``view_motion``)
TEXTURE_GRADIENT = 0.05     # log per pixel: blocks with weaker texture give no motion (event steps blur them)
ON_MOTION = ("warn", "raise", "ignore")


class MotionBlurWarning(UserWarning):
    """A refocused image whose content moved more than ``MOTION_LIMIT_PX`` while its views were taken."""


# track_focus: a focus curve over the depths whose peak stands less than this share above its lowest value
# cannot tell depth (a textureless region: every refocused image alike); a match below this normalised
# correlation is no match (calibration.galvo's MIN_MATCH_SCORE)
MIN_FOCUS_CONTRAST = 0.05
MIN_FOLLOW_SCORE = 0.6


class TrackingWarning(UserWarning):
    """track_focus could not measure: the ROI has no texture to focus on or to follow."""


def _warp(img, homography, border=cv2.BORDER_CONSTANT, interpolation=cv2.INTER_LANCZOS4):
    """img sampled at homography @ (x, y, 1) (array indices), Lanczos, zero (or reflected) outside."""
    return cv2.warpPerspective(img, homography, (img.shape[1], img.shape[0]),
                               flags=interpolation | cv2.WARP_INVERSE_MAP, borderMode=border, borderValue=0)


def _with_motion(maps: np.ndarray, motion_px) -> np.ndarray:
    """Reference-to-view maps followed by each view's extra image displacement ``motion_px`` (K, 2)."""
    out = maps.copy()
    out[:, :2, :] += np.asarray(motion_px, np.float64)[:, :, None] * maps[:, 2:3, :]
    return out


def aligned_views(lf: LightField, depth, motion=None):
    """Generator of (aligned view, coverage) for every view, aligned onto the reference view for a point at
    ``depth`` (``motion``: an image velocity, see ``motion_shifts``). Coverage is 1 where the view has data."""
    maps = lf.alignments(depth)
    if motion is not None:
        maps = _with_motion(maps, motion_shifts(lf, motion))
    ones = np.ones(lf.shape, np.float32)
    for view, m in zip(lf.views, maps):
        yield (_warp(view.astype(np.float32), m),
               (_warp(ones, m, interpolation=cv2.INTER_LINEAR) > 0.999).astype(np.float32))


class _Spectra:
    """Fourier transforms of a light field's (padded) views, computed once per light field.

    Shift-and-add in the Fourier domain is exact for band-limited views: a sub-pixel shift is a phase ramp,
    with none of the blur of bilinear resampling. (Bilinear blur is worst at half-pixel shifts, so it pulls
    focus measures towards depths where every shift is a whole pixel; measured: 7% depth bias.) The sum of
    shifted views is one inverse FFT per depth.
    """

    def __init__(self, lf: LightField, pad: int):
        self.pad = pad
        v = lf.views if lf.views.ndim == 4 else lf.views[..., None]
        padded = np.pad(v, ((0, 0), (pad, pad), (pad, pad), (0, 0)), mode="reflect")
        self.hp, self.wp = padded.shape[1:3]
        self.spec = np.fft.rfft2(padded, axes=(1, 2)).astype(np.complex64)   # (K, Hp, Wp//2+1, C)
        self.ky = np.fft.fftfreq(self.hp)[:, None]
        self.kx = np.fft.rfftfreq(self.wp)[None, :]
        self.channels = lf.views.ndim == 4

    def shifted_sum(self, shifts) -> np.ndarray:
        # the phase ramp is separable: exp(2 pi i (ky dy + kx dx)) = col(ky) row(kx), so no per-pixel exp
        col = np.exp(2j * np.pi * self.ky[:, 0][None, :] * shifts[:, 1, None]).astype(np.complex64)  # (K, Hp)
        row = np.exp(2j * np.pi * self.kx[0][None, :] * shifts[:, 0, None]).astype(np.complex64)     # (K, Wp')
        total = np.zeros(self.spec.shape[1:], np.complex64)
        for k in range(len(shifts)):       # measured fastest: ~8x an einsum over (K, H, W) here
            total += np.outer(col[k], row[k])[..., None] * self.spec[k]
        img = np.fft.irfft2(total, s=(self.hp, self.wp), axes=(0, 1))
        p = self.pad
        img = img[p:self.hp - p, p:self.wp - p]
        return img if self.channels else img[..., 0]


def _spectra(lf: LightField, max_shift: float) -> _Spectra:
    pad = int(np.ceil(max_shift)) + 4
    cached = lf.cache.get("spectra")
    if cached is None or cached.pad < pad:
        cached = _Spectra(lf, max(pad, 16))
        lf.cache["spectra"] = cached
    return cached


def motion_shifts(lf: LightField, motion) -> np.ndarray:
    """(K, 2) image displacement of an object moving at ``motion`` = (vx, vy) pixels per second, in each view
    relative to the light field's mean time. Views taken at different times (the galvo's) see a moving object
    at different places; adding this to the disparity shifts refocuses it as it was at the mean time."""
    vx, vy = (float(v) for v in motion)
    dt = lf.times - lf.times.mean()
    return np.stack([vx * dt, vy * dt], axis=-1)


def _flow_logs(logs, cover):
    """Dense optical flow (Farneback) from logs[0] to logs[1] and to logs[2], on one 8-bit scale set by the
    pixels every view covers."""
    lo, hi = np.percentile(np.concatenate([g[cover] for g in logs]), [1, 99]) if cover.any() else (0.0, 1.0)
    codes = [np.clip((g - lo) / max(hi - lo, 1e-6) * 255, 0, 255).astype(np.uint8) for g in logs]
    return [cv2.calcOpticalFlowFarneback(codes[0], c, None, 0.5, 3, 15, 5, 7, 1.5, 0) for c in codes[1:]]


def view_motion(lf: LightField, depth: float = math.inf, tile: int = 8) -> dict:
    """How far content moves (pixels) while the views are taken, the scan's parallax taken out.

    Views 0, 1 and K-1 are aligned for ``depth``; under a closed periodic scan (circle, Lissajous) view K-1
    sits one step before view 0 on the curve and view 1 one step after. Content off ``depth`` is displaced
    between them by a multiple a of the change in view position (its leftover parallax), moving content by
    v times the time between them; the flows 0 -> 1 and 0 -> K-1 (4 numbers) fit a and v (3) by least
    squares per ``tile`` x ``tile`` block with texture (log gradient > ``TEXTURE_GRADIENT`` on half of it; the
    flow's median over the block). ``motion_px`` = |v| (t_{K-1} + t_1 - 2 t_0) (one period for evenly spread
    views), the 97th percentile over the blocks (content covering 3 % of the textured image counts);
    ``velocity_px_s`` the median v of the blocks moving more than ``MOTION_LIMIT_PX``. Views taken at one
    instant, fewer than ``MOTION_MIN_VIEWS`` views, or a first and last view not adjacent on the scan (an
    open curve): motion_px is NaN (unknown). With 8 views the steps along the scan are too coarse: the static,
    path-traced scenes/galvo_static read 2.1-2.9 px at 96 x 72, against 0.7-1.6 px with 16-32 views."""
    out = {"motion_px": float("nan"), "velocity_px_s": (0.0, 0.0), "moving_share": 0.0, "limit_px": MOTION_LIMIT_PX}
    key = ("view_motion", float(depth), tile)
    if key in lf.cache:
        return lf.cache[key]
    pos, t = lf.positions, lf.times
    span = t[-1] + t[1] - 2 * t[0] if len(t) >= MOTION_MIN_VIEWS else 0.0
    if span <= 0 or np.linalg.norm(pos[-1] - pos[0]) > 2 * np.linalg.norm(pos[1] - pos[0]) + 1e-12:
        lf.cache[key] = out
        return out
    maps = lf.alignments(depth)
    ones = np.ones(lf.shape, np.float32)
    logs, cover = [], np.ones(lf.shape, bool)
    for i in (0, 1, len(t) - 1):
        v = lf.views[i] if lf.views.ndim == 3 else lf.views[i].mean(axis=-1)
        logs.append(np.log(np.maximum(_warp(v.astype(np.float32), maps[i]), 1e-6)))
        cover &= _warp(ones, maps[i], interpolation=cv2.INTER_LINEAR) > 0.999
    flow = np.concatenate(_flow_logs(logs, cover), axis=-1)                 # (H, W, 4): 0 -> 1, 0 -> K-1
    textured = cover & (np.hypot(*np.gradient(logs[0])) > TEXTURE_GRADIENT)
    h, w = textured.shape
    blocks = [np.median(flow[y:y + tile, x:x + tile][textured[y:y + tile, x:x + tile]], axis=0)
              for y in range(0, h - tile + 1, tile) for x in range(0, w - tile + 1, tile)
              if textured[y:y + tile, x:x + tile].mean() >= 0.5]
    if not blocks:
        out["motion_px"] = 0.0
        lf.cache[key] = out
        return out
    (p1x, p1y), (p2x, p2y) = pos[1] - pos[0], pos[-1] - pos[0]
    t1, t2 = t[1] - t[0], t[-1] - t[0]
    model = np.array([[p1x, t1, 0], [p1y, 0, t1], [p2x, t2, 0], [p2y, 0, t2]])   # (a, vx, vy) -> flows
    velocity = (np.array(blocks) @ np.linalg.pinv(model).T)[:, 1:]
    mag = np.hypot(velocity[:, 0], velocity[:, 1]) * span
    moving = mag > MOTION_LIMIT_PX
    out.update(motion_px=float(np.percentile(mag, 97)), moving_share=float(moving.mean()))
    if moving.any():
        out["velocity_px_s"] = tuple(float(v) for v in np.median(velocity[moving], axis=0))
    lf.cache[key] = out
    return out


def _flag_motion(lf: LightField, depth, on_motion: str) -> None:
    m = view_motion(lf, depth)
    if not m["motion_px"] > MOTION_LIMIT_PX:
        return
    vx, vy = m["velocity_px_s"]
    msg = (f"refocus at {depth:g}: content moves {m['motion_px']:.1f} px while the views are taken (more than "
           f"{MOTION_LIMIT_PX:g} px; {m['moving_share']:.0%} of the textured image): it is smeared by as much; "
           f"refocus(..., motion=({vx:.0f}, {vy:.0f})) follows it (pixels per second)")
    if on_motion == "raise":
        raise ConfigError(msg)
    warnings.warn(msg, MotionBlurWarning, stacklevel=3)


def check_lightfield(lf, where: str) -> None:
    """A clear error for what is not a light field (e.g. None from a failed step), instead of an AttributeError
    deep inside."""
    if not isinstance(lf, LightField):
        raise ConfigError(f"{where}: expected a LightField (ef.from_galvo, ef.from_spatial, ef.galvo_lightfields), "
                          f"got {type(lf).__name__}")


def _pair(value, name: str):
    """A number or (x, y) pair of finite numbers, as given (a float or a float tuple)."""
    if np.iterable(value) and not isinstance(value, str):
        items = list(value)
        if len(items) != 2:
            raise ConfigError(f"{name} = {value!r}: expected a number or an (x, y) pair")
        return tuple(finite(v, name) for v in items)
    return finite(value, name)


def _check_refocus(depth, alpha, motion):
    """refocus's depth (> 0, math.inf allowed) or alpha (a number or (x, y)), and motion ((vx, vy) px/s)."""
    if alpha is None:
        if depth is None or isinstance(depth, bool) or not isinstance(depth, numbers.Real) or not depth > 0:
            raise ConfigError(f"refocus: depth = {depth!r}: must be > 0 (math.inf for infinity), or give alpha")
        depth = float(depth)
    else:
        alpha = _pair(alpha, "refocus: alpha")
    if motion is not None:
        if isinstance(motion, str) or not np.iterable(motion):
            raise ConfigError(f"refocus: motion = {motion!r}: expected (vx, vy) in pixels per second")
        motion = _pair(motion, "refocus: motion")
    return depth, alpha, motion


def refocus(lf: LightField, depth: float | None = None, alpha=None, motion=None,
            on_motion: str = "warn") -> np.ndarray:
    """The light field refocused at ``depth`` (scene units; math.inf allowed) or at the disparity slope
    ``alpha`` (pixels per unit of view position, on-axis for a galvo, see ``LightField``): (H, W[, C]) linear
    intensity.
    ``motion``: (vx, vy) image velocity in pixels per second of the object to make sharp (``motion_shifts``).
    ``on_motion``: what to do when, with no ``motion`` given, content at ``depth`` moves more than
    ``MOTION_LIMIT_PX`` over the views (``view_motion``; module docstring): "warn" (``MotionBlurWarning``),
    "raise" (ConfigError) or "ignore"."""
    check_lightfield(lf, "refocus")
    depth, alpha, motion = _check_refocus(depth, alpha, motion)
    if alpha is None:
        depth = lf.check_depth(depth, "refocus: depth")
    if on_motion not in ON_MOTION:
        raise ConfigError(f"refocus: on_motion = {on_motion!r}: allowed {', '.join(ON_MOTION)}")
    if on_motion != "ignore" and motion is None and alpha is None:
        _flag_motion(lf, depth, on_motion)
    if alpha is None and not lf.shift_invariant:
        return _refocus_warped(lf, depth, motion)
    shifts = lf.shifts(depth, alpha)
    if motion is not None:
        shifts = shifts + motion_shifts(lf, motion)
    spectra = _spectra(lf, np.abs(shifts).max())
    return np.maximum(spectra.shifted_sum(shifts) / len(lf.views), 0.0)


def _refocus_warped(lf: LightField, depth: float, motion=None) -> np.ndarray:
    """Refocus by exact per-view homographies (galvo light fields): each pixel the mean of the views that
    have data there (where a view's sample falls inside its image: ``aligned_views``' coverage); where none
    has, the mean of all views with reflected borders. The mean over every view with reflected borders put
    mirrored copies of the scene inside the image, a band as wide as the views' spread: on the demo, strips of
    each card 6-10 px in from the edges over a uniform wall, 25-35 % of its brightness. Values are sampled
    with reflected borders all the same: Lanczos near a view's edge would mix in the zeros of a constant one."""
    maps = lf.alignments(depth)
    if motion is not None:
        maps = _with_motion(maps, motion_shifts(lf, motion))
    ones = np.ones(lf.shape, np.float32)
    total = cover = every = None
    for view, m in zip(lf.views, maps):
        w = _warp(view.astype(np.float32), m, border=cv2.BORDER_REFLECT_101).astype(np.float64)
        c = (_warp(ones, m, interpolation=cv2.INTER_LINEAR) > 0.999).astype(np.float64)
        c = c[..., None] if w.ndim == 3 else c
        total, cover, every = (w * c, c, w) if total is None else (total + w * c, cover + c, every + w)
    mean = np.where(cover > 0, total / np.maximum(cover, 1.0), every / len(lf.views))
    return np.maximum(mean, 0.0)


def depth_planes(near: float, far: float, count: int) -> np.ndarray:
    """``count`` depths from near to far, uniform in inverse depth (uniform in disparity)."""
    near, far = finite(near, "depth planes: near"), finite(far, "depth planes: far")
    count = number(count, "depth planes: count", 2, MAX_PLANES, integer=True, strict=True)
    if not 0 < near < far:
        raise ConfigError(f"depth planes: need 0 < near ({near}) < far ({far})")
    return 1.0 / np.linspace(1.0 / near, 1.0 / far, count)


def focal_stack(lf: LightField, depths, motion=None, on_motion: str = "warn") -> np.ndarray:
    """(D, H, W[, C]) refocused images, one per depth (moving content checked once, at the first depth)."""
    check_lightfield(lf, "focal_stack")
    depths = _depth_list(depths, "focal_stack: depths")
    return np.stack([refocus(lf, float(z), motion=motion, on_motion=on_motion if i == 0 else "ignore")
                     for i, z in enumerate(depths)])


def _follow(template: np.ndarray, image: np.ndarray, roi, search: float = 1.0):
    """The ROI of the same size where ``template`` best matches ``image`` (normalised cross-correlation),
    searched within ``search`` ROI sizes of the old position."""
    x0, y0, x1, y1 = roi
    h, w = image.shape[:2]
    rw, rh = x1 - x0, y1 - y0
    sx0, sy0 = max(0, x0 - int(search * rw)), max(0, y0 - int(search * rh))
    sx1, sy1 = min(w, x1 + int(search * rw)), min(h, y1 + int(search * rh))
    window = image[sy0:sy1, sx0:sx1]
    if window.ndim == 3:
        window, template = window.mean(-1), template.mean(-1)
    if not np.std(template) > 1e-6 * (abs(float(np.mean(template))) + 1e-30):
        return roi                       # a flat template matches anywhere: stay where it was
    score = cv2.matchTemplate(window.astype(np.float32), template.astype(np.float32), cv2.TM_CCOEFF_NORMED)
    _, best, _, (bx, by) = cv2.minMaxLoc(score)
    if not best >= MIN_FOLLOW_SCORE:     # no match worth the name: stay where it was
        return roi
    return (sx0 + bx, sy0 + by, sx0 + bx + rw, sy0 + by + rh)


def _best_depth(lf, depths, roi, measure, motion):
    x0, y0, x1, y1 = roi
    stack = focal_stack(lf, depths, motion, on_motion="ignore")
    scores = np.array([focus_measure(s if s.ndim == 2 else s.mean(-1), measure)[y0:y1, x0:x1].mean()
                       for s in stack])
    k = int(np.argmax(scores))
    top, level = float(scores.max()), float(np.mean(stack[:, y0:y1, x0:x1]))
    # flat: no focus at all (rounding noise against the image's own scale) or a peak hardly above the rest
    flat = not top > 1e-9 * max(level * level, level, 1e-30) or (top - float(scores.min())) / top < MIN_FOCUS_CONTRAST
    return refine_peak(1.0 / depths, scores, k), flat


def _depth_list(depths, name: str) -> np.ndarray:
    """One or more depths, each > 0 (math.inf allowed)."""
    if isinstance(depths, (str, bytes)) or not np.iterable(depths) or not len(depths):
        raise ConfigError(f"{name} = {depths!r}: expected one or more depths > 0")
    return np.array([number(z, name, 0, lo_open=True, strict=True) if z != math.inf else math.inf for z in depths])


def _check_track(lightfields, depths, roi, measure, smooth):
    """track_focus's arguments: light fields (one or more), depths (at least two), an ROI inside the views,
    an image focus measure, smoothing in [0, 1)."""
    lightfields = list(lightfields) if np.iterable(lightfields) else lightfields
    if not isinstance(lightfields, list) or not lightfields:
        raise ConfigError(f"track_focus: lightfields = {lightfields!r}: expected one or more LightField")
    for lf in lightfields:
        check_lightfield(lf, "track_focus")
    depths = _depth_list(depths, "track_focus: depths")
    h, w = lightfields[0].shape
    if isinstance(roi, str) or not np.iterable(roi) or len(roi) != 4:
        raise ConfigError(f"track_focus: roi = {roi!r}: expected (x0, y0, x1, y1) pixels")
    roi = tuple(int(number(v, "track_focus: roi", 0, integer=True, strict=True)) for v in roi)
    if not (roi[0] < roi[2] <= w and roi[1] < roi[3] <= h):
        raise ConfigError(f"track_focus: roi = {roi}: need 0 <= x0 < x1 <= {w} and 0 <= y0 < y1 <= {h}")
    if measure not in IMAGE_MEASURES:
        raise ConfigError(f"track_focus: measure = {measure!r}; allowed: {', '.join(IMAGE_MEASURES)}")
    if not 0 <= finite(smooth, "track_focus: smooth") < 1:
        raise ConfigError(f"track_focus: smooth = {smooth!r}: allowed range is [0, 1)")
    return lightfields, depths, roi


def track_focus(lightfields, depths, roi, measure: str = "tenengrad", smooth: float = 0.0, follow: bool = False,
                compensate_motion: bool = True):
    """Refocus a sequence of light fields on the object inside ``roi`` = (x0, y0, x1, y1) pixels as it moves in
    depth: for each light field, the depth whose refocused ROI is sharpest (sub-step refined, optionally
    smoothed in inverse depth over time).

    ``follow``: the ROI moves with the object, found in each light field (refocused at the previous depth) by
    matching the previous refocused ROI. Then, with ``compensate_motion`` (used only with ``follow``: the
    velocity comes from the followed ROI), a second pass refocuses with the
    object's image velocity (from the ROI track) taken out of every view (``motion_shifts``): views spread
    over a scan period otherwise smear a fast object, and its motion biases the depth (it correlates with the
    scan's position over the period). Returns (depths chosen, refocused images, ROIs, image velocities px/s).
    """
    lightfields, depths, roi = _check_track(lightfields, depths, roi, measure, smooth)
    rois, inverse, images = [], [], []
    for lf in lightfields:                       # pass 1: where the object is, and its depth without motion
        if follow and images:
            x0, y0, x1, y1 = roi
            roi = _follow(images[-1][y0:y1, x0:x1], refocus(lf, 1.0 / inverse[-1], on_motion="ignore"), roi)
        rois.append(roi)
        inv, flat = _best_depth(lf, depths, roi, measure, None)
        inverse.append(inv)
        if flat:
            warnings.warn(f"track_focus: light field {len(rois) - 1}: the ROI {tuple(roi)} looks the same at every "
                          "depth (no texture to focus on): its depth is not measured", TrackingWarning, stacklevel=2)
        images.append(refocus(lf, 1.0 / inverse[-1], on_motion="ignore") if follow else None)
    velocities = np.zeros((len(lightfields), 2))
    if follow and compensate_motion and len(lightfields) > 1:
        centres = np.array([[(r[0] + r[2]) / 2, (r[1] + r[3]) / 2] for r in rois], dtype=np.float64)
        times = np.array([lf.times.mean() for lf in lightfields])
        # the first ROI is the user's box, not a match: fit the matched ones (whole-pixel positions, so a
        # smooth fit, at most quadratic, beats differences) and evaluate its derivative at every period
        first = 1 if len(lightfields) > 2 else 0
        degree = min(2, len(lightfields) - first - 1)
        for i in (0, 1):
            fit = np.polynomial.Polynomial.fit(times[first:], centres[first:, i], degree)
            velocities[:, i] = fit.deriv()(times) if degree > 0 else 0.0
        inverse = [_best_depth(lf, depths, r, measure, v)[0] for lf, r, v in zip(lightfields, rois, velocities)]
    chosen, out, prev = [], [], None
    for lf, inv, v in zip(lightfields, inverse, velocities):
        if prev is not None and smooth > 0:
            inv = (1 - smooth) * inv + smooth * prev
        prev = inv
        z = 1.0 / inv if inv > 0 else math.inf
        chosen.append(z)
        out.append(refocus(lf, z, motion=v if follow and compensate_motion else None))
    return np.array(chosen), np.stack(out), rois, velocities
