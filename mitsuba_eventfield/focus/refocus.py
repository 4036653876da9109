"""Post-capture refocus by align-and-add and focal stacks (focus tracking over time: ``focus.tracking``).

Refocusing at depth z maps every view back onto the reference view for points at z (``LightField.alignments``)
and averages in linear intensity, which is what a lens with the synthetic aperture would integrate.

* Spatial multiplexing (one shift per view): the shifts are exact Fourier phase ramps on reflect-padded views,
  so no resampling blur biases focus measures; the sum is kept within the views' local values as the galvo's
  Lanczos samples are (``_fourier_within_views``).
* Galvo: each view is warped by its exact homography (``optics.galvo``) with Lanczos interpolation, each
  sample kept within the values of its 3 x 3 source neighbours (``_no_ringing``: unclipped, Lanczos rang below
  zero next to black print, holes in the refocused image). Bicubic is 6x faster (0.10 against 0.61 ms a
  120 x 90 warp) and found the same depths on scenes/offaxis_cards, but its blur hides detail. A
  constant shift per view is right only on the optical axis: off axis the scan moves the image (1 + t^2) times
  more, and a shift-only refocus read a card 9.6 degrees off axis 54-68 % too far. ``alpha`` refocus (a
  disparity slope rather than a depth) keeps the on-axis shifts.
* Both: a pixel some views do not see (a band along the edges, as wide as the views' spread) is the mean
  of the views that do (``covered_mean``).

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
Only pixels whose flow survives a round trip count (``_flow_logs``): the text wall of scenes/galvo_static at a
2-degree scan read 2.1-2.3 px static without that check (a false warning), 1.1-1.8 px with it, and 4.1-4.2 px
with its card moving 4 px a period (tests/lightfield/test_view_motion.py).
"""
from __future__ import annotations

import math
import numbers
import warnings

import cv2
import numpy as np

from ..errors import ConfigError
from ..lightfield.model import LightField
from ..validate import MAX_PLANES, finite, number, number_or_pair
from ..workers import ordered_map
from .measures import log_gradient

MOTION_LIMIT_PX = 2.0       # module docstring: content moving more than this over the views is flagged
MOTION_MIN_VIEWS = 12       # fewer views: motion is not measured (``view_motion``)
TEXTURE_GRADIENT = 0.05     # log per pixel: blocks with weaker texture give no motion (event steps blur them)
FLOW_CONSISTENCY_PX = 0.5   # a flow whose round trip misses by more is unreliable (``_flow_logs``)
ON_MOTION = ("warn", "raise", "ignore")


class MotionBlurWarning(UserWarning):
    """A refocused image whose content moved more than ``MOTION_LIMIT_PX`` while its views were taken."""



_NEIGHBOURS = np.ones((3, 3), np.uint8)
RING_MARGIN = 1.25          # _no_ringing: a sample may pass its neighbours' values by this factor (log step 0.22)


def _warp(img, homography, border=cv2.BORDER_CONSTANT, interpolation=cv2.INTER_LANCZOS4, bounds=None):
    """img sampled at homography @ (x, y, 1) (array indices), Lanczos, zero (or reflected) outside. A Lanczos
    sample is kept within the values of the pixels around it (``_no_ringing``; ``bounds``: a [low, high] sum
    that gets the bounds used)."""
    warped = _warp_plain(img, homography, border, interpolation)
    if interpolation != cv2.INTER_LANCZOS4:
        return warped
    return _no_ringing(warped, img, homography, border, bounds)


def _warp_plain(img, homography, border, interpolation):
    return cv2.warpPerspective(img, homography, (img.shape[1], img.shape[0]),
                               flags=interpolation | cv2.WARP_INVERSE_MAP, borderMode=border, borderValue=0)


def _no_ringing(warped, img, homography, border, bounds=None):
    """``warped`` clipped to the least and greatest value of each sample's 3 x 3 source neighbourhood (those
    images warped bilinearly), widened by the factor ``RING_MARGIN``. Lanczos rings at a strong edge: on
    scenes/galvo_static (black letters, 0.013, on a wall of up to 6.4) its negative lobes took 444 of 10,800
    refocused pixels below zero (then clipped to 0, black holes in the letters), and the log of the aligned
    views that the ``variance`` focus measure takes fell to log(1e-6) there, a spike that drowned the focus
    curve. The margin is for band-limited detail, whose peaks between samples pass every sample: refocusing
    ray-traced views of a texture with 3-6 px wavelengths (tests/optics/test_galvo_geometry.py's), the
    reference view came out at 60.7 dB PSNR with plain Lanczos, 48.8 dB clipped without a margin, 60.7 dB with
    a factor of 1.1 or more (bicubic: 52.3, bilinear: 32.8). The factor bounds the rings in the log, where
    events and focus measures look: a black letter's -1.7 undershoot becomes 0.8 of its value. It costs 26 %
    of a refocus (346 x 260, 32 views: 130 against 103 ms). ``bounds``: a [low, high] sum the bounds are added to
    (``_fourier_within_views``)."""
    lo, hi = _ring_bounds(img, homography, border)
    if bounds is not None:
        bounds[0], bounds[1] = bounds[0] + lo, bounds[1] + hi
    return np.clip(warped, lo, hi)


