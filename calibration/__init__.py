"""Calibration from the data itself (installed as ``mitsuba_eventfield.calibration``).

Planned (issue 7): galvo view/phase calibration by template matching along the scan curve, depth vs. curve-size
fits, kaleidoscope tile registration. Nothing is implemented here yet.
"""
