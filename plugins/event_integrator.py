"""Mitsuba integrator plugin ``eventfield``: a nested radiance integrator plus per-pixel event-camera state.

Parameters (XML ``<integrator type="eventfield">``; every pixel-model field overrides the preset's value):

=============================  =========  =========  ======================================================
Parameter                      Type       Default    Description
=============================  =========  =========  ======================================================
preset                         string     ideal      ideal | davis346 | prophesee_gen4 (``pixel_model``)
threshold                      float      0.2        contrast threshold C (log units), ON and OFF
threshold_on                   float      0.2        ON threshold, when it differs from OFF
threshold_off                  float      0.2        OFF threshold
threshold_sigma                float      0          per-pixel threshold mismatch (log units)
threshold_jitter               float      0          threshold noise of each reset (log units)
refractory_s                   float      0          shortest time between two events of a pixel (s)
leak_rate_hz                   float      0          spontaneous ON events per pixel per second
leak_jitter                    float      0          relative per-pixel spread of the leak rate
shot_noise_hz                  float      0          noise events per pixel per second in the dark
shot_noise_bright_factor       float      0.25       noise rate when bright, relative to the dark rate
cutoff_hz                      float      0          photoreceptor low-pass cutoff when bright (0: none)
cutoff_min_fraction            float      0.01       dim pixels: cutoff never below this fraction
bright_intensity               float      1          radiance treated as bright (low-pass, shot noise)
linlog_threshold               float      0.001      radiance below which the response is linear
timestamp_resolution_us        float      0          timestamp clock (0: exact)
readout_cap                    float      0          events per second the readout passes (0: unlimited)
readout_cap_native_pixels      integer    0          > 0: readout_cap is for this many pixels, scaled to the film
seed                           integer    0          seeds the mismatch and every noise draw
(nested integrator)            integrator path       the radiance integrator, e.g. ``<integrator type="direct"/>``
=============================  =========  =========  ======================================================

Example::

    <integrator type="eventfield">
        <float name="threshold" value="0.2"/>
        <string name="preset" value="davis346"/>
        <integrator type="path"><integer name="max_depth" value="4"/></integrator>
    </integrator>

``mi.render(scene)`` with this integrator renders the radiance (returned unchanged, so it still looks like a
photo) and stages its log brightness. The time-stepping loop (``mitsuba_eventfield.render``) then calls
:meth:`EventIntegrator.commit` with the step's start and end time to turn the staged frame into events, or
discards it (adaptive stepping re-renders a shorter step). State lives in Dr.Jit arrays: log brightness at the
previous instant, reference level and per-pixel ON/OFF thresholds.

Pixel realism (``pixel_model.PixelConfig``; all off in the default ``ideal`` preset): threshold mismatch and
the reset's jitter, leak, shot noise and the photoreceptor low-pass evolve in the step's single Dr.Jit kernel
(counter-based random draws, ``counter_rng``, keyed by the seed). :meth:`commit_events` makes the step's events
either on the device (``event_fill``: count, prefix sum, fill, refractory selection, shot noise, sort, clock;
the readout cap in ``readout``) or on the host (``host_events``, then :meth:`readout`), whichever is faster on
the backend (:attr:`device_resident`); both give the same events.
"""
from __future__ import annotations

import contextlib
import math
from dataclasses import fields

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_eventfield.plugins import (counter_rng, event_batch, event_fill, event_select, host_events, pixel_model,
                                        pixel_state, pixel_step, readout)

from ._per_variant import per_variant, subclass
from .properties import number_prop

WHERE, DEFAULT_THRESHOLD, DEFAULT_LINLOG = "integrator 'eventfield'", 0.2, 1e-3


def is_event_integrator(obj) -> bool:
    return any(isinstance(obj, cls) for cls in integrator_class.classes.values())


