"""Depth calibration: curve size against known depths (the paper's supplement, section 2).

A point source (LED) at known depths z_i gives the scan curve's scale S_i (pixels per radian, from
``galvo.fit_tracks`` on its centroid). Two models are fitted and compared by their residuals in the measured
quantity, the scale (px/rad), where the measurement noise is uniform; depth residuals are reported too, but
they are dominated by the far points, where dS/dz ~ pivot / z^2 is smallest:

* ``linear`` (the paper's): z = c0 + c1 * S;
* ``inverse`` (what the mirror geometry predicts): S = p + q / z, i.e. S = S_inf (1 - pivot / z) to first
  order, so pivot = -q / p. Its p and q are exactly a LightField's disparity model (A, B) once divided by 2
  (light-field positions are optical angles, twice the mechanical ones).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from .galvo import CalibrationError


@dataclass
class DepthCalibration:
    depths: list               # calibration depths (scene units)
    scales: list               # fitted curve scale at each depth (px per mechanical radian, x axis)
    inverse: tuple             # (p, q): S = p + q / z
    linear: tuple              # (c0, c1): z = c0 + c1 * S
    inverse_y: tuple | None    # (p, q) fitted on the y scales, when given (the y mirror pivots further away)
    rms_inverse: float         # residual RMS of each model in scale (px/rad): the comparison
    rms_linear: float
    depth_rms_inverse: float   # and in depth (scene units)
    depth_rms_linear: float
    best: str                  # model with the smaller scale residual
    std: dict = field(default_factory=dict)      # standard errors: p, q, pivot (and p_y, q_y, pivot_y)
    optics: dict = field(default_factory=dict)   # what it was made for (optics.optics_record), set when saved

    @property
    def quality(self) -> dict:
        """How well the fit is determined: residual, pivot uncertainty, depths used."""
        return {"rms_scale_px_per_rad": self.rms_inverse, "pivot": self.pivot, "pivot_std": self.std.get("pivot"),
                "samples": len(self.depths)}

    @property
    def pivot(self) -> float:
        """Distance of the scan pivot in front of the camera implied by the inverse model."""
        p, q = self.inverse
        return -q / p

    def depth(self, scale, model: str | None = None):
        """Depth of a curve scale S (px per rad), with the best (or given) model."""
        s = np.asarray(scale, dtype=np.float64)
        if (model or self.best) == "linear":
            return self.linear[0] + self.linear[1] * s
        p, q = self.inverse
        with np.errstate(divide="ignore"):
            return np.where(s < p, q / (s - p), np.inf)

    def disparity_model(self):
        """((A_x, A_y), (B_x, B_y)) of LightField.alpha(z) = A + B / z, pixels per optical radian. Without y
        scales the x fit is used for both axes (exact only for mirrors at one pivot)."""
        px, qx = self.inverse
        py, qy = self.inverse_y or self.inverse
        return (px / 2, py / 2), (qx / 2, qy / 2)

    def as_dict(self) -> dict:
        return {"kind": "depth", **asdict(self), "quality": self.quality}


def _fit_inverse(z, s, axis: str) -> tuple:
    """S = p + q / z by least squares; (p, q, standard errors of p, q and pivot = -q / p)."""
    A = np.c_[np.ones_like(z), 1 / z]
    (p, q), *_ = np.linalg.lstsq(A, s, rcond=None)
    r = A @ (p, q) - s
    cov = np.linalg.inv(A.T @ A) * float(r @ r) / max(len(z) - 2, 1)
    grad = np.array([q / p ** 2, -1 / p]) if p != 0 else np.array([np.inf, np.inf])   # d pivot / d (p, q)
    std = {f"p{axis}": float(np.sqrt(cov[0, 0])), f"q{axis}": float(np.sqrt(cov[1, 1])),
           f"pivot{axis}": float(np.sqrt(max(grad @ cov @ grad, 0.0)))}
    return float(p), float(q), std


def _check_inverse(p: float, q: float, z, axis: str) -> None:
    """Refuse an inverse-depth model that the mirror geometry cannot produce over the calibrated depths: S grows
    with depth towards S_inf = p > 0 (dS/dz = -q / z^2 > 0, so the pivot -q / p is positive) and stays positive,
    so the pivot lies in front of the nearest depth. Anything else inverts depth maps made with it."""
    where = f"scales along {axis}"
    if not (np.isfinite(p) and np.isfinite(q)):
        raise CalibrationError(f"{where}: the inverse-depth fit is not finite (p = {p}, q = {q})")
    if p <= 0:
        raise CalibrationError(f"{where}: the fitted scale at infinity is {p:.4g} px/rad (<= 0): no galvo shows "
                               "that; check the captures and their depths")
    pivot = -q / p
    if pivot <= 0:
        raise CalibrationError(f"{where}: the fit puts the pivot at {pivot:.4g} (<= 0): the scale shrinks with depth "
                               "where the mirror geometry makes it grow, so depth maps would be inverted; check that "
                               "each capture has its own depth")
    if pivot >= z.min():
        raise CalibrationError(f"{where}: the fit puts the pivot at {pivot:.4g}, beyond the nearest calibration depth "
                               f"{z.min():.4g}: the scale would change sign inside the calibrated range (inverted)")


def fit_depth(depths, scales, scales_y=None) -> DepthCalibration:
    """Fit both models to (depth, curve scale along x) pairs, and the inverse model to the y scales when given.
    Refuses (CalibrationError, with the reason) fewer than 3 distinct depths, non-finite or non-positive input,
    and fits the geometry cannot produce (``_check_inverse``; the linear model's depth falling with scale)."""
    z = np.asarray(depths, dtype=np.float64)
    s = np.asarray(scales, dtype=np.float64)
    if len(z) != len(s) or len(np.unique(z)) < 3:
        raise CalibrationError(f"depth calibration needs at least 3 distinct depths (got {len(np.unique(z))})")
    if not (np.all(np.isfinite(z)) and np.all(z > 0)) or not np.all(np.isfinite(s)):
        raise CalibrationError("depths must be finite and > 0, and scales finite")
    p, q, std = _fit_inverse(z, s, "")
    _check_inverse(p, q, z, "x")
    c0, c1 = np.linalg.lstsq(np.c_[np.ones_like(s), s], z, rcond=None)[0]
    if not c1 > 0:
        raise CalibrationError(f"the linear model z = {c0:.4g} + {c1:.4g} S has depth falling with scale "
                               "(inverted): the scales do not grow with depth")
    rms = lambda e: float(np.sqrt(np.mean(e ** 2)))  # noqa: E731
    rms_inv, rms_lin = rms(p + q / z - s), rms((z - c0) / c1 - s)
    with np.errstate(divide="ignore", invalid="ignore"):
        depth_inv, depth_lin = rms(q / (s - p) - z), rms(c0 + c1 * s - z)
    inverse_y = None
    if scales_y is not None:
        if len(scales_y) != len(z) or not np.all(np.isfinite(scales_y)):
            raise CalibrationError(f"scales_y: {len(scales_y)} values for {len(z)} depths; need one finite scale "
                                   "per depth")
        py, qy, std_y = _fit_inverse(z, np.asarray(scales_y, dtype=np.float64), "_y")
        _check_inverse(py, qy, z, "y")
        inverse_y, std = (py, qy), {**std, **std_y}
    return DepthCalibration(z.tolist(), s.tolist(), (p, q), (float(c0), float(c1)), inverse_y, rms_inv, rms_lin,
                            depth_inv, depth_lin, "inverse" if rms_inv <= rms_lin else "linear", std)
