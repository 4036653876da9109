"""Galvo view calibration from the data itself (the paper's supplement, section 1).

A patch of the scene, followed through frames reconstructed over a scan, moves along the scan curve: its
displacement from the first frame is

    delta(t) = S * (angles(t + tau0) - angles(tau0))          (pixels; S = diag(Sx, Sy), per radian)

where ``angles`` is the commanded curve of ``mitsuba_eventfield.scan`` (the same code that drives the mirror
and the simulation), ``tau0`` is where on the curve the first frame sits (its phase) and S the pixels per
radian of mechanical angle at the patch's depth (the curve "size", depth-dependent through the pivot). Template
matching (OpenCV, normalised correlation, sub-pixel parabola refinement) measures delta; a robust
least-squares fit (scipy) gives tau0, Sx, Sy and their standard errors. The fit refuses, with the reason,
when the data cannot determine it: too few frames, a textureless patch, weak matches, or an uncertain result.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from mitsuba_eventfield.errors import ConfigError, EventFieldError
from mitsuba_eventfield.focus.measures import parabola_offset
from mitsuba_eventfield.focus.tracking import MIN_MATCH_SCORE   # a match below it is not trusted
from mitsuba_eventfield.optics.galvo import focal_length_px
from mitsuba_eventfield.optics.scan import ScanCurve


class CalibrationError(EventFieldError):
    """The data cannot determine the calibration; the message says why."""


MIN_PATCH_STD = 0.02            # log-intensity spread below which a patch is textureless
# Fewer matched frames than this share of those given: refused. Noise then decides which frames are fitted and
# the fit's standard errors understate its error: in evaluation.failure's noise sweep (a card at 0.5 m, 96 x 72,
# 24 frames from events) fits on 4-9 matched frames were off by 3-13 % in scale while claiming 1-3 %; with half
# the frames or more matched the error stayed under 2 %.
MIN_MATCHED_SHARE = 0.5


@dataclass
class PatchTrack:
    """Sub-pixel displacement of one patch in each frame relative to the first, with match scores."""
    centre: tuple
    delta: np.ndarray           # (K, 2) pixels, x right, y down
    score: np.ndarray           # (K,) normalised correlation of the best match



def fit_std(fit) -> np.ndarray:
    """Standard errors of a ``least_squares`` fit's parameters (Gauss-Newton covariance scaled by the residual
    variance); infinite when the Jacobian is singular."""
    n = len(fit.x)
    sigma2 = float(fit.fun @ fit.fun) / max(len(fit.fun) - n, 1)
    try:
        return np.sqrt(np.maximum(np.diag(np.linalg.inv(fit.jac.T @ fit.jac) * sigma2), 0))
    except np.linalg.LinAlgError:
        return np.full(n, np.inf)

def _subpixel_peak(corr, x, y):
    """Parabola through the peak and its neighbours, per axis."""
    h, w = corr.shape
    dx = parabola_offset(corr[y, x - 1], corr[y, x], corr[y, x + 1]) if 0 < x < w - 1 else 0.0
    dy = parabola_offset(corr[y - 1, x], corr[y, x], corr[y + 1, x]) if 0 < y < h - 1 else 0.0
    return x + dx, y + dy


def track_patch(frames, centre, half: int = 12, search: int = 16) -> PatchTrack:
    """Follow the patch of size (2 half + 1)^2 around ``centre`` (x, y) of frames[0] through all frames."""
    import cv2
    frames = np.asarray(frames, dtype=np.float32)
    k, h, w = frames.shape
    cx, cy = int(round(centre[0])), int(round(centre[1]))
    if not (half + search <= cx < w - half - search and half + search <= cy < h - half - search):
        lo = half + search
        where = (f"x in [{lo}, {w - lo - 1}] and y in [{lo}, {h - lo - 1}]" if w > 2 * lo and h > 2 * lo else
                 f"frames of at least {2 * lo + 1}x{2 * lo + 1} pixels")
        raise CalibrationError(f"patch at ({cx}, {cy}) with half-size {half} and search radius {search} does not "
                               f"fit in the {w}x{h} frames (allowed: {where})")
    tpl = frames[0, cy - half:cy + half + 1, cx - half:cx + half + 1]
    if tpl.std() < MIN_PATCH_STD:
        raise CalibrationError(f"patch at ({cx}, {cy}) is textureless (std {tpl.std():.4f} < {MIN_PATCH_STD}): "
                               "nothing to match; choose a textured patch")
    delta, score = np.zeros((k, 2)), np.zeros(k)
    for i in range(k):
        win = frames[i, cy - half - search:cy + half + search + 1, cx - half - search:cx + half + search + 1]
        corr = cv2.matchTemplate(win, tpl, cv2.TM_CCOEFF_NORMED)
        _, best, _, (bx, by) = cv2.minMaxLoc(corr)
        sx, sy = _subpixel_peak(corr, bx, by)
        delta[i] = (sx - search, sy - search)
        score[i] = best
    return PatchTrack((cx, cy), delta, score)


@dataclass
class GalvoCalibration:
    """Where the first frame sits on the scan curve, and the curve's size at the patch depth."""
    curve: dict                  # the commanded curve (scan.curve_to_dict)
    t_first: float               # time of the first frame in the capture's clock (s)
    tau0: float                  # curve time of the first frame (s): the view of frame k is angles(tau0 + t_k - t_first)
    phase_deg: float             # tau0 as a phase of the period, degrees
    scale_px_per_rad: tuple      # (Sx, Sy) at the patch depth
    std: dict = field(default_factory=dict)   # standard errors: phase_deg, scale_x, scale_y
    rms_px: float = 0.0
    frames_used: int = 0
    patches: list = field(default_factory=list)
    optics: dict = field(default_factory=dict)   # what it was made for (optics.optics_record), set when saved
    # the capture it was fitted on (``capture_of``): a free-running galvo's phase holds for that capture only
    capture: dict = field(default_factory=dict)

    def __post_init__(self):
        """Fields checked as they are read back (a calibration file is edited by hand): tau0 = "abc" failed
        deep in NumPy, NaN as an unnamed LightField error, and a curve edited to another frequency than the
        optics the file was made for was used as it was."""
        from mitsuba_eventfield.optics.scan import curve_from_dict, curve_to_dict
        from mitsuba_eventfield.validate import finite, positive

        from .optics import _same
        for name in ("t_first", "tau0", "phase_deg", "rms_px"):
            setattr(self, name, finite(getattr(self, name), f"galvo calibration: {name}"))
        scale = self.scale_px_per_rad
        if not isinstance(scale, (tuple, list)) or len(scale) != 2:
            raise ConfigError(f"galvo calibration: scale_px_per_rad = {scale!r}: expected two numbers (x, y)")
        self.scale_px_per_rad = tuple(positive(v, "galvo calibration: scale_px_per_rad") for v in scale)
        if not isinstance(self.curve, dict):
            raise ConfigError(f"galvo calibration: curve = {self.curve!r}: expected a scan curve record")
        keys = ("events", "t_first_us", "t_last_us")
        if self.capture != {} and not (isinstance(self.capture, dict) and set(self.capture) == set(keys) and all(
                isinstance(self.capture[k], int) and not isinstance(self.capture[k], bool) for k in keys)):
            raise ConfigError(f"galvo calibration: capture = {self.capture!r}: expected {{}} or the integers "
                              f"{', '.join(keys)} (re-run eventfield calibrate)")
        curve = curve_to_dict(curve_from_dict(self.curve, where="galvo calibration: curve"))
        scan = self.optics.get("scan") if isinstance(self.optics, dict) else None
        if isinstance(scan, dict) and not _same(curve, curve_to_dict(curve_from_dict(scan, where="optics.scan"))):
            raise ConfigError("galvo calibration: its curve differs from the scan of the optics it was made for "
                              "(optics.scan): re-run eventfield calibrate")

    @property
    def quality(self) -> dict:
        """How well the fit is determined: residual, parameter uncertainty, matches used."""
        sx, sy = self.scale_px_per_rad
        rel = max(self.std.get("scale_x", math.inf) / sx, self.std.get("scale_y", math.inf) / sy)
        return {"rms_px": self.rms_px, "phase_std_deg": self.std.get("phase_deg"), "scale_rel_std": rel,
                "samples": self.frames_used}

    def radius_px(self) -> tuple:
        """Curve size in pixels along x and y (scale x the curve's peak angle per axis)."""
        from mitsuba_eventfield.optics.scan import curve_from_dict
        c = curve_from_dict(self.curve)
        t = np.linspace(0, c.period or 1.0, 2001)
        ax, ay = c.angles(t)
        return (self.scale_px_per_rad[0] * np.ptp(ax) / 2, self.scale_px_per_rad[1] * np.ptp(ay) / 2)

    @property
    def clock_phase_deg(self) -> float:
        """Phase of the scan at time 0 of the capture's clock, degrees: independent of which frames were fitted,
        so it compares directly with the phase commanded to the galvo (the mirror's lag shows up here)."""
        from mitsuba_eventfield.optics.scan import curve_from_dict
        period = curve_from_dict(self.curve).period
        return float((self.tau0 - self.t_first) % period / period * 360)

    def view_angles(self, times):
        """Mechanical angles of the views at capture times ``times`` (s)."""
        from mitsuba_eventfield.optics.scan import curve_from_dict
        return curve_from_dict(self.curve).angles(self.tau0 + np.asarray(times, dtype=np.float64) - self.t_first)

    def as_dict(self) -> dict:
        return {"kind": "galvo", **asdict(self), "quality": self.quality}


