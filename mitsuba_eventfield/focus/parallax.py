"""How far a light field's views move with depth: what depth from focus has to tell depths apart with (its
resolution per pixel), and how finely its planes must be spaced for a focus curve to be sampled at all."""
from __future__ import annotations

import math
import warnings

import cv2
import numpy as np

from ..lightfield.model import LightField

RESOLUTION_GRID_PX = 8      # the view motion varies slowly over the image: computed every 8 pixels, interpolated
DEPTH_TOLERANCE = 0.1       # depth.py's docstring: a confident depth is told from one this share farther
# adjacent depth planes may move the views by at most this (pixels) before the focus curve is undersampled: on
# the demo's cards (160x120, 0.3-4 m, tenengrad) 8 planes (1.4 px a step) read 0.503 m for the 0.5 m card, 4
# (3.4 px) 0.476 m and 2 (10 px) 0.623 m, confidently (a walkthrough: --planes 2 put a card at --near exactly)
MAX_PLANE_STEP_PX = 2.0


class DepthPlanesWarning(UserWarning):
    """Depth planes too far apart for the views' motion: the focus curve is undersampled."""


def _view_motion(lf: LightField, z: float, points: np.ndarray) -> np.ndarray:
    """(K, 2, N): each view's displacement of ``points`` (3, N; homogeneous pixel centres) at depth ``z``, about
    the views' mean."""
    p = lf.alignments(float(z)) @ points
    d = p[:, :2] / p[:, 2:3] - points[:2]
    return d - d.mean(axis=0)


def check_plane_step(lf: LightField, planes: np.ndarray) -> float:
    """The most (pixels, any view, the image's centre and corners) adjacent ``planes`` (uniform in inverse
    depth) move the views apart; a ``DepthPlanesWarning`` where that passes ``MAX_PLANE_STEP_PX``, with the plane
    count that keeps it at 1 px."""
    if len(planes) < 2:
        return 0.0
    h, w = lf.shape
    points = np.array([[w / 2, 0.0, w - 1.0, 0.0, w - 1.0], [h / 2, 0.0, 0.0, h - 1.0, h - 1.0], [1.0] * 5])
    near, far = float(planes[0]), float(planes[-1])
    slope = (_view_motion(lf, near, points) - _view_motion(lf, far, points)) / (1.0 / near - 1.0 / far)
    step = float(np.sqrt((slope ** 2).sum(axis=1)).max()) * abs(1.0 / planes[1] - 1.0 / planes[0])
    if step > MAX_PLANE_STEP_PX:
        need = int(math.ceil((len(planes) - 1) * step)) + 1
        warnings.warn(f"depth planes: {len(planes)} from {near:g} to {far:g} move the views by up to {step:.1f} px "
                      f"from one plane to the next (more than {MAX_PLANE_STEP_PX:g}): the focus curve is "
                      "undersampled, depths between planes come from a fit across them (5-25 % off on the demo's "
                      f"cards at 2-4 planes); {need} planes keep it at 1 px",
                      DepthPlanesWarning, stacklevel=3)
    return step


def depth_resolution_px(lf: LightField, depth: np.ndarray, near: float, far: float,
                        tolerance: float = DEPTH_TOLERANCE) -> np.ndarray:
    """(H, W): how far (RMS over the views, about their mean, pixels) a point at each pixel's ``depth`` moves in
    the views when its depth grows by ``tolerance`` of itself: what the light field gives to tell the two depths
    apart. The views' displacement is close to affine in inverse depth, so its slope is taken between ``near``
    and ``far`` (the range searched), on a grid of pixel centres that ``cv2.resize`` interpolates."""
    h, w = lf.shape
    gh, gw = max(2, -(-h // RESOLUTION_GRID_PX)), max(2, -(-w // RESOLUTION_GRID_PX))
    gx, gy = np.meshgrid((np.arange(gw) + 0.5) * w / gw - 0.5, (np.arange(gh) + 0.5) * h / gh - 0.5)
    points = np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)])           # (3, N): cv2.resize's centres
    slope = (_view_motion(lf, near, points) - _view_motion(lf, far, points)) / (1.0 / near - 1.0 / far)
    rms = np.sqrt(np.mean(np.sum(slope ** 2, axis=1), axis=0)).reshape(gh, gw).astype(np.float32)
    per_inverse_depth = cv2.resize(rms, (w, h), interpolation=cv2.INTER_LINEAR)
    return per_inverse_depth * tolerance / ((1.0 + tolerance) * np.maximum(depth, 1e-12))
