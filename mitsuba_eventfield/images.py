"""Image outputs: float EXR (with our metadata in the header), tone-mapped PNG, colour-mapped depth with a scale
bar. All writes are atomic (``atomic.py``)."""
from __future__ import annotations

import json

import cv2
import numpy as np

from .atomic import atomic_output
from .errors import EventFieldError


def write_exr(path: str, channels: dict, meta: dict | None = None) -> str:
    """``channels``: name -> (H, W) float array (e.g. {"Y": image} or {"depth": d, "confidence": c})."""
    import OpenEXR
    if not path.lower().endswith(".exr"):
        raise EventFieldError(f"{path}: expected a .exr path")
    data = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in channels.items()}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    if meta:
        header["eventfield_meta"] = json.dumps(meta, default=str)
    with atomic_output(path, "image") as tmp:
        with OpenEXR.File(header, data) as f:
            f.write(tmp)
    return path


def read_exr(path: str) -> tuple[dict, dict]:
    import OpenEXR
    with OpenEXR.File(path) as f:
        meta = f.header().get("eventfield_meta")
        return ({k: np.array(c.pixels) for k, c in f.channels().items()}, json.loads(meta) if meta else {})


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


def depth_png(depth: np.ndarray, confidence: np.ndarray | None = None, near: float | None = None,
              far: float | None = None, min_confidence: float = 0.2, unit: str = "m") -> np.ndarray:
    """Colour-mapped depth (turbo, near = red) with low-confidence pixels greyed out and a labelled scale bar
    on the right. Returns an RGB uint8 image."""
    d = np.asarray(depth, dtype=np.float64)
    good = np.isfinite(d) & ((confidence >= min_confidence) if confidence is not None else True)
    near = float(np.percentile(d[good], 2)) if near is None and good.any() else (near or 0.1)
    far = float(np.percentile(d[good], 98)) if far is None and good.any() else (far or 10.0)
    far = max(far, near * 1.001)
    # map inverse depth (uniform in disparity) so near detail is not crushed
    t = (1 / np.clip(d, near, far) - 1 / far) / (1 / near - 1 / far)
    rgb = cv2.applyColorMap((np.clip(t, 0, 1) * 255).astype(np.uint8), cv2.COLORMAP_TURBO)[..., ::-1].copy()
    rgb[~good] = (96, 96, 96)
    h = rgb.shape[0]
    scale_h = max(h, 120)
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