def capture_of(events) -> dict:
    """What tells one capture from another: its event count and its first and last events' times (us)."""
    n = len(events)
    return {"events": int(n), "t_first_us": int(events.t[0]) if n else 0, "t_last_us": int(events.t[-1]) if n else 0}


def check_capture(calibration: GalvoCalibration, events, where: str = "galvo calibration") -> None:
    """Warn (one line) when a galvo calibration is applied to a capture other than the one it was fitted on:
    without a sync the galvo's phase at the camera's t = 0 differs from capture to capture (a phase fitted on
    one and applied to another read a 0.5 m card at 0.58 m, silently). A camera that clocks the galvo keeps it:
    hence a warning, not a refusal. Files from before 2026-11-27 name no capture: nothing to check."""
    import warnings
    fitted = calibration.capture
    if fitted and fitted != capture_of(events):
        warnings.warn(f"{where}: its phase was fitted on another capture ({fitted['events']} events, "
                      f"{fitted['t_first_us']} to {fitted['t_last_us']} us): a free-running galvo's phase holds "
                      "for that capture only; calibrate this one, unless the galvo is clocked by the camera",
                      stacklevel=3)


def _model(params, curve: ScanCurve, dt):
    tau0, sx, sy = params
    ax, ay = curve.angles(tau0 + dt)
    a0x, a0y = curve.angles(np.float64(tau0))
    return np.stack([sx * (ax - a0x), sy * (ay - a0y)], axis=-1)


