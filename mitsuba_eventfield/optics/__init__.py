"""Optics models, one module per physical idea: the two-mirror galvo geometry (``galvo``) and the galvo's scan
envelope (``envelope``). Pure functions and small dataclasses; no Mitsuba import, so the device layer, the
sensor plugins and the light-field code all share them."""
