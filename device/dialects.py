"""SCPI dialects of two-channel function generators: the exact command strings, as pure functions.

Each dialect turns (channel, frequency Hz, amplitude Vpp, offset V, phase deg) into commands, and knows how
to switch the output, set a high-impedance load (the galvo driver's input is high-Z: a 50-ohm setting would
double the voltage), hold a channel at a DC level (the idle axis of a line scan: generators refuse a 0 Vpp sine),
align the two channels' phases, and read the settings back. ``decode`` turns one command string back into the
settings it changes, so the controller can check every byte against the envelope just before it is written.
The command sets follow the vendors' programming manuals for the Keysight 33500 series, Rigol DG800/DG1000Z and
Siglent SDG1000X/2000X; check them against your instrument's manual before first use.
"""
from __future__ import annotations

import math
import re

from .spec import SafetyError


def _on_off(text: str) -> bool:
    """An output state as the instrument reports it: exactly on or off, else ValueError (counted as on: a stale
    or garbled answer read as "off" let a dropped OFF pass as confirmed)."""
    word = text.strip().upper()
    if word in ("1", "ON"):
        return True
    if word in ("0", "OFF"):
        return False
    raise ValueError(f"output state {text!r} is neither on nor off")


def _g(v: float) -> str:
    """A number as SCPI NR2/NR3 text, always with a decimal point or exponent ("0.0", "250.0", "1e+06"):
    valid for every instrument, and pyvisa-sim's parser rejects a bare "0"."""
    s = f"{float(v):.10g}"         # (a Fraction or Decimal has no "g" format of its own)
    return s if ("." in s or "e" in s or "n" in s) else s + ".0"


def _high_z(text: str) -> bool:
    """Load read-back: "INF"/"HZ" or a huge number (Keysight answers +9.9E+37 ohm)."""
    t = text.strip().upper()
    if t in ("INF", "INFINITY", "HZ", "HIGHZ"):
        return True
    try:
        return float(t) >= 1e6
    except ValueError:
        return False


def _function_name(text: str) -> str:
    """Function read-back as "SIN" / "DC" (instruments answer SIN, SINE or SINUSOID)."""
    t = text.strip().upper()
    return "SIN" if t.startswith("SIN") else t


def toward_zero(v: float) -> float:
    """``v`` rounded toward zero to 9 significant digits (the dialects send 10: a value at a limit must never be
    rounded past it)."""
    a = abs(v)
    if not a > 1e-290:           # zero, or so small that its digit unit underflows (5e-324 deg: hypothesis)
        return v
    unit = 10.0 ** (math.floor(math.log10(a)) - 8)
    return math.copysign(math.floor(a / unit) * unit, v)


class Dialect:
    name = "generic"

    def identify(self):
        return "*IDN?"

    def clear(self):
        return ["*CLS"]

    def error_query(self):
        return "SYST:ERR?"

    def parse_error(self, text: str):
        """(code, message) of one error-queue entry; code 0 = queue empty."""
        code, _, msg = text.strip().partition(",")
        return int(float(code)), msg.strip().strip('"')

    def vpp_unit(self, ch) -> list:
        """The commands that make channel ``ch``'s amplitude read and set in Vpp (none where it always is)."""
        return []

    def decode(self, cmd: str) -> list:
        """[(channel, setting, value)] that ``cmd`` changes; channel None for instrument-wide commands.
        Raises SafetyError for a command this dialect does not produce (nothing unknown is ever sent)."""
        raise NotImplementedError


class _SourceSubsystem(Dialect):
    """Generators that follow the SCPI SOURce/OUTPut tree (Keysight, Rigol): they differ only in the leading
    colon, the amplitude-unit command and the phase-alignment command."""
    prefix = ""
    sets_unit = False
    phase_sync = ""

    def vpp_unit(self, ch):
        return [f"{self.prefix}SOUR{ch}:VOLT:UNIT VPP"] if self.sets_unit else []

    def configure(self, ch, freq, vpp, offset, phase):
        src = f"{self.prefix}SOUR{ch}"
        return ([f"{src}:FUNC SIN"] + self.vpp_unit(ch)
                + [f"{src}:FREQ {_g(freq)}", f"{src}:VOLT {_g(vpp)}", f"{src}:VOLT:OFFS {_g(offset)}",
                   f"{src}:PHAS {_g(phase)}"])

    def dc(self, ch, offset):
        return [f"{self.prefix}SOUR{ch}:FUNC DC", f"{self.prefix}SOUR{ch}:VOLT:OFFS {_g(offset)}"]

    def amplitude(self, ch, vpp):
        return [f"{self.prefix}SOUR{ch}:VOLT {_g(vpp)}"]

    def offset(self, ch, volts):
        return [f"{self.prefix}SOUR{ch}:VOLT:OFFS {_g(volts)}"]

    def high_z(self, ch):
        return [f"{self.prefix}OUTP{ch}:LOAD INF"]

    def output(self, ch, on):
        return [f"{self.prefix}OUTP{ch} {'ON' if on else 'OFF'}"]

    def align_phases(self):
        return [self.phase_sync]

    def readback(self, ch):
        src, out = f"{self.prefix}SOUR{ch}", f"{self.prefix}OUTP{ch}"
        unit = {"unit": (f"{src}:VOLT:UNIT?", lambda text: text.strip().upper())} if self.sets_unit else {}
        return {**unit, "function": (f"{src}:FUNC?", _function_name),
                "frequency": (f"{src}:FREQ?", float), "vpp": (f"{src}:VOLT?", float),
                "offset": (f"{src}:VOLT:OFFS?", float), "phase": (f"{src}:PHAS?", float),
                "high_z": (f"{out}:LOAD?", _high_z),
                "output": (f"{out}?", _on_off)}

    def error_query(self):
        return f"{self.prefix}SYST:ERR?"

    def decode(self, cmd):
        if cmd in ("*CLS", self.phase_sync):
            return [(None, "clear" if cmd == "*CLS" else "phase_sync", None)]
        p = re.escape(self.prefix)
        m = re.fullmatch(p + r"SOUR([12]):(FUNC|VOLT:UNIT|FREQ|VOLT|VOLT:OFFS|PHAS) (\S+)", cmd)
        if m:
            key = {"FUNC": "function", "VOLT:UNIT": "unit", "FREQ": "frequency", "VOLT": "vpp",
                   "VOLT:OFFS": "offset", "PHAS": "phase"}[m.group(2)]
            value = m.group(3) if key in ("function", "unit") else float(m.group(3))
            return [(int(m.group(1)), key, value)]
        m = re.fullmatch(p + r"OUTP([12])(:LOAD INF| ON| OFF)", cmd)
        if m:
            what = m.group(2).strip()
            return [(int(m.group(1)), "high_z", True)] if what == ":LOAD INF" else [(int(m.group(1)), "output",
                                                                                     what == "ON")]
        raise SafetyError(f"{self.name}: refusing to send an unknown command {cmd!r}")


