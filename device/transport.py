"""How commands reach the generator: PyVISA (pyvisa-py, or pyvisa-sim YAML instruments), the in-memory
simulated generator of every dialect (``device.simulator``), or a recorder.

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


def simulated(dialect_name: str, **kw):
    """An in-memory generator speaking ``dialect_name`` (every dialect; ``device.simulator``)."""
    from .dialects import dialect
    from .simulator import SimulatedGenerator
    dialect(dialect_name)                  # the one "unknown dialect" message
    return SimulatedGenerator(dialect_name, **kw)


def open_transport(dialect_name: str, resource: str | None = None, simulate: bool = False):
    """What the CLI connects to: the simulated generator, or a VISA resource."""
    if simulate:
        return simulated(dialect_name)
    if not resource:
        raise SafetyError("give --resource (a VISA address) or --simulate")
    return VisaTransport(resource)


def simulated_visa(dialect_name: str) -> VisaTransport:
    """A pyvisa-sim instrument speaking ``dialect_name`` (device/sim/<dialect>.yaml): exercises the PyVISA path."""
    if dialect_name not in SIM_RESOURCES:
        raise SafetyError(f"no simulated instrument for dialect {dialect_name!r}; available: "
                          + ", ".join(SIM_RESOURCES))
    return VisaTransport(SIM_RESOURCES[dialect_name], f"{os.path.join(SIM_DIR, dialect_name + '.yaml')}@sim")
