"""How a step's frame is rendered: ``mi.render`` frozen with ``dr.freeze`` (recorded once, replayed), ``mi.render``
traced at every call (``EVENTFIELD_FREEZE=0``, or a scene Dr.Jit cannot record), samples where they matter
(``sample_allocation``), or the dynamic pixels with the static ones from a one-period cache (``static_pixels``).
One home, so that the time-stepping loop and the accuracy-limit probe render frames the
same way."""
from __future__ import annotations

import numpy as np

from .. import backend
from ..errors import EventFieldError
from ..images import luminance
from ..scene.timed import load_scene
from ..validate import FRAME_SPP, MAX_SEED, MAX_SPP, number

mi, dr = backend.mi, backend.dr

FREEZE_ENV = backend.FREEZE_ENV


def frozen_render(inner, spp: int):
    """The radiance render of one step as a Dr.Jit frozen function (``dr.freeze``); None with
    ``EVENTFIELD_FREEZE=0``.

    ``mi.render`` traces the integrator again at every call (about 2-3 ms on the CPU even when every kernel is
    cached); a frozen function records the kernels once and replays them with the step's new inputs (the scene's
    moved shapes, the sensor's time, the seed), bit for bit the same frame (tests/simulate/test_frozen_render.py,
    every design). Measured per frame on the 2-core CPU (4 spp, steady state, traced -> frozen): fan 48x36
    2.8 -> 0.8 ms, 96x72 4.0 -> 2.0 ms, 173x130 7.2 -> 5.2 ms, 346x260 20.6 -> 18.2 ms; demo 346x260 34.8 -> 32.2 ms.
    The recorded function calls ``mi.render``, not the integrator's ``render`` directly: the latter's first call
    in a process rounded differently from its later ones (one timestamp moved by 1 us), ``mi.render`` does not.
    Scenes whose kernels Dr.Jit refuses to record (a virtual call on an object that is not among the inputs,
    e.g. textured area emitters) are traced every step, with a note. Not measured on a GPU."""
    if not backend.freezing():
        return None

    def render(scene, sensor, seed):     # every object the kernels read is an input, so it is traversed
        return mi.render(scene, sensor=sensor, integrator=inner, seed=seed, spp=spp)
    return backend.FrozenOrTraced(render)


class FrameRenderer:
    """Renders the scene as it is now into a radiance tensor (H, W, C) for the event integrator to stage."""

    def __init__(self, inner, spp: int, allocation=None, notes: list | None = None, static=None, frozen=None):
        """``frozen``: the step's frozen render (``frozen_render``) where it already exists: recorded by the
        default steps' noise probe (``accuracy_limit.noise_map``), whose frames it replays."""
        self.inner, self.spp, self.allocation, self.static = inner, spp, allocation, static
        self.notes = notes if notes is not None else []
        self.frozen = None if allocation is not None else frozen or frozen_render(inner, spp)

    def render(self, timed, seed: int, once: bool = False, step: int | None = None):
        """``once``: a frame outside the stepping (the accuracy-limit probe with another seed): every pixel.
        It goes through the steps' frozen render (same inputs, another seed: a replay, 0.8 ms against 2.8 ms
        traced at 48x36, or on a freshly loaded scene the second of the two recordings the steps would make
        anyway), except where the steps render the static-pixel split: that render's full frame would be
        recorded for this one frame, so it is traced. ``step``: the step's index from the render's
        start (the static-pixel split needs its place in the scan period)."""
        if self.allocation is not None:
            return self.allocation.render(timed.scene, timed.sensor, self.inner, seed)
        if self.static is not None and not once:
            return self.static.render(timed, self.inner, seed, step)
        if self.frozen is not None and self.static is None:
            frame = self.frozen(timed.scene, timed.sensor, dr.opaque(mi.UInt32, seed))
            if self.frozen.refused is not None:     # Dr.Jit refused to record this scene: traced every step
                self.notes.append(f"the step's render could not be frozen, so it is traced at every step "
                                  f"(Dr.Jit: {self.frozen.refused})")
                self.frozen = None
            return frame
        return mi.render(timed.scene, sensor=timed.sensor, integrator=self.inner, seed=seed, spp=self.spp)


def render_frames(scene, times, spp: int = FRAME_SPP, seed: int = 0, log: bool = True,
                  linlog_threshold: float | None = None, rgb: bool = False, sensor=None) -> np.ndarray:
    """Frames of the scene at the given times (seconds): (T, H, W) log brightness exactly as the event pixel
    sees it (lin-log, fixed seed), or linear radiance with ``log=False``. Ground truth for reconstruction, and
    the frame input of the complementary filter. ``rgb=True`` (with ``log=False``, scene loaded in a colour
    variant): (T, H, W, 3) linear RGB, what a colour camera sees. ``sensor``: another Mitsuba sensor to look
    through (e.g. ``truth.centre_pinhole``: a conventional camera beside the event camera)."""
    if rgb and log:
        raise EventFieldError("render_frames: rgb=True needs log=False (the event pixel's log is of luminance)")
    from ..plugins import pixel_model
    from ..plugins.event_integrator import DEFAULT_LINLOG, is_event_integrator
    timed = load_scene(scene)
    spp = int(number(spp, "render_frames: spp", 1, MAX_SPP, integer=True, strict=True))
    seed = int(number(seed, "render_frames: seed", 0, MAX_SEED, integer=True, strict=True))
    integ = timed.scene.integrator()
    if linlog_threshold is None:
        linlog_threshold = (pixel_model.pixel_config(integ.scene_preset, **integ.scene_overrides).linlog_threshold
                            if is_event_integrator(integ) else DEFAULT_LINLOG)
    inner = integ.inner if is_event_integrator(integ) else integ
    frames = []
    times = np.atleast_1d(np.asarray(times, dtype=np.float64))
    if times.size == 0:
        raise EventFieldError("render_frames: times is empty: give at least one time in seconds")
    if not np.isfinite(times).all():
        raise EventFieldError(f"render_frames: times must be finite seconds (got {times[~np.isfinite(times)][0]})")
    for t in times:
        timed.set_time(float(t))
        img = mi.render(timed.scene, integrator=inner, seed=seed, spp=spp, sensor=sensor or timed.scene.sensors()[0])
        arr = np.array(img)
        if rgb:
            if arr.shape[-1] < 3:
                raise EventFieldError("render_frames: rgb=True needs the scene loaded in a colour variant "
                                      f"(load_scene(..., color=True)); the active variant is {mi.variant()}")
            frames.append(arr[..., :3])
            continue
        lum = arr[..., 0] if arr.shape[-1] == 1 else \
            luminance(arr[..., 0], arr[..., 1], arr[..., 2])
        frames.append(pixel_model.linlog_np(lum, linlog_threshold) if log else lum)
    return np.stack(frames)
