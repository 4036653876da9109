"""Mitsuba's Python base classes differ per variant, so each plugin class is built once per variant.

A plugin's methods are written as a plain module-level class (readable, testable, no closure); ``subclass``
copies them onto the active variant's Mitsuba base class. Nanobind classes accept exactly one base, so the
methods cannot be a mixin, and they call their base explicitly (``mi.Sensor.traverse(self, cb)``), not
``super()``.
"""
import mitsuba as mi


def per_variant(define):
    """Wrap a class factory: calling the result returns the class for the active variant (built on first use).
    The built classes are in ``.classes`` (for isinstance checks across variants)."""
    classes = {}

    def get():
        variant = mi.variant()
        if variant not in classes:
            classes[variant] = define()
        return classes[variant]

    get.classes = classes
    return get


def subclass(base, methods, name: str):
    """A subclass of ``base`` (a Mitsuba class of the active variant) named ``name`` with the attributes of
    the plain class ``methods``."""
    body = {k: v for k, v in vars(methods).items() if k not in ("__dict__", "__weakref__")}
    return type(name, (base,), body)
