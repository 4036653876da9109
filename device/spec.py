"""What the galvo and its driver accept, as the device layer checks it.

The galvo's own limits (travel, frequency derating, drive voltage) are the one scan envelope of
``mitsuba_eventfield.optics.envelope``, which the simulator enforces too: a scan one refuses, the other
refuses with the same reason. ``GalvoSpec`` adds the driver's scaling (``volts_per_deg``) as the user sets it
on the rig, and the generator-channel view of the same limits:

* ``check_axis`` (the envelope's per-axis check): a whole scan request (per-axis sine, phase, offset,
  duration), before a connection is even opened;
* ``check_channel``: one generator channel's settings (function, frequency, Vpp, offset), used by the
  controller's guard on every command it is about to send, so a wrong byte cannot leave the process even if the
  planning code above it had a bug.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

from ..errors import EventFieldError
from ..optics.envelope import (GALVO_MODELS, PHASE_RANGE_DEG, VOLTS_PER_DEG_RANGE, EnvelopeError,  # noqa: F401
                               ScanEnvelope)
from ..validate import finite


class SafetyError(EventFieldError):
    """A request outside the galvo's or the generator's safe envelope, or an instrument that does not confirm
    what it was told. Outputs are off (or were never switched on)."""


# Longest unattended scan the CLI accepts (seconds); 0 means "until Ctrl-C / SIGTERM".
MAX_DURATION_S = 24 * 3600.0
_MODEL = GALVO_MODELS["gvs01x"]
MIN_FREQUENCY_HZ = 1e-3        # a 1000 s period: slower is no scan (generators reach about 1 uHz)
MIN_VPP = 1e-3                 # the smallest sine the supported generators play (1 mVpp into high-Z)


def finite_number(value, what: str) -> float:
    """``value`` as a float if it is a real, finite number (not bool, NaN or inf); else SafetyError."""
    return finite(value, what, error=SafetyError)


def check_duration(seconds) -> float:
    """A scan duration: finite, 0 (until interrupted) to MAX_DURATION_S."""
    d = finite_number(seconds, "duration")
    if not 0.0 <= d <= MAX_DURATION_S:
        raise SafetyError(f"duration = {d:g} s: allowed range is 0 (until Ctrl-C) to {MAX_DURATION_S:g} s")
    return d


def _safety(check, *args):
    """Run an envelope check; its refusal becomes a SafetyError with the same message."""
    try:
        return check(*args)
    except EnvelopeError as e:
        raise SafetyError(str(e)) from None


@dataclass(frozen=True)
class GalvoSpec:
    volts_per_deg: float = _MODEL.volts_per_deg        # mechanical degrees
    max_volts: float = _MODEL.max_volts                # command input range, +-
    max_mech_deg: float = _MODEL.max_mech_deg
    # (frequency Hz, largest sine amplitude in mechanical degrees), increasing frequency
    envelope: tuple = field(default=_MODEL.derating)
    model: str = _MODEL.name

    def __post_init__(self):
        lo, hi = VOLTS_PER_DEG_RANGE
        vpd = finite_number(self.volts_per_deg, "volts_per_deg")
        if not lo <= vpd <= hi:
            raise SafetyError(f"volts_per_deg = {vpd:g}: allowed range is {lo:g} to {hi:g} V per mechanical degree "
                              "(check the driver's jumper)")
        model = GALVO_MODELS.get(self.model)
        if model is None or model.volts_per_deg is None:     # "ideal": a simulated mirror with no limits
            real = ", ".join(n for n, m in GALVO_MODELS.items() if m.volts_per_deg is not None)
            raise SafetyError(f"model = {self.model!r}: the device layer drives a real galvo; allowed {real}")
        for name in ("max_volts", "max_mech_deg"):
            value, most = finite_number(getattr(self, name), name), getattr(model, name)
            if not 0 < value <= most:
                raise SafetyError(f"{name} = {value:g}: allowed range is (0, {most:g}], the {model.name} galvo's "
                                  "(a rig's spec may narrow its limits, never widen them)")
        pts = tuple(self.envelope)
        if not pts or any(len(p) != 2 for p in pts):
            raise SafetyError("envelope: expected ((frequency Hz, amplitude deg), ...) pairs")
        for f, a in pts:
            if not (finite_number(f, "envelope frequency") > 0 and finite_number(a, "envelope amplitude") > 0):
                raise SafetyError(f"envelope point ({f!r}, {a!r}): frequency and amplitude must be > 0")
        if any(f1 <= f0 for (f0, _), (f1, _) in zip(pts[:-1], pts[1:])):
            raise SafetyError("envelope: frequencies must increase")
        # a copy of plain numbers: the caller's list, kept and read at every check, could change after this one
        object.__setattr__(self, "envelope", tuple((float(f), float(a)) for f, a in pts))
        self._within(model)

    def _within(self, model) -> None:
        """Refuse an envelope above the galvo model's anywhere: both are piecewise linear in log-log, so their
        points together are where the difference can peak."""
        mine = ScanEnvelope(model.name, model.max_mech_deg, self.envelope, None)
        if mine.max_frequency > model.max_frequency:
            raise SafetyError(f"envelope: up to {mine.max_frequency:g} Hz, above the {model.name} galvo's "
                              f"{model.max_frequency:g} Hz (a rig's spec may narrow its limits, never widen them)")
        for f in sorted({f for f, _ in self.envelope} | {f for f, _ in model.derating if f <= mine.max_frequency}):
            here, most = mine.derated_amplitude_deg(f), model.derated_amplitude_deg(f)
            if here > most * (1 + 1e-9):
                raise SafetyError(f"envelope: {here:.4g} deg at {f:g} Hz, above the {model.name} galvo's "
                                  f"{most:.4g} deg there (a rig's spec may narrow its limits, never widen them)")

    @property
    def scan_envelope(self) -> ScanEnvelope:
        """This rig's envelope: the galvo model's limits with the driver scaling set here."""
        return ScanEnvelope(self.model, self.max_mech_deg, tuple(tuple(p) for p in self.envelope),
                            self.volts_per_deg, self.max_volts)

    @property
    def max_frequency(self) -> float:
        return self.scan_envelope.max_frequency

    def max_amplitude_deg(self, frequency: float) -> float:
        """Largest safe sine amplitude at ``frequency`` (log-log interpolation of the envelope)."""
        return self.scan_envelope.max_amplitude_deg(frequency)

    def check_axis(self, axis: str, frequency: float, amplitude_deg: float, offset_deg: float,
                   phase_deg: float = 0.0) -> None:
        """Raise SafetyError naming the limit if the sine on this axis is unsafe (amplitude 0: a DC level)."""
        _safety(self.scan_envelope.check_axis, axis, frequency, amplitude_deg, offset_deg, phase_deg)

    def vpp(self, amplitude_deg: float) -> float:
        """Volts peak to peak of a sine of ``amplitude_deg`` mechanical degrees through this driver: the one
        conversion the guard, the planner and the dialects share (2 x amplitude x volts per degree)."""
        return 2.0 * amplitude_deg * self.volts_per_deg

    def amplitude_deg(self, vpp: float) -> float:
        """The mechanical amplitude in degrees of a sine of ``vpp`` volts peak to peak (``vpp`` inverted)."""
        return vpp / (2.0 * self.volts_per_deg)

    def check_playable(self, axis: str, frequency: float, amplitude_deg: float, ramp_steps: int = 1) -> None:
        """What a generator can play at all, for a whole request (``GalvoController.plan``; the per-command guard
        sees channels half set up), the first of ``ramp_steps`` amplitude steps included: 1e-300 Hz or 1e-320 deg
        passed the envelope, and the instrument then refused them with errors several lines long."""
        if frequency < MIN_FREQUENCY_HZ:
            raise SafetyError(f"axis {axis}: frequency {frequency:g} Hz: allowed range is {MIN_FREQUENCY_HZ:g} to "
                              f"{self.max_frequency:g} Hz")
        from .dialects import toward_zero
        smallest = self.amplitude_deg(MIN_VPP) * ramp_steps
        # as sent: the first step's Vpp rounded toward zero (at exactly the minimum it became 0.00099999999)
        if 0 < amplitude_deg and toward_zero(self.vpp(amplitude_deg) / ramp_steps) < MIN_VPP:
            raise SafetyError(f"axis {axis}: amplitude {amplitude_deg:g} deg: below the generators' smallest sine "
                              f"({MIN_VPP * 1e3:g} mVpp) at the first of {ramp_steps} ramp steps: at least "
                              f"{smallest:.3g} deg here; 0 holds the axis still")

    def _check_travel(self, where: str, amplitude_deg: float, offset_deg: float) -> None:
        _safety(self.scan_envelope.check_travel, where, amplitude_deg, offset_deg)

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
        amplitude_deg = self.amplitude_deg(finite_number(vpp, f"{where}: Vpp"))
        self.check_axis(str(channel), finite_number(frequency, f"{where}: frequency"), amplitude_deg, offset_deg)

    def as_dict(self) -> dict:
        return asdict(self)
