"""Mitsuba integrator plugin ``eventfield``: a nested radiance integrator plus per-pixel event-camera state.

XML::

    <integrator type="eventfield">
        <float name="threshold" value="0.2"/>          <!-- contrast threshold C (log units), ON and OFF -->
        <float name="threshold_on" value="0.25"/>      <!-- optional: separate ON / OFF thresholds -->
        <float name="linlog_threshold" value="1e-3"/>  <!-- radiance below which the response is linear -->
        <integrator type="path"><integer name="max_depth" value="4"/></integrator>   <!-- default: path -->
    </integrator>

``mi.render(scene)`` with this integrator renders the radiance (returned unchanged, so it still looks like a
photo) and stages its log brightness. The time-stepping loop (``mitsuba_eventfield.render``) then calls
:meth:`EventIntegrator.commit` with the step's start and end time to turn the staged frame into events, or
discards it (adaptive stepping re-renders a shorter step). State lives in Dr.Jit arrays: log brightness at the
previous instant, reference level and per-pixel ON/OFF thresholds.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from . import pixel_model
from ._per_variant import per_variant

DEFAULT_THRESHOLD = 0.2
DEFAULT_LINLOG = 1e-3


def is_event_integrator(obj) -> bool:
    return any(isinstance(obj, cls) for cls in integrator_class.classes.values())


def _define_class():
    class EventIntegrator(mi.SamplingIntegrator):
        def __init__(self, props: mi.Properties):
            super().__init__(props)
            self.inner = None
            for name in props.keys():
                value = props.get(name)
                if isinstance(value, mi.Integrator):
                    if self.inner is not None:
                        raise ValueError("integrator 'eventfield': give at most one nested radiance integrator")
                    self.inner = value
            if self.inner is None:
                self.inner = mi.load_dict({"type": "path"})
            c = float(props.get("threshold", DEFAULT_THRESHOLD))
            # the scene's own values: per-render overrides fall back to these, never to an earlier override
            self.scene_defaults = {"threshold_on": float(props.get("threshold_on", c)),
                                   "threshold_off": float(props.get("threshold_off", c)),
                                   "linlog_threshold": float(props.get("linlog_threshold", DEFAULT_LINLOG))}
            self.configure(**self.scene_defaults)

        # ---------------------------------------------------------------- configuration
        def configure(self, threshold_on=None, threshold_off=None, linlog_threshold=None):
            """Set the pixel parameters (checked) and forget all pixel state."""
            for name, value in (("threshold_on", threshold_on), ("threshold_off", threshold_off),
                                ("linlog_threshold", linlog_threshold)):
                if value is not None and not (math.isfinite(value) and value > 0):
                    raise ValueError(f"integrator 'eventfield': {name} = {value!r} is not allowed (must be a finite "
                                     "number > 0)")
            if threshold_on is not None:
                self.threshold_on = float(threshold_on)
            if threshold_off is not None:
                self.threshold_off = float(threshold_off)
            if linlog_threshold is not None:
                self.linlog_threshold = float(linlog_threshold)
            self.reset()

        def reset(self):
            self.size = None           # (width, height) once the first frame is seen
            self.log_prev = None       # L at the last committed instant
            self.anchor = None         # log brightness at the first commit; reference = anchor + counts * C
            self.k_on = self.k_off = None  # ON / OFF events fired so far by each pixel (Int32)
            self.c_on = self.c_off = None
            self.staged = None         # L of the frame rendered but not yet committed
            self.staged_image = None

        def pixel_model_metadata(self) -> dict:
            return {"model": "ideal", "threshold_on": self.threshold_on, "threshold_off": self.threshold_off,
                    "linlog_threshold": self.linlog_threshold,
                    "timestamps": "linear interpolation of log brightness between rendered instants"}

        # ---------------------------------------------------------------- Mitsuba entry point
        def render(self, scene, sensor=0, seed=0, spp=0, develop=True, evaluate=True):
            if isinstance(sensor, int):
                sensor = scene.sensors()[sensor]
            image = self.inner.render(scene, sensor, seed, spp, develop, evaluate)
            self.stage(image)
            return image

        def stage(self, image):
            """Compute and keep the log brightness of a rendered (H, W, C) radiance tensor."""
            height, width, channels = image.shape
            flat = image.array
            if channels == 1:
                intensity = flat
            else:  # rgb(a): photometric luminance of the first three channels
                idx = dr.arange(mi.UInt32, width * height) * channels
                intensity = mi.luminance(mi.Color3f(dr.gather(mi.Float, flat, idx), dr.gather(mi.Float, flat, idx + 1),
                                                    dr.gather(mi.Float, flat, idx + 2)))
            # left unevaluated: commit() fuses it with the crossing count into one kernel
            self.stage_log(pixel_model.linlog(dr, intensity, self.linlog_threshold), (width, height))
            self.staged_image = image

        def stage_log(self, log_brightness, size):
            """Stage a log-brightness frame directly (period reuse feeds cached frames through here)."""
            if self.size is not None and self.size != tuple(size):
                raise ValueError(f"film size changed from {self.size} to {tuple(size)} between steps")
            self.staged, self.staged_size, self.staged_image = log_brightness, tuple(size), None

        def staged_max_change(self) -> float:
            """Largest |Delta L| of the staged frame against the last committed one (0 before the first commit)."""
            if self.log_prev is None:
                return 0.0
            return float(dr.max(dr.abs(self.staged - self.log_prev)).array[0])

        # ---------------------------------------------------------------- events
        def commit(self, t0: float, t1: float):
            """Accept the staged frame as the brightness at time t1 (seconds) and return the events of (t0, t1].

            Returns numpy arrays (x uint16, y uint16, t float64 seconds, p int8 +1/-1), unsorted. The first commit
            only initialises the pixels (reference = current brightness) and fires nothing.
            """
            if self.staged is None:
                raise RuntimeError("commit() without a staged frame: render first")
            width, height = self.staged_size
            log_now, self.staged, self.staged_image = self.staged, None, None
            if self.log_prev is None:
                n_pix = width * height
                self.size = (width, height)
                self.log_prev = mi.Float(log_now)
                self.anchor = mi.Float(log_now)
                self.k_on = dr.zeros(mi.Int32, n_pix)
                self.k_off = dr.zeros(mi.Int32, n_pix)
                self.c_on = dr.full(mi.Float, self.threshold_on, n_pix)
                self.c_off = dr.full(mi.Float, self.threshold_off, n_pix)
                dr.make_opaque(self.c_on, self.c_off, self.k_on, self.k_off)
                dr.eval(self.log_prev, self.anchor)
                return _no_events()
            log_ref = pixel_model.reference_level(dr, mi.Float, self.anchor, self.k_on, self.k_off, self.c_on,
                                                  self.c_off)
            n = pixel_model.count_crossings(dr, mi.Int32, log_now, log_ref, self.c_on, self.c_off)
            k_on, k_off = self.k_on + dr.maximum(n, 0), self.k_off + dr.maximum(-n, 0)
            dr.eval(n, k_on, k_off, log_now, log_ref)
            fired = dr.compress(n != 0)
            if dr.width(fired) == 0:
                out = _no_events()
            else:  # only firing pixels leave Dr.Jit, gathered in a single kernel
                sparse = [dr.gather(type(a), a, fired) for a in
                          (n, self.log_prev, log_now, log_ref, self.c_on, self.c_off)]
                dr.eval(*sparse)
                pix, t, p = pixel_model.expand_crossings(fired.numpy(), *(a.numpy() for a in sparse), t0, t1)
                out = ((pix % width).astype(np.uint16), (pix // width).astype(np.uint16), t, p)
            self.log_prev, self.k_on, self.k_off = log_now, k_on, k_off
            return out

        def periodic_key(self):
            """Integer array that, with the previous log brightness, fixes every future event of the ideal pixel
            (net event count per pixel), or None when no such exact key exists (unequal ON/OFF thresholds).
            Equal keys one scan period apart, with identical input frames, mean the events repeat exactly."""
            if self.k_on is None or self.threshold_on != self.threshold_off:
                return None
            key = self.k_on - self.k_off
            dr.eval(key)
            return key

        def traverse(self, callback):
            self.inner.traverse(callback)

        def to_string(self):
            return (f"EventIntegrator[threshold_on={self.threshold_on}, threshold_off={self.threshold_off}, "
                    f"linlog_threshold={self.linlog_threshold}, inner={self.inner}]")


    return EventIntegrator


integrator_class = per_variant(_define_class)   # the EventIntegrator class of the active variant


def _no_events():
    return (np.empty(0, np.uint16), np.empty(0, np.uint16), np.empty(0, np.float64), np.empty(0, np.int8))
