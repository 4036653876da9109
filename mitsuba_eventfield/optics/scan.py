"""Galvo scan curves: the one definition used by the galvo sensor, the device waveforms and the calibration.

A curve gives the two **mechanical** mirror angles (x, y) in radians at time t (seconds); the optical
deflection is twice that. Every curve evaluates on NumPy arrays and on Dr.Jit arrays with the same code path
(``xp`` is ``numpy`` or ``drjit``), so what the renderer traces is what the device is told to drive.

Curves (``make_curve(name, **params)`` or ``curve_from_dict``), angles in degrees at the interface:

* ``circle``: frequency, amplitude (radius), phase, centre offsets. x = A cos(2 pi f t + phi), y = A sin(...).
* ``lissajous``: freq_x, freq_y, amplitude_x, amplitude_y, phase_x, phase_y (x = A_x sin(2 pi f_x t + phi_x)).
  ``line`` is a Lissajous with one axis at zero amplitude.
* ``raster``: triangle wave in x at ``frequency`` (two lines per period of x), slow triangle in y over ``lines``.
* ``moore``: a Moore curve (the closed Hilbert curve) of a given ``order`` traversed at constant speed once per
  period: a space-filling scan of the square [-A, A]^2.

``with_bandwidth(natural_hz, damping)`` returns what a mirror with a second-order response actually does:
each sinusoid is scaled by |H| and delayed by arg H (exact for circles and Lissajous; other curves are filtered
harmonic by harmonic from a table). A record's ``time_offset`` (s) moves the curve ahead in time (``shifted``):
where a galvo calibration places the views of a recording (``calibration.calibrated_optics``).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from fractions import Fraction
from functools import cached_property

import numpy as np

from ..errors import ConfigError
from ..validate import finite, number
from .envelope import (DEFAULT_DAMPING, DEFAULT_GALVO_MODEL, IDEAL_TRAVEL_DEG, EnvelopeError, galvo_model,
                       second_order_response)
from .galvo import OPTICAL_PER_MECHANICAL

DEFAULT_MAX_ANGLE_DEG = IDEAL_TRAVEL_DEG   # the mechanical travel curves had before galvo models existed
TWO_PI = 2.0 * math.pi


def _xp(t):
    """numpy for NumPy input or Python numbers, drjit for Dr.Jit arrays."""
    if isinstance(t, (np.ndarray, float, int, np.floating, np.integer)):
        return np
    import drjit as dr
    return dr


def _frac(xp, v):
    return v - xp.floor(v)


@dataclass(frozen=True)
class ScanCurve:
    """Base class. Subclasses define :meth:`angles` and :meth:`velocity` (rad and rad/s, mechanical).
    ``galvo_model``/``max_angle_deg``: the envelope the scan must stay in (``optics.envelope``)."""
    max_angle_deg: float = DEFAULT_MAX_ANGLE_DEG
    galvo_model: str = "ideal"

    @property
    def name(self) -> str:
        return getattr(self, "kind", "curve")

    @property
    def period(self) -> float | None:
        raise NotImplementedError

    def angles(self, t):
        raise NotImplementedError

    def velocity(self, t):
        raise NotImplementedError

    def optical_angles(self, t):
        """Beam deflection (``galvo.OPTICAL_PER_MECHANICAL`` x mechanical): a view's light-field position."""
        ax, ay = self.angles(t)
        return OPTICAL_PER_MECHANICAL * ax, OPTICAL_PER_MECHANICAL * ay

    def peak_angle_deg(self) -> float:
        t = np.linspace(0.0, self.period or 1.0, 4097)
        ax, ay = self.angles(t)
        return float(np.degrees(max(np.max(np.abs(ax)), np.max(np.abs(ay)))))

    def to_dict(self) -> dict:
        d = {k: v for k, v in asdict(self).items() if not k.startswith("_") and k != "kind"}
        d["curve"] = self.name
        return d

    # ------------------------------------------------------------------ inverse: when is a point reached?
    def times_of(self, point_rad, tol_rad: float | None = None, samples: int = 20000) -> np.ndarray:
        """All times in [0, period) at which the curve passes through ``point_rad`` (x, y), refined to
        machine precision; ``tol_rad`` is how close the curve must come (default: 1e-6 of its extent)."""
        from scipy.optimize import minimize_scalar
        T = self.period
        if T is None:
            raise ValueError(f"{self.name}: not periodic, so the time of a point is not defined")
        px, py = point_rad
        t = np.arange(samples) * (T / samples)
        ax, ay = self.angles(t)
        d2 = (ax - px) ** 2 + (ay - py) ** 2
        extent = max(np.ptp(ax), np.ptp(ay), 1e-12)
        tol = 1e-6 * extent if tol_rad is None else tol_rad
        minima = np.nonzero((d2 <= np.roll(d2, 1)) & (d2 < np.roll(d2, -1)))[0]
        out = []
        for i in minima:
            f = lambda s: float(np.sum((np.array(self.angles(np.float64(s))) - (px, py)) ** 2))  # noqa: E731
            r = minimize_scalar(f, bounds=(t[i] - T / samples, t[i] + T / samples), method="bounded",
                                options={"xatol": 1e-15 * max(T, 1.0)})
            if r.fun <= tol ** 2:
                out.append(r.x % T)
        return np.sort(np.array(out))

    def time_of(self, point_rad, tol_rad: float | None = None) -> float:
        """First time in [0, period) at which the curve passes through ``point_rad``."""
        ts = self.times_of(point_rad, tol_rad)
        if len(ts) == 0:
            raise ValueError(f"{self.name}: the curve does not pass through {tuple(point_rad)} rad")
        return float(ts[0])

    def phase_time(self, t: float) -> float:
        """``t`` reduced into [0, period), in float64 and rounded to the nanosecond, so that instants one period
        apart give bit-identical values (float32 time would lose the phase after a few seconds)."""
        T = self.period
        if T is None:
            return t
        phase, whole = round(math.fmod(t, T) % T, 9), round(T, 9)
        return 0.0 if phase >= whole else phase     # fmod can land a hair below T: that instant is phase 0

    def envelope(self, where: str = "scan"):
        return galvo_model(self.galvo_model, where, self.max_angle_deg)

    def validate(self, where: str = "scan", envelope=None) -> "ScanCurve":
        """The curve itself if its galvo (``envelope``, default: its model's) can drive it; else EnvelopeError
        with the device layer's reason, prefixed by ``where``."""
        try:
            (envelope or self.envelope(where)).check_curve(self)
        except EnvelopeError as e:
            raise EnvelopeError(f"{where}: {e}" if not str(e).startswith(where) else str(e)) from None
        return self


