"""Event frames as images: ON events red, OFF events blue, on white, over a time window."""
from __future__ import annotations

import numpy as np

from ..atomic import atomic_output
from ..errors import ConfigError, EventFieldError
from ..validate import check_allocation, file_path, finite, instance, number, positive
from .stream import EventStream


def _check_window(events, t0_us, t1_us, where: str) -> None:
    """An EventStream and a time window [t0, t1) of finite microseconds (either end None: open)."""
    instance(events, EventStream, f"{where}: events", "ef.read_events, ef.render_events")
    t0, t1 = (None if v is None else finite(v, f"{where}: {n}") for v, n in ((t0_us, "t0_us"), (t1_us, "t1_us")))
    if t0 is not None and t1 is not None and t1 < t0:
        raise ConfigError(f"{where}: t1_us = {t1_us!r} is before t0_us = {t0_us!r}: the window must have t0 <= t1")


def window_outside(events: EventStream, t0_us=None, t1_us=None) -> bool:
    """Whether the window [t0, t1) lies wholly outside the stream's span (its picture would be empty, written
    as if it were a result)."""
    end = events.start_us + int(events.duration_us)
    return (t0_us is not None and t0_us > end) or (t1_us is not None and t1_us <= events.start_us)


def event_frame_rgb(events: EventStream, t0_us=None, t1_us=None, saturation: int | None = None) -> np.ndarray:
    """(H, W, 3) uint8 RGB image of the events in [t0, t1): net ON red, net OFF blue, on white.

    Colour strength is the net count (ON - OFF) over ``saturation`` (default: the 99th percentile of the
    non-zero |net| counts, at least 1). Pixels whose events cancel are drawn light grey.
    """
    _check_window(events, t0_us, t1_us, "event_frame_rgb")
    if saturation is not None:
        saturation = positive(saturation, "event_frame_rgb: saturation")
    win = events.time_window(t0_us, t1_us)
    net = win.signed_counts().astype(np.float64)
    if saturation is None:
        nz = np.abs(net[net != 0])
        saturation = max(1.0, float(np.percentile(nz, 99))) if len(nz) else 1.0
    a_on, a_off = np.clip(net / saturation, 0, 1), np.clip(-net / saturation, 0, 1)
    img = np.ones(net.shape + (3,))
    img[..., 1] -= np.maximum(a_on, a_off)
    img[..., 2] -= a_on                      # ON -> red
    img[..., 0] -= a_off                     # OFF -> blue
    cancelled = (net == 0) & (win.counts() > 0)
    img[cancelled] = 0.85
    return (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8)


PREVIEW_MIN_SIDE = 400      # px: a smaller sensor's preview is enlarged by a whole factor (96x72 was unreadable)


def auto_scale(width: int, height: int) -> int:
    """The whole factor (up to 8) that brings a ``width`` x ``height`` preview to ``PREVIEW_MIN_SIDE`` pixels
    along its longer side, each event pixel a block."""
    return int(min(8, max(1, -(-PREVIEW_MIN_SIDE // max(width, height, 1)))))


def write_preview(path: str, events: EventStream, t0_us=None, t1_us=None, scale: int | None = None) -> str:
    """A PNG of the events in [t0_us, t1_us) (ON red, OFF blue), enlarged ``scale`` times (None:
    ``auto_scale``)."""
    import cv2
    path = file_path(path, "write_preview: path")
    if not path.lower().endswith(".png"):
        raise EventFieldError(f"{path}: preview must be a .png file")
    if scale is not None:
        scale = number(scale, "scale", 1, 64, integer=True)
    _check_window(events, t0_us, t1_us, "write_preview")
    scale = auto_scale(events.width, events.height) if scale is None else scale
    if window_outside(events, t0_us, t1_us):
        raise EventFieldError(f"{path}: the window t0_us = {t0_us!r}, t1_us = {t1_us!r} is outside the stream, which "
                              f"covers {events.start_us} to {events.start_us + int(events.duration_us)} us")
    if events.width == 0 or events.height == 0:
        raise EventFieldError(f"{path}: cannot preview a {events.width}x{events.height} sensor")
    # the float working image (24 bytes a pixel) and the upscaled one (3 bytes a pixel): a 65536 x 65536
    # sensor asked for 32 GiB in a MemoryError
    check_allocation(events.width * events.height * (24 + 3 * scale * scale), f"{path}: a preview of "
                     f"{events.width}x{events.height} pixels at scale {scale}")
    img = event_frame_rgb(events, t0_us, t1_us)
    if scale > 1:
        img = np.repeat(np.repeat(img, scale, axis=0), scale, axis=1)
    with atomic_output(path, "preview") as tmp:
        if not cv2.imwrite(tmp, img[..., ::-1]):
            raise EventFieldError(f"{path}: OpenCV could not write the PNG")
    return path
