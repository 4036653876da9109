"""Depth calibration: curve size against known depths (the paper's supplement, section 2).

A point source (LED) at known depths z_i gives the scan curve's scale S_i (pixels per radian, from
``galvo.fit_tracks`` on its centroid). Two models are fitted and compared by their residuals in the measured
quantity, the scale (px/rad), where the measurement noise is uniform; depth residuals are reported too, but
they are dominated by the far points, where dS/dz ~ pivot / z^2 is smallest:

* ``inverse`` (what the mirror geometry predicts, ``optics.galvo.GalvoGeometry.scan_scale``): a point at
  depth z seen at field position t moves by 2 f g (k - pivot / z) pixels per mechanical radian, k = 1 + t^2
  (1 on the axis), so S = p k + q / z with p = 2 f g (g: the mirror's angle gain, 1 when it turns as
  commanded) and pivot = -q / p; (p, q) are the on-axis model (k = 1). Each capture's k comes from where its
  LED's track is centred (``fit_depth_from_tracks``): fitted as if on the axis, an LED at 0.9 of the half width
  (fov 40 deg) read the gain 8.5 % high and the pivot 8 % short. It is used everywhere: ``geometry`` turns it
  into the exact two-mirror geometry (pivots and gains per axis) that refocus and depth from focus map views
  with.
* ``linear`` (the paper's): z = c0 + c1 * S. Size is linear in 1/z, not in z, so this model cannot follow the
  physics; it is kept for comparison, and using it (``depth(..., model="linear")``) warns with the depth range
  outside which it is more than 5 % off the inverse fit.
"""
from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass, field

import numpy as np

from .galvo import CalibrationError

LINEAR_MODEL_TOLERANCE = 0.05     # relative depth error at which the linear model is said to break
# a fitted pivot this many times the nominal mirror distance (or a this-many-th of it) is not a rig's tolerance
# but another unit: LED depths in cm for optics in metres fitted a pivot of 19.96 against 0.2, without a word
PIVOT_PLAUSIBLE = 3.0


