"""Events of many frames in a few kernels: the frames-to-events converter's fast path (issue 15, part 4).

A step at a time, every frame pays the same fixed cost (a pixel kernel, a scan, a sync to size the event
arrays, a fill, a sort, each a launch; about 0.4 ms at 346x260 on the CPU before any event) and the fill
finds each event's pixel by a binary search over the scan. Given ``B`` frames at once:

1. pixels: one kernel loops every pixel through the ``B`` steps (``pixel_step.advance``, the per-step kernel's
   own definition), keeping each step's crossing count, reference level and end brightness;
2. count and prefix sum over the ``B x N`` (step, pixel) lanes, frame-major; one sync reads the total;
3. fill: each firing lane writes its own crossings into its slot range (a loop over the lane's count, as
   esim_torch's fill does) instead of every event searching for its pixel;
4. time order: one stable radix sort of the chunk by microsecond (``event_fill._time_sorted``).

The events equal, bit for bit, those of ``B`` calls of ``EventIntegrator.commit_device`` joined in order: the
same float operations in the same order, and a stable sort keyed by time over slots in (step, pixel,
crossing) order is the per-step order concatenated (a step's times never pass the next step's start, the
per-step clipping of the interpolation fraction to [0, 1] bounds them, and rounding to microseconds keeps
that order). Pixel models that draw random numbers per step (threshold jitter, shot noise) or keep
per-event state (refractory period, readout cap) are not batched: ``batchable`` says so and the caller steps
them one frame at a time.
"""
from __future__ import annotations

import contextlib

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_eventfield.plugins import event_fill, pixel_model, pixel_step


# Lane-steps (pixels x frames) per kernel by backend. CPU: the chunk's events must stay in cache for the sort
# (346x260 and 640x480, 2 kHz stack: 2-4 frames a kernel best, 1.2x one frame; 16 frames 0.6x). CUDA: enough
# lanes to fill the GPU and few launches per frame (not measured on a GPU yet).
LANE_STEPS = {"llvm": 600_000, "cuda": 16_000_000}
MAX_FRAMES_PER_KERNEL = 64


def default_frames_per_kernel(n_pix: int, frame_interval_s: float) -> int:
    """Frames per kernel for a film of ``n_pix`` pixels on the active backend (``LANE_STEPS``), but never so
    many that the chunk's time span needs more radix passes than one frame does (the sort key is microseconds
    from the chunk's start, ``event_fill.RADIX_BITS`` per pass: at 2 kHz, 4 frames sort in one pass, 6 in two,
    which costs more than the fewer launches save)."""
    lanes = LANE_STEPS["cuda" if mi.variant().startswith("cuda") else "llvm"]
    frames = int(max(1, min(MAX_FRAMES_PER_KERNEL, round(lanes / n_pix))))
    while frames > 1 and _passes(frames * frame_interval_s) > _passes(frame_interval_s):
        frames -= 1
    return frames


