"""Mitsuba's Python base classes differ per variant, so each plugin class is defined once per variant."""
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
