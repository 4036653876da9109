"""How commands reach the generator: PyVISA (pyvisa-py, or pyvisa-sim YAML instruments), or a recorder.

Every transport has ``write(cmd)``, ``query(cmd) -> str`` and ``close()``. ``RecordingTransport`` keeps the
exact byte sequence (tests compare it per dialect) and answers queries from a dict or a callable.
"""
from __future__ import annotations

import os

from .spec import SafetyError

SIM_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "sim")
SIM_RESOURCES = {"keysight": "TCPIP0::sim-keysight::inst0::INSTR", "rigol": "TCPIP0::sim-rigol::inst0::INSTR"}


class VisaTransport:
    def __init__(self, resource: str, backend: str = "@py", timeout_ms: int = 2000):
        try:
            import pyvisa
        except ImportError:
            raise SafetyError("PyVISA is not installed: pip install pyvisa pyvisa-py") from None
        try:
            self.rm = pyvisa.ResourceManager(backend)
            self.inst = self.rm.open_resource(resource, read_termination="\n", write_termination="\n",
                                              timeout=timeout_ms)
        except Exception as e:  # noqa: BLE001  (VISA reports missing resources in many ways)
            raise SafetyError(f"cannot open VISA resource {resource!r} ({backend}): {e}") from None
        self.resource = resource

    def write(self, cmd: str) -> None:
        self.inst.write(cmd)

    def query(self, cmd: str) -> str:
        return self.inst.query(cmd).strip()

    def close(self) -> None:
        try:
            self.inst.close()
        finally:
            self.rm.close()


def simulated(dialect_name: str) -> VisaTransport:
    """A pyvisa-sim instrument speaking ``dialect_name`` (device/sim/<dialect>.yaml)."""
    if dialect_name not in SIM_RESOURCES:
        raise SafetyError(f"no simulated instrument for dialect {dialect_name!r}; available: "
                          + ", ".join(SIM_RESOURCES))
    return VisaTransport(SIM_RESOURCES[dialect_name], f"{os.path.join(SIM_DIR, dialect_name + '.yaml')}@sim")


class RecordingTransport:
    """Records every command; answers queries from ``answers`` (dict or callable). ``fail_on``: raise the given
    exception when a command starting with that prefix is sent (to test faults mid-sequence)."""

    def __init__(self, answers=None, fail_on: str | None = None, error=TimeoutError("simulated timeout")):
        self.sent = []
        self.answers = answers or {}
        self.fail_on, self.error = fail_on, error

    def _check(self, cmd):
        if self.fail_on and cmd.startswith(self.fail_on):
            self.fail_on = None
            raise self.error

    def write(self, cmd: str) -> None:
        self._check(cmd)
        self.sent.append(cmd)

    def query(self, cmd: str) -> str:
        self._check(cmd)
        self.sent.append(cmd)
        if callable(self.answers):
            return self.answers(cmd)
        return self.answers.get(cmd, "+0,\"No error\"" if cmd.upper().endswith("ERR?") else "0")

    def close(self) -> None:
        pass