def _ring_bounds(img, homography, border) -> tuple:
    """(low, high): ``img``'s 3 x 3 local least and greatest values warped bilinearly like it, widened by
    ``RING_MARGIN`` away from zero on either side (views are intensities, but a LightField does not refuse
    signed ones)."""
    lo = _warp_plain(cv2.erode(img, _NEIGHBOURS, borderType=cv2.BORDER_REFLECT), homography, border,
                     cv2.INTER_LINEAR)
    hi = _warp_plain(cv2.dilate(img, _NEIGHBOURS, borderType=cv2.BORDER_REFLECT), homography, border,
                     cv2.INTER_LINEAR)
    return (np.where(lo > 0, lo / RING_MARGIN, lo * RING_MARGIN),
            np.where(hi > 0, hi * RING_MARGIN, hi / RING_MARGIN))


def _with_motion(maps: np.ndarray, motion_px) -> np.ndarray:
    """Reference-to-view maps followed by each view's extra image displacement ``motion_px`` (K, 2)."""
    out = maps.copy()
    out[:, :2, :] += np.asarray(motion_px, np.float64)[:, :, None] * maps[:, 2:3, :]
    return out


def covered(shape, homography) -> np.ndarray:
    """(H, W) bool: the reference pixels whose sample under ``homography`` falls inside a view of ``shape``
    (bilinear weights all inside it): where that view has data. The one coverage rule of every covering-views
    mean and of the motion measure."""
    return _warp(np.ones(shape, np.float32), homography, interpolation=cv2.INTER_LINEAR) > 0.999