def track_point(frames, threshold: float = 0.02) -> PatchTrack:
    """Displacement of a bright point (an LED) from the first frame: intensity-weighted centroid of the pixels
    above ``threshold`` x the frame's maximum (frames in linear intensity). A low threshold keeps the whole
    blob: a truncated blob's centroid shifts with its sub-pixel position."""
    frames = np.asarray(frames, dtype=np.float64)
    ys, xs = np.mgrid[0:frames.shape[1], 0:frames.shape[2]] + 0.5
    cents, score = [], []
    for f in frames:
        w = np.where(f >= threshold * f.max(), f - threshold * f.max(), 0.0)
        if f.max() <= 0 or w.sum() <= 0:
            raise CalibrationError("a frame has no bright point: the LED is outside the view or too dim")
        cents.append(((w * xs).sum() / w.sum(), (w * ys).sum() / w.sum()))
        score.append(1.0)
    c = np.array(cents)
    return PatchTrack(tuple(c[0]), c - c[0], np.array(score))


def galvo_scale_limit(optics: dict, margin: float = 1.25) -> float:
    """The largest curve scale (px per mechanical radian) a galvo with these optics (an ``optics_record``: fov
    and film size) can show: 2 f at infinity (optical angles are twice the mechanical ones; the pivot factor
    1 - pivot / z is below 1 in front of the mirrors), times the keystone 1 + t^2 at the film's corner, times
    ``margin`` for the cross terms. A fit beyond it has locked onto something that is not the scan."""
    width, height = optics["width"], optics["height"]
    f = focal_length_px(width, optics["fov_x_deg"])
    corner = math.hypot(width, height) / 2 / f
    return margin * 2 * f * (1 + corner ** 2)


