"""Mitsuba plugins of mitsuba-eventfield (installed as ``mitsuba_eventfield.plugins``).

Thin plugin shells over pure functions (``pixel_model``) that tests can call directly. Mitsuba registers
plugins per variant, so :func:`register` is called by ``mitsuba_eventfield.set_variant`` for each variant used.
"""
from __future__ import annotations

_registered: set[str] = set()


def register() -> None:
    """Register every plugin of this package for the active Mitsuba variant (idempotent)."""
    import mitsuba as mi

    variant = mi.variant()
    if variant in _registered:
        return
    from .event_integrator import integrator_class
    from .galvo_sensor import sensor_class as galvo_class

    cls = integrator_class()
    mi.register_integrator("eventfield", lambda props: cls(props))
    galvo = galvo_class()
    mi.register_sensor("galvo", lambda props: galvo(props))
    from .kaleidoscope_sensor import sensor_class as kaleido_class
    kaleido = kaleido_class()
    mi.register_sensor("kaleidoscope", lambda props: kaleido(props))
    _registered.add(variant)