class Keysight33500(_SourceSubsystem):
    name = "keysight"
    sets_unit = True
    phase_sync = "SOUR1:PHAS:SYNC"


class RigolDG(_SourceSubsystem):
    name = "rigol"
    prefix = ":"
    # DG800/900/1000Z: :SOUR<n>:VOLT:UNIT {VPP|VRMS|DBM}; a generator left in Vrms put out 2.83x the Vpp asked
    sets_unit = True
    phase_sync = ":SOUR1:PHAS:INIT"


_BSWV = re.compile(r"([A-Z]+),([^,]+)")
_SIGLENT_KEYS = {"WVTP": "function", "FRQ": "frequency", "AMP": "vpp", "OFST": "offset", "PHSE": "phase"}


def _siglent_fields(text):
    return dict(_BSWV.findall(text.split(" ", 1)[-1]))


def _siglent_field(text, key):
    return float(re.sub(r"[A-Za-z]+$", "", _siglent_fields(text)[key]))


def _siglent_high_z(text):
    """"C1:OUTP ON,LOAD,HZ,PLRT,NOR": the item after LOAD."""
    items = text.split(" ", 1)[-1].split(",")
    return "LOAD" in items[:-1] and items[items.index("LOAD") + 1].strip() == "HZ"


class SiglentSDG(Dialect):
    name = "siglent"

    def configure(self, ch, freq, vpp, offset, phase):
        return [f"C{ch}:BSWV WVTP,SINE,FRQ,{_g(freq)},AMP,{_g(vpp)},OFST,{_g(offset)},PHSE,{_g(phase)}"]

    def dc(self, ch, offset):
        return [f"C{ch}:BSWV WVTP,DC,OFST,{_g(offset)}"]

    def amplitude(self, ch, vpp):
        return [f"C{ch}:BSWV AMP,{_g(vpp)}"]

    def offset(self, ch, volts):
        return [f"C{ch}:BSWV OFST,{_g(volts)}"]

    def high_z(self, ch):
        return [f"C{ch}:OUTP LOAD,HZ"]

    def output(self, ch, on):
        return [f"C{ch}:OUTP {'ON' if on else 'OFF'}"]

    def align_phases(self):
        return ["MODE PHASE-LOCKED"]

    def readback(self, ch):
        q, o = f"C{ch}:BSWV?", f"C{ch}:OUTP?"
        return {"function": (q, lambda s: {"SINE": "SIN", "DC": "DC"}.get(_siglent_fields(s).get("WVTP"), "?")),
                "frequency": (q, lambda s: _siglent_field(s, "FRQ")), "vpp": (q, lambda s: _siglent_field(s, "AMP")),
                "offset": (q, lambda s: _siglent_field(s, "OFST")), "phase": (q, lambda s: _siglent_field(s, "PHSE")),
                "high_z": (o, _siglent_high_z),
                "output": (o, lambda s: _on_off(s.split(" ", 1)[-1].split(",")[0]))}

    def decode(self, cmd):
        if cmd in ("*CLS", "MODE PHASE-LOCKED"):
            return [(None, "clear" if cmd == "*CLS" else "phase_sync", None)]
        m = re.fullmatch(r"C([12]):BSWV (\S+)", cmd)
        if m:
            ch, out = int(m.group(1)), []
            for key, value in _BSWV.findall(m.group(2)):
                if key not in _SIGLENT_KEYS:
                    raise SafetyError(f"{self.name}: refusing to send an unknown field {key!r} in {cmd!r}")
                name = _SIGLENT_KEYS[key]
                out.append((ch, name, {"SINE": "SIN"}.get(value, value) if name == "function" else float(value)))
            return out
        m = re.fullmatch(r"C([12]):OUTP (ON|OFF|LOAD,HZ)", cmd)
        if m:
            ch = int(m.group(1))
            return [(ch, "high_z", True)] if m.group(2) == "LOAD,HZ" else [(ch, "output", m.group(2) == "ON")]
        raise SafetyError(f"{self.name}: refusing to send an unknown command {cmd!r}")


DIALECTS = {d.name: d for d in (Keysight33500, RigolDG, SiglentSDG)}


def dialect(name: str) -> Dialect:
    if name not in DIALECTS:
        raise SafetyError(f"unknown dialect {name!r}; allowed: {', '.join(DIALECTS)}")
    return DIALECTS[name]()
