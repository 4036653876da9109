"""Image outputs: float EXR (with our metadata in the header), tone-mapped PNG, colour-mapped depth with a scale
bar. All writes are atomic (``atomic.py``)."""
from __future__ import annotations

import json
import os

import cv2
import numpy as np

from .atomic import atomic_output
from .errors import EventFieldError


# Rec. 709 / sRGB primaries, as Mitsuba's mi.luminance: what a mono event pixel sees of a colour image
LUMA = np.array([0.212671, 0.715160, 0.072169], np.float32)


def luminance(r, g, b):
    """Luminance of linear R, G, B (arrays or numbers), with the event pixel's weights (``LUMA``)."""
    return r * LUMA[0] + g * LUMA[1] + b * LUMA[2]


# OpenCV decodes only the channels named Y, R, G, B (and A) of an EXR; a file with none of them is unreadable to
# cv2.imread. So the primary channel of a file without one is stored as Y, and its own name (depth, log, ...)
# kept in this header attribute, from which read_exr restores it. (OpenCV also needs OPENCV_IO_ENABLE_OPENEXR=1
# and a build with OpenEXR; docs/design.md "EXR files and OpenCV".)
CV2_CHANNELS = ("Y", "R", "G", "B")
PRIMARY_ATTRIBUTE = "eventfield_primary"


def write_exr(path: str, channels: dict, meta: dict | None = None) -> str:
    """``channels``: name -> (H, W) float array, e.g. {"Y": image}, {"R": r, "G": g, "B": b} (or {"RGB": (H, W, 3)})
    or {"depth": d, "confidence": c}. Float32, ZIP-compressed scanlines: what OpenEXR and OpenCV both read. When
    no channel is one OpenCV reads, the first is stored as Y (see PRIMARY_ATTRIBUTE); read_exr gives the names
    back as they were given."""
    import OpenEXR
    if not path.lower().endswith(".exr"):
        raise EventFieldError(f"{path}: expected a .exr path")
    data = {}
    for name, value in channels.items():
        a = np.asarray(value, dtype=np.float32)
        if name == "RGB" and a.ndim == 3 and a.shape[2] == 3:
            data.update({c: np.ascontiguousarray(a[..., i]) for i, c in enumerate("RGB")})
        elif a.ndim == 2:
            data[name] = np.ascontiguousarray(a)
        else:
            raise EventFieldError(f"{path}: channel {name!r} must be a 2-D (height, width) array, got shape {a.shape}")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    if data and not any(c in data for c in CV2_CHANNELS):
        primary = next(iter(data))
        header[PRIMARY_ATTRIBUTE] = primary
        data = {("Y" if k == primary else k): v for k, v in data.items()}
    if meta:
        header["eventfield_meta"] = json.dumps(meta, default=str)
    with atomic_output(path, "image") as tmp:
        with OpenEXR.File(header, data) as f:
            try:
                f.write(tmp)
            except RuntimeError as e:     # OpenEXR says an OS error in words only: a full disk was "unexpected"
                raise _os_error_of(e, path) from None
    return path


def _os_error_of(e: RuntimeError, path: str) -> Exception:
    """The OSError an OpenEXR write error names (its message ends with the system's own words for it), so that
    a full disk reads as one everywhere; other errors as they were."""
    import errno
    for code in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT, errno.EACCES, errno.EROFS):
        if os.strerror(code) in str(e):
            return OSError(code, os.strerror(code), path)
    return e


def read_exr(path: str) -> tuple[dict, dict]:
    """(channels, meta): name -> (H, W) float array under the names given to write_exr (R, G, B separately for
    a colour image), and our metadata from the header."""
    import OpenEXR
    if not os.path.isfile(path):
        raise EventFieldError(f"{path}: no such EXR file")
    try:
        with OpenEXR.File(path, separate_channels=True) as f:   # (closing it empties its header: read all inside)
            primary, meta = f.header().get(PRIMARY_ATTRIBUTE), f.header().get("eventfield_meta")
            channels = {k: np.array(c.pixels) for k, c in f.channels().items()}
    except Exception as e:             # empty, cut or foreign: OpenEXR says only "Unable to open ... for read"
        raise EventFieldError(f"{path}: not a readable EXR file ({' '.join(str(e).split())[:120]})") from None
    if primary and "Y" in channels and primary not in channels:
        channels = {(primary if k == "Y" else k): v for k, v in channels.items()}
    return channels, json.loads(meta) if meta else {}


def to_uint8(img: np.ndarray, log: bool = False, percentile: float = 99.5) -> np.ndarray:
    """Linear intensity -> 8-bit: scaled so ``percentile`` maps to white, sRGB-like gamma (or log range)."""
    a = np.asarray(img, dtype=np.float64)
    if log:
        lo, hi = np.percentile(a, 100 - percentile), np.percentile(a, percentile)
        out = (a - lo) / max(hi - lo, 1e-12)
    else:
        out = np.clip(a / max(np.percentile(a, percentile), 1e-12), 0, 1) ** (1 / 2.2)
    return (np.clip(out, 0, 1) * 255 + 0.5).astype(np.uint8)


