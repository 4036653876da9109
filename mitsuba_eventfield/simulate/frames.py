"""How a step's frame is rendered: ``mi.render`` (traced at every call), the same render frozen with ``dr.freeze``
for small frames (recorded once, replayed), or samples where they matter (``sample_allocation``). One home, so
that the time-stepping loop and the accuracy-limit probe render frames the same way."""
from __future__ import annotations

import os

from .. import backend

mi, dr = backend.mi, backend.dr

FREEZE_ENV = "EVENTFIELD_FREEZE"
FREEZE_MAX_SAMPLES = 32_768      # frames of at most this many samples (W x H x spp) are rendered frozen


def frozen_render(inner, spp: int, samples: int):
    """The radiance render of one step as a Dr.Jit frozen function (``dr.freeze``), for small frames only; None
    otherwise or with ``EVENTFIELD_FREEZE=0``.

    ``mi.render`` traces the integrator again at every call (about 3 ms on the CPU even when every kernel is
    cached); a frozen function records the kernels once and replays them with the step's new inputs (the scene's
    moved shapes, the sensor's time, the seed), bit for bit the same frame (tests/simulate/test_frozen_render.py,
    every design). Measured per frame on the 2-core CPU (4 spp, steady state, plain -> frozen): fan 48x36
    2.8 -> 1.15 ms, 96x72 4.0 -> 3.0 ms, 173x130 7.2 -> 8.5 ms; demo 173x130 10.5 -> 14.4 ms, 346x260 34 -> 53 ms.
    The replay costs more than the trace saves above about 100x75 pixels at 4 spp, hence ``FREEZE_MAX_SAMPLES``
    (not measured on a GPU). Scenes whose kernels Dr.Jit refuses to record (nested virtual calls, e.g. textured
    area emitters) are traced every step, with a note (``_Loop.render_frame``)."""
    if os.environ.get(FREEZE_ENV, "1") == "0" or samples > FREEZE_MAX_SAMPLES:
        return None

    @dr.freeze
    def render(scene, sensor, seed):     # every object the kernels read is an input, so it is traversed
        return inner.render(scene, sensor, seed, spp, True, True)
    return render


class FrameRenderer:
    """Renders the scene as it is now into a radiance tensor (H, W, C) for the event integrator to stage."""

    def __init__(self, inner, spp: int, size, allocation=None, notes: list | None = None):
        self.inner, self.spp, self.allocation = inner, spp, allocation
        self.notes = notes if notes is not None else []
        self.frozen = None if allocation is not None else frozen_render(inner, spp, size[0] * size[1] * spp)

    def render(self, timed, seed: int, once: bool = False):
        """``once``: a frame outside the stepping (the accuracy-limit probe with another seed): traced, not
        recorded, so that the frozen steps are not recorded again for it."""
        if self.allocation is not None:
            return self.allocation.render(timed.scene, timed.sensor, self.inner, seed)
        if self.frozen is not None and not once:
            try:
                return self.frozen(timed.scene, timed.sensor, dr.opaque(mi.UInt32, seed))
            except RuntimeError as e:               # Dr.Jit refused to record this scene: trace every step
                if "frozen function" not in str(e):
                    raise
                self.frozen = None
                why = " ".join(str(e.__cause__ or e).split()).split("validate(): ")[-1].split(". ")[0][:160]
                self.notes.append(f"the step's render could not be frozen, so it is traced at every step "
                                  f"(Dr.Jit: {why})")
        return self.inner.render(timed.scene, timed.sensor, seed, self.spp, True, True)
