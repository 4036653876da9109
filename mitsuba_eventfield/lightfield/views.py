"""Views of spatially multiplexed captures (kaleidoscope tiles, microlens arrays) as aligned stacks.

The layout comes from the optics metadata the ``kaleidoscope`` sensor writes into every event file, so a
capture can be split without its scene:

    stack = ef.extract_views(frame, events.meta["optics"])   # (n*n, h, w[, C]), unflipped and aligned
    streams = ef.split_events(events)                        # one EventStream per view, view coordinates
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from ..events.stream import EventStream
from ..validate import instance, number


@dataclass
class ViewStack:
    """n x n views: ``images[k]`` with index ``ij[k]`` and sub-aperture centre ``positions[k]`` (metres on the
    main lens, local frame). Views are unflipped and share one pixel grid: a point on the focus plane sits at
    the same pixel in every view."""
    images: np.ndarray
    ij: np.ndarray
    positions: np.ndarray

    def __post_init__(self):
        self.images = np.asarray(self.images)
        self.ij, self.positions = np.asarray(self.ij), np.asarray(self.positions, dtype=np.float64)
        if self.images.ndim not in (3, 4) or not len(self.images):
            raise ConfigError(f"ViewStack: images shape {self.images.shape}: expected (K, h, w) or (K, h, w, C) "
                              "with K >= 1")
        k = len(self.images)
        if self.ij.shape != (k, 2) or self.positions.shape != (k, 2):
            raise ConfigError(f"ViewStack: ij {self.ij.shape} and positions {self.positions.shape} must both be "
                              f"({k}, 2), one row per image")

    def view(self, i, j) -> np.ndarray:
        """The image of view (i, j): centred indices, whole numbers for an odd view count, halves for an even
        one (a microlens array of 2 or 4 views a side has no view (0, 0))."""
        found = np.nonzero((self.ij[:, 0] == i) & (self.ij[:, 1] == j))[0]
        if not len(found):
            lo, hi = self.ij.min(axis=0), self.ij.max(axis=0)
            raise ConfigError(f"ViewStack.view: no view ({i}, {j}); i runs {lo[0]:g}..{hi[0]:g} and j "
                              f"{lo[1]:g}..{hi[1]:g} in steps of 1")
        return self.images[int(found[0])]


def _layout(optics: dict, where: str):
    instance(optics, dict, f"{where}: optics", "an event stream's meta['optics']")
    if optics.get("design") not in ("kaleidoscope", "microlens") or "views" not in optics:
        raise ConfigError(f"{where}: the metadata describes no kaleidoscope or microlens layout (optics.design "
                          f"is {optics.get('design')!r})")
    return optics["design"], optics["views"]


def extract_views(frame: np.ndarray, optics: dict, margin: int = 0) -> ViewStack:
    """Split a film image (H, W[, C]) into its views; ``margin`` crops pixels off each tile edge (seams)."""
    design, views = _layout(optics, "extract_views")
    frame = np.asarray(frame)
    if frame.ndim not in (2, 3) or not frame.size or not np.issubdtype(frame.dtype, np.number):
        raise ConfigError(f"extract_views: frame of shape {frame.shape} ({frame.dtype}): expected a film image "
                          "(H, W) or (H, W, C) of numbers")
    _check_film(frame.shape[:2], optics, design, views, "extract_views: frame")
    most = (min(min(v["tile"][2:4]) for v in views) - 1) // 2 if design == "kaleidoscope" else None
    margin = int(number(margin, "extract_views: margin", 0, most, integer=True, strict=True))
    out = []
    for v in views:
        if design == "kaleidoscope":
            x0, y0, w, h = v["tile"]
            tile = frame[y0 + margin:y0 + h - margin, x0 + margin:x0 + w - margin]
            if v["flip_x"]:
                tile = tile[:, ::-1]
            if v["flip_y"]:
                tile = tile[::-1]
        else:
            ox, oy = v["pixel_offset"]
            tile = frame[oy::v["stride"], ox::v["stride"]]
        out.append(np.ascontiguousarray(tile))
    return ViewStack(np.stack(out), np.array([[v["i"], v["j"]] for v in views]),
                     np.array([v["subaperture"] for v in views], dtype=np.float64))


def _check_film(shape, optics: dict, design: str, views: list, what: str) -> None:
    """The film (height, width) ``shape`` against the layout: n x n views, a kaleidoscope's tiles covering it
    exactly, a microlens film a whole number of lenslets (n pixels) a side. A smaller frame failed inside
    NumPy; a larger one was cut silently."""
    n = optics.get("n")
    if not isinstance(n, int) or n < 1 or len(views) != n * n:
        raise ConfigError(f"{what}: the optics metadata lists {len(views)} views for n = {n!r}: expected n x n")
    if design == "kaleidoscope":
        need = (max(v["tile"][1] + v["tile"][3] for v in views), max(v["tile"][0] + v["tile"][2] for v in views))
        if tuple(shape) != need:
            raise ConfigError(f"{what} is {shape[1]}x{shape[0]} pixels: the kaleidoscope's {n}x{n} tiles cover "
                              f"{need[1]}x{need[0]}")
    elif shape[0] % n or shape[1] % n:
        raise ConfigError(f"{what} is {shape[1]}x{shape[0]} pixels: a microlens film of {n} views a side is a "
                          f"whole number of {n}-pixel lenslets in each direction")


def view_of_pixel(x, y, optics: dict):
    """Per pixel: (view index k, x and y in that view's unflipped coordinates)."""
    design, views = _layout(optics, "view_of_pixel")
    x, y = np.broadcast_arrays(np.asarray(x, np.int64), np.asarray(y, np.int64))
    n = optics["n"]
    if design == "kaleidoscope":
        tw, th = views[0]["tile"][2], views[0]["tile"][3]
        outside = (x < 0) | (x >= n * tw) | (y < 0) | (y >= n * th)
    else:
        outside = (x < 0) | (y < 0)
    if np.any(outside):        # a negative index picked the last view, one past the film a view that is not there
        k = int(np.argmax(outside))
        raise ConfigError(f"view_of_pixel: pixel ({int(x.flat[k])}, {int(y.flat[k])}) is outside the film"
                          + (f" ({n * tw}x{n * th})" if design == "kaleidoscope" else ""))
    if design == "kaleidoscope":
        col, row = x // tw, y // th
        k = row * n + col
        flip_x = np.array([v["flip_x"] for v in views])[k]
        flip_y = np.array([v["flip_y"] for v in views])[k]
        vx, vy = x - col * tw, y - row * th
        return k, np.where(flip_x, tw - 1 - vx, vx), np.where(flip_y, th - 1 - vy, vy)
    col, row = x % n, y % n
    return row * n + col, x // n, y // n


def split_events(events: EventStream) -> list:
    """One EventStream per view (same order as the metadata's views), in unflipped view coordinates."""
    instance(events, EventStream, "split_events: events", "ef.read_events, ef.render_events")
    optics = events.meta.get("optics", {})
    design, views = _layout(optics, "split_events")
    _check_film((events.height, events.width), optics, design, views, "split_events: the stream's film")
    k, vx, vy = view_of_pixel(events.x, events.y, optics)
    if design == "kaleidoscope":
        w, h = views[0]["tile"][2], views[0]["tile"][3]
    else:
        w, h = events.width // optics["n"], events.height // optics["n"]
    out = []
    for idx, v in enumerate(views):
        sel = k == idx
        meta = dict(events.meta, view={"i": v["i"], "j": v["j"], "subaperture": v["subaperture"]})
        out.append(EventStream(vx[sel], vy[sel], events.t[sel], events.p[sel], w, h, meta))
    return out