def write_png(path: str, img8: np.ndarray) -> str:
    if not path.lower().endswith(".png"):
        raise EventFieldError(f"{path}: expected a .png path")
    with atomic_output(path, "image") as tmp:
        bgr = img8[..., ::-1] if img8.ndim == 3 else img8
        if not cv2.imwrite(tmp, bgr):
            raise EventFieldError(f"{path}: OpenCV could not write the PNG")
    return path


DEPTH_PNG_MIN_HEIGHT = 120     # px: the scale bar's height; a smaller map is enlarged by a whole factor (up to 8)


def depth_png(depth: np.ndarray, confidence: np.ndarray | None = None, near: float | None = None,
              far: float | None = None, min_confidence: float = 0.2, unit: str = "m") -> np.ndarray:
    """Colour-mapped depth (turbo, near = red) with low-confidence pixels greyed out and a labelled scale bar
    on the right; a map less than ``DEPTH_PNG_MIN_HEIGHT`` tall is shown enlarged by a whole factor, each pixel
    a block (the EXR beside it holds the values). Returns an RGB uint8 image."""
    d = np.asarray(depth, dtype=np.float64)
    good = np.isfinite(d) & ((confidence >= min_confidence) if confidence is not None else True)
    near = float(np.percentile(d[good], 2)) if near is None and good.any() else (near or 0.1)
    far = float(np.percentile(d[good], 98)) if far is None and good.any() else (far or 10.0)
    far = max(far, near * 1.001)
    # map inverse depth (uniform in disparity) so near detail is not crushed
    t = (1 / np.clip(d, near, far) - 1 / far) / (1 / near - 1 / far)
    rgb = cv2.applyColorMap((np.clip(t, 0, 1) * 255).astype(np.uint8), cv2.COLORMAP_TURBO)[..., ::-1].copy()
    rgb[~good] = (96, 96, 96)
    if rgb.shape[0] < DEPTH_PNG_MIN_HEIGHT:        # a small map, pixel for pixel, was a corner of its scale bar
        k = min(8, -(-DEPTH_PNG_MIN_HEIGHT // rgb.shape[0]))
        rgb = np.repeat(np.repeat(rgb, k, axis=0), k, axis=1)
    h = rgb.shape[0]
    scale_h = max(h, DEPTH_PNG_MIN_HEIGHT)
    bar_w, pad = 14, 56
    canvas = np.full((scale_h, rgb.shape[1] + bar_w + pad, 3), 255, np.uint8)
    canvas[:h, :rgb.shape[1]] = rgb
    ramp = np.linspace(1, 0, scale_h - 20)[:, None]                     # top = near
    bar = cv2.applyColorMap((ramp * 255).astype(np.uint8).repeat(bar_w, 1), cv2.COLORMAP_TURBO)[..., ::-1]
    x0 = rgb.shape[1] + 4
    canvas[10:scale_h - 10, x0:x0 + bar_w] = bar
    font = cv2.FONT_HERSHEY_SIMPLEX
    for frac in (0.0, 0.5, 1.0):                                        # labels in depth units at 3 ticks
        inv = 1 / near - frac * (1 / near - 1 / far)
        y = int(10 + frac * (scale_h - 21))
        cv2.putText(canvas, f"{1 / inv:.3g}{unit}", (x0 + bar_w + 2, min(max(y + 4, 10), scale_h - 2)), font,
                    0.33, (0, 0, 0), 1, cv2.LINE_AA)
    return canvas


def depth_colours(near: float, far: float, bad: str = "0.6") -> tuple:
    """(colormap, norm) for a depth panel of a matplotlib figure: ``depth_png``'s scale (turbo over inverse
    depth from ``near`` to ``far``, near red), ``bad`` for masked pixels, so that one depth has one colour in
    every figure and PNG (the demo's figure drew near blue on a linear scale, its depth.png near red)."""
    import matplotlib
    from matplotlib.colors import FuncNorm
    cmap = matplotlib.colormaps["turbo_r"].with_extremes(bad=bad)
    far = max(float(far), float(near) * 1.001)
    def negative_inverse(v):     # increasing in depth; matplotlib also maps 0 (its colour bar's edges): -inf
        with np.errstate(divide="ignore"):
            return -1.0 / np.asarray(v, np.float64)
    return cmap, FuncNorm((negative_inverse, negative_inverse), vmin=float(near), vmax=far, clip=True)


def depth_colourbar(fig, mappable, ax, label: str = "m"):
    """The colour bar of a ``depth_colours`` panel laid out like ``depth_png``'s: near at the top, ticks at
    round depths spread over the inverse-depth scale (linear ticks crowded at its far end)."""
    near, far = mappable.norm.vmin, mappable.norm.vmax
    bar = fig.colorbar(mappable, ax=ax, fraction=0.046, label=label)
    inv = np.linspace(1.0 / near, 1.0 / far, 5)
    bar.set_ticks([float(f"{1.0 / v:.2g}") for v in inv])
    bar.ax.invert_yaxis()
    return bar


def save_figure(fig, path: str, what: str = "figure", dpi: int = 110) -> str:
    """A matplotlib figure as a PNG, atomically (nothing half-written under ``path``), then closed."""
    import matplotlib.pyplot as plt
    with atomic_output(path, what) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)
    return path
