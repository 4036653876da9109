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

from dataclasses import asdict, dataclass

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
        return {"kind": "depth", **asdict(self)}


def fit_depth(depths, scales, scales_y=None) -> DepthCalibration:
    """Fit both models to (depth, curve scale along x) pairs, and the inverse model to the y scales when given;
    refuses with fewer than 3 distinct depths."""
    z = np.asarray(depths, dtype=np.float64)
    s = np.asarray(scales, dtype=np.float64)
    if len(z) != len(s) or len(np.unique(z)) < 3:
        raise CalibrationError(f"depth calibration needs at least 3 distinct depths (got {len(np.unique(z))})")
    if np.any(z <= 0) or not np.all(np.isfinite(s)):
        raise CalibrationError("depths must be > 0 and scales finite")
    A = np.c_[np.ones_like(z), 1 / z]
    p, q = np.linalg.lstsq(A, s, rcond=None)[0]
    c0, c1 = np.linalg.lstsq(np.c_[np.ones_like(s), s], z, rcond=None)[0]
    rms = lambda e: float(np.sqrt(np.mean(e ** 2)))  # noqa: E731
    rms_inv, rms_lin = rms(p + q / z - s), rms((z - c0) / c1 - s)
    with np.errstate(divide="ignore", invalid="ignore"):
        depth_inv, depth_lin = rms(q / (s - p) - z), rms(c0 + c1 * s - z)
    inverse_y = None
    if scales_y is not None:
        if len(scales_y) != len(z) or not np.all(np.isfinite(scales_y)):
            raise CalibrationError(f"scales_y: {len(scales_y)} values for {len(z)} depths; need one finite scale "
                                   "per depth")
        py, qy = np.linalg.lstsq(A, np.asarray(scales_y, dtype=np.float64), rcond=None)[0]
        inverse_y = (float(py), float(qy))
    return DepthCalibration(z.tolist(), s.tolist(), (float(p), float(q)), (float(c0), float(c1)), inverse_y,
                            rms_inv, rms_lin, depth_inv, depth_lin, "inverse" if rms_inv <= rms_lin else "linear")
