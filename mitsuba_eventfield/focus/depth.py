"""Depth from focus on light fields: focus measures over a focal stack, sub-step peak refinement, confidence.

Measures: ``sml`` and ``tenengrad`` on the refocused image (``focus.focus_measure``), and ``variance``
(angular consistency: the spread of the aligned views at a pixel is smallest at the right depth), which uses
the views themselves rather than the refocused image. ``variance`` is the most robust on views reconstructed
from events but resamples every view per plane (Lanczos): about 8x the cost of the others. (Summing shifted
squared views in the Fourier domain was 4x faster, 10x less accurate: squaring doubles the bandwidth.)

The peak is refined between planes by the parabola through it and its neighbours, at an end of the range
with the nearest plane beyond it (``_refine_ends``), never past the range's ends.

Confidence in [0, 1] is c / (c + c0) with c = peak - median of a pixel's focus curve and c0 = 5% of the
90th percentile of c over the image: a textureless pixel has a flat curve and gets ~0 instead of a confident
wrong depth. That floor is relative, so five checks set confidence to 0 (``DepthMap.evidence``,
``DepthMap.at_limit``, ``DepthMap.own_texture``, ``DepthMap.resolution_px``; thresholds from
``evaluation.failure``'s texture-contrast and depth-range sweeps and the scenes named below). The confidence
is a score, not a probability: with these checks nearly every pixel is either 0 or above ~0.75, so thresholds
from 0.2 to 0.7 select nearly the same pixels. ``DepthMap.notes`` says, in words, why textured pixels were not
confident.

* **No parallax in the views.** Where the views barely change over the light field, the focus curve's peak
  comes from the alignment warps alone (identical views refocus sharpest where the warps spread least), not
  from the scene: with texture below the event threshold (no events) every view is the start frame, and 99 %
  of the pixels came out confident with a 67 % depth error. Evidence = the views' spread at a pixel (std of log
  over the views, averaged over the window) over the least spread the scan must give it (the window's log
  gradient x the RMS view displacement at the searched depth of least parallax / sqrt 2). It is 0 without
  events and 1-4 with them; below ``MIN_EVIDENCE`` = 0.3 a pixel is not confident. (The near-end check below
  now refuses such pixels too, but as lying nearer than the range: advice to search nearer for views without
  parallax; this check names the cause: tests/lightfield/test_depth_without_parallax.py.)
* **Too few events.** Views reconstructed from events change in steps of the threshold, one per event. Where
  the view sequence changes level fewer than ``MIN_CHANGES`` = 2 times per pixel (mean over the window), an
  edge is seen to pass but not where to: with the texture 3 thresholds deep (peak to peak) half the pixels
  still came out confident, with a 6 % (tenengrad) or 23 % (variance) median depth error; with this check
  0.2 % stay confident (1.2 % error), and at 6 thresholds deep 88 % (1.7 %). Continuous views (rendered,
  or Monte-Carlo noise) change at every view and always pass. Both checks set ``DepthMap.evidence`` to 0
  where they fail.
* **Peak beyond the range.** A pixel that some plane beyond the range brings into better focus than every
  plane inside it has its depth beyond the range searched (``beyond_range``; ``DepthMap.at_limit``): planes
  one step beyond each end, then out to half the nearest depth searched (``NEAR_BEYOND``) and twice the
  farthest (``FAR_BEYOND``), about 6 more refocused planes (+4 % of the map's time at 96x72, 32 planes). A
  card at 0.5 m searched from 0.52-0.7 m read the nearest plane, 4-40 % off; searched from 1 m its curve
  peaked on a ghost inside the range (63 % of its pixels confident, 100 % off). Now 99-100 % of its pixels
  are flagged from 0.52 to 1 m, and none when searched from 0.3-0.48 m. Not caught: an object nearer than
  half the nearest depth searched.
* **No texture of its own.** The focus window lends a textureless pixel the peak of the texture beside it
  (edge fattening): on scenes/offaxis_cards (96 x 72, events only, 0.3-4 m) the plain wall up to 10.8 px from
  the cards read a card's depth, confidently. ``own_texture`` is the pixel's texture on its most uniform side
  (``measures.one_sided_texture``: the spread of the log image about its plane over the least textured of the
  four focus-window squares the pixel is a corner of) in the image refocused at its sharpest plane; below
  ``OWN_TEXTURE_SHARE`` = 0.2 of the image's 90th percentile a pixel is not confident. Measured around the
  pixel (log gradient, 3 x 3 mean), a wall beside an occluding edge passed (the edge was its texture): a band
  up to 3.3 px (558 wall pixels on offaxis_cards; in the 160 x 120 demo 890 pixels, 17 % of the confident
  ones, more than 10 % off every depth within them). Now 133 and 84 (1.9 %), within 4 px of an edge; the cards
  stay confident (tests/lightfield/test_offaxis_cards.py). The price: a plain pixel beside any edge, a printed one
  too, is not confident (there the data cannot tell them apart): on runner 47 % of the textured pixels
  instead of 66 %, its near tail (90th-percentile error) 5 % instead of 13 % (tests/apps/test_scanrate.py).
* **Depth finer than the optics resolve.** ``depth_resolution_px`` is how far a point at the pixel's depth
  moves in the views (RMS about their mean) when its depth grows by ``DEPTH_TOLERANCE`` = 10 %; below
  ``RESOLVABLE_PX`` = 0.05 px the depth is not confident. From events the textured cards of offaxis_cards
  localise to 0.03-0.11 px (2-3 % depth error at 1.2 and 0.5 m, where 10 % moves 0.14 and 0.34 px); with a
  rendered start frame to 0.010-0.014 px. scenes/galvo_static at 120 x 90 moves its 2.5 m wall 0.010 px for
  10 %: 31 % of that image was confident, 75 % of it more than 10 % off (the wall at the far end of the range)
  and 39 % of it moved by more than 10 % when the period's window moved by 3 us. Now only the card's text is
  confident, 4 % off, and 0.5 % of it moves by more than 10 % (tests/lightfield/test_depth_confidence.py). A
  region's median resolves more than its pixels: the same wall's median depth reads 2.67 m
  (tests/simulate/test_default_steps.py). The check is read at the farthest depth whose focus is within
  ``1 - PLATEAU`` = 10 % of the curve's contrast of its peak (``indistinct_depth``), not at the estimate: an
  unresolved wall's curve is that flat from somewhat nearer than its resolution limit out to the end of the
  range, and the estimate fell near: on the README's galvo_static render (346 x 260) 699 wall pixels away
  from the card read 1.41-1.57 m confidently (resolution limit 1.59 m, truth 2.5), now none; the card keeps
  3459 of its 3466 (tests/lightfield/test_depth_confidence.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import ConfigError
from ..lightfield.model import LightField
from .measures import (IMAGE_MEASURES, focus_measure,  # noqa: F401  (focus_measure, refine_peak: re-exported)
                       check_window, log_gradient, one_sided_texture, parabola_offset, parabola_vertex, refine_peak)
from .parallax import (DEPTH_TOLERANCE, RESOLUTION_GRID_PX, check_plane_step,  # noqa: F401  (re-exported)
                       depth_resolution_px)
from .refocus import aligned_views, check_lightfield, depth_planes, refocus

MEASURES = IMAGE_MEASURES + ("variance",)
# the measure when none is named, in Python and on the command line alike (Python's "sml" against the CLI's
# "variance" put a script's depths up to 3.6 m from the same command's). On an events-only galvo light field
# (galvo_static, 128x96) the angular variance had the lowest median error (0.035 against 0.057 sml, 0.34
# tenengrad); Tenengrad is the kaleidoscope's best and the fastest (README, "Light fields"): name it there.
DEFAULT_MEASURE = "variance"
MIN_EVIDENCE = 0.3          # module docstring: views that change less than this share of what the scan must give
MIN_CHANGES = 2.0           # module docstring: level changes along the views per pixel, mean over the window
OWN_TEXTURE_SHARE = 0.2     # module docstring: a pixel's own texture against the image's 90th percentile ...
OWN_TEXTURE_FLOOR = 5e-3    # ... or this log spread, the larger (a mostly plain image's percentile is rounding)
RESOLVABLE_PX = 0.05        # ... by its views moving at least this far (RMS over the views, pixels) ...
PLATEAU = 0.9               # ... at the farthest depth whose focus is within 10 % of the curve's contrast of its peak
NOTE_SHARE = 0.02           # DepthMap.notes: a reason is reported where it holds for this share of the image
# DepthMap.reasons: why a pixel is not confident, one code a pixel (the depth EXR's "reason" channel)
REASONS = {0: "passed every check (its confidence is its focus curve's peak over the median)",
           1: "no parallax evidence: its views change less than the optics' parallax must (no texture or events)",
           2: "no texture of its own at its depth (beside an edge: the focus window's texture lent to it)",
           3: "sharpest nearer than the depths searched", 4: "sharpest farther than the depths searched",
           5: f"beyond the depth resolution: its focus curve does not tell its depth from one where "
              f"{DEPTH_TOLERANCE:.0%} more depth moves its views less than {RESOLVABLE_PX} px"}
REASON_META = {"reason_codes": {str(code): words for code, words in REASONS.items()}}


@dataclass
class DepthMap:
    depth: np.ndarray          # (H, W) scene units
    confidence: np.ndarray     # (H, W) in [0, 1]
    planes: np.ndarray         # depths searched
    measure: str
    evidence: np.ndarray | None = None   # (H, W) views' change over what the scan must give (module docstring)
    at_limit: np.ndarray | None = None   # (H, W) bool: peak at an end of the range searched (a bound, not a depth)
    own_texture: np.ndarray | None = None     # (H, W) texture on its most uniform side at its depth / image's p90
    resolution_px: np.ndarray | None = None   # (H, W) view motion telling its depth from DEPTH_TOLERANCE farther
    # (H, W) the confidence before the own-texture, resolution and past-the-end checks: how well the depth aligns
    # its views, for methods that map the views at each pixel's depth (focus.galvo_periods). There a depth the
    # optics cannot resolve costs less than RESOLVABLE_PX of alignment, and the image's median would cost more
    focus_confidence: np.ndarray | None = None
    unresolved: np.ndarray | None = None      # (H, W) bool: fails the resolution check alone (module docstring)
    indistinct_depth: np.ndarray | None = None  # (H, W) the farthest depth the focus curve does not tell from its peak

    def notes(self) -> list:
        """Why textured pixels are not confident, as report lines (each only where it holds for at least
        ``NOTE_SHARE`` of the image): sharpest nearer or farther than the depths searched (``at_limit``), or
        beyond the depth resolution (``unresolved``, with the farthest depth the light field resolves: it grows
        in proportion to the views' parallax, for a galvo the film's width, the scan's amplitude and the
        mirror's distance). A pixel sharpest beyond the far end where that end is itself unresolved counts as
        unresolved."""
        reasons = self.reasons()
        if reasons is None:
            return []
        near, far = float(self.planes[0]), float(self.planes[-1])
        unresolved = reasons == 5
        out = []
        for share, where, hint in (((reasons == 3).mean(), f"nearer than {near:.4g}", "search from nearer"),
                                   ((reasons == 4).mean(), f"farther than {far:.4g}", "search farther")):
            if share >= NOTE_SHARE:
                out.append(f"{share:.0%} of the pixels are textured but sharpest {where}, beyond the depths "
                           f"searched: {hint}")
        if unresolved.mean() >= NOTE_SHARE:
            # resolution_px falls as 1 / depth: the depth where it reaches RESOLVABLE_PX, per pixel
            farthest = float(np.median(self.resolution_px * self.depth) / RESOLVABLE_PX)
            out.append(f"{unresolved.mean():.0%} of the pixels are textured but beyond the depth resolution: past a "
                       f"depth of about {farthest:.3g}, {DEPTH_TOLERANCE:.0%} more depth moves the views by less than "
                       f"{RESOLVABLE_PX} px (a wider scan or a larger film resolves farther, in proportion)")
        return out

    def reasons(self) -> np.ndarray | None:
        """(H, W) uint8: the first of ``REASONS`` that holds at each pixel (None for a map made without the
        checks). A pixel sharpest beyond the far end where that end is itself unresolved is unresolved (5)."""
        checks = (self.at_limit, self.own_texture, self.resolution_px, self.evidence, self.unresolved)
        if any(c is None for c in checks):
            return None
        near, far = float(self.planes[0]), float(self.planes[-1])
        nearer = self.at_limit & (1.0 / self.depth > 0.5 * (1.0 / near + 1.0 / far))
        farther = self.at_limit & ~nearer
        out = np.zeros(self.depth.shape, np.uint8)
        own = self.own_texture < OWN_TEXTURE_SHARE
        for code, where in ((4, farther), (5, self.unresolved | (farther & (self.resolution_px < RESOLVABLE_PX))),
                            (3, nearer), (2, own), (1, self.evidence < MIN_EVIDENCE)):
            out[where] = code           # the last written wins: 1 before 2 before 3 ...
        return out

    def channels(self) -> dict:
        """The map as EXR channels: depth, confidence and, where the checks ran, reason (``REASONS``' codes;
        their words go in the file's metadata as ``reason_codes``: ``REASON_META``). Every depth writer uses it."""
        reasons = self.reasons()
        return {"depth": self.depth, "confidence": self.confidence,
                **({"reason": reasons.astype(np.float32)} if reasons is not None else {})}

    def confident_share(self, threshold: float = 0.5, mask=None) -> float:
        """Share of the pixels (of ``mask``) whose confidence reaches ``threshold``: 0 when the light field
        cannot tell depth anywhere (no parallax in its views, everything beyond the range searched)."""
        return float((self.confidence >= threshold)[mask if mask is not None else ...].mean())


def _volume(lf: LightField, planes, measure, window, textures: list | None = None):
    """(D, H, W) focus of each plane; ``textures``: a list that gets each plane's log texture
    (``one_sided_texture`` of the image refocused there, over the focus window: for ``variance``, of the mean
    of the aligned log views)."""
    vol = []
    for z in planes:
        if measure == "variance":
            s1 = s2 = cov = None
            for v, c in aligned_views(lf, float(z)):
                g = v if v.ndim == 2 else v.mean(-1)
                g = np.log(np.maximum(g, 1e-6)) * c          # log: variance independent of brightness
                s1 = g if s1 is None else s1 + g
                s2 = g * g if s2 is None else s2 + g * g
                cov = c if cov is None else cov + c
            cov = np.maximum(cov, 1)
            var = np.maximum(s2 / cov - (s1 / cov) ** 2, 0)
            if textures is not None:
                textures.append(one_sided_texture(s1 / cov, window))
            var = cv2.boxFilter(var.astype(np.float32), -1, (window, window), borderType=cv2.BORDER_REFLECT)
            vol.append(-var)                                    # focus = agreement = low variance
        else:
            img = refocus(lf, float(z), on_motion="ignore")
            img = img if img.ndim == 2 else img.mean(-1)
            vol.append(focus_measure(img, measure, window))
            if textures is not None:
                textures.append(one_sided_texture(np.log(np.maximum(img, 1e-6)), window))
    return np.stack(vol)


def depth_from_focus(lf: LightField, near: float, far: float, planes: int = 32, measure: str = DEFAULT_MEASURE,
                     window: int = 7) -> DepthMap:
    """Per-pixel depth: the plane whose refocused image is sharpest, refined between planes."""
    check_lightfield(lf, "depth_from_focus")
    if measure not in MEASURES:
        raise ConfigError(f"depth_from_focus: unknown focus measure {measure!r}; allowed: {', '.join(MEASURES)}")
    window = check_window(window, "depth_from_focus")
    zs = depth_planes(near, far, planes)
    for value, name in ((near, "near"), (far, "far")):       # named as given (a near one said "refocus: depth")
        lf.check_depth(value, f"depth_from_focus: {name}")
    check_plane_step(lf, zs)
    inv = 1.0 / zs
    textures = []
    vol = _volume(lf, zs, measure, window, textures)           # (D, H, W)
    k = np.argmax(vol, axis=0)
    h, w = k.shape
    kk = np.clip(k, 1, len(zs) - 2)
    rows, cols = np.mgrid[0:h, 0:w]
    off = parabola_offset(vol[kk - 1, rows, cols], vol[kk, rows, cols], vol[kk + 1, rows, cols])
    off = np.where((k == kk), off, 0.0)                        # the ends: _refine_ends
    step = inv[1] - inv[0]                                     # uniform in inverse depth
    inv_depth = inv[k] + off * step
    outer_inv, outer_vol = _outer_volume(lf, inv, measure, window)
    inv_depth, past = _refine_ends(inv, vol, k, *_with_infinity(lf, inv, k, outer_inv, outer_vol, measure, window),
                                   inv_depth)
    depth = 1.0 / np.maximum(inv_depth, 1e-12)
    # confidence: how far the peak stands above the curve's median, against a floor set by the image's
    # well-textured pixels, so a flat (textureless) curve gets ~0 whatever its noise does
    contrast = vol.max(axis=0) - np.median(vol, axis=0)
    floor = 0.05 * float(np.percentile(contrast, 90)) + 1e-12
    conf = contrast / (contrast + floor)
    # the checks of the module docstring
    evidence = parallax_evidence(lf, zs, window)
    beyond = _beyond(vol, outer_vol)   # past: beyond the range too, yet the end plane aligns its views best of
    at_limit, own = beyond | past, own_texture(textures, k)     # the range (focus_confidence: galvo_periods)
    aligns = (evidence >= MIN_EVIDENCE) & ~beyond
    resolution = depth_resolution_px(lf, depth, zs[0], zs[-1])
    textured = own >= OWN_TEXTURE_SHARE
    indistinct = np.maximum(indistinct_depth(vol, k, zs), depth)
    resolved = resolution * depth / indistinct >= RESOLVABLE_PX       # resolution_px falls as 1 / depth
    focus_conf = np.clip(np.nan_to_num(np.where(aligns, conf, 0.0)), 0, 1)
    return DepthMap(depth, np.where(textured & resolved & ~past, focus_conf, 0.0), zs, measure, evidence, at_limit, own,
                    resolution, focus_conf, aligns & textured & ~resolved, indistinct)


# inverse depths beyond each end of the range, as fractions of the end's: up to half the nearest depth searched
# (a card at 0.5 m searched from 1 m focused on a ghost inside the range) and twice the farthest
NEAR_BEYOND = (4 / 3, 5 / 3, 2.0)
FAR_BEYOND = (0.5,)
PAST_END = 0.1      # _refine_ends: a vertex this share of the way to the outer plane past an end (design.md)


def _outer_planes(lf: LightField, inv: np.ndarray) -> list:
    """Depths beyond each end of the range (inverse depths ``inv``, uniform and decreasing): one plane step
    beyond it, then out to ``NEAR_BEYOND`` / ``FAR_BEYOND`` of the end's inverse depth. The nearer ones only
    while the disparity keeps its sign (a galvo has none in front of its pivot); the farther ones only where
    infinity is more than half a plane beyond the farthest plane (else that plane stands for all beyond), and
    where a step beyond it would pass infinity, ``FAR_BEYOND``'s plane alone. All within the depths the light
    field refocuses at (``LightField.depth_range``): a calibrated galvo whose y pivot (0.211 m) lay beyond
    its x pivot had its half-of-0.4 m plane pass the sign test on x and then refused by refocus, which stopped
    ``scanrate-depth --calibration``."""
    step = abs(inv[0] - inv[1])
    near_sign = np.sign(lf.alpha(1.0 / inv[0])[0])
    nearest, farthest = lf.depth_range()
    out = []
    for q in sorted({inv[0] + step, *(inv[0] * f for f in NEAR_BEYOND if inv[0] * f > inv[0] + step)}):
        if np.sign(lf.alpha(1.0 / q)[0]) != near_sign or 1.0 / q < nearest:
            break
        out.append(1.0 / q)
    if inv[-1] > 0.5 * step:
        # a step beyond the farthest plane may pass infinity (few planes): then FAR_BEYOND's planes are the
        # only ones beyond it, whether or not they are a step away
        one_step = inv[-1] - step
        far = {one_step, *(inv[-1] * f for f in FAR_BEYOND if inv[-1] * f < one_step or one_step <= 0)}
        out += [1.0 / q for q in sorted(far, reverse=True) if q > 0 and 1.0 / q <= farthest]
    return out


def _outer_volume(lf: LightField, inv: np.ndarray, measure: str, window: int) -> tuple:
    """(inverse depths, focus volume) of the planes beyond the range (``_outer_planes``); (empty, None) where
    there are none."""
    outer = _outer_planes(lf, inv)
    if not outer:
        return np.zeros(0), None
    return 1.0 / np.asarray(outer, np.float64), _volume(lf, outer, measure, window)


def _beyond(vol: np.ndarray, outer_vol) -> np.ndarray:
    if outer_vol is None:
        return np.zeros(vol.shape[1:], bool)
    return outer_vol.max(axis=0) > vol.max(axis=0)


def beyond_range(lf: LightField, vol: np.ndarray, inv: np.ndarray, measure: str, window: int) -> np.ndarray:
    """(H, W) bool: pixels that some plane beyond the range (``_outer_planes``) brings into better focus than
    every plane of the range (``vol``, over the planes ``inv``): their depth lies beyond the range searched,
    whether the curve peaks at an end plane or on a ghost inside the range (module docstring)."""
    return _beyond(vol, _outer_volume(lf, inv, measure, window)[1])


def _with_infinity(lf: LightField, inv, k, outer_inv, outer_vol, measure: str, window: int) -> tuple:
    """The outer planes, and where none lies beyond the farthest plane (it is within half a step of infinity,
    so it stands for everything beyond in ``beyond_range``) but some pixel peaks there, the plane at infinity
    too: for refining those pixels only, not for flagging them."""
    if (outer_inv < inv[-1]).any() or not (k == len(inv) - 1).any():
        return outer_inv, outer_vol
    at_infinity = _volume(lf, [math.inf], measure, window)
    return (np.append(outer_inv, 0.0),
            at_infinity if outer_vol is None else np.concatenate([outer_vol, at_infinity]))


def _refine_ends(inv, vol, k, outer_inv, outer_vol, inv_depth):
    """(``inv_depth`` with the pixels whose focus curve peaks at an end plane refined like the others, past):
    the parabola through the end plane, its inside neighbour and the nearest outer plane (``beyond_range``'s),
    moved inwards only, at most half the way to the inside neighbour. Without it a card between two of few
    planes read as the end plane, confidently (kaleidoscope cards, 3 planes over 0.5-2 m: 0.6 m at 0.50, 1.5
    m at 2.00). ``past``: the vertex lies over ``PAST_END`` of the way to the outer plane (not the plane at infinity
    ``_with_infinity`` adds) beyond the end plane: the peak is beyond the range (``at_limit``)."""
    past, out = np.zeros(k.shape, bool), inv_depth.copy()
    if outer_vol is None:
        return inv_depth, past
    for end, inside in ((0, 1), (len(inv) - 1, len(inv) - 2)):
        beyond = np.flatnonzero(outer_inv > inv[end]) if end == 0 else np.flatnonzero(outer_inv < inv[end])
        at = k == end
        if not len(beyond) or not at.any():
            continue
        j = beyond[np.argmin(np.abs(outer_inv[beyond] - inv[end]))]
        v = parabola_vertex((outer_inv[j], inv[end], inv[inside]), (outer_vol[j][at], vol[end][at], vol[inside][at]))
        half = inv[end] + 0.5 * (inv[inside] - inv[end])
        out[at] = np.clip(v, min(inv[end], half), max(inv[end], half))
        past[at] = ((v - inv[end]) / (outer_inv[j] - inv[end]) > PAST_END) & (outer_inv[j] > 0)
    return out, past


def view_spread_px(lf: LightField, depths) -> np.ndarray:
    """RMS displacement (pixels) of the views about their mean for a point at each of ``depths`` seen at the
    image centre (off axis a galvo moves points more, so this is the least over the image)."""
    h, w = lf.shape
    centre = np.array([w / 2.0, h / 2.0, 1.0])
    out = []
    for z in depths:
        p = lf.alignments(float(z)) @ centre
        p = p[:, :2] / p[:, 2:3]
        out.append(float(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1)))))
    return np.array(out)


