"""Drive a two-axis galvo from a scan curve, through a function generator, safely.

The curve comes from ``mitsuba_eventfield.scan`` (the same object the simulation renders): each axis of a
circle, line or Lissajous scan is one sine, generator channel 1 = x mirror, channel 2 = y mirror. Everything is
checked against the galvo's envelope (``spec.GalvoSpec``) before the first byte is sent. Starting ramps the
amplitude up in steps after switching the load to high impedance and aligning the channels' phases; stopping
ramps down and switches the outputs off. Any error, Ctrl-C or interpreter exit while outputs may be on
switches them off.
"""
from __future__ import annotations

import atexit
import time
from dataclasses import dataclass

from .dialects import Dialect, dialect
from .spec import GalvoSpec, SafetyError


@dataclass
class AxisSine:
    channel: int
    frequency: float
    amplitude_deg: float
    phase_deg: float
    offset_deg: float


def sines_from_curve(curve) -> list:
    """The per-axis sines of a circle / line / Lissajous scan (``scan.Lissajous``); others are refused."""
    if getattr(curve, "kind", None) not in ("circle", "line", "lissajous"):
        raise SafetyError(f"the {getattr(curve, 'name', curve)!r} scan is not a pair of sines: a function generator "
                          "drives circles, lines and Lissajous curves only (sine only)")
    out = []
    for ch, (f, a, ph, off) in enumerate(((curve.freq_x, curve.amplitude_x, curve.phase_x, curve.offset_x),
                                          (curve.freq_y, curve.amplitude_y, curve.phase_y, curve.offset_y)), start=1):
        out.append(AxisSine(ch, f, a, ph % 360.0, off))
    return out


