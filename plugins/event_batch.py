"""Events of many frames in a few kernels: the frames-to-events converter's fast path (issue 15, part 4).

A step at a time, every frame pays the same fixed cost (a pixel kernel, a scan, a sync to size the event
arrays, a fill, a sort, each a launch; about 0.4 ms at 346x260 on the CPU before any event). Given ``B``
frames at once:

1. count: one kernel loops every pixel through the ``B`` steps (``pixel_step.advance``, the per-step kernel's
   own definition) and keeps each (step, pixel) lane's crossing count ``|n|``, frame-major, and the state
   after the last step;
2. prefix sum over the ``B x N`` lanes; one sync reads the total;
3. fill and time order: ``event_fill.fill``, the one fill of every device path. Its crossing writer
   (``Chunk.write``) steps the pixels again from the chunk's first state, so nothing but the counts is stored
   between the passes (storing each lane's levels and reading them back cost more than stepping twice: the
   converter's kernels at 346x260, 4 frames a kernel, 53 against 113 M pixel-steps/s); one stable radix sort
   of the chunk by microsecond.

The events equal, bit for bit, those of ``B`` calls of ``EventIntegrator.commit_device`` joined in order: the
same float operations in the same order, and a stable sort keyed by time over slots in (step, pixel,
crossing) order is the per-step order concatenated (a step's times never pass the next step's start: the
interpolation fraction is clipped to [0, 1] and rounding to microseconds keeps order; the one exception is a
float64 ``t0 + 1.0 (t1 - t0)`` one ulp above ``t1`` where ``t1`` is exactly half a microsecond, which the
per-step concatenation would leave out of order and the chunk sorts). Pixel models that draw random numbers
per step (threshold jitter, shot noise) or keep per-event state (refractory period, readout cap) are not
batched: ``batchable`` says so and the caller steps them one frame at a time.
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_eventfield.plugins import event_fill, pixel_model, pixel_step


# Lane-steps (pixels x frames) per kernel by backend, and the fewest frames. CPU (converter kernels alone, 2 kHz
# stack, 2 cores, best of 6; M pixel-steps/s by frames a kernel): 346x260 1: 53, 2: 97, 3: 112, 4: 118, 6: 115,
# 8: 114, 11: 102, 16: 97; 640x480 1: 104, 2: 118, 3: 119; 1280x720 1: 100, 2: 112, 3: 124, 4: 120. One frame a
# kernel pays about eight launches a frame (~0.8 ms at any size); past a few hundred thousand lane-steps the
# chunk's events leave the cache. CUDA: enough lanes to fill the GPU and few launches and syncs per frame, which
# is where batching is for (not measured on a GPU).
LANE_STEPS = {"llvm": 360_000, "cuda": 16_000_000}
MIN_FRAMES_PER_KERNEL = 3
MAX_FRAMES_PER_KERNEL = 64


def default_frames_per_kernel(n_pix: int, frame_interval_s: float) -> int:
    """Frames per kernel for a film of ``n_pix`` pixels on the active backend: about ``LANE_STEPS`` lane-steps,
    at least ``MIN_FRAMES_PER_KERNEL``. On the CPU never so many that the chunk's time span needs more radix
    passes than one frame does (the sort key is microseconds from the chunk's start, up to
    ``event_fill.PASS_BITS`` per pass: 2^20 us, about a second, in one; a second pass costs more than the fewer
    launches save there; on a GPU a pass is cheap next to the launches and syncs batching saves)."""
    cuda = mi.variant().startswith("cuda")
    frames = round(LANE_STEPS["cuda" if cuda else "llvm"] / n_pix)
    frames = int(min(MAX_FRAMES_PER_KERNEL, max(MIN_FRAMES_PER_KERNEL, frames)))
    while not cuda and frames > 1 and _passes(frames * frame_interval_s) > _passes(frame_interval_s):
        frames -= 1
    return frames


def _passes(span_s: float) -> int:
    bits = max(1, (int(np.ceil(span_s * 1e6)) + 3).bit_length())
    return -(-bits // event_fill.PASS_BITS["llvm"])


_disabled = [False]


@contextlib.contextmanager
def one_frame_a_step():
    """Within the block no integrator batches (``batchable`` is False): the per-step device path, for
    comparing the two (tests, benchmarks)."""
    before, _disabled[0] = _disabled[0], True
    try:
        yield
    finally:
        _disabled[0] = before


def batchable(integ) -> bool:
    """True when ``integ``'s pixel model can take many frames per kernel (see the module docstring)."""
    cfg = integ.config
    return not _disabled[0] and integ.device_resident and \
        not (cfg.threshold_jitter or cfg.shot_noise_hz or cfg.refractory_s or cfg.readout_cap)


