"""What a galvo can be driven to do: the one scan envelope the simulator and the device layer both enforce.

A scan is refused here, with one message, whether it comes from a scene's ``galvo`` sensor, ``make_curve`` or
``eventfield device scan``: the device layer (``device/spec.py``) adds only the generator's own limits.

The limits of a galvo model (``GALVO_MODELS``):

* the mechanical travel (``max_mech_deg``, |offset| + amplitude per axis);
* frequency derating: the largest sine amplitude falls with frequency (peak angular acceleration is bounded),
  interpolated log-log between measured (frequency, amplitude) points, nothing above the last frequency;
* the drive: ``volts_per_deg`` (the driver's jumper) times |offset| + amplitude within +-``max_volts``.

``gvs01x`` carries the Thorlabs GVS01x-class figures (docs/design.md, "Galvo controller facts"; docs/device.md):
+-10 V input at 0.8 V per mechanical degree (12.5 deg travel), a full-travel sine only to about 35 Hz, half
travel to about 130 Hz, and 0.2 deg at 1 kHz (the small-angle bandwidth). ``ideal`` is a mirror without
derating or drive limit, only the 10 deg travel the simulator has always assumed: for exploring designs
beyond today's hardware, and for files written before galvo models existed.

Sine scans (circle, line, Lissajous) are checked axis by axis exactly as the device drives them. Tabulated
scans (raster, Moore), which a sine generator cannot drive, get a necessary condition only: their peak angle
against the travel and against the sine derating at their faster axis's back-and-forth rate. A triangle's
corners need more acceleration than a sine of the same rate and amplitude, so a refused tabulated scan is
certainly impossible, but an accepted one is not thereby safe to drive.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .. import validate
from ..errors import ConfigError

PHASE_RANGE_DEG = (-360.0, 360.0)
IDEAL_TRAVEL_DEG = 10.0        # the limitless "ideal" mirror's mechanical travel (the curves' before galvo models)
DEFAULT_DAMPING = 0.7          # a mirror's second-order response (``second_order_response``) when none is given
# Drivers scale 0.5-1.0 V per mechanical degree; anything outside this bracket is a typo (or a unit mix-up of
# optical vs mechanical degrees or mV) that would scale every voltage we send by the same mistake.
VOLTS_PER_DEG_RANGE = (0.1, 2.0)
MAX_CURVE_PHASE_DEG = 720.0     # the circle adds 90 deg to the user's phase; beyond +-720 deg is a mistake


class EnvelopeError(ConfigError):
    """A scan outside the galvo's envelope (the message names the axis, the value and the limit)."""


def finite(value, what: str) -> float:
    """``value`` as a float if it is a real, finite number (not bool, NaN or inf); else EnvelopeError."""
    return validate.finite(value, what, error=EnvelopeError)


@dataclass(frozen=True)
class AxisSine:
    """One mirror axis of a sine scan, as a generator channel drives it (degrees, mechanical)."""
    channel: int
    frequency: float
    amplitude_deg: float
    phase_deg: float
    offset_deg: float

    @property
    def is_dc(self) -> bool:
        return self.amplitude_deg == 0.0


def axis_sines(curve) -> list:
    """The per-axis sines of a circle / line / Lissajous scan (channel 1 = x mirror, 2 = y mirror)."""
    if getattr(curve, "kind", None) not in ("circle", "line", "lissajous"):
        raise EnvelopeError(f"the {getattr(curve, 'name', curve)!r} scan is not a pair of sines: a function "
                            "generator drives circles, lines and Lissajous curves only (sine only)")
    out = []
    for ch, axis, (f, a, ph, off) in ((1, "x", (curve.freq_x, curve.amplitude_x, curve.phase_x, curve.offset_x)),
                                      (2, "y", (curve.freq_y, curve.amplitude_y, curve.phase_y, curve.offset_y))):
        ph = finite(ph, f"axis {axis}: phase")
        if abs(ph) > MAX_CURVE_PHASE_DEG:
            raise EnvelopeError(f"axis {axis}: phase {ph:g} deg: allowed range is +-{MAX_CURVE_PHASE_DEG:g} deg")
        out.append(AxisSine(ch, f, a, ph % 360.0, off))
    return out