def parallax_evidence(lf: LightField, depths, window: int = 7) -> np.ndarray:
    """(H, W): how much the views change at each pixel (std of log over the views) relative to the least the
    scan must make them change there (log gradient x the least RMS view displacement over ``depths`` /
    sqrt 2), both averaged over the ``window``. 0 for identical views, and where the views change level
    fewer than ``MIN_CHANGES`` times (window mean; module docstring); inf where some depth searched has no
    parallax (then identical views are consistent with it)."""
    views = lf.views if lf.views.ndim == 3 else lf.views.mean(axis=-1)
    logs = np.log(np.maximum(views, 1e-6)).astype(np.float32)
    grad = log_gradient(logs.mean(axis=0))
    box = lambda img: cv2.boxFilter(img.astype(np.float32), -1, (window, window),  # noqa: E731
                                    borderType=cv2.BORDER_REFLECT)
    least = float(view_spread_px(lf, depths).min())
    if least < 1e-6:
        return np.full(lf.shape, np.inf)
    expected = box(grad) * least / math.sqrt(2)
    changes = box((np.abs(np.diff(logs, axis=0)) > 1e-6).sum(axis=0))       # level changes along the views
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(expected > 1e-4, box(logs.std(axis=0)) / expected, 0.0)
    return np.where(changes >= MIN_CHANGES, ratio, 0.0).astype(np.float64)