@dataclass(frozen=True)
class Lissajous(ScanCurve):
    """x = ox + Ax sin(2 pi fx t + phx), y = oy + Ay sin(2 pi fy t + phy); angles in degrees, phases in degrees."""
    freq_x: float = 250.0
    freq_y: float = 250.0
    amplitude_x: float = 1.0
    amplitude_y: float = 1.0
    phase_x: float = 90.0
    phase_y: float = 0.0
    offset_x: float = 0.0
    offset_y: float = 0.0
    kind: str = "lissajous"      # "circle" and "line" are Lissajous curves too; kept for metadata and messages

    def _params(self):
        r = math.radians
        return (TWO_PI * self.freq_x, TWO_PI * self.freq_y, r(self.amplitude_x), r(self.amplitude_y),
                r(self.phase_x), r(self.phase_y), r(self.offset_x), r(self.offset_y))

    @cached_property         # the curve is frozen; the rationals cost ~10 us, and a render asks every step
    def period(self) -> float | None:
        fx, fy = self.freq_x, self.freq_y
        if self.amplitude_x == 0:
            fx = fy
        if self.amplitude_y == 0:
            fy = fx
        if fx == fy:              # one frequency (a circle, a line): 1 / f at any f (1e-5 Hz had no period here)
            return 1.0 / fx
        fx, fy = (Fraction(f).limit_denominator(10_000) for f in (fx, fy))
        if abs(float(fx) - self.freq_x) > 1e-9 * self.freq_x or abs(float(fy) - self.freq_y) > 1e-9 * self.freq_y:
            return None
        # gcd of two rationals: gcd(numerators) / lcm(denominators)
        g = Fraction(math.gcd(fx.numerator * fy.denominator, fy.numerator * fx.denominator),
                     fx.denominator * fy.denominator)
        return float(1 / g)

    def angles(self, t):
        xp = _xp(t)
        wx, wy, ax, ay, px, py, ox, oy = self._params()
        return ox + ax * xp.sin(wx * t + px), oy + ay * xp.sin(wy * t + py)

    def velocity(self, t):
        xp = _xp(t)
        wx, wy, ax, ay, px, py, _, _ = self._params()
        return ax * wx * xp.cos(wx * t + px), ay * wy * xp.cos(wy * t + py)

    def peak_angle_deg(self) -> float:
        return max(abs(self.offset_x) + abs(self.amplitude_x), abs(self.offset_y) + abs(self.amplitude_y))

    def with_bandwidth(self, natural_hz: float, damping: float = DEFAULT_DAMPING) -> "Lissajous":
        """Steady-state response of second-order mirrors: each axis scaled by |H(f)| and delayed by arg H(f)."""
        hx, hy = second_order_response(self.freq_x, natural_hz, damping), second_order_response(self.freq_y, natural_hz, damping)
        return replace(self, amplitude_x=self.amplitude_x * abs(hx), amplitude_y=self.amplitude_y * abs(hy),
                       phase_x=self.phase_x + math.degrees(np.angle(hx)),
                       phase_y=self.phase_y + math.degrees(np.angle(hy)))


