"""Events of many frames in a few kernels: the frames-to-events converter's fast path (issue 15, part 4).

A step at a time, every frame pays the same fixed cost (a pixel kernel, a scan, a sync to size the event
arrays, a fill, a sort, each a launch; about 0.4 ms at 346x260 on the CPU before any event). Given ``B``
frames at once:

1. pixels: one kernel loops every pixel through the ``B`` steps (``pixel_step.advance``, the per-step kernel's
   own definition), keeping each step's crossing count, reference level and brightness before and after;
2. count and prefix sum over the ``B x N`` (step, pixel) lanes, frame-major; one sync reads the total;
3. fill and time order: ``event_fill.fill``, the one fill of every device path (a lane a pixel writes its
   crossings into its slot ranges; one stable radix sort of the chunk by microsecond).

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

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_eventfield.plugins import event_fill, pixel_model, pixel_step


# Lane-steps (pixels x frames) per kernel by backend. CPU: the chunk's events must stay in cache (converter, 2 kHz
# stack, 346x260, best of 4 warm runs, Mpix-steps/s by frames a kernel: 1: 89, 2: 95, 3: 98, 4: 96, 5: 97, 6: 92,
# 7: 80, 8: 80; 640x480: 1: 93, 2: 82, 3: 84), so about four 346x260 frames. CUDA: enough lanes to fill the GPU
# and few launches and syncs per frame, which is where batching is for (not measured on a GPU).
LANE_STEPS = {"llvm": 360_000, "cuda": 16_000_000}
MAX_FRAMES_PER_KERNEL = 64


def default_frames_per_kernel(n_pix: int, frame_interval_s: float) -> int:
    """Frames per kernel for a film of ``n_pix`` pixels on the active backend (``LANE_STEPS``). On the CPU
    never so many that the chunk's time span needs more radix passes than one frame does (the sort key is
    microseconds from the chunk's start, up to ``event_fill.PASS_BITS`` per pass: 2^20 us, about a second, in
    one; a second pass costs more than the fewer launches save there; on a GPU a pass is cheap next to the
    launches and syncs batching saves)."""
    cuda = mi.variant().startswith("cuda")
    frames = int(max(1, min(MAX_FRAMES_PER_KERNEL, round(LANE_STEPS["cuda" if cuda else "llvm"] / n_pix))))
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
    frames: ``log_frames`` is a Float of ``B x N`` log brightnesses (frame-major), frame ``b`` the brightness
    at ``times[b + 1]`` seconds (the low-pass recovers the radiance from it, as the per-step kernel does for a
    staged log frame). Advances the integrator's state; returns the chunk's events time-sorted on the device,
    as per-step commits would."""
    if not batchable(integ):
        raise ValueError("commit_frames: this pixel model steps one frame at a time (event_batch.batchable)")
    times = np.asarray(times, np.float64)
    steps, n_pix = len(times) - 1, integ.size[0] * integ.size[1] if integ.size else 0
    if integ.log_prev is None or dr.width(log_frames) != steps * n_pix or steps < 1:
        raise ValueError(f"commit_frames: {dr.width(log_frames)} values for {steps} frames of {n_pix} pixels "
                         "(after a first frame has set the pixels)")
    before, after, n_all, ref_all = _pixel_loop(integ, log_frames, times, steps, n_pix)
    return _fill(integ, before, after, n_all, ref_all, times, steps, n_pix, base_us)


def _pixel_loop(integ, log_frames, times, steps: int, n_pix: int):
    """Every pixel through the steps in one kernel. Returns, per (step, pixel) lane (frame-major), the log
    brightness before and after the step, the crossing count and the reference level."""
    cfg = integ.config
    lane = dr.arange(mi.UInt32, n_pix)
    n_opaque = event_fill._opaque(n_pix, mi.UInt32)
    before, after = dr.empty(mi.Float, steps * n_pix), dr.empty(mi.Float, steps * n_pix)
    n_all, ref_all = dr.empty(mi.Int32, steps * n_pix), dr.empty(mi.Float, steps * n_pix)
    # the per-step kernel's dt is mi.Float(t1 - t0): the same float64 difference, rounded to float32
    dts = mi.Float(np.diff(times).astype(np.float32))
    needs_dt = bool(cfg.cutoff_hz or cfg.leak_rate_hz)
    has_offset = integ.offset is not None

    def body(b, log_prev, k_on, k_off, *offset):
        idx = b * n_opaque + lane
        log_in = dr.gather(mi.Float, log_frames, idx)
        dt = dr.gather(mi.Float, dts, b) if needs_dt else None
        intensity = pixel_model.linlog_inverse(dr, log_in, integ.linlog_threshold) if cfg.cutoff_hz else None
        lv = pixel_step.advance(integ, log_prev, k_on, k_off, offset[0] if has_offset else None, log_in,
                                intensity, dt, integ.c_on, integ.c_off)
        dr.scatter(n_all, lv.n, idx)
        dr.scatter(ref_all, lv.log_ref, idx)
        dr.scatter(before, log_prev, idx)
        dr.scatter(after, lv.log_now, idx)
        return (b + 1, lv.log_now, lv.k_on, lv.k_off) + ((lv.offset,) if has_offset else ())

    state = (dr.zeros(mi.UInt32, n_pix), integ.log_prev, integ.k_on, integ.k_off)
    state += (integ.offset,) if has_offset else ()
    bound = event_fill._opaque(steps, mi.UInt32)
    out = dr.while_loop(state, lambda b, *rest: b < bound, body)
    dr.eval(before, after, n_all, ref_all, *out[1:])
    integ.log_prev, integ.k_on, integ.k_off = out[1], out[2], out[3]
    if has_offset:
        integ.offset = out[4]
    return before, after, n_all, ref_all


def _fill(integ, before, after, n_all, ref_all, times, steps: int, n_pix: int, base_us: int):
    """Count, prefix sum, then ``event_fill.fill`` (per-lane fill, time order) of the chunk's crossings."""
    size = mi.UInt32(dr.abs(n_all))
    ends = dr.prefix_reduce(dr.ReduceOp.Add, size, exclusive=False)
    total = event_fill._read([dr.gather(mi.UInt32, ends, steps * n_pix - 1)])[0]
    crossings = event_fill.Crossings(n_all, size, before, after, ref_all, integ.c_on, integ.c_off, times,
                                     integ.size[0], n_pix)
    return event_fill.fill(crossings, ends, total, base_us, integ.config.timestamp_resolution_us)