def own_texture(textures: list, k: np.ndarray) -> np.ndarray:
    """(H, W): each pixel's texture on its most uniform side (``one_sided_texture`` over the focus window) in
    the image refocused at its sharpest plane ``k`` (``textures``: one image a plane), as a share of the image's
    90th percentile (or of ``OWN_TEXTURE_FLOOR``). Only plane ``k``: at the planes beside it an occluding edge is
    blurred over the plain pixels next to it (``k - 1 .. k + 1``: 36 more wrong pixels in the demo)."""
    own = np.zeros(k.shape, np.float32)
    for i, t in enumerate(textures):
        at = k == i
        own[at] = t[at]
    return own / max(float(np.percentile(own, 90)), OWN_TEXTURE_FLOOR)   # a mostly plain image's is ~1e-8


def indistinct_depth(vol: np.ndarray, k: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """(H, W): the farthest depth searched that each pixel's focus curve does not tell from its sharpest plane
    ``k``: planes from ``k`` outwards (farther) while the focus stays within ``1 - PLATEAU`` of the curve's
    contrast (peak over median) of its peak. Depths are told apart worse the farther they are, so this end of
    the interval decides whether the pixel's depth is resolved (module docstring)."""
    peak, median = vol.max(axis=0), np.median(vol, axis=0)
    level = peak - (1.0 - PLATEAU) * (peak - median)
    end, going = k.copy(), np.ones(k.shape, bool)
    for j in range(1, len(planes)):
        going &= (k + j < len(planes)) & (np.take_along_axis(vol, np.minimum(k + j, len(planes) - 1)[None], 0)[0]
                                          >= level)
        if not going.any():
            break
        end[going] = k[going] + j
    return planes[end]
