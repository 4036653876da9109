"""What the galvo and its driver accept: the safety envelope every request and every command is checked against.

Defaults are the Thorlabs GVS01x-class figures of docs/device.md: +-10 V command input, 0.5/0.8/1.0 V per
mechanical degree (a jumper), about 1 kHz small-angle bandwidth, a full-travel sine only up to ~35 Hz and
~130 Hz at half travel. The usable amplitude therefore falls with frequency; here it is interpolated log-log
between those points (and 0.2 deg at 1 kHz). Set your own galvo's figures.

Two levels of checking use this one envelope:

* ``check_request`` / ``check_axis``: a whole scan request (per-axis sine, phase, offset, duration), before a
  connection is even opened;
* ``check_channel``: one generator channel's settings (function, frequency, Vpp, offset), used by the
  controller's guard on every command it is about to send, so a wrong byte cannot leave the process even if the
  planning code above it had a bug.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

from mitsuba_eventfield.errors import EventFieldError


class SafetyError(EventFieldError):
    """A request outside the galvo's or the generator's safe envelope, or an instrument that does not confirm
    what it was told. Outputs are off (or were never switched on)."""


# Drivers scale 0.5-1.0 V per mechanical degree; anything outside this bracket is a typo (or a unit mix-up of
# optical vs mechanical degrees or mV) that would scale every voltage we send by the same mistake.
VOLTS_PER_DEG_RANGE = (0.1, 2.0)
# Longest unattended scan the CLI accepts (seconds); 0 means "until Ctrl-C / SIGTERM".
MAX_DURATION_S = 24 * 3600.0
PHASE_RANGE_DEG = (-360.0, 360.0)


def finite_number(value, what: str) -> float:
    """``value`` as a float if it is a real, finite number (not bool, NaN or inf); else SafetyError."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SafetyError(f"{what} = {value!r} is not a finite number")
    return float(value)


def check_duration(seconds) -> float:
    """A scan duration: finite, 0 (until interrupted) to MAX_DURATION_S."""
    d = finite_number(seconds, "duration")
    if not 0.0 <= d <= MAX_DURATION_S:
        raise SafetyError(f"duration = {d:g} s: allowed range is 0 (until Ctrl-C) to {MAX_DURATION_S:g} s")
    return d


