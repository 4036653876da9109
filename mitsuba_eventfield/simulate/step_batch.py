"""A render's steps committed to the event pixels in batches: the converter's many-frames kernels
(``plugins/event_batch.py``) fed with rendered frames.

Committed one at a time, every step pays the event engine's fixed cost: about eight kernel launches and one
device-to-host read of the step's event total, which the arrays are sized by (on the CPU about 1 ms a step,
Python included; on a GPU each read also drains the queue, so the render waits on it). :class:`StepBatch`
keeps each step's log-brightness frame in a device buffer instead (one small kernel a step) and commits
``frames`` of them at once: one read, one fill and one sort per batch, and the same events, bit for bit, as
committing each step (``event_batch``'s equality, tested on renders in tests/simulate/test_step_batch.py).

A render batches its steps only where nothing needs the pixel state between steps and the batch's events are
those of its steps (:func:`for_loop`):

* every pixel model does: threshold jitter and shot noise draw from the per-pixel generator carried through
  the batch's loop, the refractory period keeps its last emissions there, the readout cap takes the batch's
  steps at once (``readout.ReadoutLimiter.filter_device``). A model that reads the linear radiance
  (photoreceptor low-pass, shot noise) is held the render's radiance, whose log the batch takes as the
  per-step kernel does (holding the log and recovering the radiance from it would be equal only to rounding);
* the steps are known in advance (uniform, or placed by the image motion): log-change steps are sized from
  the last step's change, and a step may be rendered again;
* the events of a periodic view's first periods are not being kept to be copied (``periodic``: they are
  kept per step on the host).

A batch also ends where the timestamp base changes (a new scan period on the phase grid: the chunk's times
are one period's phases), where a step brings a log frame to a batch of radiances or back (a reused period's
cached frames are logs), and before a checkpoint saves the pixel state (``flush``).
"""
from __future__ import annotations

import math
import time

import numpy as np

from .. import backend
from ..plugins import event_batch, event_fill, pixel_step

mi, dr = backend.mi, backend.dr


class StepBatch:
    """Rendered steps held on the device until ``frames`` of them are committed together."""

    def __init__(self, integ, sink, summary, n_pix: int, frames: int):
        self.integ, self.sink, self.summary = integ, sink, summary
        self.n_pix, self.frames = n_pix, frames
        self.buffer = dr.empty(mi.Float, frames * n_pix)     # the held steps' log frames, step-major
        self.lane = dr.arange(mi.UInt32, n_pix)
        self.times: list[float] = []       # the first held step's start, then each held step's end (seconds)
        self.base_us = 0
        self.until_us = 0
        self.intensity = False             # the held frames are radiances (else log brightnesses)
        self.wants_intensity = pixel_step.needs_intensity(integ.config)

    def add(self, t0: float, t1: float, base_us: int, complete_until_us: int) -> None:
        """Hold the integrator's staged frame as the step (t0, t1] (timestamps + ``base_us``); commit the batch
        when it is full. The staged frame is taken: the integrator's state moves on only when the batch is
        committed."""
        intensity = self.wants_intensity and self.integ.staged_intensity is not None
        if self.times and (base_us != self.base_us or t0 != self.times[-1] or intensity != self.intensity):
            self.flush()
        te = time.perf_counter()
        if not self.times:
            self.times, self.base_us, self.intensity = [t0], base_us, intensity
        slot = event_fill._opaque((len(self.times) - 1) * self.n_pix, mi.UInt32)
        frame = self.integ.staged_intensity if intensity else self.integ.staged
        dr.scatter(self.buffer, frame, self.lane + slot)
        dr.eval(self.buffer)                 # one kernel a step; the rendered image is released
        self.integ.staged = self.integ.staged_intensity = None
        self.times.append(t1)
        self.until_us = complete_until_us
        self.summary.events_s += time.perf_counter() - te
        if len(self.times) > self.frames:
            self.flush()

    def flush(self) -> None:
        """Commit the held steps (if any) and hand their events to the sink."""
        if len(self.times) < 2:
            self.times = []
            return
        te = time.perf_counter()
        events = event_batch.commit_frames(self.integ, self.buffer, self.times, self.base_us, self.intensity)
        self.times = []
        tw = time.perf_counter()
        self.summary.events_s += tw - te
        self.sink.add_step(events, complete_until_us=self.until_us)
        self.summary.write_s += time.perf_counter() - tw


def for_loop(integ, st, sink, summary, n_pix: int, keeps_period_events: bool) -> StepBatch | None:
    """The loop's step batch, or None where its steps are committed one at a time (module docstring)."""
    if not integ.batchable or st.adaptive or keeps_period_events:
        return None
    if st.schedule is not None:
        longest = float(np.max(np.diff(st.schedule)))
    elif st.steps:
        longest = st.duration / st.steps
    else:
        return None
    if not math.isfinite(longest):
        return None
    frames = event_batch.default_frames_per_kernel(n_pix, longest)
    if frames < 2:
        return None
    return StepBatch(integ, sink, summary, n_pix, frames)