@dataclass
class DepthCalibration:
    depths: list               # calibration depths (scene units)
    scales: list               # fitted curve scale at each depth (px per mechanical radian, x axis)
    inverse: tuple             # (p, q): S = p k + q / z (k: the capture's field factor, 1 on the axis)
    linear: tuple              # (c0, c1): z = c0 + c1 * S
    inverse_y: tuple | None    # (p, q) fitted on the y scales, when given (the y mirror pivots further away)
    rms_inverse: float         # residual RMS of each model in scale (px/rad): the comparison
    rms_linear: float
    depth_rms_inverse: float   # and in depth (scene units)
    depth_rms_linear: float
    best: str                  # model with the smaller scale residual
    std: dict = field(default_factory=dict)      # standard errors: p, q, pivot (and p_y, q_y, pivot_y)
    optics: dict = field(default_factory=dict)   # what it was made for (optics.optics_record), set when saved
    field_factors: list | None = None   # per capture (k_x, k_y) where its LED was (None: all on the axis)

    def __post_init__(self):
        """The models checked as a hand-edited file is read, by the fit's own rules (``_check_inverse``): a pivot
        behind the camera (-0.2 m) was loaded and made depth maps."""
        from mitsuba_eventfield.errors import ConfigError
        z = np.asarray(self.depths, dtype=np.float64) if isinstance(self.depths, list) else np.zeros(0)
        if z.size < 3 or not (np.all(np.isfinite(z)) and np.all(z > 0)):
            raise ConfigError(f"depth calibration: depths = {self.depths!r}: expected three or more depths > 0")
        for name, axis in (("inverse", "x"), ("inverse_y", "y")):
            v = getattr(self, name)
            if v is None and name == "inverse_y":
                continue
            if not (isinstance(v, (list, tuple)) and len(v) == 2 and all(
                    isinstance(c, (int, float)) and not isinstance(c, bool) for c in v)):
                raise ConfigError(f"depth calibration: {name} = {v!r}: expected (p, q), two numbers")
            setattr(self, name, tuple(float(c) for c in v))
            try:
                _check_inverse(*getattr(self, name), z, axis)
            except CalibrationError as e:
                raise ConfigError(f"depth calibration: {name}: {e}") from None

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

    def depth(self, scale, model: str = "inverse"):
        """Depth of an on-axis curve scale S (px per rad): the inverse (physical) model, or the paper's
        ``linear`` one (fitted to the scales as measured, wherever the LED was), which warns where it breaks
        (``linear_valid_range``)."""
        s = np.asarray(scale, dtype=np.float64)
        if model == "linear":
            lo, hi = self.linear_valid_range()
            warnings.warn(f"the linear size-vs-depth model cannot follow the mirror geometry (size is linear in "
                          f"1/z): it is within {LINEAR_MODEL_TOLERANCE:.0%} of the inverse fit only for depths "
                          f"{lo:.3g} to {hi:.3g} (calibrated {min(self.depths):.3g} to {max(self.depths):.3g})",
                          stacklevel=2)
            return self.linear[0] + self.linear[1] * s
        if model != "inverse":
            raise ValueError(f"model = {model!r}: allowed inverse, linear")
        p, q = self.inverse
        with np.errstate(divide="ignore"):
            return np.where(s < p, q / (s - p), np.inf)

    def linear_valid_range(self) -> tuple:
        """(nearest, farthest) depth over which the linear model stays within LINEAR_MODEL_TOLERANCE of the
        inverse fit, searched from a tenth of the nearest to ten times the farthest calibration depth."""
        p, q = self.inverse
        # the linear model was fitted to the scales as measured, where the LEDs were: the inverse model there
        k = float(np.mean(np.asarray(self.field_factors)[:, 0])) if self.field_factors else 1.0
        z = np.geomspace(min(self.depths) / 10, max(self.depths) * 10, 4000)
        z = z[z > -q / p * 1.01]                                    # in front of the pivot only
        ok = np.abs(self.linear[0] + self.linear[1] * (p * k + q / z) - z) <= LINEAR_MODEL_TOLERANCE * z
        inside = z[ok]
        return (float(inside.min()), float(inside.max())) if inside.size else (float("nan"), float("nan"))

    def geometry(self, nominal):
        """The exact galvo geometry (``optics.galvo.GalvoGeometry``) with the calibrated pivots and angle gains
        per axis (from S = 2 f g (1 - pivot / z)); the film and focal length of ``nominal``. Without y scales
        the x fit serves both axes (exact only for mirrors at one pivot)."""
        px, qx = self.inverse
        py, qy = self.inverse_y or self.inverse
        two_f = 2.0 * nominal.focal_px
        return nominal.with_pivots(-qx / px, -qy / py, px / two_f, py / two_f)

    def as_dict(self) -> dict:
        return {"kind": "depth", **asdict(self), "quality": self.quality}


def _fit_inverse(z, s, axis: str, k=None) -> tuple:
    """S = p k + q / z by least squares (``k``: each capture's field factor, default 1); (p, q, standard errors
    of p, q and pivot = -q / p)."""
    A = np.c_[np.ones_like(z) if k is None else k, 1 / z]
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


# a fit whose pivot's standard error passes this share of the pivot is refused: it pins nothing. Two depth labels
# swapped (0.8 and 0.4 m) gave 0.018 +- 0.110 (rms 13.6 px/rad), and of five depths 0.061 +- 0.046; the right
# labels 0.0996 +- 0.0007 (0.5 px of noise)
MAX_PIVOT_REL_STD = 0.25


def _check_pinned(p: float, q: float, std: dict, rms: float, axis: str) -> None:
    pivot, err = -q / p, std[f"pivot{'_y' if axis == 'y' else ''}"]
    if not err <= MAX_PIVOT_REL_STD * pivot:
        raise CalibrationError(f"scales along {axis}: the fit does not pin the pivot ({pivot:.4g} +- {err:.2g}, rms "
                               f"{rms:.3g} px/rad): check that each capture is given its own depth")


