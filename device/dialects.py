"""SCPI dialects of two-channel function generators: the exact command strings, as pure functions.

Each dialect turns (channel, frequency Hz, amplitude Vpp, offset V, phase deg) into commands, and knows how
to switch the output, set a high-impedance load (the galvo driver's input is high-Z: a 50-ohm setting would
double the voltage), align the two channels' phases, and read the settings back. The command sets follow the
vendors' programming manuals for the Keysight 33500 series, Rigol DG800/DG1000Z and Siglent SDG1000X/2000X;
check them against your instrument's manual before first use.
"""
from __future__ import annotations

import re


def _g(v: float) -> str:
    """A number as SCPI NR2/NR3 text, always with a decimal point or exponent ("0.0", "250.0", "1e+06"):
    valid for every instrument, and pyvisa-sim's parser rejects a bare "0"."""
    s = f"{v:.10g}"
    return s if ("." in s or "e" in s or "n" in s) else s + ".0"


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


class _SourceSubsystem(Dialect):
    """Generators that follow the SCPI SOURce/OUTPut tree (Keysight, Rigol): they differ only in the leading
    colon, the amplitude-unit command and the phase-alignment command."""
    prefix = ""
    sets_unit = False
    phase_sync = ""

    def configure(self, ch, freq, vpp, offset, phase):
        src = f"{self.prefix}SOUR{ch}"
        return ([f"{src}:FUNC SIN"] + ([f"{src}:VOLT:UNIT VPP"] if self.sets_unit else [])
                + [f"{src}:FREQ {_g(freq)}", f"{src}:VOLT {_g(vpp)}", f"{src}:VOLT:OFFS {_g(offset)}",
                   f"{src}:PHAS {_g(phase)}"])

    def amplitude(self, ch, vpp):
        return [f"{self.prefix}SOUR{ch}:VOLT {_g(vpp)}"]

    def high_z(self, ch):
        return [f"{self.prefix}OUTP{ch}:LOAD INF"]

    def output(self, ch, on):
        return [f"{self.prefix}OUTP{ch} {'ON' if on else 'OFF'}"]

    def align_phases(self):
        return [self.phase_sync]

    def readback(self, ch):
        src = f"{self.prefix}SOUR{ch}"
        return {"frequency": (f"{src}:FREQ?", float), "vpp": (f"{src}:VOLT?", float),
                "offset": (f"{src}:VOLT:OFFS?", float), "phase": (f"{src}:PHAS?", float),
                "output": (f"{self.prefix}OUTP{ch}?", lambda s: s.strip() in ("1", "ON"))}

    def error_query(self):
        return f"{self.prefix}SYST:ERR?"


class Keysight33500(_SourceSubsystem):
    name = "keysight"
    sets_unit = True
    phase_sync = "SOUR1:PHAS:SYNC"


class RigolDG(_SourceSubsystem):
    name = "rigol"
    prefix = ":"
    phase_sync = ":SOUR1:PHAS:INIT"


_BSWV = re.compile(r"([A-Z]+),([^,]+)")


def _siglent_field(text, key):
    fields = dict(_BSWV.findall(text.split(" ", 1)[-1]))
    return float(re.sub(r"[A-Za-z]+$", "", fields[key]))


class SiglentSDG(Dialect):
    name = "siglent"

    def configure(self, ch, freq, vpp, offset, phase):
        return [f"C{ch}:BSWV WVTP,SINE,FRQ,{_g(freq)},AMP,{_g(vpp)},OFST,{_g(offset)},PHSE,{_g(phase)}"]

    def amplitude(self, ch, vpp):
        return [f"C{ch}:BSWV AMP,{_g(vpp)}"]

    def high_z(self, ch):
        return [f"C{ch}:OUTP LOAD,HZ"]

    def output(self, ch, on):
        return [f"C{ch}:OUTP {'ON' if on else 'OFF'}"]

    def align_phases(self):
        return ["MODE PHASE-LOCKED"]

    def readback(self, ch):
        q = f"C{ch}:BSWV?"
        return {"frequency": (q, lambda s: _siglent_field(s, "FRQ")), "vpp": (q, lambda s: _siglent_field(s, "AMP")),
                "offset": (q, lambda s: _siglent_field(s, "OFST")), "phase": (q, lambda s: _siglent_field(s, "PHSE")),
                "output": (f"C{ch}:OUTP?", lambda s: " ON" in f" {s.split(' ', 1)[-1].split(',')[0]}")}


DIALECTS = {d.name: d for d in (Keysight33500, RigolDG, SiglentSDG)}


def dialect(name: str) -> Dialect:
    if name not in DIALECTS:
        from .spec import SafetyError
        raise SafetyError(f"unknown dialect {name!r}; allowed: {', '.join(DIALECTS)}")
    return DIALECTS[name]()
