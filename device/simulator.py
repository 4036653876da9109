"""A simulated two-channel function generator for every dialect: no hardware, no PyVISA.

It keeps the state a real generator keeps per channel (function, frequency, Vpp, offset, phase, load, output),
refuses what a real one refuses (values outside its ranges, a 0 Vpp sine, commands it does not know) by pushing
an error into its queue and leaving the setting unchanged, and answers read-back queries in its dialect's
format. That is the failure the controller must survive: a refused command leaves the *previous* setting in
place, which may be a dangerous preset (``preset=``).

Tests use ``raise_on`` to make the link fail at a given command, ``refuse`` to make the instrument refuse one,
and ``history`` (every write with the state
after it) to check what the galvo would have seen at every instant; ``eventfield device --simulate`` uses it too.
"""
from __future__ import annotations

import math
import re
from collections import deque

from .dialects import SafetyError, dialect

# The instrument's own limits (a 33500-class generator into high-Z), not the galvo's: it accepts much more than
# the galvo can take, which is exactly why the controller must not rely on it.
LIMITS = {"frequency": (1e-6, 1e5), "vpp": (1e-3, 20.0), "offset": (-10.0, 10.0), "phase": (-360.0, 360.0)}
MAX_PEAK_V = 10.0
DEFAULT_CHANNEL = {"function": "SIN", "frequency": 1000.0, "vpp": 0.1, "offset": 0.0, "phase": 0.0,
                   "high_z": False, "output": False, "unit": "VPP"}
UNITS = ("VPP", "VRMS", "DBM")     # the amplitude units SCPI generators keep (a preset may hold another)


def amplitude_vpp(unit: str, value: float) -> float:
    """An amplitude setting in ``unit`` as Vpp (a sine; dBm is power into the 50 ohm it refers to)."""
    if unit == "VRMS":
        return value * 2.0 * math.sqrt(2.0)
    if unit == "DBM":
        return 2.0 * math.sqrt(2.0) * math.sqrt(50.0 * 1e-3 * 10.0 ** (value / 10.0))
    return value


def amplitude_in(unit: str, vpp: float) -> float:
    """``amplitude_vpp``'s inverse: a real generator changing unit keeps its output, and shows it anew."""
    if unit == "VRMS":
        return vpp / (2.0 * math.sqrt(2.0))
    if unit == "DBM":
        return 10.0 * math.log10((vpp / (2.0 * math.sqrt(2.0))) ** 2 / 50.0 / 1e-3)
    return vpp
IDENTITY = {"keysight": "Keysight Technologies,33522B,SIM00001,sim-2.0",
            "rigol": "Rigol Technologies,DG812,SIM00002,sim-2.0",
            "siglent": "Siglent Technologies,SDG2042X,SIM00003,sim-2.0"}