class GalvoController:
    """``transport``: write/query/close (device.transport); ``dialect``: a Dialect or its name."""

    def __init__(self, transport, dialect_or_name, spec: GalvoSpec | None = None, ramp_steps: int = 5,
                 ramp_time: float = 0.5, readback_tolerance: float = 1e-3):
        self.t = transport
        self.d: Dialect = dialect(dialect_or_name) if isinstance(dialect_or_name, str) else dialect_or_name
        self.spec = spec or GalvoSpec()
        if ramp_steps < 1 or ramp_time < 0:
            raise SafetyError(f"ramp_steps = {ramp_steps} must be >= 1 and ramp_time = {ramp_time} >= 0")
        self.ramp_steps, self.ramp_time, self.tol = ramp_steps, ramp_time, readback_tolerance
        self.sines = None
        self.running = False
        if transport is not None:              # planning-only controllers (no transport) never drive outputs
            atexit.register(self._emergency_off)

    # ------------------------------------------------------------------ planning (no bytes sent)
    def plan(self, curve) -> list:
        """Check a curve against the envelope and return its per-axis sines (raises SafetyError; sends nothing)."""
        sines = sines_from_curve(curve)
        for s, axis in zip(sines, "xy"):
            self.spec.check_axis(axis, s.frequency, s.amplitude_deg, s.offset_deg)
        return sines

    def _vpp(self, s: AxisSine, fraction: float = 1.0) -> float:
        return 2.0 * s.amplitude_deg * self.spec.volts_per_deg * fraction

    # ------------------------------------------------------------------ commands
    def _send(self, cmds):
        for c in cmds:
            self.t.write(c)

    def outputs_off(self):
        for ch in (1, 2):
            self._send(self.d.output(ch, False))

    def _emergency_off(self):
        if self.running:
            try:
                self.outputs_off()
            finally:
                self.running = False

    def start(self, curve, sleep=time.sleep) -> dict:
        """Check, configure, ramp up, align phases, verify. Returns the read-back report."""
        sines = self.plan(curve)                          # raises before any byte
        self.sines = sines
        try:
            self._send(self.d.clear())
            for s in sines:
                self._send(self.d.output(s.channel, False) + self.d.high_z(s.channel))
            first = 1.0 / self.ramp_steps
            for s in sines:
                self._send(self.d.configure(s.channel, s.frequency, self._vpp(s, first),
                                            s.offset_deg * self.spec.volts_per_deg, s.phase_deg))
            self._send(self.d.align_phases())
            self.running = True
            for s in sines:
                self._send(self.d.output(s.channel, True))
            for k in range(2, self.ramp_steps + 1):
                sleep(self.ramp_time / self.ramp_steps)
                for s in sines:
                    self._send(self.d.amplitude(s.channel, self._vpp(s, k / self.ramp_steps)))
            report = self.read_back()
            errors = self.errors()
            if errors:
                raise SafetyError("the generator reported errors: " + "; ".join(f"{c}: {m}" for c, m in errors))
            report["errors"] = errors
            return report
        except BaseException:
            # outputs off whatever went wrong (instrument error, timeout, Ctrl-C); a dead link may refuse this too
            self.running = False
            try:
                self.outputs_off()
            except Exception:  # noqa: BLE001
                pass
            raise

    def stop(self, sleep=time.sleep) -> None:
        """Ramp the amplitude down, then switch the outputs off (also when the ramp fails)."""
        try:
            if self.sines:
                for k in range(self.ramp_steps - 1, 0, -1):
                    for s in self.sines:
                        self._send(self.d.amplitude(s.channel, self._vpp(s, k / self.ramp_steps)))
                    sleep(self.ramp_time / self.ramp_steps)
        finally:
            self.running = False
            self.outputs_off()

    # ------------------------------------------------------------------ reading
    def errors(self, limit: int = 32) -> list:
        """Drain the error queue: [(code, message)] (empty when the instrument reports none)."""
        out = []
        for _ in range(limit):
            code, msg = self.d.parse_error(self.t.query(self.d.error_query()))
            if code == 0:
                break
            out.append((code, msg))
        return out

    def read_back(self) -> dict:
        """Settings per channel as the instrument reports them, and mismatches against the request."""
        report = {"channels": {}, "mismatches": []}
        for s in self.sines or []:
            got = {}
            for name, (q, parse) in self.d.readback(s.channel).items():
                try:
                    got[name] = parse(self.t.query(q))
                except (ValueError, KeyError, IndexError) as e:
                    got[name] = f"unreadable: {e}"
            report["channels"][s.channel] = got
            want = {"frequency": s.frequency, "vpp": self._vpp(s), "offset": s.offset_deg * self.spec.volts_per_deg,
                    "phase": s.phase_deg}
            for name, w in want.items():
                g = got.get(name)
                if not isinstance(g, float) or abs(g - w) > self.tol * max(1.0, abs(w)):
                    report["mismatches"].append(f"channel {s.channel} {name}: requested {w:g}, instrument reports {g}")
        return report

    def identity(self) -> str:
        return self.t.query(self.d.identify())

    def metadata(self, curve) -> dict:
        """What to store with a capture: instrument, dialect, galvo spec, the curve, and the read-back."""
        from mitsuba_eventfield.scan import curve_to_dict
        return {"instrument": self.identity(), "dialect": self.d.name, "galvo": self.spec.as_dict(),
                "scan": curve_to_dict(curve), "read_back": self.read_back()}


def tag_events(events, device_metadata: dict, **optics):
    """Give a captured event stream the description a simulated one carries: ``meta["device"]`` (instrument,
    read-back, galvo spec) and ``meta["optics"]`` with design "galvo" and the driven scan curve, so
    ``events.scan_angles()``, light fields and calibration work on it exactly as on simulated data.
    ``optics``: what is known of the camera side (fov_x_deg, mirror_distance, mirror_separation, ...)."""
    events.meta["device"] = device_metadata
    events.meta["optics"] = dict({"design": "galvo", "scan": device_metadata["scan"]}, **optics)
    return events
