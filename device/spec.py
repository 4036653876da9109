"""What the galvo and its driver accept: the safety envelope every command is checked against first.

Defaults are the Thorlabs GVS01x-class figures of DESIGN.md section 5: +-10 V command input, 0.5/0.8/1.0 V
per mechanical degree (a jumper), about 1 kHz small-angle bandwidth, a full-travel sine only up to ~35 Hz and
~130 Hz at half travel. The usable amplitude therefore falls with frequency; here it is interpolated
log-log between those points (and 0.2 deg at 1 kHz). Set your own galvo's figures.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

from mitsuba_eventfield.errors import EventFieldError


class SafetyError(EventFieldError):
    """A request outside the galvo's or the generator's safe envelope. Nothing was sent."""


@dataclass(frozen=True)
class GalvoSpec:
    volts_per_deg: float = 0.8                  # mechanical degrees
    max_volts: float = 10.0                     # command input range, +-
    max_mech_deg: float = 12.5
    # (frequency Hz, largest sine amplitude in mechanical degrees), increasing frequency
    envelope: tuple = field(default=((35.0, 12.5), (130.0, 6.25), (1000.0, 0.2)))

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

    def check_axis(self, axis: str, frequency: float, amplitude_deg: float, offset_deg: float) -> None:
        """Raise SafetyError naming the limit if the sine on this axis is unsafe."""
        for name, v in (("frequency", frequency), ("amplitude", amplitude_deg), ("offset", offset_deg)):
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                raise SafetyError(f"axis {axis}: {name} = {v!r} is not a finite number")
        if frequency <= 0:
            raise SafetyError(f"axis {axis}: frequency {frequency} Hz must be > 0")
        if amplitude_deg < 0:
            raise SafetyError(f"axis {axis}: amplitude {amplitude_deg} deg must be >= 0")
        top = self.envelope[-1][0]
        if frequency > top:
            raise SafetyError(f"axis {axis}: {frequency:g} Hz is above the galvo's {top:g} Hz limit")
        limit = self.max_amplitude_deg(frequency)
        if amplitude_deg > limit:
            raise SafetyError(f"axis {axis}: amplitude {amplitude_deg:g} deg at {frequency:g} Hz exceeds the galvo's "
                              f"derated limit of {limit:.4g} deg (peak acceleration envelope)")
        if abs(offset_deg) + amplitude_deg > self.max_mech_deg:
            raise SafetyError(f"axis {axis}: |offset| + amplitude = {abs(offset_deg) + amplitude_deg:g} deg exceeds "
                              f"the mechanical travel of +-{self.max_mech_deg:g} deg")
        volts = (abs(offset_deg) + amplitude_deg) * self.volts_per_deg
        if volts > self.max_volts:
            raise SafetyError(f"axis {axis}: |offset| + amplitude = {volts:g} V exceeds the +-{self.max_volts:g} V "
                              "command input")

    def as_dict(self) -> dict:
        return asdict(self)