class _EventIntegratorMethods:
    """The ``eventfield`` integrator's methods, bound to the active variant's ``mi.SamplingIntegrator`` by
    ``integrator_class`` (``_per_variant.subclass``)."""

    def __init__(self, props: mi.Properties):
        mi.SamplingIntegrator.__init__(self, props)
        self._pixels = pixel_state.PixelVariables()
        self.inner = None
        overrides = {}
        names = {f.name for f in fields(pixel_model.PixelConfig)} - {"preset"}
        for name in props.keys():
            value = props.get(name)
            if isinstance(value, mi.Integrator):
                if self.inner is not None:
                    raise ValueError("integrator 'eventfield': give at most one nested radiance integrator")
                self.inner = value
            elif name in names or name == "threshold":      # (ranges: the pixel model's own checks)
                v = number_prop(props, name, None, WHERE, integer=name in ("seed", "readout_cap_native_pixels"))
                # threshold sets both; threshold_on / _off, given too, win whatever their order
                overrides.update({name: v} if name in names else {"threshold_on": v, "threshold_off": v} | overrides)
            elif name != "preset":
                raise ValueError(f"integrator 'eventfield': unknown parameter {name!r}; allowed: preset, "
                                 f"threshold, {', '.join(sorted(names))}")
        if self.inner is None:
            self.inner = mi.load_dict({"type": "path"})
        self.scene_preset = props.get("preset", "ideal")
        self.scene_overrides = overrides
        self.configure(pixel_model.pixel_config(self.scene_preset, "integrator 'eventfield'", **overrides))

    # ---------------------------------------------------------------- configuration
    def configure(self, config):
        """Set the pixel model (a PixelConfig) and forget all pixel state."""
        self.config = config.validate("integrator 'eventfield'")
        self.threshold_on, self.threshold_off = config.threshold_on, config.threshold_off
        self.linlog_threshold = config.linlog_threshold
        self.reset()

    def reset(self):
        self.size = None           # (width, height) once the first frame is seen
        self.log_prev = None       # (filtered) log brightness at the last committed instant
        self.anchor = None         # log brightness at the first commit; reference = anchor + counts * C
        self.k_on = self.k_off = None  # ON / OFF events fired so far by each pixel (Int32)
        self.offset = None         # reference drift from leak and jitter (None when neither is on)
        self.c_on = self.c_off = None
        self.held_on = self.held_off = None   # jittered thresholds each pixel holds until it fires (jitter only)
        self.staged = self.staged_intensity = None
        self.noise_left = self.noise_k = None  # shot noise: hazard left before each pixel's next event, events so far
        self.seed_word = self.leak_rate = self.last_emit = self.limiter = None  # seed_word: keys the draws
        self.refractory_dropped = self.noise_events = 0

    # ---------------------------------------------------------------- checkpoints
    def get_state(self) -> dict:
        """Everything that fixes the pixels' future events, as NumPy arrays (``pixel_state.get_state``)."""
        return pixel_state.get_state(self)

    def set_state(self, d: dict) -> None:
        """Restore :meth:`get_state`'s result (same pixel model, same film)."""
        pixel_state.set_state(self, d)

    def pixel_model_metadata(self) -> dict:
        d = {"model": "ideal" if not (self.config.stochastic or self.config.threshold_sigma) else "realistic",
             "timestamps": "linear interpolation of log brightness between rendered instants"}
        d.update(self.config.as_dict())
        return d

    @property
    def deterministic(self) -> bool:
        return not self.config.stochastic

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
        self.staged_intensity = intensity

    def stage_log(self, log_brightness, size, intensity=None):
        """Stage a log-brightness frame directly (period reuse feeds cached frames through here), with its linear
        radiance where the caller has it (else the pixel model recovers it from the log where it needs it)."""
        if self.size is not None and self.size != tuple(size):
            raise ValueError(f"film size changed from {self.size} to {tuple(size)} between steps")
        self.staged, self.staged_size = log_brightness, tuple(size)
        self.staged_intensity = intensity

    def staged_max_change(self) -> float:
        """Largest |Delta L| of the staged frame against the last committed one (0 before the first commit)."""
        if self.log_prev is None:
            return 0.0
        dr.eval(self.staged)     # keep the frame: commit() must not re-run its (possibly heavy) expression
        return float(dr.max(dr.abs(self.staged - self.log_prev)).array[0])

    # ---------------------------------------------------------------- events
    def _init_state(self, log_now, width, height):
        too_large = event_fill.film_limit_error(width, height)    # checked up front by the facades too
        if too_large:
            raise ValueError(f"film {too_large}")
        cfg, n_pix = self.config, width * height
        sensor = pixel_model.sensor_constants(cfg, n_pix)
        self.size = (width, height)
        self.log_prev = mi.Float(log_now)
        self.anchor = mi.Float(log_now)
        self.k_on, self.k_off = dr.zeros(mi.Int32, n_pix), dr.zeros(mi.Int32, n_pix)
        # per-pixel constants drawn in NumPy, copied into Dr.Jit's memory (event_fill.device_copy): an array on
        # NumPy's memory has that memory's alignment, a kernel variant of its own and, in the frozen chunk passes
        # (event_batch), now and then another recording
        self.c_on = event_fill.device_copy(sensor["c_on"], mi.Float)
        self.c_off = event_fill.device_copy(sensor["c_off"], mi.Float)
        if cfg.leak_rate_hz or cfg.threshold_jitter:
            self.offset = dr.zeros(mi.Float, n_pix)
        if cfg.leak_rate_hz:
            self.leak_rate = event_fill.device_copy(sensor["leak_rate"], mi.Float)
            # a sensor in steady state has its pixels at random phases of their leak cycle
            self.offset = -mi.Float(sensor["leak_phase"]) * self.c_on
        self.seed_word = counter_rng.seed_array(mi, cfg.seed)
        pixel_step.start_draws(self, n_pix)
        if cfg.refractory_s:
            self.last_emit = np.full(n_pix, -np.inf)
        if cfg.readout_cap:
            self.limiter = self._make_limiter(n_pix)
        state = [self.log_prev, self.anchor, self.k_on, self.k_off, self.c_on, self.c_off]
        state += [v for v in (self.offset, self.leak_rate, self.held_on, self.held_off, self.noise_left, self.noise_k)
                  if v is not None]
        dr.make_opaque(*state)

    def _make_limiter(self, n_pix: int):
        cfg = self.config
        cfg.check_film(n_pix)
        return readout.ReadoutLimiter(cfg.readout_cap_for(n_pix), cfg.seed)

    def commit(self, t0: float, t1: float):
        """Accept the staged frame as the brightness at time t1 (seconds) and return the events of (t0, t1].

        Returns numpy arrays (x uint16, y uint16, t float64 seconds, p int8 +1/-1), unsorted. The first commit
        only initialises the pixels (reference = current brightness) and fires nothing.
        """
        step = self._take_staged(t1 - t0, "commit()")
        if step is None:
            return _no_events()
        if self.last_emit is not None and not isinstance(self.last_emit, np.ndarray):
            self.last_emit = self.last_emit.numpy()          # after device-path steps: the same state, moved
        width = self.staged_size[0]
        pix, t, p = host_events.step_events(self, step, t0, t1)
        self._advance(step)
        return (pix % width).astype(np.uint16), (pix // width).astype(np.uint16), t, p

    def _take_staged(self, duration: float, caller: str):
        """The staged frame through the pixel step (its arrays by name), or None when it only initialised the
        pixels (the first commit)."""
        if self.staged is None:
            raise RuntimeError(f"{caller} without a staged frame: render first")
        width, height = self.staged_size
        log_in, intensity = self.staged, self.staged_intensity
        self.staged = self.staged_intensity = None
        if self.log_prev is None:
            self._init_state(log_in, width, height)
            dr.eval(self.log_prev, self.anchor)
            return None
        return self._pixel_step(log_in, intensity, duration)

    def _advance(self, step: dict) -> None:
        self.log_prev, self.k_on, self.k_off, self.offset = step["log_now"], step["k_on"], step["k_off"], \
            step["offset"]
        if step["held"] is not None:
            self.held_on, self.held_off = step["held"]
        if step["noise_state"] is not None:
            self.noise_left, self.noise_k = step["noise_state"]

    path_override = None       # "host" or "device" inside event_path(); None: chosen per backend

    @property
    def device_resident(self) -> bool:
        """True when a step's events are made on the device (:meth:`commit_device`), False for the NumPy path
        (:meth:`commit` and :meth:`readout`); both give the same events. On a GPU always the device. On the CPU
        (LLVM) the NumPy path is faster a step at a time for pixel models with a refractory period or shot
        noise (about 50 kernel launches a step against sparse NumPy work on shared memory), so those take it
        there; steps committed several at a time (:meth:`commit_frames`) are made on the device for every
        model (benchmarks/results/pixel.md). ``event_path()`` overrides the choice."""
        if self.path_override is not None:
            return self.path_override == "device"
        cfg = self.config
        return mi.variant().startswith("cuda") or not (cfg.refractory_s or cfg.shot_noise_hz)

    def commit_events(self, t0: float, t1: float, base_us: int = 0):
        """Accept the staged frame as the brightness at t1 and return the step's events of (t0, t1], time-sorted
        and read out, with timestamps ``rint(t 1e6) + base_us`` microseconds: made on the device
        (``event_fill.DeviceEvents``) or on the host (``event_fill.HostEvents``) as :attr:`device_resident`
        says. Both paths give the same events, bit for bit, the readout cap's drops included (``readout``: its
        random keys are a hash both paths compute)."""
        if self.device_resident:
            events = self.commit_device(t0, t1, base_us)
            if self.limiter is None:
                return events
            return self.limiter.filter_device(events, [events.count], t0, t1, self.config.timestamp_resolution_us)
        x, y, ts, p = self.commit(t0, t1)
        t_us = np.rint(ts * 1e6).astype(np.int64) + base_us
        order = pixel_model.time_order(t_us, int(math.floor(t0 * 1e6)) + base_us)
        return event_fill.HostEvents(*self.readout(x[order], y[order], t_us[order], p[order]))

    def commit_device(self, t0: float, t1: float, base_us: int = 0):
        """:meth:`commit` and the clock of :meth:`readout` on the device (count, prefix sum, fill, refractory
        selection, shot noise, sort): the step's events, time-sorted, with integer microsecond timestamps
        ``rint(t 1e6) + base_us`` (clock-quantised), as ``event_fill.DeviceEvents``. Bit-identical to the host
        path. The readout cap is not applied here (:meth:`commit_events` does)."""
        step = self._take_staged(t1 - t0, "commit_device()")
        if step is None:
            return event_fill.empty()
        cfg = self.config
        refractory = None
        if cfg.refractory_s:
            if isinstance(self.last_emit, np.ndarray):     # after host-path steps: the same state, moved
                self.last_emit = event_fill.device_copy(self.last_emit, mi.Float64)
            refractory = event_select.Refractory(self.last_emit, cfg.refractory_s)
        noise = step["noise"][:3] if step["noise"] is not None else None
        events = event_fill.crossing_events(step["n"], self.log_prev, step["log_now"], step["log_ref"],
                                            step["c_on"], step["c_off"], self.staged_size[0], t0, t1, base_us,
                                            cfg.timestamp_resolution_us, refractory, noise)
        if refractory is not None:
            self.last_emit = refractory.last_emit
        self.refractory_dropped += events.refractory_dropped
        self.noise_events += events.noise_events
        self._advance(step)
        return events

    @property
    def batchable(self) -> bool:
        """True when :meth:`commit_frames` can take this pixel model many frames per kernel."""
        return event_batch.batchable(self)

    def commit_frames(self, log_frames, times, base_us: int = 0):
        """The events of several frames at once (``event_batch.commit_frames``): ``log_frames`` holds
        ``len(times) - 1`` log-brightness frames, frame-major, at ``times[1:]``; ``times[0]`` is the last
        committed instant. The same events as that many :meth:`commit_device` calls, in fewer kernels."""
        return event_batch.commit_frames(self, log_frames, times, base_us)

    def _pixel_step(self, log_in, intensity, duration: float) -> dict:
        """One step of every pixel, evaluated in one Dr.Jit kernel (``pixel_step.step``: photoreceptor low-pass,
        leak, threshold jitter, crossing counts and shot noise). Returns the step's arrays by name."""
        cfg = self.config
        if intensity is None and pixel_step.needs_intensity(cfg):
            intensity = pixel_model.linlog_inverse(dr, log_in, self.linlog_threshold)
        dt = None
        if pixel_step.needs_dt(cfg):
            dt = mi.Float(duration)
            dr.make_opaque(dt)                  # a new literal per step would recompile the kernel
        held = (self.held_on, self.held_off) if cfg.threshold_jitter else None
        noise_state = (self.noise_left, self.noise_k) if cfg.shot_noise_hz else None
        st = pixel_step.step(self, dr.arange(mi.UInt32, dr.width(log_in)), self.log_prev, self.k_on, self.k_off,
                             self.offset, noise_state, log_in, intensity, dt, held)
        lv = st.levels
        todo = [lv.n, lv.k_on, lv.k_off, lv.log_now, lv.log_ref]
        if cfg.threshold_jitter:                # gathered below: evaluate here, in the one kernel
            todo += [st.c_on, st.c_off, *st.held]
        noise = None
        if st.noise is not None:
            hit, u_pol, u_t = st.noise
            noise = (hit, u_pol, u_t, mi.Int32(dr.select(hit, 1, 0)))
            todo += list(noise) + list(st.noise_state)
        todo += [lv.offset] if lv.offset is not None else []
        dr.eval(*todo)
        return {"n": lv.n, "k_on": lv.k_on, "k_off": lv.k_off, "log_now": lv.log_now, "log_ref": lv.log_ref,
                "c_on": st.c_on, "c_off": st.c_off, "offset": lv.offset, "noise": noise, "held": st.held,
                "noise_state": st.noise_state}

    def readout(self, x, y, t_us, p):
        """The sensor's output stage on one step's time-sorted events: clock quantisation, readout cap."""
        cfg = self.config
        if cfg.timestamp_resolution_us:
            res = cfg.timestamp_resolution_us
            t_us = (np.floor(t_us / res) * res).astype(np.int64)
        if self.limiter is not None:       # every step, empty ones too: its count keys the limiter's draws
            keep = self.limiter.filter(t_us)
            x, y, t_us, p = x[keep], y[keep], t_us[keep], p[keep]
        return x, y, t_us, p

    def readout_dropped(self) -> int:
        return 0 if self.limiter is None else self.limiter.dropped

    def periodic_key(self):
        """Integer array that, with the previous log brightness, fixes every future event of the ideal pixel
        (net event count per pixel), or None when no such exact key exists (unequal ON/OFF thresholds, or a
        pixel model whose state drifts or draws noise).
        Equal keys one scan period apart, with identical input frames, mean the events repeat exactly."""
        if self.k_on is None or not self.deterministic or self.threshold_on != self.threshold_off \
                or self.config.threshold_sigma:
            return None
        key = self.k_on - self.k_off
        dr.eval(key)
        return key

    def traverse(self, callback):
        self.inner.traverse(callback)

    def to_string(self):
        return f"EventIntegrator[preset={self.config.preset}, inner={self.inner}]"

pixel_state.add_pixel_variables(_EventIntegratorMethods)


def _define_class():
    return subclass(mi.SamplingIntegrator, _EventIntegratorMethods, "EventIntegrator")


integrator_class = per_variant(_define_class)   # the EventIntegrator class of the active variant


@contextlib.contextmanager
def event_path(path: str):
    """Within the block, every event integrator of the active variant makes its events on the ``"host"``
    (NumPy expansion and sort) or on the ``"device"`` (``event_fill``), whatever the backend and pixel model:
    for comparing the two paths (tests, benchmarks, checking a new backend). They give the same events."""
    if path not in ("host", "device"):
        raise ValueError(f"event_path({path!r}): allowed: 'host', 'device'")
    cls = integrator_class()
    before = cls.path_override
    cls.path_override = path
    try:
        yield
    finally:
        cls.path_override = before


def host_path():
    return event_path("host")


def device_path():
    return event_path("device")


def _no_events():
    return (np.empty(0, np.uint16), np.empty(0, np.uint16), np.empty(0, np.float64), np.empty(0, np.int8))
