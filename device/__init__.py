"""Device layer for the real galvo rig (installed as ``mitsuba_eventfield.device``).

Planned (issue 8): SCPI/VISA signal-generator control with a safety envelope, driven by the shared scan-curve
module. Nothing is implemented here yet.
"""
