"""Device layer for the real galvo rig (installed as ``mitsuba_eventfield.device``).

A function generator (SCPI over PyVISA: Keysight 33500, Rigol DG, Siglent SDG dialects) drives the two-axis
galvo with the SAME scan curve the simulation renders (``mitsuba_eventfield.scan``). Every request is checked
against the galvo's envelope before a byte is sent; outputs go off on any error, Ctrl-C and exit.
"""
from .capture import tag_events  # noqa: F401
from .controller import AxisSine, GalvoController, sines_from_curve  # noqa: F401
from .dialects import DIALECTS, dialect  # noqa: F401
from .simulator import SimulatedGenerator  # noqa: F401
from .spec import GalvoSpec, SafetyError  # noqa: F401
from .transport import VisaTransport, open_transport, simulated, simulated_visa  # noqa: F401
