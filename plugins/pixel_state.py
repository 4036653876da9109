"""The event pixels' state: where it lives (``PixelVariables``), and as plain NumPy arrays and numbers, and back:
what a checkpoint saves (``simulate/checkpoint.py``) so that a resumed render makes the events of an
uninterrupted one."""
from __future__ import annotations

import json

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_eventfield.errors import ConfigError
from mitsuba_eventfield.plugins import counter_rng

STATE_ARRAYS = {"log_prev": "Float", "anchor": "Float", "k_on": "Int32", "k_off": "Int32", "c_on": "Float",
                "c_off": "Float", "offset": "Float", "leak_rate": "Float", "held_on": "Float", "held_off": "Float",
                "noise_left": "Float64", "noise_k": "UInt32"}


class PixelVariables:
    """Where the event integrator keeps its pixels' state (``PIXEL_VARIABLES``): a plain object, which Dr.Jit's
    traversal of a Python plugin (every Dr.Jit array in its ``__dict__``, ``drjit.detail.traverse_py_cb_ro``)
    does not enter. The frozen step render (``simulate/frames.py``) takes the scene, and so the integrator, as
    an input: with the state in ``__dict__`` every state array was an input of every replay, and the first
    commit (None -> arrays) changed the inputs' layout, so Dr.Jit recorded the render 3 to 5 times a render
    instead of 2 (about 3.5 ms each at 48x36: the demo's 12 steps took 40-45 ms, now 33-38)."""


PIXEL_VARIABLES = ("size", "log_prev", "anchor", "k_on", "k_off", "offset", "c_on", "c_off", "held_on", "held_off",
                   "staged", "staged_intensity", "staged_size", "noise_left", "noise_k", "seed_word", "leak_rate",
                   "last_emit", "limiter")


def _pixel_variable(name: str) -> property:
    return property(lambda self: getattr(self._pixels, name, None),
                    lambda self, value: setattr(self._pixels, name, value),
                    doc=f"``{name}``, kept in ``PixelVariables`` (not traversed by frozen functions)")


def add_pixel_variables(methods) -> None:
    """Give the integrator's methods class a property per state variable, stored in ``self._pixels``."""
    for name in PIXEL_VARIABLES:
        setattr(methods, name, _pixel_variable(name))


def get_state(integ) -> dict:
    """Everything that fixes the pixels' future events, as NumPy arrays and plain numbers (a checkpoint):
    levels, event counts, thresholds, drift, the shot noise's hazard left and event counts, last emissions, the
    readout limiter's counters. (The random draws are keyed by these counters and the seed: no generator
    state.)"""
    if integ.staged is not None:
        raise RuntimeError("get_state() with a staged frame: commit it first")
    d = {"size": np.array(integ.size or (0, 0)), "refractory_dropped": integ.refractory_dropped,
         "noise_events": integ.noise_events}
    for name in STATE_ARRAYS:
        if getattr(integ, name) is not None:
            d[name] = getattr(integ, name).numpy()
    if integ.last_emit is not None:
        d["last_emit"] = integ.last_emit if isinstance(integ.last_emit, np.ndarray) else integ.last_emit.numpy()
    if integ.limiter is not None:
        lim = integ.limiter
        d["limiter"] = np.array(json.dumps(lim.state()))
    return d


def set_state(integ, d: dict) -> None:
    """Restore :func:`get_state`'s result into ``integ`` (same pixel model, same film)."""
    integ.reset()
    if integ.config.threshold_jitter and "held_on" not in d:
        raise ConfigError("checkpoint: made by a version whose threshold jitter was drawn every step, not held "
                          "from one event to the next: render again from the start")
    if "rng_state" in d:
        raise ConfigError("checkpoint: made by a version that drew its noise from per-pixel PCG32 streams, which "
                          "this version replaced with counter-based draws: render again from the start")
    integ.size = tuple(int(v) for v in d["size"])
    for name, kind in STATE_ARRAYS.items():
        if name in d:
            setattr(integ, name, getattr(mi, kind)(d[name]))
    integ.seed_word = counter_rng.seed_array(mi, integ.config.seed)
    if "last_emit" in d:
        integ.last_emit = np.array(d["last_emit"], dtype=np.float64)
    cfg = integ.config
    if cfg.readout_cap:
        integ.limiter = integ._make_limiter(integ.size[0] * integ.size[1])
        saved = json.loads(str(d["limiter"]))
        if "steps" not in saved:          # a checkpoint of the generator-drawn limiter (before 2026-11-25)
            raise ConfigError("checkpoint: its readout limiter drew its drops from a random generator, which this "
                              "version replaced with hashed keys: render again from the start")
        integ.limiter.set_state(saved)
    integ.refractory_dropped, integ.noise_events = int(d["refractory_dropped"]), int(d["noise_events"])
    dr.make_opaque(*[v for v in (getattr(integ, n) for n in STATE_ARRAYS) if v is not None])