def fit_depth_from_tracks(depths, fits, geometry) -> DepthCalibration:
    """``fit_depth`` of LED captures: each ``fits`` entry a ``GalvoCalibration`` of one capture
    (``led.fit_led``: its scales and its track's centre, ``patches[0]``), ``geometry`` the captures' nominal
    ``GalvoGeometry`` (its film and focal length give each centre's field factors)."""
    factors = [geometry.field_factors(*fit.patches[0]) for fit in fits]
    result = fit_depth(depths, [fit.scale_px_per_rad[0] for fit in fits], [fit.scale_px_per_rad[1] for fit in fits],
                       field_factors=factors)
    ratio = result.pivot / geometry.pivot_x if geometry.pivot_x > 0 else 1.0
    if not 1 / PIVOT_PLAUSIBLE <= ratio <= PIVOT_PLAUSIBLE:     # the depths' unit, most likely (cm given for m)
        warnings.warn(f"the fitted pivot, {result.pivot:.4g}, is {ratio:.3g} times the optics' mirror distance "
                      f"{geometry.pivot_x:.4g}: are the capture depths in the optics' unit (metres)?", stacklevel=2)
    return result


def fit_depth(depths, scales, scales_y=None, field_factors=None) -> DepthCalibration:
    """Fit both models to (depth, curve scale along x) pairs, and the inverse model to the y scales when given.
    ``field_factors``: each capture's (k_x, k_y) (``GalvoGeometry.field_factors`` where its LED was; None: every LED
    on the axis). Refuses (CalibrationError, with the reason) fewer than 3 distinct depths, non-finite or
    non-positive input, fits the geometry cannot produce (``_check_inverse``; the linear model's depth falling
    with scale) and fits that do not pin the pivot (``MAX_PIVOT_REL_STD``: depth labels swapped)."""
    z = np.asarray(depths, dtype=np.float64)
    s = np.asarray(scales, dtype=np.float64)
    if len(z) != len(s) or len(np.unique(z)) < 3:
        raise CalibrationError(f"depth calibration needs at least 3 distinct depths (got {len(np.unique(z))})")
    if not (np.all(np.isfinite(z)) and np.all(z > 0)) or not np.all(np.isfinite(s)):
        raise CalibrationError("depths must be finite and > 0, and scales finite")
    k = np.ones((len(z), 2)) if field_factors is None else np.asarray(field_factors, dtype=np.float64)
    if k.shape != (len(z), 2) or not (np.all(np.isfinite(k)) and np.all(k >= 1)):
        raise CalibrationError(f"field_factors: shape {k.shape} for {len(z)} depths; need one (k_x, k_y) >= 1 "
                               "per depth")
    p, q, std = _fit_inverse(z, s, "", k[:, 0])
    _check_inverse(p, q, z, "x")
    c0, c1 = np.linalg.lstsq(np.c_[np.ones_like(s), s], z, rcond=None)[0]
    if not c1 > 0:
        raise CalibrationError(f"the linear model z = {c0:.4g} + {c1:.4g} S has depth falling with scale "
                               "(inverted): the scales do not grow with depth")
    rms = lambda e: float(np.sqrt(np.mean(e ** 2)))  # noqa: E731
    rms_inv, rms_lin = rms(p * k[:, 0] + q / z - s), rms((z - c0) / c1 - s)
    _check_pinned(p, q, std, rms_inv, "x")
    with np.errstate(divide="ignore", invalid="ignore"):
        depth_inv, depth_lin = rms(q / (s - p * k[:, 0]) - z), rms(c0 + c1 * s - z)
    inverse_y = None
    if scales_y is not None:
        if len(scales_y) != len(z) or not np.all(np.isfinite(scales_y)):
            raise CalibrationError(f"scales_y: {len(scales_y)} values for {len(z)} depths; need one finite scale "
                                   "per depth")
        py, qy, std_y = _fit_inverse(z, np.asarray(scales_y, dtype=np.float64), "_y", k[:, 1])
        _check_inverse(py, qy, z, "y")
        _check_pinned(py, qy, std_y, rms(py * k[:, 1] + qy / z - np.asarray(scales_y, dtype=np.float64)), "y")
        inverse_y, std = (py, qy), {**std, **std_y}
    return DepthCalibration(z.tolist(), s.tolist(), (p, q), (float(c0), float(c1)), inverse_y, rms_inv, rms_lin,
                            depth_inv, depth_lin, "inverse" if rms_inv <= rms_lin else "linear", std,
                            field_factors=None if field_factors is None else k.tolist())