def commit_frames(integ, log_frames, times, base_us: int = 0) -> event_fill.DeviceEvents:
    """Events of the steps from ``times[0]`` (the pixels' current instant) through ``B = len(times) - 1``
    frames: ``log_frames`` is a Float of ``B x N`` log brightnesses (frame-major; any further values are not
    read: a caller's buffer for more frames may be passed whole), frame ``b`` the brightness at
    ``times[b + 1]`` seconds (the low-pass recovers the radiance from it, as the per-step kernel does for a
    staged log frame). Advances the integrator's state; returns the chunk's events time-sorted on the device,
    as per-step commits would."""
    if not batchable(integ):
        raise ValueError("commit_frames: this pixel model steps one frame at a time (event_batch.batchable)")
    times = np.asarray(times, np.float64)
    steps, n_pix = len(times) - 1, integ.size[0] * integ.size[1] if integ.size else 0
    if integ.log_prev is None or dr.width(log_frames) < steps * n_pix or steps < 1:
        raise ValueError(f"commit_frames: {dr.width(log_frames)} values for {steps} frames of {n_pix} pixels "
                         "(after a first frame has set the pixels)")
    chunk = Chunk(integ, _state(integ), log_frames, times, integ.size[0], n_pix)
    kept = dr.empty(mi.UInt32, steps * n_pix)

    def count(b, lane, log_prev, levels):
        dr.scatter(kept, mi.UInt32(dr.abs(levels.n)), lane)
    final = chunk.run(count)
    dr.eval(kept, *final)
    _set_state(integ, final)
    ends = dr.prefix_reduce(dr.ReduceOp.Add, kept, exclusive=False)
    total = event_fill._read([dr.gather(mi.UInt32, ends, steps * n_pix - 1)])[0]
    return event_fill.fill(chunk, ends, total, base_us, integ.config.timestamp_resolution_us)


def _state(integ) -> tuple:
    return (integ.log_prev, integ.k_on, integ.k_off) + ((integ.offset,) if integ.offset is not None else ())


def _set_state(integ, state) -> None:
    integ.log_prev, integ.k_on, integ.k_off = state[:3]
    if integ.offset is not None:
        integ.offset = state[3]


@dataclass
class Chunk:
    """``B`` frames of every pixel from a state, as ``event_fill.fill`` takes crossings: stepping the pixels is
    cheap next to storing each (step, pixel) lane's brightness before and after, reference level and count
    (16 bytes a lane written, then read back by the fill), so the count pass keeps only ``|n|`` and the fill
    steps the pixels again from the same state (the same operations: the same values, bit for bit)."""
    integ: object
    state: tuple                 # log_prev, k_on, k_off[, offset] at times[0]
    log_frames: object
    times: np.ndarray
    width: int
    n_pix: int

    def run(self, each_step) -> tuple:
        """One kernel: every pixel through the ``B`` steps (``pixel_step.advance``, the per-step kernel's own
        definition); ``each_step(b, lane, log_prev, levels)`` is traced into the loop body (``lane``: the
        frame-major index b N + pixel). Returns the state after the last step (lazy)."""
        integ, cfg = self.integ, self.integ.config
        pixel = dr.arange(mi.UInt32, self.n_pix)
        n_d = event_fill._opaque(self.n_pix, mi.UInt32)
        # the per-step kernel's dt is mi.Float(t1 - t0): the same float64 difference, rounded to float32
        dts = mi.Float(np.diff(self.times).astype(np.float32)) if cfg.cutoff_hz or cfg.leak_rate_hz else None
        has_offset = len(self.state) == 4

        def body(b, log_prev, k_on, k_off, *offset):
            lane = b * n_d + pixel
            log_in = dr.gather(mi.Float, self.log_frames, lane)
            dt = dr.gather(mi.Float, dts, b) if dts is not None else None
            intensity = pixel_model.linlog_inverse(dr, log_in, integ.linlog_threshold) if cfg.cutoff_hz else None
            levels = pixel_step.advance(integ, log_prev, k_on, k_off, offset[0] if has_offset else None, log_in,
                                        intensity, dt, integ.c_on, integ.c_off)
            each_step(b, lane, log_prev, levels)
            return (b + 1, levels.log_now, levels.k_on, levels.k_off) + ((levels.offset,) if has_offset else ())

        bound = event_fill._opaque(len(self.times) - 1, mi.UInt32)
        out = dr.while_loop((dr.zeros(mi.UInt32, self.n_pix),) + tuple(self.state), lambda b, *rest: b < bound,
                            body)
        return tuple(out[1:])

    def write(self, ends, xy, key_of, key_out, word_out) -> None:
        """``event_fill``'s crossing writer: the pixels stepped again, each step's crossings into their slots."""
        t_d = mi.Float64(self.times)

        def write_step(b, lane, log_prev, levels):
            kept = mi.UInt32(dr.abs(levels.n))
            event_fill.write_crossings(levels.n, kept, dr.gather(mi.UInt32, ends, lane) - kept, log_prev,
                                       levels.log_now, levels.log_ref, self.integ.c_on, self.integ.c_off,
                                       dr.gather(mi.Float64, t_d, b), dr.gather(mi.Float64, t_d, b + 1), xy,
                                       key_of, key_out, word_out)
        self.run(write_step)