def scale_note(result: GalvoCalibration, optics: dict, tolerance: float = 0.05) -> str | None:
    """A line for a fit whose curve is larger than these optics can show at any depth where its patches are
    (``GalvoGeometry.scan_scale`` at infinity, the largest; nearer patches show less; off the axis the keystone
    adds t^2): the scan's recorded amplitude is likely smaller than what the mirror did (a driver's gain), and
    the fitted scale, which the light fields do not use (the phase is what a galvo calibration applies), says
    by how much. None when the fit is within ``tolerance`` of that bound."""
    from mitsuba_eventfield.optics.galvo import GalvoGeometry
    nominal = GalvoGeometry(optics["width"], optics["height"], focal_length_px(optics["width"], optics["fov_x_deg"]),
                            0.0, 0.0)
    most = np.max([nominal.scan_scale(math.inf, *patch) for patch in result.patches or [(None, None)]], axis=0)
    ratio = float(np.max(np.asarray(result.scale_px_per_rad) / most))
    if ratio <= 1 + tolerance:
        return None
    return (f"the fitted curve is {ratio:.2f}x the largest these optics show where its patches are "
            f"({most.max():.0f} px/rad, at infinity): the scan moved the mirror about {ratio:.2f}x the recorded "
            "amplitude (check the driver's gain, volts per degree); the calibration's phase is applied, its scale "
            "is not")


def fit_galvo(frames, times, curve: ScanCurve, patches, half: int = 12, search: int = 16,
              max_phase_std_deg: float = 5.0, max_scale_rel_std: float = 0.05,
              scale_limit: float | None = None, min_matched_share: float = MIN_MATCHED_SHARE) -> GalvoCalibration:
    """Calibrate the galvo views from reconstructed frames (log intensity, (K, H, W)) at ``times`` (s).

    ``patches``: centres (x, y) of textured patches at one depth (their displacements are fitted jointly).
    Refuses (CalibrationError) with the reason when frames are too few or not finite, a patch is textureless,
    matches are weak (fewer than ``min_matched_share`` of the frames match), the result is too uncertain
    (phase std > ``max_phase_std_deg`` or scale std > 5%) or physically impossible (a curve radius beyond
    half the frame diagonal, or a scale beyond ``scale_limit``, see ``galvo_scale_limit``).
    """
    frames = np.asarray(frames)
    times = np.asarray(times, dtype=np.float64)
    if frames.ndim != 3 or len(frames) != len(times):
        raise CalibrationError("frames must be (K, H, W) with one time per frame")
    if len(frames) < 4:
        raise CalibrationError(f"{len(frames)} frames: at least 4 are needed (3 unknowns, tau0 and two scales, "
                               "from the displacements of frames 1..K-1)")
    if not np.all(np.isfinite(frames)):
        raise CalibrationError("the frames contain NaN or infinite values")
    tracks = [track_patch(frames, c, half, search) for c in patches]
    result = fit_tracks(tracks, times, curve, max_phase_std_deg, max_scale_rel_std, scale_limit, min_matched_share)
    # the views of one scan must overlap: a radius beyond half the diagonal moves them off the film
    diagonal = math.hypot(frames.shape[1], frames.shape[2])
    if max(result.radius_px()) > diagonal / 2:
        raise CalibrationError(f"absurd curve radius {max(result.radius_px()):.1f} px: beyond half the "
                               f"{frames.shape[2]}x{frames.shape[1]} frame's diagonal ({diagonal / 2:.1f} px)")
    return result


PHASE_AGREEMENT_DEG = 2.0     # the scan phase a solver assumed and the one its frames gave: the same within this


def fit_galvo_consistent(frames_at, curve: ScanCurve, patches, **fit_kw) -> GalvoCalibration:
    """``fit_galvo`` on frames that an events-only solver builds under an assumed scan phase: ``frames_at(dt)``
    returns (frames, times) made with the scan curve moved ``dt`` seconds ahead (``optics.scan.shifted``). That
    solver's views are right only at the true phase, and a camera's clock starts anywhere in the scan
    (docs/calibration.md: 90 deg off read the curve 27 % large). So the frames are made again at the phase
    each fit finds until the two agree (``PHASE_AGREEMENT_DEG``); where the commanded phase gives no fit, from
    half, a quarter and three quarters of a period. The first refusal is raised when no start settles."""
    period, refusals = curve.period, []
    for start in (0.0, 0.5, 0.25, 0.75):
        assumed, found = start * period, None
        try:
            for _ in range(4):
                if found is not None:
                    assumed = found
                result = fit_galvo(*frames_at(assumed), curve, patches, **fit_kw)
                found = (result.tau0 - result.t_first) % period
                if abs((found - assumed + period / 2) % period - period / 2) <= PHASE_AGREEMENT_DEG * period / 360:
                    return result
            refusals.append(CalibrationError(f"the scan phase did not settle: views made at "
                                             f"{assumed * 360 / period:.1f} deg gave {found * 360 / period:.1f} deg"
                                             " after four passes"))
        except CalibrationError as e:
            refusals.append(e)
    raise refusals[0]