def _passes(span_s: float) -> int:
    bits = max(1, (int(np.ceil(span_s * 1e6)) + 3).bit_length())
    return -(-bits // event_fill.RADIX_BITS)


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
    """True when ``integ``'s pixel model can take many frames per kernel (see the module docstring) and its
    film is under 32,768 rows (the fill packs y into 15 bits)."""
    cfg = integ.config
    return not _disabled[0] and integ.device_resident and (integ.size is None or integ.size[1] < 1 << 15) and \
        not (cfg.threshold_jitter or cfg.shot_noise_hz or cfg.refractory_s or cfg.readout_cap)


def commit_frames(integ, log_frames, times, base_us: int = 0, intensity=None) -> event_fill.DeviceEvents:
    """Events of the steps from ``times[0]`` (the pixels' current instant) through ``B = len(times) - 1``
    frames: ``log_frames`` is a Float of ``B x N`` log brightnesses (frame-major), frame ``b`` the brightness
    at ``times[b + 1]`` seconds. ``intensity``: the frames' radiance where it is known (a render's), for the
    low-pass; otherwise recovered from the log brightness, as the per-step kernel does. Advances the
    integrator's state; returns the chunk's events time-sorted on the device, as per-step commits would."""
    n_pix = integ.size[0] * integ.size[1]
    times = np.asarray(times, np.float64)
    steps = len(times) - 1
    if not batchable(integ):
        raise ValueError("commit_frames: this pixel model steps one frame at a time (event_batch.batchable)")
    if integ.log_prev is None or dr.width(log_frames) != steps * n_pix or steps < 1:
        raise ValueError(f"commit_frames: {dr.width(log_frames)} values for {steps} frames of {n_pix} pixels "
                         "(after a first frame has set the pixels)")
    levels, n_all, ref_all = _pixel_loop(integ, log_frames, intensity, times, steps, n_pix)
    return _fill(integ, levels, n_all, ref_all, times, steps, n_pix, base_us)


def _pixel_loop(integ, log_frames, intensity_frames, times, steps: int, n_pix: int):
    """Every pixel through the steps in one kernel. Returns ``levels`` ((B + 1) x N: the brightness before
    the first step, then after each), the crossing counts and the reference levels (B x N each)."""
    cfg = integ.config
    lane = dr.arange(mi.UInt32, n_pix)
    n_opaque = event_fill._opaque(n_pix, mi.UInt32)
    levels = dr.empty(mi.Float, (steps + 1) * n_pix)
    dr.scatter(levels, integ.log_prev, lane)
    n_all, ref_all = dr.empty(mi.Int32, steps * n_pix), dr.empty(mi.Float, steps * n_pix)
    # the per-step kernel's dt is mi.Float(t1 - t0): the same float64 difference, rounded to float32
    dts = mi.Float(np.diff(times).astype(np.float32))
    needs_dt = bool(cfg.cutoff_hz or cfg.leak_rate_hz)
    has_offset = integ.offset is not None

    def body(b, log_prev, k_on, k_off, *offset):
        idx = b * n_opaque + lane
        log_in = dr.gather(mi.Float, log_frames, idx)
        dt = dr.gather(mi.Float, dts, b) if needs_dt else None
        intensity = None
        if cfg.cutoff_hz:
            intensity = dr.gather(mi.Float, intensity_frames, idx) if intensity_frames is not None else \
                pixel_model.linlog_inverse(dr, log_in, integ.linlog_threshold)
        lv = pixel_step.advance(integ, log_prev, k_on, k_off, offset[0] if has_offset else None, log_in,
                                intensity, dt, integ.c_on, integ.c_off)
        dr.scatter(n_all, lv.n, idx)
        dr.scatter(ref_all, lv.log_ref, idx)
        dr.scatter(levels, lv.log_now, idx + n_opaque)
        return (b + 1, lv.log_now, lv.k_on, lv.k_off) + ((lv.offset,) if has_offset else ())

    state = (dr.zeros(mi.UInt32, n_pix), integ.log_prev, integ.k_on, integ.k_off)
    state += (integ.offset,) if has_offset else ()
    bound = event_fill._opaque(steps, mi.UInt32)
    out = dr.while_loop(state, lambda b, *rest: b < bound, body)
    dr.eval(levels, n_all, ref_all, *out[1:])
    integ.log_prev, integ.k_on, integ.k_off = out[1], out[2], out[3]
    if has_offset:
        integ.offset = out[4]
    return levels, n_all, ref_all


def _fill(integ, levels, n_all, ref_all, times, steps: int, n_pix: int, base_us: int):
    """Count, prefix sum, per-lane fill and time order of the chunk's crossings. The fill writes two words an
    event: its sort key (microseconds from the chunk's start, as ``event_fill._time_sorted`` keys a step) and
    x | y << 16 | ON << 31, so the sort moves 8 bytes an event and no event divides by the width."""
    size = mi.UInt32(dr.abs(n_all))
    ends = dr.prefix_reduce(dr.ReduceOp.Add, size, exclusive=False)
    total = event_fill._read([dr.gather(mi.UInt32, ends, steps * n_pix - 1)])[0]
    if total == 0:
        return event_fill.empty()
    pixel = dr.arange(mi.UInt32, n_pix)     # one lane a pixel, looping over the steps, then its crossings
    start = ends - size
    n_opaque, w_opaque = event_fill._opaque(n_pix, mi.UInt32), event_fill._opaque(integ.size[0], mi.UInt32)
    t_d = mi.Float64(times)
    start_us = int(np.floor(times[0] * 1e6)) + int(base_us) - 1
    base_d, start_d = event_fill._opaque(base_us, mi.Int64), event_fill._opaque(start_us, mi.Int64)
    key_out, word_out = dr.empty(mi.UInt32, total), dr.empty(mi.UInt32, total)
    y = pixel // w_opaque
    xy = event_fill.pack_xy(pixel - y * w_opaque, y)
    c_on, c_off = mi.Float64(integ.c_on), mi.Float64(integ.c_off)

    def step_body(step):
        lane = step * n_opaque + pixel
        count = dr.gather(mi.UInt32, size, lane)
        n = dr.gather(mi.Int32, n_all, lane)
        on = n > 0
        sign = dr.select(on, mi.Int32(1), mi.Int32(-1))
        word = xy | dr.select(on, mi.UInt32(1 << 31), mi.UInt32(0))
        first = dr.gather(mi.UInt32, start, lane)
        segment = (mi.Float64(dr.gather(mi.Float, levels, lane)),
                   mi.Float64(dr.gather(mi.Float, levels, lane + n_opaque)),
                   mi.Float64(dr.gather(mi.Float, ref_all, lane)), dr.select(on, c_on, c_off),
                   dr.gather(mi.Float64, t_d, step), dr.gather(mi.Float64, t_d, step + 1))

        def crossing_body(k):
            t_s = event_fill._crossing_time(mi.Int64(k) + 1, sign, *segment)
            dr.scatter(key_out, mi.UInt32(mi.Int64(dr.round(t_s * 1e6)) + base_d - start_d), first + k)
            dr.scatter(word_out, word, first + k)
            return (k + 1,)

        dr.while_loop((dr.zeros(mi.UInt32, n_pix),), lambda k: k < count, crossing_body)
        return (step + 1,)

    bound = event_fill._opaque(steps, mi.UInt32)
    dr.while_loop((dr.zeros(mi.UInt32, n_pix),), lambda step: step < bound, step_body)
    dr.eval(key_out, word_out)
    return _sorted(key_out, word_out, total, start_d, int(np.ceil((times[-1] - times[0]) * 1e6)) + 3,
                   integ.config.timestamp_resolution_us)


def _sorted(key, word, total: int, start_d, key_bound: int, resolution_us: float) -> event_fill.DeviceEvents:
    """The chunk in time order (stable: equal microseconds keep slot order), unpacked into columns."""
    order = event_fill.stable_order(key, key_bound)
    key, word = dr.gather(mi.UInt32, key, order), dr.gather(mi.UInt32, word, order)
    t_us = mi.Int64(key) + start_d
    if resolution_us:              # the sensor clock, after ordering by true time (as the per-step path)
        res = event_fill._opaque(resolution_us, mi.Float64)
        t_us = mi.Int64(dr.floor(mi.Float64(t_us) / res) * res)
    xy, p = word & 0x7FFFFFFF, event_fill.polarity((word >> 31) != 0)
    dr.eval(xy, t_us, p)
    return event_fill.DeviceEvents(xy, t_us, p, count=total)