def circle(frequency=250.0, amplitude=1.0, phase=0.0, offset_x=0.0, offset_y=0.0,
           max_angle_deg=DEFAULT_MAX_ANGLE_DEG, galvo_model="ideal") -> Lissajous:
    """Counter-clockwise circle of radius ``amplitude`` mechanical degrees, starting at angle ``phase``."""
    c = Lissajous(max_angle_deg=max_angle_deg, galvo_model=galvo_model, freq_x=frequency, freq_y=frequency, amplitude_x=amplitude,
                  amplitude_y=amplitude, phase_x=phase + 90.0, phase_y=phase, offset_x=offset_x, offset_y=offset_y,
                  kind="circle")
    return c


@dataclass(frozen=True)
class TabulatedCurve(ScanCurve):
    """A periodic curve given by samples over one period, linearly interpolated (raster, Moore, filtered)."""
    period_s: float = 1.0
    source: dict = field(default_factory=dict)       # how the table was made, for metadata
    _table: tuple = field(default=(), repr=False)     # ((x...), (y...)) in radians, len N (periodic)
    kind: str = "tabulated"
    time_shift: float = 0.0                           # s: angles(t) reads the table at t + time_shift

    @property
    def period(self) -> float:
        return self.period_s

    def _lookup(self, t, derivative=False):
        xp = _xp(t)
        tx, ty = self._table
        n = len(tx)
        u = _frac(xp, ((t + self.time_shift) if self.time_shift else t) / self.period_s) * n   # renders: no shift
        if xp is np:
            i0 = np.floor(u).astype(np.int64) % n
            i1 = (i0 + 1) % n
            w = u - np.floor(u)
            ax, ay = np.asarray(tx), np.asarray(ty)
            g = lambda a, i: a[i]  # noqa: E731
        else:
            import drjit as dr
            import mitsuba as mi
            i0 = mi.UInt32(dr.floor(u)) % n
            i1 = (i0 + 1) % n
            w = u - dr.floor(u)
            ax, ay = mi.Float(tx), mi.Float(ty)
            g = lambda a, i: dr.gather(mi.Float, a, i)  # noqa: E731
        x0, x1, y0, y1 = g(ax, i0), g(ax, i1), g(ay, i0), g(ay, i1)
        if derivative:
            s = n / self.period_s
            return (x1 - x0) * s, (y1 - y0) * s
        return x0 + (x1 - x0) * w, y0 + (y1 - y0) * w

    def angles(self, t):
        return self._lookup(t)

    def velocity(self, t):
        return self._lookup(t, derivative=True)

    def peak_angle_deg(self) -> float:
        return float(np.degrees(max(np.max(np.abs(self._table[0])), np.max(np.abs(self._table[1])))))

    def fundamental_hz(self) -> float:
        """The faster axis's back-and-forth rate: half its direction reversals per period, over the period."""
        rates = []
        for axis in self._table:
            step = np.diff(np.asarray(axis + axis[:1]))
            moving = np.sign(step[step != 0])
            reversals = int(np.count_nonzero(moving != np.roll(moving, 1))) if moving.size else 0
            rates.append(max(reversals, 2) / 2 / self.period_s)
        return max(rates)

    def to_dict(self) -> dict:
        return dict(self.source, max_angle_deg=self.max_angle_deg, galvo_model=self.galvo_model)

    def with_bandwidth(self, natural_hz: float, damping: float = DEFAULT_DAMPING) -> "TabulatedCurve":
        n = len(self._table[0])
        freqs = np.fft.rfftfreq(n, d=self.period_s / n)
        h = second_order_response(freqs, natural_hz, damping)
        filt = [np.fft.irfft(np.fft.rfft(np.asarray(a)) * h, n) for a in self._table]
        src = dict(self.source, bandwidth_hz=natural_hz, damping=damping)
        return replace(self, source=src, _table=(tuple(filt[0]), tuple(filt[1])))