@dataclass(frozen=True)
class GalvoSpec:
    volts_per_deg: float = 0.8                  # mechanical degrees
    max_volts: float = 10.0                     # command input range, +-
    max_mech_deg: float = 12.5
    # (frequency Hz, largest sine amplitude in mechanical degrees), increasing frequency
    envelope: tuple = field(default=((35.0, 12.5), (130.0, 6.25), (1000.0, 0.2)))

    def __post_init__(self):
        lo, hi = VOLTS_PER_DEG_RANGE
        vpd = finite_number(self.volts_per_deg, "volts_per_deg")
        if not lo <= vpd <= hi:
            raise SafetyError(f"volts_per_deg = {vpd:g}: allowed range is {lo:g} to {hi:g} V per mechanical degree "
                              "(check the driver's jumper)")
        for name in ("max_volts", "max_mech_deg"):
            if not finite_number(getattr(self, name), name) > 0:
                raise SafetyError(f"{name} = {getattr(self, name)!r}: must be > 0")
        pts = tuple(self.envelope)
        if not pts or any(len(p) != 2 for p in pts):
            raise SafetyError("envelope: expected ((frequency Hz, amplitude deg), ...) pairs")
        for f, a in pts:
            if not (finite_number(f, "envelope frequency") > 0 and finite_number(a, "envelope amplitude") > 0):
                raise SafetyError(f"envelope point ({f!r}, {a!r}): frequency and amplitude must be > 0")
        if any(f1 <= f0 for (f0, _), (f1, _) in zip(pts[:-1], pts[1:])):
            raise SafetyError("envelope: frequencies must increase")

    @property
    def max_frequency(self) -> float:
        return self.envelope[-1][0]

    def max_amplitude_deg(self, frequency: float) -> float:
        """Largest safe sine amplitude at ``frequency`` (log-log interpolation of the envelope)."""
        pts = self.envelope
        if frequency <= pts[0][0]:
            return min(pts[0][1], self.max_mech_deg)
        if frequency > pts[-1][0]:
            return 0.0
        for (f0, a0), (f1, a1) in zip(pts[:-1], pts[1:]):
            if frequency <= f1:
                w = math.log(frequency / f0) / math.log(f1 / f0)
                return min(math.exp(math.log(a0) + w * (math.log(a1) - math.log(a0))), self.max_mech_deg)
        return 0.0

    def check_axis(self, axis: str, frequency: float, amplitude_deg: float, offset_deg: float,
                   phase_deg: float = 0.0) -> None:
        """Raise SafetyError naming the limit if the sine on this axis is unsafe (amplitude 0: a DC level)."""
        for name, v in (("frequency", frequency), ("amplitude", amplitude_deg), ("offset", offset_deg),
                        ("phase", phase_deg)):
            finite_number(v, f"axis {axis}: {name}")
        if not PHASE_RANGE_DEG[0] <= phase_deg <= PHASE_RANGE_DEG[1]:
            raise SafetyError(f"axis {axis}: phase {phase_deg:g} deg: allowed range is {PHASE_RANGE_DEG[0]:g} to "
                              f"{PHASE_RANGE_DEG[1]:g} deg")
        if frequency <= 0:
            raise SafetyError(f"axis {axis}: frequency {frequency} Hz must be > 0")
        if amplitude_deg < 0:
            raise SafetyError(f"axis {axis}: amplitude {amplitude_deg} deg must be >= 0")
        if frequency > self.max_frequency:
            raise SafetyError(f"axis {axis}: {frequency:g} Hz is above the galvo's {self.max_frequency:g} Hz limit")
        limit = self.max_amplitude_deg(frequency)
        if amplitude_deg > limit:
            raise SafetyError(f"axis {axis}: amplitude {amplitude_deg:g} deg at {frequency:g} Hz exceeds the galvo's "
                              f"derated limit of {limit:.4g} deg (peak acceleration envelope)")
        self._check_travel(f"axis {axis}", amplitude_deg, offset_deg)

    def _check_travel(self, where: str, amplitude_deg: float, offset_deg: float) -> None:
        if abs(offset_deg) + amplitude_deg > self.max_mech_deg:
            raise SafetyError(f"{where}: |offset| + amplitude = {abs(offset_deg) + amplitude_deg:g} deg exceeds "
                              f"the mechanical travel of +-{self.max_mech_deg:g} deg")
        volts = (abs(offset_deg) + amplitude_deg) * self.volts_per_deg
        if volts > self.max_volts:
            raise SafetyError(f"{where}: |offset| + amplitude = {volts:g} V exceeds the +-{self.max_volts:g} V "
                              "command input")

    def check_channel(self, channel: int, function: str, frequency: float, vpp: float, offset_v: float) -> None:
        """One generator channel as it would drive the galvo: a sine of ``vpp`` volts peak to peak at
        ``frequency`` around ``offset_v``, or a DC level ``offset_v``. Raises SafetyError if unsafe."""
        where = f"channel {channel}"
        offset_deg = finite_number(offset_v, f"{where}: offset") / self.volts_per_deg
        if function == "DC":
            self._check_travel(where, 0.0, offset_deg)
            return
        if function != "SIN":
            raise SafetyError(f"{where}: function {function!r} is not a sine or DC level")
        amplitude_deg = finite_number(vpp, f"{where}: Vpp") / (2.0 * self.volts_per_deg)
        self.check_axis(str(channel), finite_number(frequency, f"{where}: frequency"), amplitude_deg, offset_deg)

    def as_dict(self) -> dict:
        return asdict(self)
