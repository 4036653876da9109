"""Drive a two-axis galvo from a scan curve, through a function generator, safely.

The curve comes from ``mitsuba_eventfield.scan`` (the same object the simulation renders): each axis of a
circle, line or Lissajous scan is one sine, generator channel 1 = x mirror, channel 2 = y mirror; an axis with
zero amplitude (the idle axis of a line) is held at a DC level, because generators refuse a 0 Vpp sine and a
refused command would leave the channel at whatever it held before.

Three layers keep the galvo inside its envelope (``spec.GalvoSpec``):

1. ``plan`` checks the whole request before a connection is used (every value finite and in range, amplitude
   derated with frequency, travel, volts).
2. A guard in ``_send`` decodes every command just before it is written and checks the channel settings it
   would produce; only commands this controller composes get through, and "output on" only after step 3.
3. The instrument must confirm: after configuring (outputs off), every setting and the error queue are read back
   and must match what was sent; only then are the outputs switched on. A refused command therefore leaves the
   outputs off. The error queue is read after every ramp step and the full read-back is repeated at the end.

Switching off: ``stop`` ramps down; ``close`` (also the context-manager exit and an ``atexit`` hook) switches the
outputs off *before* the connection closes, whenever this controller may have switched them on. While outputs
may be on, SIGTERM is turned into an exception (when nothing else handles it) so that path runs too. SIGKILL
cannot be caught: run ``eventfield device stop`` after one.
"""
from __future__ import annotations

import atexit
import contextlib
import math
import signal
import sys
import threading
import time

from mitsuba_eventfield.optics.envelope import AxisSine, EnvelopeError, axis_sines  # noqa: F401  (AxisSine: API)

from .dialects import Dialect, dialect, toward_zero
from .signals import signals_held
from .spec import GalvoSpec, SafetyError, finite_number


MAX_READBACK_TOLERANCE = 0.05      # relative: a read-back further from the request than this is a mismatch
OFF_BY_HAND = "switch the generator's outputs off by hand"


def _one_line(e: BaseException) -> str:
    return " ".join(str(e).split()) or type(e).__name__


def sines_from_curve(curve) -> list:
    """The per-axis sines of a circle / line / Lissajous scan (``optics.envelope.axis_sines``); others refused."""
    try:
        return axis_sines(curve)
    except EnvelopeError as e:
        raise SafetyError(str(e)) from None


def check_envelope(spec: GalvoSpec, curve) -> list:
    """A curve's per-axis sines, each checked against the galvo's envelope on both axes (the simulator's
    reason); what any output (generator or card) must pass. Raises SafetyError."""
    sines = sines_from_curve(curve)
    for s, axis in zip(sines, "xy"):
        spec.check_axis(axis, s.frequency, s.amplitude_deg, s.offset_deg, s.phase_deg)
    return sines


