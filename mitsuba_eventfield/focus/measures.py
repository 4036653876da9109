"""Focus measures and sub-step peak refinement: the leaf every focus-based method (depth from focus, focus
tracking, refocus scoring, calibration peak finding) calls. NumPy and OpenCV only.

Measures (``focus_measure``): ``sml`` (sum-modified-Laplacian) and ``tenengrad`` (Sobel gradient energy), both
averaged over a window. ``depth.depth_from_focus`` adds ``variance`` (angular consistency of the aligned
views), which needs the views rather than one image. Texture: ``log_gradient`` (symmetric, per pixel) and
``one_sided_texture`` (a pixel's most uniform side: not lent across an occluding edge).
"""
from __future__ import annotations

import cv2
import numpy as np

from ..errors import ConfigError
from ..validate import array, number

IMAGE_MEASURES = ("sml", "tenengrad")
MAX_WINDOW = 255      # pixels: the box a focus measure is averaged over


def check_window(window, where: str) -> int:
    """The focus measure's averaging box: a whole number of pixels in [1, MAX_WINDOW]."""
    return int(number(window, f"{where}: window", 1, MAX_WINDOW, integer=True, strict=True))


def focus_measure(img: np.ndarray, measure: str = "sml", window: int = 7) -> np.ndarray:
    """Per-pixel focus of one image (H, W), aggregated over a ``window`` x ``window`` box."""
    img = array(img, "focus_measure: img", 2).astype(np.float32)
    window = check_window(window, "focus_measure")
    if measure == "sml":
        kx = np.array([[0, 0, 0], [-1, 2, -1], [0, 0, 0]], np.float32)
        m = np.abs(cv2.filter2D(img, -1, kx)) + np.abs(cv2.filter2D(img, -1, kx.T))
    elif measure == "tenengrad":
        gx, gy = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3)
        m = gx * gx + gy * gy
    else:
        raise ConfigError(f"focus_measure: unknown focus measure {measure!r}; allowed: {', '.join(IMAGE_MEASURES)}")
    return cv2.boxFilter(m, -1, (window, window), normalize=True, borderType=cv2.BORDER_REFLECT)


def log_gradient(log_img) -> np.ndarray:
    """(H, W) gradient magnitude of a log image per pixel (Sobel / 8: the slope of a ramp per pixel): the
    texture measure of depth from focus's evidence check and of the scoring's textured pixels."""
    g = np.asarray(log_img, np.float32)
    return np.hypot(cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3)) / 8


def one_sided_texture(log_img, box: int = 7) -> np.ndarray:
    """(H, W) texture on each pixel's most uniform side: the standard deviation of the log image about its
    best-fitting plane over a ``box`` x ``box`` square with the pixel at one of its corners, the least of the
    four such squares.

    A symmetric measure (a gradient, a window around the pixel) is as high on the plain side of an occluding
    edge as on the textured side: the edge itself is the texture. A pixel of a plain wall beside a nearer
    card has one side (away from the card) that is plain, so its least corner square is flat; a pixel of the
    card has card texture on every side. The plane is taken out because defocus leaves a linear ramp as it is:
    a ramp (shading, or the blurred edge of a card refocused far from it) tells no depth, and with the plain
    deviation a wall 5-7 px from offaxis_cards' near card, refocused at 0.3 m, passed as textured. Depth from
    focus reads this as the texture a pixel's depth rests on (``depth.own_texture``)."""
    g = np.asarray(log_img, np.float64)
    if g.ndim != 2:
        raise ConfigError(f"one_sided_texture: log_img has shape {g.shape}: expected an (H, W) image")
    box = check_window(box, "one_sided_texture")

    def mean(a):         # over the centred square; reflected at the image's border, the coordinates with it
        return cv2.boxFilter(a, -1, (box, box), borderType=cv2.BORDER_REFLECT)

    # OpenCV's box of even size covers c - box // 2 .. c + (box - 1) // 2: the squares with the pixel at a corner
    # are centred (box - 1) // 2 before it and box // 2 after it on each axis. The image and its coordinates are
    # reflected by box // 2 first (as the box filter reflects them), so that squares centred beyond the border
    # exist, and a ramp stays a plane across the reflection
    h, w = g.shape
    lo, hi = (box - 1) // 2, box // 2
    g = np.pad(g, hi, mode="symmetric")
    m = mean(g)
    var = mean(g * g) - m * m
    for x in np.indices((h, w), np.float64):                       # y, then x: the plane's two slopes
        x = np.pad(x - x.mean(), hi, mode="symmetric")             # centred: less cancellation
        mx = mean(x)
        var_x = mean(x * x) - mx * mx
        cov = mean(g * x) - m * mx
        var = var - np.where(var_x > 1e-9, cov * cov / np.maximum(var_x, 1e-9), 0.0)
    spread = np.sqrt(np.maximum(var, 0.0))
    spread = np.where(np.isfinite(spread), spread, 0.0)           # no texture where the image is not finite
    least = np.min([spread[hi + dy:hi + dy + h, hi + dx:hi + dx + w] for dy in (-lo, hi) for dx in (-lo, hi)],
                   axis=0)
    return least.astype(np.float32)


def parabola_offset(before, peak, after):
    """Offset in [-0.5, 0.5] steps of the vertex of the parabola through three samples around a maximum
    (0 where they do not curve downwards). Numbers or arrays that broadcast."""
    return parabola_vertex((-1.0, 0.0, 1.0), (before, peak, after))


def parabola_vertex(x, y):
    """Position of the vertex of the parabola through three points ``(x[i], y[i])`` around a maximum at
    ``x[1]`` (spacing need not be uniform: an end plane's neighbour beyond the range is not a plane step
    away), kept within half the way to each neighbour; ``x[1]`` where the points do not curve downwards.
    ``x``: three numbers; ``y``: three numbers or arrays that broadcast. With uniform spacing this is
    :func:`parabola_offset` in ``x`` units."""
    d0, d2 = float(x[0]) - float(x[1]), float(x[2]) - float(x[1])
    e0, e2 = (np.asarray(y[0], np.float64) - y[1]), (np.asarray(y[2], np.float64) - y[1])
    a = (e0 / d0 - e2 / d2) / (d0 - d2)           # y - y1 = a t^2 + b t, t = x - x1
    b = e0 / d0 - a * d0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(a < 0, np.clip(-b / (2 * a), min(d0, d2) / 2, max(d0, d2) / 2), 0.0)
    return float(x[1]) + (float(t) if t.ndim == 0 else t)


def refine_peak(x, scores, k):
    """Sub-step position (in x units) of the maximum of ``scores`` at index ``k`` (the parabola through it and
    its neighbours, at their own positions: ``track_focus`` takes a caller's depths, whose inverses need not be
    evenly spaced, and the offset of even steps scaled by one side's step missed the vertex there; the end
    samples are not refined)."""
    if k <= 0 or k >= len(scores) - 1:
        return x[k]
    return parabola_vertex(x[k - 1:k + 2], scores[k - 1:k + 2])