def aligned_views(lf: LightField, depth, motion=None):
    """Generator of (aligned view, coverage) for every view, aligned onto the reference view for a point at
    ``depth`` (``motion``: an image velocity, see ``motion_shifts``). Coverage is 1 where the view has data."""
    maps = lf.alignments(depth)
    if motion is not None:
        maps = _with_motion(maps, motion_shifts(lf, motion))
    yield from ordered_map(lambda vm: (_warp(vm[0].astype(np.float32), vm[1]), covered(lf.shape, vm[1]).astype(
        np.float32)), zip(lf.views, maps))


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
    pixels every view covers, and where both flows are reliable: each flow and the flow back from its target
    agree (forward-backward, within ``FLOW_CONSISTENCY_PX``). Returns (flows, reliable mask).

    Why the check: on repetitive texture (lines of text) Farneback's window can lock onto the next line in one
    view pair and not the other; the scenes/galvo_static wall at a 2-degree scan (173 x 130, 32 views) had
    blocks whose flow spread over 8 px within the block, reading 8 px of motion on a static scene and a
    MotionBlurWarning at 2.1-2.3 px. Those pixels fail the round trip; without them the scene reads 1.1-1.8."""
    lo, hi = np.percentile(np.concatenate([g[cover] for g in logs]), [1, 99]) if cover.any() else (0.0, 1.0)
    codes = [np.clip((g - lo) / max(hi - lo, 1e-6) * 255, 0, 255).astype(np.uint8) for g in logs]
    h, w = codes[0].shape
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    flows, reliable = [], np.ones((h, w), bool)
    for c in codes[1:]:
        fwd = cv2.calcOpticalFlowFarneback(codes[0], c, None, 0.5, 3, 15, 5, 7, 1.5, 0)
        back = cv2.calcOpticalFlowFarneback(c, codes[0], None, 0.5, 3, 15, 5, 7, 1.5, 0)
        back_at = cv2.remap(back, gx + fwd[..., 0], gy + fwd[..., 1], cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_REPLICATE)
        reliable &= np.hypot(*(fwd + back_at).transpose(2, 0, 1)) < FLOW_CONSISTENCY_PX
        flows.append(fwd)
    return flows, reliable


def view_motion(lf: LightField, depth: float = math.inf, tile: int = 8) -> dict:
    """How far content moves (pixels) while the views are taken, the scan's parallax taken out.

    Views 0, 1 and K-1 are aligned for ``depth``; under a closed periodic scan (circle, Lissajous) view K-1
    sits one step before view 0 on the curve and view 1 one step after. Content off ``depth`` is displaced
    between them by a multiple a of the change in view position (its leftover parallax), moving content by
    v times the time between them; the flows 0 -> 1 and 0 -> K-1 (4 numbers) fit a and v (3) by least
    squares per ``tile`` x ``tile`` block with texture (log gradient > ``TEXTURE_GRADIENT`` on half of it) and
    reliable flow on half of its textured pixels (``_flow_logs``; the flow's median over those pixels).
    ``motion_px`` = |v| (t_{K-1} + t_1 - 2 t_0) (one period for evenly spread views), the 97th percentile over the blocks (content covering 3 % of the textured image counts);
    ``velocity_px_s`` the median v of the blocks moving more than ``MOTION_LIMIT_PX``. Views taken at one
    instant, fewer than ``MOTION_MIN_VIEWS`` views, or a first and last view not adjacent on the scan (an
    open curve): motion_px is NaN (unknown). With 8 views the steps along the scan are too coarse: the static,
    path-traced scenes/galvo_static read 2.1-2.9 px at 96 x 72, against 0.7-1.6 px with 16-32 views. Views
    solved from events read higher than rendered ones at that size: 2.06-2.13 px at 2.5 m with 24 views (a
    false warning) against 1.17, although each solved view is within 0.32 px (p90 of the flow on edges) of
    the rendered one; the card moving at 555 px/s reads 2.3-2.5 px there. At 173 x 130 the floor is 1.1-1.8
    px and the card reads 4.1-4.2 px."""
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
    logs, cover = [], np.ones(lf.shape, bool)
    for i in (0, 1, len(t) - 1):
        v = lf.views[i] if lf.views.ndim == 3 else lf.views[i].mean(axis=-1)
        logs.append(np.log(np.maximum(_warp(v.astype(np.float32), maps[i]), 1e-6)))
        cover &= covered(lf.shape, maps[i])
    flows, reliable = _flow_logs(logs, cover)
    flow = np.concatenate(flows, axis=-1)                                    # (H, W, 4): 0 -> 1, 0 -> K-1
    textured = cover & (log_gradient(logs[0]) > TEXTURE_GRADIENT)     # the texture measure of depth from focus
    used = textured & reliable
    h, w = textured.shape
    blocks = [np.median(flow[y:y + tile, x:x + tile][used[y:y + tile, x:x + tile]], axis=0)
              for y in range(0, h - tile + 1, tile) for x in range(0, w - tile + 1, tile)
              if textured[y:y + tile, x:x + tile].mean() >= 0.5
              and used[y:y + tile, x:x + tile].sum() >= 0.5 * textured[y:y + tile, x:x + tile].sum()]
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
    msg = (f"refocus at {depth:g} m: content moves {m['motion_px']:.1f} px while the views are taken (more than "
           f"{MOTION_LIMIT_PX:g} px; {m['moving_share']:.0%} of the textured image): it is smeared by as much; "
           f"refocus(..., motion=({vx:.0f}, {vy:.0f})) follows it (pixels per second; eventfield refocus --follow="
           f"{vx:.0f},{vy:.0f})")
    if on_motion == "raise":
        raise ConfigError(msg)
    warnings.warn(msg, MotionBlurWarning, stacklevel=3)


def check_lightfield(lf, where: str) -> None:
    """A clear error for what is not a light field (e.g. None from a failed step), instead of an AttributeError
    deep inside."""
    if not isinstance(lf, LightField):
        raise ConfigError(f"{where}: expected a LightField (ef.from_galvo, ef.from_spatial, ef.galvo_lightfields), "
                          f"got {type(lf).__name__}")


def _check_refocus(depth, alpha, motion):
    """refocus's depth (> 0, math.inf allowed) or alpha (a number or (x, y)), and motion ((vx, vy) px/s)."""
    if alpha is None:
        if depth is None or isinstance(depth, bool) or not isinstance(depth, numbers.Real) or not depth > 0:
            raise ConfigError(f"refocus: depth = {depth!r}: must be > 0 (math.inf for infinity), or give alpha")
        depth = float(depth)
    else:
        alpha = number_or_pair(alpha, "refocus: alpha")
    if motion is not None:
        if isinstance(motion, str) or not np.iterable(motion):
            raise ConfigError(f"refocus: motion = {motion!r}: expected (vx, vy) in pixels per second")
        motion = number_or_pair(motion, "refocus: motion")
    return depth, alpha, motion


def _check_motion_within_image(lf: LightField, motion) -> None:
    """Content moved farther than the image over the views is refused (--follow=1e308,1: minutes of OpenCV)."""
    span, side = float(np.abs(lf.times - lf.times.mean()).max()), max(np.shape(lf.views[0])[:2])
    if not max(abs(motion[0]), abs(motion[1])) * span <= side:
        raise ConfigError(f"refocus: motion = ({motion[0]:g}, {motion[1]:g}) px/s moves content "
                          f"{max(abs(motion[0]), abs(motion[1])) * span:.4g} px from the views' mean time, farther "
                          f"than the {side}-pixel image: allowed |v| up to {side / max(span, 1e-12):.4g} px/s here")


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
    if motion is not None:
        _check_motion_within_image(lf, motion)
    if alpha is None and not lf.shift_invariant:
        return _refocus_warped(lf, depth, motion)
    shifts = lf.shifts(depth, alpha)
    if motion is not None:
        shifts = shifts + motion_shifts(lf, motion)
    spectra = _spectra(lf, np.abs(shifts).max())
    return np.maximum(_covered_borders(lf, shifts, spectra.shifted_sum(shifts) / len(lf.views)), 0.0)


def covered_mean(lf: LightField, maps, interpolation=cv2.INTER_LANCZOS4, bounds=None) -> tuple:
    """(each pixel's mean over the views whose sample (``maps``: reference-to-view index maps) falls inside
    their image (``covered``), how many such views, the mean over all views with reflected borders). Values
    are sampled with reflected borders all the same: Lanczos next to a view's edge would mix in the zeros of
    a constant border. ``bounds``: a [low, high] sum of the views' Lanczos bounds (``_warp``)."""
    def one(view_map):            # a view's part, on a worker: nothing shared (sums are made below, in order)
        view, m = view_map
        own = [0.0, 0.0] if bounds is not None else None
        w = _warp(view.astype(np.float32), m, border=cv2.BORDER_REFLECT_101, interpolation=interpolation,
                  bounds=own)
        return w.astype(np.float64), covered(lf.shape, m).astype(np.float64), own

    total = cover = every = None
    for w, c, own in ordered_map(one, zip(lf.views, maps)):
        if own is not None:
            bounds[0], bounds[1] = bounds[0] + own[0], bounds[1] + own[1]
        c = c[..., None] if w.ndim == 3 else c
        total, cover, every = (w * c, c, w) if total is None else (total + w * c, cover + c, every + w)
    return total / np.maximum(cover, 1.0), cover, every / len(lf.views)


def _refocus_warped(lf: LightField, depth: float, motion=None) -> np.ndarray:
    """Refocus by exact per-view homographies (galvo light fields): each pixel the mean of the views that
    have data there (``covered_mean``); where none has, the mean of all views with reflected borders. The
    mean over every view with reflected borders put mirrored copies of the scene inside the image, a band as
    wide as the views' spread: on the demo, strips of each card 6-10 px in from the edges over a uniform wall,
    25-35 % of its brightness."""
    maps = lf.alignments(depth)
    if motion is not None:
        maps = _with_motion(maps, motion_shifts(lf, motion))
    mean, cover, every = covered_mean(lf, maps)
    return np.maximum(np.where(cover > 0, mean, every), 0.0)


def _covered_borders(lf: LightField, shifts, fourier: np.ndarray) -> np.ndarray:
    """The Fourier shift-and-add (reflected padding: every view counted everywhere) where every view sees the
    pixel, and the mean over the views that do (``covered_mean``, translations by ``shifts``) in the band
    along the edges where some do not: the galvo's mirrored-border copies, at a kaleidoscope's smaller
    spread."""
    maps = np.tile(np.eye(3), (len(shifts), 1, 1))
    maps[:, :2, 2] = shifts
    bounds = [0.0, 0.0]
    mean, cover, _ = covered_mean(lf, maps, bounds=bounds)
    return np.where((cover > 0) & (cover < len(lf.views)), mean,
                    _fourier_within_views(fourier, bounds, len(lf.views)))


def _fourier_within_views(fourier: np.ndarray, bounds, views: int) -> np.ndarray:
    """The Fourier shift-and-add kept within the mean of the views' ``_ring_bounds`` (their sum ``bounds``, taken
    by the same views' warps in ``covered_mean``): an exact sub-pixel shift rings at a sharp edge as Lanczos does
    (black blocks, 0.013, on 6.4 in a 3 x 3 kaleidoscope refocused half a pixel off their alignment: 68 pixels
    below every view's value, clipped to 0)."""
    return np.clip(fourier, bounds[0] / views, bounds[1] / views)


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


def _depth_list(depths, name: str) -> np.ndarray:
    """One or more depths, each > 0 (math.inf allowed)."""
    if isinstance(depths, (str, bytes)) or not np.iterable(depths) or not len(depths):
        raise ConfigError(f"{name} = {depths!r}: expected one or more depths > 0")
    return np.array([number(z, name, 0, lo_open=True, strict=True, inf_ok=True) if z != math.inf else math.inf
                     for z in depths])