@dataclass(frozen=True)
class ScanEnvelope:
    name: str = "gvs01x"
    max_mech_deg: float = 12.5
    # (frequency Hz, largest sine amplitude in mechanical degrees), increasing frequency; () = no derating
    derating: tuple = ((35.0, 12.5), (130.0, 6.25), (1000.0, 0.2))
    volts_per_deg: float | None = 0.8      # None: no drive limit (a simulated ideal mirror)
    max_volts: float = 10.0

    @property
    def max_frequency(self) -> float:
        return self.derating[-1][0] if self.derating else math.inf

    def derated_amplitude_deg(self, frequency: float) -> float:
        """The derating alone at ``frequency`` (log-log interpolation of its points; inf without derating)."""
        pts = self.derating
        if not pts:
            return math.inf
        if frequency <= pts[0][0]:
            return pts[0][1]
        for (f0, a0), (f1, a1) in zip(pts[:-1], pts[1:]):
            if frequency <= f1:
                w = math.log(frequency / f0) / math.log(f1 / f0)
                return math.exp(math.log(a0) + w * (math.log(a1) - math.log(a0)))
        return 0.0

    def max_amplitude_deg(self, frequency: float) -> float:
        """Largest sine amplitude (around zero offset) at ``frequency``: the derating and the travel."""
        return min(self.derated_amplitude_deg(frequency), self.max_mech_deg)

    def check_travel(self, where: str, amplitude_deg: float, offset_deg: float) -> None:
        reach = abs(offset_deg) + amplitude_deg
        if reach > self.max_mech_deg * (1 + 1e-12):
            raise EnvelopeError(f"{where}: |offset| + amplitude = {reach:g} deg exceeds the mechanical travel of "
                                f"+-{self.max_mech_deg:g} deg")
        if self.volts_per_deg is not None and reach * self.volts_per_deg > self.max_volts * (1 + 1e-12):
            raise EnvelopeError(f"{where}: |offset| + amplitude = {reach * self.volts_per_deg:g} V exceeds the "
                                f"+-{self.max_volts:g} V command input")

    def check_axis(self, axis: str, frequency: float, amplitude_deg: float, offset_deg: float,
                   phase_deg: float = 0.0) -> None:
        """Raise EnvelopeError naming the limit if the sine on this axis is unsafe (amplitude 0: a DC level)."""
        for name, v in (("frequency", frequency), ("amplitude", amplitude_deg), ("offset", offset_deg),
                        ("phase", phase_deg)):
            finite(v, f"axis {axis}: {name}")
        if not PHASE_RANGE_DEG[0] <= phase_deg <= PHASE_RANGE_DEG[1]:
            raise EnvelopeError(f"axis {axis}: phase {phase_deg:g} deg: allowed range is {PHASE_RANGE_DEG[0]:g} "
                                f"to {PHASE_RANGE_DEG[1]:g} deg")
        if frequency <= 0:
            raise EnvelopeError(f"axis {axis}: frequency {frequency} Hz must be > 0")
        if amplitude_deg < 0:
            raise EnvelopeError(f"axis {axis}: amplitude {amplitude_deg} deg must be >= 0")
        if frequency > self.max_frequency:
            raise EnvelopeError(f"axis {axis}: {frequency:g} Hz is above the galvo's {self.max_frequency:g} Hz "
                                "limit")
        limit = self.derated_amplitude_deg(frequency)
        if amplitude_deg > limit * (1 + 1e-12):
            raise EnvelopeError(f"axis {axis}: amplitude {amplitude_deg:g} deg at {frequency:g} Hz exceeds the "
                                f"galvo's derated limit of {limit:.4g} deg (peak acceleration envelope)")
        self.check_travel(f"axis {axis}", amplitude_deg, offset_deg)

    def check_sines(self, sines) -> list:
        for s, axis in zip(sines, "xy"):
            self.check_axis(axis, s.frequency, s.amplitude_deg, s.offset_deg, s.phase_deg)
        return sines

    def check_curve(self, curve) -> None:
        """The whole scan against the envelope: sine scans axis by axis, tabulated scans conservatively."""
        if getattr(curve, "kind", None) in ("circle", "line", "lissajous"):
            self.check_sines(axis_sines(curve))
            return
        peak = curve.peak_angle_deg()
        self.check_travel(f"the {curve.name} scan", peak, 0.0)
        frequency = curve.fundamental_hz()
        if frequency > self.max_frequency:
            raise EnvelopeError(f"the {curve.name} scan: {frequency:g} Hz (its fastest axis) is above the galvo's "
                                f"{self.max_frequency:g} Hz limit")
        limit = self.derated_amplitude_deg(frequency)
        if peak > limit * (1 + 1e-12):
            raise EnvelopeError(f"the {curve.name} scan: amplitude {peak:g} deg at {frequency:g} Hz (its fastest "
                                f"axis) exceeds the galvo's derated limit of {limit:.4g} deg (peak acceleration "
                                "envelope)")

    def as_dict(self) -> dict:
        return {"name": self.name, "max_mech_deg": self.max_mech_deg, "derating": [list(p) for p in self.derating],
                "volts_per_deg": self.volts_per_deg, "max_volts": self.max_volts}


GALVO_MODELS = {
    "gvs01x": ScanEnvelope(),
    "ideal": ScanEnvelope("ideal", IDEAL_TRAVEL_DEG, (), None),
}
DEFAULT_GALVO_MODEL = "gvs01x"


def galvo_model(name: str, where: str = "scan", max_angle_deg: float | None = None) -> ScanEnvelope:
    """The envelope of a named galvo model; ``max_angle_deg`` (a scene's ``max_angle``) lowers a real galvo's
    travel or sets an ideal mirror's."""
    if name not in GALVO_MODELS:
        raise EnvelopeError(f"{where}: galvo_model = {name!r}: allowed {', '.join(GALVO_MODELS)}")
    model = GALVO_MODELS[name]
    if max_angle_deg is None:
        return model
    limit = finite(max_angle_deg, f"{where}: max_angle")
    if limit <= 0:
        raise EnvelopeError(f"{where}: max_angle = {max_angle_deg!r}: must be a finite number > 0 degrees")
    # a real galvo's travel can only be narrowed (a safety margin); an ideal mirror's is whatever is asked
    if model.name == "ideal" or limit < model.max_mech_deg:
        return replace(model, max_mech_deg=limit)
    return model


def second_order_response(freq_hz, natural_hz: float, damping: float):
    """Complex frequency response of a unity-gain second-order system (mirror + servo) at ``freq_hz``."""
    w = 2.0 * math.pi * np.asarray(freq_hz, dtype=np.float64)
    wn = 2.0 * math.pi * natural_hz
    return wn ** 2 / (wn ** 2 - w ** 2 + 2j * damping * wn * w)