CURVES = ("circle", "lissajous", "line", "raster", "moore")
_ARGS = {
    "circle": {"frequency", "amplitude", "phase", "offset_x", "offset_y"},
    "lissajous": {"freq_x", "freq_y", "amplitude_x", "amplitude_y", "phase_x", "phase_y", "offset_x", "offset_y"},
    "line": {"frequency", "amplitude", "phase", "axis"},
    "raster": {"frequency", "lines", "amplitude_x", "amplitude_y", "samples_per_line"},
    "moore": {"frequency", "order", "amplitude", "samples_per_segment"},
}
_FREQ_KEYS = ("frequency", "freq_x", "freq_y")


def make_curve(name: str, max_angle_deg: float | None = None, bandwidth_hz: float = 0.0,
               damping: float = DEFAULT_DAMPING, where: str = "scan", galvo_model: str = DEFAULT_GALVO_MODEL,
               envelope=None, **params) -> ScanCurve:
    """Build a curve by name and check it against the envelope of ``galvo_model`` (``optics.envelope``; a
    scan the device layer refuses is refused here with the same reason). ``max_angle_deg``: narrows a real
    galvo's travel, or sets an ideal mirror's (default: the model's own). ``envelope``: a rig's own
    ``ScanEnvelope`` instead of a named model (the device layer's, with its driver scaling). Errors name ``where``,
    the parameter and its allowed range. The check is of the commanded curve, before any ``bandwidth_hz``."""
    if name not in CURVES:
        raise ConfigError(f"{where}: unknown curve {name!r}; allowed: {', '.join(CURVES)}")
    unknown = set(params) - _ARGS[name]
    if unknown:
        raise ConfigError(f"{where}: parameter {sorted(unknown)[0]!r} does not apply to a {name} scan; "
                          f"allowed: {', '.join(sorted(_ARGS[name]))}")
    envelope = envelope or _envelope(galvo_model, where, max_angle_deg)
    top = envelope.max_frequency        # the range a bad frequency names; above it the envelope's check says so
    for k, f in ((k, params[k]) for k in _FREQ_KEYS if k in params):
        if not (isinstance(f, (int, float)) and top < f < math.inf):
            number(f, f"{where}: {k} (Hz)", 0, top if math.isfinite(top) else None, lo_open=True, strict=True)
    for k, v in params.items():
        if k not in _FREQ_KEYS and k != "axis":
            finite(v, f"{where}: {k}")
    limits = {"max_angle_deg": envelope.max_mech_deg, "galvo_model": envelope.name}
    if name == "circle":
        curve = circle(**limits, **params)
    elif name == "lissajous":
        curve = Lissajous(**limits, **params)
    elif name == "line":
        axis = params.pop("axis", "x")
        if axis not in ("x", "y"):
            raise ConfigError(f"{where}: axis = {axis!r}: allowed values are 'x', 'y'")
        f, a, ph = params.get("frequency", 250.0), params.get("amplitude", 1.0), params.get("phase", 0.0)
        curve = Lissajous(**limits, freq_x=f, freq_y=f, amplitude_x=a if axis == "x" else 0.0,
                          amplitude_y=a if axis == "y" else 0.0, phase_x=ph, phase_y=ph, kind="line")
    elif name == "raster":
        from .tabulated import raster, whole_counts
        curve = raster(**limits, **whole_counts("raster", params, where))
    else:
        from .tabulated import moore, whole_counts
        curve = moore(**limits, **whole_counts("moore", params, where))
    curve.validate(where, envelope)              # the commanded scan is what the galvo must be able to drive
    if bandwidth_hz:              # 0: the default, an ideal mirror
        number(bandwidth_hz, f"{where}: bandwidth (Hz; 0: an ideal mirror)", 0, strict=True)
        if not (math.isfinite(damping) and damping > 0):
            raise ConfigError(f"{where}: damping = {damping!r}: must be a finite number > 0")
        curve = curve.with_bandwidth(bandwidth_hz, damping)
        # a lightly damped mirror overshoots: what it actually does must stay within its travel too
        try:
            envelope.check_travel(f"the {curve.name} scan as the mirror responds (bandwidth {bandwidth_hz:g} Hz, "
                                  f"damping {damping:g})", curve.peak_angle_deg(), 0.0)
        except EnvelopeError as e:
            raise EnvelopeError(f"{where}: {e}") from None
    return curve