def _initial_guess(residuals, curve: ScanCurve, sel_t, obs):
    """Best tau0 on a grid (the curve is periodic: avoid local minima); at each, per axis, the scale and every
    track's offset by one linear least-squares fit. Returns (tau0, sx, sy, offsets (P, 2))."""
    best = None
    o_all = np.concatenate(obs)
    lengths = [len(t) for t in sel_t]
    which = np.repeat(np.arange(len(sel_t)), lengths)
    indicator = (which[:, None] == np.arange(len(sel_t))[None, :]).astype(np.float64)    # (N, P): a track's own
    for tau in np.linspace(0, curve.period, 72, endpoint=False):
        a = np.concatenate([_model((tau, 1.0, 1.0), curve, t) for t in sel_t])
        scales, offsets = [], []
        for axis in (0, 1):
            design = np.column_stack([a[:, axis], indicator])
            solution = np.linalg.lstsq(design, o_all[:, axis], rcond=None)[0]
            scales.append(float(solution[0]))
            offsets.append(solution[1:])
        sx, sy = scales
        if sx <= 1e-9 or sy <= 1e-9:     # a circle fits (tau + T/2, -S) as well: the physical scales are positive
            continue                     # (and above the fit's bound: below it SciPy's error leaked out)
        offsets = np.stack(offsets, axis=-1)
        cost = float(np.sum(residuals(np.concatenate([[tau, sx, sy], offsets.ravel()])) ** 2))
        if best is None or cost < best[0]:
            best = (cost, tau, sx, sy, offsets)
    if best is None:
        moved = float(np.max(np.ptp(o_all, axis=0))) if len(o_all) else 0.0
        raise CalibrationError(f"no phase gives positive curve scales: the patches move by at most {moved:.3g} px "
                               "and not along the scan curve (a static scene or one without the scan, too few "
                               "events, a wrong curve, or a patch that does not move with the scan)")
    return best[1:]


def _check_fit(result: GalvoCalibration, max_phase_std_deg, max_scale_rel_std, scale_limit) -> GalvoCalibration:
    """Refuse an uncertain or physically impossible fit, with the numbers."""
    sx, sy = result.scale_px_per_rad
    std = result.std
    phase_std = std["phase_deg"]
    if not (np.isfinite(sx) and np.isfinite(sy) and np.isfinite(result.tau0) and np.isfinite(result.rms_px)):
        raise CalibrationError(f"the fit gave non-finite values: tau0 {result.tau0}, scales ({sx}, {sy}) px/rad")
    if not np.isfinite(phase_std) or phase_std > max_phase_std_deg or \
            max(std["scale_x"] / max(abs(sx), 1e-9), std["scale_y"] / max(abs(sy), 1e-9)) > max_scale_rel_std:
        raise CalibrationError(f"the fit is too uncertain: phase {result.phase_deg:.2f} +- {phase_std:.2f} deg, "
                               f"scales {sx:.1f} +- {std['scale_x']:.1f}, {sy:.1f} +- {std['scale_y']:.1f} px/rad "
                               f"(rms residual {result.rms_px:.2f} px): more frames, tracks or less noise are needed, "
                               "or the scan's frequency in the optics is not the mirror's")
    if scale_limit is not None and max(sx, sy) > scale_limit:
        raise CalibrationError(f"absurd curve size: scales ({sx:.1f}, {sy:.1f}) px/rad, but these optics show at "
                               f"most {scale_limit:.1f} (2 f with keystone at the film's corner): the tracks do not "
                               "follow the scan")
    return result


