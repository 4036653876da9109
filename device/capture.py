"""A captured event stream described as a simulated one: the device's metadata and the driven scan."""
from __future__ import annotations


def tag_events(events, device_metadata: dict, **optics):
    """Give a captured event stream the description a simulated one carries: ``meta["device"]`` (instrument,
    read-back, galvo spec) and ``meta["optics"]`` with design "galvo" and the driven scan curve, so
    ``events.scan_angles()``, light fields and calibration work on it exactly as on simulated data.
    ``optics``: what is known of the camera side (fov_x_deg, mirror_distance, mirror_separation, ...)."""
    events.meta["device"] = device_metadata
    events.meta["optics"] = dict({"design": "galvo", "scan": device_metadata["scan"]}, **optics)
    return events