def _envelope(name, where, max_angle_deg):
    if not isinstance(name, str):
        raise ConfigError(f"{where}: galvo_model = {name!r}: expected a name")
    return galvo_model(name, where, max_angle_deg)


def curve_to_dict(curve: ScanCurve, bandwidth_hz: float = 0.0, damping: float = DEFAULT_DAMPING) -> dict:
    """A description from which :func:`curve_from_dict` rebuilds the same curve (stored in event metadata)."""
    if isinstance(curve, TabulatedCurve):
        d = dict(curve.source, **({"time_offset": curve.time_shift} if curve.time_shift else {}))
        # a filtered table keeps its bandwidth_hz / damping unless overridden
        if bandwidth_hz:
            d.pop("bandwidth_hz", None), d.pop("damping", None)
    else:
        d = curve.to_dict()
        if d["curve"] == "circle":
            d = {"curve": "circle", "frequency": curve.freq_x, "amplitude": curve.amplitude_x,
                 "phase": curve.phase_y, "offset_x": curve.offset_x, "offset_y": curve.offset_y}
        elif d["curve"] == "line":
            axis = "x" if curve.amplitude_x else "y"
            d = {"curve": "line", "axis": axis, "frequency": curve.freq_x,
                 "amplitude": curve.amplitude_x or curve.amplitude_y, "phase": curve.phase_x}
        d.pop("max_angle_deg", None), d.pop("galvo_model", None)
    d["max_angle_deg"] = curve.max_angle_deg
    d["galvo_model"] = curve.galvo_model
    if bandwidth_hz:
        d["bandwidth_hz"], d["damping"] = bandwidth_hz, damping
    return d


def curve_from_dict(d: dict, where: str = "scan") -> ScanCurve:
    """The curve a ``curve_to_dict`` record describes. Records without a galvo model were written before the
    models existed, under the ideal mirror's 10 degree travel: they are read that way."""
    if not isinstance(d, dict):
        raise ConfigError(f"{where}: expected a scan record (a dict with 'curve', 'frequency', ...), "
                          f"got {type(d).__name__}")
    d = dict(d)
    name, shift = d.pop("curve", None), finite(d.pop("time_offset", 0.0), f"{where}: time_offset")
    curve = make_curve(name, max_angle_deg=d.pop("max_angle_deg", DEFAULT_MAX_ANGLE_DEG),
                       bandwidth_hz=d.pop("bandwidth_hz", 0.0), damping=d.pop("damping", DEFAULT_DAMPING), where=where,
                       galvo_model=d.pop("galvo_model", "ideal"), **d)
    return shifted(curve, shift) if shift else curve


def shifted(curve: ScanCurve, dt: float) -> ScanCurve:
    """``curve`` ``dt`` seconds ahead: its angles at t are the original's at t + dt (a Lissajous's phases move)."""
    if isinstance(curve, Lissajous):
        return replace(curve, phase_x=(curve.phase_x + 360.0 * curve.freq_x * dt) % 360.0,
                       phase_y=(curve.phase_y + 360.0 * curve.freq_y * dt) % 360.0)
    return replace(curve, time_shift=curve.time_shift + float(dt))


def event_angles(events, actual: bool = True):
    """Mechanical mirror angles (x, y) in radians at each event's timestamp, from the stream's metadata alone.
    ``actual``: include the recorded mirror bandwidth (what the mirror did), else the commanded curve (of
    calibrated optics, the scan the record held before the calibration's fit: ``commanded_scan``)."""
    optics = events.meta.get("optics", {})
    if optics.get("design") != "galvo" or "scan" not in optics:
        raise ConfigError("event_angles: the event stream's metadata describes no galvo scan "
                          "(optics.design != 'galvo')")
    d = dict(optics["scan"] if actual else optics.get("commanded_scan", optics["scan"]))
    if not actual:
        d.pop("bandwidth_hz", None), d.pop("damping", None)
    curve = curve_from_dict(d, where="event metadata")
    return curve.angles(np.asarray(events.t, dtype=np.float64) * 1e-6)


def scan_period(scan: dict, where: str = "event metadata") -> float:
    """The period (s) of the scan a metadata record describes; ConfigError when the scan is not periodic
    (view times and scan periods then have to be chosen explicitly)."""
    period = curve_from_dict(scan, where=where).period
    if period is None:
        raise ConfigError(f"{where}: the scan ({scan.get('curve')!r}) is not periodic: choose view times "
                          "explicitly")
    return period