def fit_tracks(tracks, times, curve: ScanCurve, max_phase_std_deg: float = 5.0,
               max_scale_rel_std: float = 0.05, scale_limit: float | None = None,
               min_matched_share: float = MIN_MATCHED_SHARE) -> GalvoCalibration:
    """The fit shared by patch tracks (scenes) and point tracks (LED): tau0, Sx, Sy with standard errors.
    Refusals as ``fit_galvo``'s (``scale_limit``: ``galvo_scale_limit`` of the optics, when known).

    Each track also has a constant offset of its own (px, x and y): a track's displacements are measured from
    its first frame, which its template was cut from and matches at a whole pixel, while every later frame
    sits at a sub-pixel shift whose peak estimate is biased by up to half a pixel. Without the offset that
    common bias pinned the first frame off the curve, read as a phase error of about 7 degrees a pixel along the
    first frame's motion: 1.7-2.3 degrees at 24-4096 views on rendered captures (7 sigma by the fit's own
    error), +0.1 at 16. With it, tau0 comes from when the track passes each point of the curve (within 0.3
    degrees on exact frames), and the stated uncertainty matches the scatter between patches."""
    from scipy.optimize import least_squares
    times = np.asarray(times, dtype=np.float64)
    period = curve.period
    if period is None:
        raise CalibrationError("the scan curve is not periodic")
    unknowns = 3 + 2 * len(tracks)           # tau0, two scales, and each track's offset
    if len(times) < 4:
        raise CalibrationError(f"{len(times)} frames: at least 4 are needed (3 unknowns)")
    if not np.all(np.isfinite(times)) or not all(np.all(np.isfinite(tr.delta)) for tr in tracks):
        raise CalibrationError("the frame times or the tracked displacements contain NaN or infinite values")
    dt = times - times[0]
    obs, sel_t = [], []
    for tr in tracks:
        good = tr.score >= MIN_MATCH_SCORE
        good[0] = True
        obs.append(tr.delta[good])
        sel_t.append(dt[good])
    n_good = sum(len(o) for o in obs)
    if 2 * n_good < unknowns + 2 or n_good < 4:
        raise CalibrationError(f"only {n_good} frames match the patches with correlation >= {MIN_MATCH_SCORE}: too "
                               "noisy or the patch leaves the search window; use more frames or a larger search")
    n_given = sum(len(tr.delta) for tr in tracks)
    if n_good < min_matched_share * n_given:
        raise CalibrationError(f"only {n_good} of {n_given} frames match the patches with correlation >= "
                               f"{MIN_MATCH_SCORE} (fewer than {min_matched_share:.0%}): noise decides which frames "
                               "are fitted and the fit's uncertainty would understate its error; use a less noisy "
                               "capture, more textured patches or a larger search")

    def residuals(p):
        offsets = np.reshape(p[3:], (-1, 2))
        return np.concatenate([(_model(p[:3], curve, t) + b - o).ravel() for t, o, b in zip(sel_t, obs, offsets)])

    tau, sx, sy, offsets = _initial_guess(residuals, curve, sel_t, obs)
    free = 2 * len(tracks)
    fit = least_squares(residuals, x0=np.concatenate([[tau, sx, sy], offsets.ravel()]), loss="soft_l1",
                        f_scale=0.5, method="trf",
                        bounds=([-np.inf, 1e-9, 1e-9] + [-np.inf] * free, [np.inf] * (3 + free)),
                        x_scale=[period / 20, abs(sx) + 1, abs(sy) + 1] + [1.0] * free)
    std = fit_std(fit)
    tau0, sx, sy = fit.x[:3]
    tau0 %= period
    result = GalvoCalibration(curve=_curve_dict(curve), t_first=float(times[0]), tau0=float(tau0),
                              phase_deg=float(tau0 / period * 360), scale_px_per_rad=(float(sx), float(sy)),
                              std={"phase_deg": float(std[0] / period * 360), "scale_x": float(std[1]),
                                   "scale_y": float(std[2])},
                              rms_px=float(np.sqrt(np.mean(fit.fun ** 2))), frames_used=n_good,
                              patches=[list(map(float, t.centre)) for t in tracks])
    return _check_fit(result, max_phase_std_deg, max_scale_rel_std, scale_limit)


def _curve_dict(curve: ScanCurve) -> dict:
    from mitsuba_eventfield.optics.scan import curve_to_dict
    return curve_to_dict(curve)