class GalvoController:
    """``transport``: write/query/close (device.transport, device.simulator); ``dialect``: a Dialect or its name.
    Use as a context manager (or call ``close``) so the outputs are off before the connection closes."""

    def __init__(self, transport, dialect_or_name, spec: GalvoSpec | None = None, ramp_steps: int = 5,
                 ramp_time: float = 0.5, readback_tolerance: float = 1e-3):
        self.t = transport
        self.d: Dialect = dialect(dialect_or_name) if isinstance(dialect_or_name, str) else dialect_or_name
        self.spec = spec or GalvoSpec()
        if isinstance(ramp_steps, bool) or not isinstance(ramp_steps, int) or not 1 <= ramp_steps <= 1000:
            raise SafetyError(f"ramp_steps = {ramp_steps!r}: allowed range is 1 to 1000")
        if not 0 <= finite_number(ramp_time, "ramp_time") <= 60:
            raise SafetyError(f"ramp_time = {ramp_time!r}: allowed range is 0 to 60 s")
        # how far a read-back may differ from what was sent: with inf, an 18 Vpp preset the link never changed
        # passed the check and was switched on
        if not 0 < finite_number(readback_tolerance, "readback_tolerance") <= MAX_READBACK_TOLERANCE:
            raise SafetyError(f"readback_tolerance = {readback_tolerance!r}: allowed range is (0, "
                              f"{MAX_READBACK_TOLERANCE:g}]")
        self.ramp_steps, self.ramp_time, self.tol = ramp_steps, ramp_time, readback_tolerance
        self.sines = None
        self.running = False           # True from the first "output on" until the outputs are confirmed off
        self._level = 0                # the ramp step reached (of ramp_steps): a stop ramps down from below it
        self._armed = False            # settings confirmed by the instrument: "output on" may be sent
        self._commanded = {1: {}, 2: {}}
        self._closed = False
        self._previous_sigterm = None
        if transport is not None:      # planning-only controllers (no transport) never drive outputs
            atexit.register(self._close_at_exit)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        # leaving while scanning, normally or by Ctrl-C / SIGTERM (the user's "stop"): ramp down first, as
        # ``stop`` does (the outputs switched off at full amplitude before); on any other error ``close``'s quick
        # switch-off, and also when the ramp itself fails or is interrupted (``close`` runs whatever happens)
        try:
            if self.running and not self._closed and (exc_type is None
                                                      or issubclass(exc_type, (KeyboardInterrupt, SystemExit))):
                with contextlib.suppress(Exception):
                    self.stop()
        finally:
            self.close()

    # ------------------------------------------------------------------ planning (no bytes sent)
    def plan(self, curve) -> list:
        """Check a curve against the envelope and what a generator can play, and return its per-axis sines
        (raises SafetyError; sends nothing)."""
        sines = check_envelope(self.spec, curve)
        for s, axis in zip(sines, "xy"):
            self.spec.check_playable(axis, s.frequency, s.amplitude_deg, self.ramp_steps)
        self._check_commands(sines)
        return sines

    def _check_commands(self, sines) -> None:
        """Every setting command ``start`` will send, as the dialect formats it, through the guard's own
        channel check on a scratch state: a value checked exactly and sent rounded to ten digits passed the
        plan at the derated limit and was refused by the guard at the last ramp step, outputs on."""
        state = {1: {}, 2: {}}
        for s in sines:
            cmds = list(self._configure(s, 1.0 / self.ramp_steps))
            cmds += [c for k in range(2, self.ramp_steps + 1) for c in self._ramp_step(s, k / self.ramp_steps)]
            for cmd in cmds:
                for ch, key, value in self.d.decode(cmd):
                    if ch is not None and key not in ("unit", "high_z", "output"):
                        state[ch][key] = value
                        self._check_state(ch, state[ch], need_all=False)

    def _vpp(self, s: AxisSine, fraction: float = 1.0) -> float:
        """Volts peak to peak, rounded down to 9 significant digits: the dialects send 10, which must never
        round a value at the limit up past it."""
        return toward_zero(self.spec.vpp(float(s.amplitude_deg)) * fraction)

    def _offset(self, s: AxisSine, fraction: float = 1.0) -> float:
        """The axis's offset in volts at ``fraction`` of the ramp, rounded toward zero as ``_vpp``."""
        return toward_zero(float(s.offset_deg) * self.spec.volts_per_deg * fraction)

    def _ramp_step(self, s: AxisSine, fraction: float) -> list:
        """The commands that take an axis to ``fraction`` of its amplitude and its offset: a DC offset stepped
        on at "output on" and off at "output off" moved the mirror by the whole offset at once (until
        2026-11-27); an axis without an offset sends no offset commands."""
        cmds = [] if s.is_dc else list(self.d.amplitude(s.channel, self._vpp(s, fraction)))
        return cmds + (list(self.d.offset(s.channel, self._offset(s, fraction))) if s.offset_deg else [])

    # ------------------------------------------------------------------ the guard: every byte passes here
    def _send(self, cmds, descent=None):
        for c in cmds:
            self._guard(c, descent)
            self.t.write(c)

    def _guard(self, cmd: str, descent=None) -> None:
        """Refuse ``cmd`` (SafetyError, nothing written) unless the channel settings it leads to are safe, or
        ``descent(channel, settings)`` says they come down from what the instrument already runs (recovery)."""
        if self._closed:
            raise SafetyError(f"refusing {cmd!r}: the controller is closed")
        pending = {ch: dict(state) for ch, state in self._commanded.items()}
        for ch, key, value in self.d.decode(cmd):
            if key == "unit" and value != "VPP":        # the amplitudes sent are Vpp: any other unit scales them
                raise SafetyError(f"refusing {cmd!r}: amplitudes are sent in Vpp")
            if ch is None or key in ("unit", "high_z"):
                continue
            pending[ch][key] = value
            if key == "output" and not value:
                continue                                   # switching off is always allowed
            if key == "output" and not self._armed:
                raise SafetyError(f"refusing {cmd!r}: channel {ch}'s settings are not confirmed by the instrument")
            if key == "phase":
                finite_number(value, f"channel {ch}: phase")
            if descent is None or not descent(ch, pending[ch]):
                self._check_state(ch, pending[ch], need_all=pending[ch].get("output", False))
        self._commanded = pending          # only once the whole command passed

    def _check_state(self, ch, state, need_all):
        """Check the known part of a channel's commanded state (all of it when its output is on)."""
        fn, f, vpp, off = (state.get(k) for k in ("function", "frequency", "vpp", "offset"))
        if need_all and (fn is None or off is None or (fn == "SIN" and (f is None or vpp is None))):
            raise SafetyError(f"refusing to switch channel {ch} on: its settings are not all known")
        if f is not None and not 0 < finite_number(f, f"channel {ch}: frequency") <= self.spec.max_frequency:
            raise SafetyError(f"channel {ch}: {f:g} Hz is outside 0 to {self.spec.max_frequency:g} Hz")
        self.spec.check_channel(ch, fn or "SIN", f if f is not None else 1e-9, vpp or 0.0, off or 0.0)

    # ------------------------------------------------------------------ commands
    def outputs_off(self):
        """Both outputs off, confirmed by reading them back (a refused "off" is sent again once); raises
        SafetyError if the instrument still reports an output on."""
        for ch in (1, 2):
            self._send(self.d.output(ch, False))
        still_on = self._outputs_on()
        for ch in still_on:
            self._send(self.d.output(ch, False))
        still_on = self._outputs_on()
        if still_on:
            raise SafetyError(f"the generator still reports output {', '.join(map(str, still_on))} on after being "
                              "told to switch off twice: switch it off by hand")
        self.running = False

    def _outputs_on(self) -> list:
        """Channels whose output the instrument reports on (or does not report clearly off)."""
        out = []
        for ch in (1, 2):
            query, parse = self.d.readback(ch)["output"]
            try:
                on = parse(self.t.query(query))
            except (ValueError, KeyError, IndexError):
                on = True
            if on:
                out.append(ch)
        return out

    def _configure(self, s: AxisSine, fraction: float):
        if s.is_dc:
            return self.d.dc(s.channel, self._offset(s, fraction))
        return self.d.configure(s.channel, s.frequency, self._vpp(s, fraction), self._offset(s, fraction),
                                s.phase_deg)

    def start(self, curve, sleep=time.sleep) -> dict:
        """Check, configure (outputs off), verify, align phases, switch on, ramp up, verify. Returns the
        read-back report; raises SafetyError (outputs off) when the instrument does not confirm."""
        sines = self.plan(curve)                          # raises before any byte
        if self.running:       # a scan is on: ramped down first ("output off" at once cut it at full amplitude)
            self.stop(sleep)
        self.sines, self._armed = sines, False
        first = 1.0 / self.ramp_steps
        try:
            self.outputs_off()                            # first bytes: whatever the generator held stays dark
            # outputs confirmed off: what an earlier scan left set is no longer what the guard checks a new
            # setting against (a second start refused a valid scan, its first bytes sent, the old Vpp at the new
            # frequency); the whole new state is read back before any output goes on
            self._commanded = {1: {}, 2: {}}
            self._send(self.d.clear())
            for s in sines:
                self._send(self.d.high_z(s.channel))
            for s in sines:
                self._send(self._configure(s, first))
            self._verify(first, outputs_on=False)         # a refused command stops us here, outputs off
            self._send(self.d.align_phases())
            self._check_errors("aligning the phases")
            self._armed = True
            self._hold_sigterm()
            self.running, self._level = True, 1
            for s in sines:
                self._send(self.d.output(s.channel, True))
            for k in range(2, self.ramp_steps + 1):
                sleep(self.ramp_time / self.ramp_steps)
                for s in sines:
                    self._send(self._ramp_step(s, k / self.ramp_steps))
                self._level = k                 # the step every axis has reached: a ramp down starts below it
                self._check_errors(f"ramp step {k} of {self.ramp_steps}")
            return self._verify(1.0, outputs_on=True)
        except BaseException as e:
            # outputs off whatever went wrong (refusal, timeout, Ctrl-C); a dead link may refuse this too, and
            # then the error says so instead of "outputs off"
            confirmed = self._switch_off_quietly()
            if not confirmed:
                raise SafetyError(f"{_one_line(e)}; the outputs could not be confirmed off: {OFF_BY_HAND}") from None
            if isinstance(e, SafetyError):
                raise SafetyError(f"{e} (outputs off)") from None
            raise

    def _verify(self, fraction: float, outputs_on: bool) -> dict:
        report = self.read_back(fraction, outputs_on)
        errors = self.errors()
        report["errors"] = errors
        problems = [f"{c}: {m}" for c, m in errors] + report["mismatches"]
        if problems:
            raise SafetyError("the generator did not confirm the settings: " + "; ".join(problems))
        return report

    def _check_errors(self, when: str):
        errors = self.errors()
        if errors:
            raise SafetyError(f"the generator reported errors at {when}: "
                              + "; ".join(f"{c}: {m}" for c, m in errors))

    def stop(self, sleep=time.sleep) -> None:
        """Ramp the amplitude down, then switch the outputs off (also when the ramp fails). Ctrl-C and SIGTERM
        wait until it is done (``ramp_time``): a second Ctrl-C cut the ramp short at full amplitude."""
        with signals_held():
            self._ramp_down(sleep)

    def _ramp_down(self, sleep) -> None:
        try:
            if self.sines and self.running:      # from below the step reached (a full scan: ramp_steps)
                for k in range(min(self._level, self.ramp_steps) - 1, 0, -1):
                    for s in self.sines:
                        self._send(self._ramp_step(s, k / self.ramp_steps))
                    sleep(self.ramp_time / self.ramp_steps)
        finally:
            self._armed = False
            self.outputs_off()
            self._release_sigterm()

    def _switch_off_quietly(self) -> bool:
        """Outputs off on an error path, whatever the link does: each channel on its own, each tried twice (a
        flaky link may drop one command), then confirmed by ``outputs_off`` where the link still answers (also
        tried twice: a property test's link that dropped one command of the confirmation left it unconfirmed).
        Ctrl-C and SIGTERM wait until it is done (a second Ctrl-C during the switch-off left both outputs on).
        Returns whether the outputs were confirmed off; if not, ``running`` stays set so ``close`` tries again."""
        self._armed = False
        with signals_held():
            for ch in (1, 2):
                for _ in range(2):
                    try:
                        self._send(self.d.output(ch, False))
                        break
                    except Exception:  # noqa: BLE001
                        continue
            for attempt in range(2):        # the confirmation too: one dropped command left it unconfirmed
                try:
                    self.outputs_off()
                    break
                except Exception:  # noqa: BLE001  (a dead link, or an output still reported on)
                    if attempt:
                        return False
        self._release_sigterm()
        return True

    def close(self) -> None:
        """Outputs off (if this controller may have switched them on), then close the connection. Idempotent.
        Raises SafetyError when the outputs could not be confirmed off (the connection is closed all the same)."""
        if self._closed or self.t is None:
            return
        confirmed = True
        try:
            if self.running or self._armed:
                confirmed = self._switch_off_quietly()
        finally:
            self._closed = True
            atexit.unregister(self._close_at_exit)
            self._release_sigterm()         # nothing more can be sent: SIGTERM is the program's again
            self.t.close()
        if not confirmed:
            raise SafetyError(f"closing the connection: the outputs could not be confirmed off: {OFF_BY_HAND}")

    def _close_at_exit(self) -> None:
        try:
            self.close()
        except SafetyError as e:        # at exit nobody catches it: one line on stderr, not a traceback
            print(f"eventfield: error: {e}", file=sys.stderr)

    # ------------------------------------------------------------------ SIGTERM while scanning
    def _hold_sigterm(self):
        """Make SIGTERM raise SystemExit while outputs may be on (so ``close`` runs), unless the program already
        handles SIGTERM itself (the CLI does) or this is not the main thread (Python allows handlers there only)."""
        if threading.current_thread() is not threading.main_thread():
            return
        if signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
            def terminated(signum, frame):
                raise SystemExit(128 + signum)
            self._previous_sigterm = signal.SIG_DFL
            signal.signal(signal.SIGTERM, terminated)

    def _release_sigterm(self):
        if self._previous_sigterm is not None and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGTERM, self._previous_sigterm)
            self._previous_sigterm = None

    # ------------------------------------------------------------------ reading
    def errors(self, limit: int = 32) -> list:
        """Drain the error queue: [(code, message)] (empty when the instrument reports none)."""
        out = []
        for _ in range(limit):
            try:
                code, msg = self.d.parse_error(self.t.query(self.d.error_query()))
            except ValueError as e:
                return out + [(-1, f"unreadable error queue: {e}")]
            if code == 0:
                break
            out.append((code, msg))
        return out

    def read_channel(self, ch: int) -> dict:
        got = {}
        for name, (q, parse) in self.d.readback(ch).items():
            try:
                got[name] = parse(self.t.query(q))
            except (ValueError, KeyError, IndexError) as e:
                got[name] = f"unreadable: {e}"
        return got

    def read_back(self, fraction: float = 1.0, outputs_on: bool | None = None) -> dict:
        """Settings per channel as the instrument reports them, and mismatches against the request (at
        ``fraction`` of the amplitude; output state checked when ``outputs_on`` is given)."""
        report = {"channels": {}, "mismatches": []}
        for s in self.sines or []:
            got = self.read_channel(s.channel)
            report["channels"][s.channel] = got
            want = {"function": "DC" if s.is_dc else "SIN", "offset": self._offset(s, fraction), "high_z": True}
            if not s.is_dc:
                want.update(frequency=s.frequency, vpp=self._vpp(s, fraction), phase=s.phase_deg)
                if "unit" in got:         # the amplitude's unit, where the dialect sets it: Vpp, not Vrms or dBm
                    want["unit"] = "VPP"
            if outputs_on is not None:
                want["output"] = outputs_on
            for name, w in want.items():
                g = got.get(name)
                if isinstance(w, (bool, str)) or isinstance(g, (bool, str)):
                    ok = g == w
                else:
                    ok = isinstance(g, float) and math.isfinite(g) and abs(g - w) <= self.tol * max(1.0, abs(w))
                if not ok:
                    report["mismatches"].append(f"channel {s.channel} {name}: requested {w}, instrument reports {g}")
        return report

    def identity(self) -> str:
        return self.t.query(self.d.identify())

    def metadata(self, curve) -> dict:
        """What to store with a capture: instrument, dialect, galvo spec, the curve, and the read-back."""
        from mitsuba_eventfield.optics.scan import curve_to_dict
        return {"instrument": self.identity(), "dialect": self.d.name, "galvo": self.spec.as_dict(),
                "scan": curve_to_dict(curve), "read_back": self.read_back()}
