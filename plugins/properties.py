"""A plugin's numeric properties, read with one error shape: ``sensor 'galvo': amplitude = 'two': must be a
number ...``, naming the plugin, the parameter, the value and the allowed range. A bare ``float(props.get(k))``
gave Python's "could not convert string to float: 'two'" (no parameter named) and ``int()`` cut 4.7 lines to 4
without a word."""
from __future__ import annotations

from mitsuba_eventfield.validate import number


def number_prop(props, key: str, default, where: str, lo=None, hi=None, *, integer: bool = False,
                lo_open: bool = False):
    """``props[key]`` as a finite number (an int if ``integer``: a fraction refused) within [lo, hi]
    (``lo_open``: lo excluded), or ``default`` (unchecked) when absent; else ValueError naming ``where`` and
    ``key``. A numeric ``<string>`` is read as its number, as Mitsuba's own XML defaults are."""
    if key not in props:
        return default
    return number(props.get(key), f"{where}: {key}", lo, hi, integer=integer, lo_open=lo_open, error=ValueError)