class SimulatedGenerator:
    """``preset``: {channel: {setting: value}} the instrument holds before we connect (e.g. 18 Vpp)."""

    def __init__(self, dialect_name: str, preset: dict | None = None, raise_on=None, refuse=None):
        self.dialect = dialect(dialect_name)
        self.state = {ch: dict(DEFAULT_CHANNEL, **((preset or {}).get(ch, {}))) for ch in (1, 2)}
        self.error_queue = deque()
        self.history = []            # (command, {ch: state copy}) after every write
        self.raise_on = raise_on     # callable(cmd) -> exception or None: the link fails at that command
        self.refuse = refuse         # callable(cmd) -> bool: the instrument refuses that command (error queue)
        self.closed = False
        self.resource = f"simulated {dialect_name}"

    # ------------------------------------------------------------------ transport interface
    def write(self, cmd: str) -> None:
        self._link(cmd)
        try:
            changes = self.dialect.decode(cmd)
        except (SafetyError, ValueError):
            self.error_queue.append((-113, "Undefined header"))
            changes = []
        if self.refuse and self.refuse(cmd):
            self.error_queue.append((-221, "Settings conflict"))
        else:
            self._apply(changes)
        self.history.append((cmd, {ch: dict(s) for ch, s in self.state.items()}))

    def query(self, cmd: str) -> str:
        self._link(cmd)
        if cmd == "*IDN?":
            return IDENTITY[self.dialect.name]
        if cmd == self.dialect.error_query():
            code, msg = self.error_queue.popleft() if self.error_queue else (0, "No error")
            return f'{code:+d},"{msg}"'
        answer = (self._answer_siglent if self.dialect.name == "siglent" else self._answer_scpi)(cmd)
        if answer is None:
            self.error_queue.append((-113, "Undefined header"))
            return ""
        return answer

    def close(self) -> None:
        self.closed = True

    # ------------------------------------------------------------------ instrument behaviour
    def _link(self, cmd):
        if self.closed:
            raise ConnectionError("simulated instrument: the connection is closed")
        error = self.raise_on(cmd) if self.raise_on else None
        if error is not None:
            raise error

    def _apply(self, changes):
        """All settings of one command, or none of them (a refused command changes nothing)."""
        pending = {}
        for ch, key, value in changes:
            if ch is None:
                continue
            if key == "unit" and value not in UNITS:
                self.error_queue.append((-224, f"Illegal parameter value; unit {value}"))
                return
            if key in LIMITS and not LIMITS[key][0] <= value <= LIMITS[key][1]:
                self.error_queue.append((-222, f"Data out of range; {key} {value:g}"))
                return
            if key == "function" and value not in ("SIN", "DC"):
                self.error_queue.append((-224, f"Illegal parameter value; function {value}"))
                return
            pending.setdefault(ch, {})[key] = value
            if key == "unit":          # the output stays; its amplitude reads in the new unit
                old = self.state[ch]
                pending[ch]["vpp"] = amplitude_in(value, amplitude_vpp(old.get("unit", "VPP"), old["vpp"]))
        for ch, new in pending.items():
            s = dict(self.state[ch], **new)
            vpp = amplitude_vpp(s.get("unit", "VPP"), s["vpp"])
            peak = abs(s["offset"]) + (vpp / 2 if s["function"] == "SIN" else 0.0)
            if peak > MAX_PEAK_V:
                self.error_queue.append((-221, f"Settings conflict; peak {peak:g} V"))
                return
        for ch, new in pending.items():
            self.state[ch].update(new)

    def _answer_scpi(self, cmd):
        p = re.escape(":" if self.dialect.name == "rigol" else "")
        m = re.fullmatch(p + r"SOUR([12]):(FUNC|FREQ|VOLT|VOLT:OFFS|PHAS|VOLT:UNIT)\?", cmd)
        if m:
            s = self.state[int(m.group(1))]
            key = {"FUNC": "function", "FREQ": "frequency", "VOLT": "vpp", "VOLT:OFFS": "offset",
                   "PHAS": "phase", "VOLT:UNIT": "unit"}[m.group(2)]
            return s[key] if key in ("function", "unit") else f"{s[key]:+.10E}"
        m = re.fullmatch(p + r"OUTP([12])(:LOAD)?\?", cmd)
        if m:
            s = self.state[int(m.group(1))]
            if m.group(2):
                return "+9.9E+37" if s["high_z"] else "+5.0E+01"
            on = s["output"]
            return ("1" if on else "0") if self.dialect.name == "keysight" else ("ON" if on else "OFF")
        return None

    def _answer_siglent(self, cmd):
        m = re.fullmatch(r"C([12]):(BSWV|OUTP)\?", cmd)
        if not m:
            return None
        ch = int(m.group(1))
        s = self.state[ch]
        if m.group(2) == "OUTP":
            return f"C{ch}:OUTP {'ON' if s['output'] else 'OFF'},LOAD,{'HZ' if s['high_z'] else '50'},PLRT,NOR"
        if s["function"] == "DC":
            return f"C{ch}:BSWV WVTP,DC,OFST,{s['offset']:.10g}V"
        return (f"C{ch}:BSWV WVTP,SINE,FRQ,{s['frequency']:.10g}HZ,PERI,{1 / s['frequency']:.10g}S,AMP,{s['vpp']:.10g}V,"
                f"OFST,{s['offset']:.10g}V,HLEV,{s['offset'] + s['vpp'] / 2:.10g}V,LLEV,{s['offset'] - s['vpp'] / 2:.10g}V,"
                f"PHSE,{s['phase']:.10g}")
