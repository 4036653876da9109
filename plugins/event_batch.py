"""Events of many frames in a few kernels: the fast path of the frames-to-events converter and of a render's
step batches (``simulate/step_batch.py``), for every pixel model (issue 15, parts 1 and 4).

A step at a time, every frame pays the same fixed cost (a pixel kernel, a scan, a sync to size the event
arrays, a fill, a sort, each a launch; about 0.4 ms at 346x260 on the CPU before any event). Given ``B``
frames at once:

1. count: one kernel loops every pixel through the ``B`` steps (``pixel_step.step``, the per-step kernel's own
   definition, and ``event_select.select_events``, the per-step path's selection) and keeps each (step, pixel)
   lane's kept count, frame-major, each pixel's events in the chunk, and the state after the last step;
2. prefix sum over the lanes; one sync reads every step's last slot (the total is the last);
3. fill and time order: ``event_fill.fill``, the one fill of every device path. Its crossing writer
   (``Chunk.write``) steps the pixels again from the chunk's first state (storing each lane's levels cost
   more: 53 against 113 M pixel-steps/s), only those that fired when they are fewer than half; one stable
   radix sort of the chunk by microsecond;
4. the readout cap, where the pixel model has one, on the whole chunk at once
   (``readout.ReadoutLimiter.filter_device``: the drops of step-by-step filtering).

The count pass (1-2) and the crossing writer (3) are frozen functions (:func:`_frozen`): recorded for a pixel
model and chunk shape, then replayed chunk after chunk instead of traced again.

Every pixel model batches. Its random draws are counter-based (``counter_rng``: keyed by the pixel and its
event counters, which the loop carries with the shot noise's hazard left: the per-step kernel's numbers);
the refractory period carries each pixel's last emission; a pixel's shot-noise event takes the last slot of
its lane, after its crossings, as on the per-step paths; the drop and noise counts come from the pixels' own
counters.

The events equal, bit for bit, those of ``B`` calls of ``EventIntegrator.commit_device`` joined in order: the
same float operations in the same order, and a stable sort keyed by time over slots in (step, pixel,
crossing, then the pixel's noise event) order is the per-step order concatenated (a step's times never pass
the next step's start: the interpolation fraction is clipped to [0, 1] and rounding to microseconds keeps
order; the one exception is a float64 ``t0 + 1.0 (t1 - t0)`` one ulp above ``t1`` where ``t1`` is exactly
half a microsecond, which the per-step concatenation would leave out of order and the chunk sorts). Tested
against the host path for every pixel model and chunking (tests/plugins/test_event_batch.py).
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_eventfield.plugins import event_fill, event_memory, event_select, pixel_model, pixel_step
from mitsuba_eventfield.plugins.frozen import FrozenCache
from mitsuba_eventfield.plugins.pixel_view import PixelView


# Lane-steps (pixels x frames) per kernel by backend, and the fewest frames. CPU (converter kernels alone, 2 kHz
# stack, 2 cores, best of 6; M pixel-steps/s by frames a kernel): 346x260 1: 53, 2: 97, 3: 112, 4: 118, 6: 115,
# 8: 114, 11: 102, 16: 97; 640x480 1: 104, 2: 118, 3: 119; 1280x720 1: 100, 2: 112, 3: 124, 4: 120: a frame a
# kernel pays ~0.8 ms of launches, past a few 100 k lane-steps the events leave the cache. CUDA (H200,
# benchmarks/results/chunk_shape_h200.md): a chunk's fixed cost (its syncs, ~90 launches) is what the frames
# share; 17 -> 64 frames at 1280x720 and 64 -> 200 at 346x260 gained 15-25 % on a sparse stack (0.2-0.3
# events a pixel-step), nothing either way on a dense one (1.1).
LANE_STEPS = {"llvm": 360_000, "cuda": 60_000_000}
MIN_FRAMES_PER_KERNEL, MAX_FRAMES_PER_KERNEL = 3, {"llvm": 64, "cuda": 200}


def default_frames_per_kernel(n_pix: int, frame_interval_s: float) -> int:
    """Frames per kernel for a film of ``n_pix`` pixels on the active backend: about ``LANE_STEPS`` lane-steps,
    at least ``MIN_FRAMES_PER_KERNEL``. On the CPU never so many that the chunk's time span needs more radix
    passes than one frame does (the sort key is microseconds from the chunk's start, up to
    ``event_fill.PASS_BITS`` per pass: 2^20 us, about a second, in one; a second pass costs more than the fewer
    launches save there; on a GPU a pass is cheap next to the launches and syncs batching saves)."""
    cuda = mi.variant().startswith("cuda")
    backend = "cuda" if cuda else "llvm"
    frames = round(LANE_STEPS[backend] / n_pix)
    frames = int(min(MAX_FRAMES_PER_KERNEL[backend], max(MIN_FRAMES_PER_KERNEL, frames)))
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
    """True when ``integ`` may take many frames per kernel: every pixel model can (module docstring), unless
    :func:`one_frame_a_step` or the host path (``event_integrator.host_path``) is asked for."""
    return not _disabled[0] and integ.path_override != "host"


def commit_frames(integ, frames, times, base_us: int = 0, intensity: bool = False) -> event_fill.DeviceEvents:
    """Events of the steps from ``times[0]`` (the pixels' current instant) through ``B = len(times) - 1``
    frames: ``frames`` is a Float of ``B x N`` log brightnesses (frame-major; any further values are not read:
    a caller's buffer for more frames may be passed whole), frame ``b`` the brightness at ``times[b + 1]``
    seconds; with ``intensity`` they are linear radiances (a render's, which the low-pass and shot noise read
    as the per-step kernel does) and their log is taken in the kernel; else the low-pass and shot noise
    recover the radiance from the log, as the per-step kernel does for a staged log frame. Advances the
    integrator's state (pixels, noise counters, last emissions, readout cap, tallies); returns the chunk's events
    time-sorted and read out on the device, as per-step commits would."""
    if not batchable(integ):
        raise ValueError("commit_frames: frames are committed one at a time here (event_batch.batchable)")
    times = np.asarray(times, np.float64)
    steps, n_pix = len(times) - 1, integ.size[0] * integ.size[1] if integ.size else 0
    if integ.log_prev is None or dr.width(frames) < steps * n_pix or steps < 1:
        raise ValueError(f"commit_frames: {dr.width(frames)} values for {steps} frames of {n_pix} pixels "
                         "(after a first frame has set the pixels)")
    cfg = integ.config
    if cfg.refractory_s and isinstance(integ.last_emit, np.ndarray):   # after host-path steps: moved
        integ.last_emit = event_fill.device_copy(integ.last_emit, mi.Float64)
    view = PixelView.of(integ)
    state = _state(integ)
    # the chunk's times as arrays in Dr.Jit's memory (from lists: an array made from NumPy memory has that
    # memory's alignment, which decides the frozen passes' input layout, so it would record them again now and
    # then, with kernels of another alignment). The per-step kernel's dt is mi.Float(t1 - t0): the same float64
    # difference, rounded to float32
    t_d = mi.Float64(times.tolist())
    dts = mi.Float(np.diff(times).astype(np.float32).tolist()) if pixel_step.needs_dt(cfg) else None
    step_last = mi.UInt32((np.arange(1, steps + 1) * n_pix - 1).tolist())      # one count lane a pixel a step
    count = _count_pass(view, (integ.size[0], n_pix, steps, intensity, dr.width(frames)))
    final, ends, fired, head = count(view.arrays(), state, frames, t_d, dts, step_last)
    # one read: every step's last slot (the chunk's total is the last), then what the tallies need
    read = head.numpy().astype(np.int64)
    event_memory.check_event_count(float(read[-1]), times[0], times[-1], n_pix)   # before the 32-bit ends are trusted
    step_ends = read[:steps]
    _set_state(integ, final)
    stats = {}
    total = int(step_ends[-1])
    if cfg.refractory_s or cfg.shot_noise_hz:
        crossings, noise_hits, noise_kept = (int(v) for v in read[steps:steps + 3])
        stats = dict(refractory_dropped=crossings + noise_hits - total, noise_events=noise_kept)
        integ.refractory_dropped += stats["refractory_dropped"]
        integ.noise_events += noise_kept
    chunk = Chunk(view, state, frames, times, t_d, dts, integ.size[0], n_pix, intensity)
    if 0 < total < 2 * n_pix:     # more events than that: most pixels fire, and the compress would be wasted
        chunk.only_firing(fired)
    events = event_fill.fill(chunk, ends, total, base_us, cfg.timestamp_resolution_us, stats=stats)
    if integ.limiter is None:
        return events
    step_counts = np.diff(np.r_[0, step_ends]).astype(np.int64)
    return integ.limiter.filter_device(events, step_counts, times[0], times[-1], cfg.timestamp_resolution_us)


def _count_pass(view: "PixelView", shape: tuple):
    """The count pass of a chunk: ``fn(arrays, state, frames, t, dt, step_last) -> (state after, ends, fired,
    head)`` for a pixel model and chunk shape (film width, pixels, steps, radiance or log frames, frame buffer
    length), frozen (:func:`_frozen`). ``ends``: each (step, pixel) lane's slot end (its kept crossings, then
    its noise event: one lane a pixel; a second lane a pixel for noise, until 2026-11-26, cost twice the scan
    and a scatter more a step, 0.1 ms a step of the demo's every-effect pixel); ``head``: every step's last
    slot end, then with a refractory period or shot noise the chunk's crossings and noise hits before any was
    dropped, and its kept noise events; last, the chunk's events summed without wrapping
    (``event_fill.approximate_sum``). The first two are
    differences of the pixels' own counters (k_on + k_off, noise_k) over the chunk, which the loop carries
    anyway; the kept noise events are the hits where nothing drops them, else one tally carried through the
    loop (four per-pixel tallies before, as fast)."""
    width, n_pix, steps, intensity, _ = shape
    model = view.model()          # the cached pass keeps the model, not this integrator's arrays
    cfg = model.config

    def make():
        def count_pass(arrays, state, frames, t_d, dts, step_last):
            chunk = Chunk(model.bind(arrays), state, frames, None, t_d, dts, width, n_pix, intensity, steps=steps)
            counts = dr.empty(mi.UInt32, steps * n_pix)
            tally = bool(cfg.refractory_s and cfg.shot_noise_hz)    # noise events kept: only a tally tells

            def count(lane, pixel, log_prev, st, sel, t0, t1, fired, *kept_noise):
                events = sel.kept + mi.UInt32(sel.hit) if sel.hit is not None else sel.kept
                dr.scatter(counts, events, lane)
                # the pixel's events in the chunk: the fill steps only the pixels that have some
                return (fired + events,) + ((kept_noise[0] + mi.UInt32(sel.hit),) if tally else ())
            final, (fired, *kept_noise) = chunk.run(count, [dr.zeros(mi.UInt32, n_pix)] * (2 if tally else 1))
            dr.eval(counts, fired, *final.values(), *kept_noise)
            ends = dr.prefix_reduce(dr.ReduceOp.Add, counts, exclusive=False)
            head = [dr.gather(mi.UInt32, ends, step_last)]
            if cfg.refractory_s or cfg.shot_noise_hz:       # UInt32 sums wrap: their difference is exact
                hits = _counted(final["noise_k"]) - _counted(state["noise_k"]) if cfg.shot_noise_hz else mi.UInt32(0)
                head += [_counted(final["k_on"] + final["k_off"]) - _counted(state["k_on"] + state["k_off"]), hits,
                         dr.sum(kept_noise[0]) if tally else hits]
            head.append(event_fill.approximate_sum(counts))         # the last: the chunk's events, unwrapped
            return final, ends, fired, event_fill.concat_arrays(head, mi.UInt32)
        return count_pass
    return _frozen("count", view, shape, make)


def _counted(per_pixel):
    """The sum of per-pixel event counters as one UInt32 (wrapping)."""
    return dr.sum(mi.UInt32(per_pixel))


def _frozen(kind: str, view: "PixelView", shape: tuple, make):
    """The chunk pass ``kind`` for a pixel model and chunk shape, made by ``make()`` once and frozen
    (``dr.freeze``; traced at every call with ``EVENTFIELD_FREEZE=0``).

    Why: the kernels of a chunk do not change from chunk to chunk, but tracing them did: the pixel model's step,
    the selection and the writer traced again for every chunk cost 0.2-0.5 ms a pass on the CPU (346x260
    demo, ideal to every effect), as much as the kernels of an ideal pixel's four steps; on a GPU, where the
    kernels take far less, more so. What a chunk changes is an argument (a replay does not redo host-side work:
    docs/design.md); the model and the shape, which the traced code reads as Python values, are the key. The
    event total is not in the key: the write pass scatters into slots sized outside it (a replay may be given
    arrays of another length, which Dr.Jit supports), and the sort, whose ``block_mkperm`` a replay would run
    at the recorded length (Dr.Jit 1.5: wrong results from a replay at another length, checked), stays outside.
    """
    return _PASSES.made((kind, view.key(), shape), make)


_PASSES = FrozenCache()


# the pixel state a chunk carries from step to step, in this order (those the pixel model has)
STATE = ("log_prev", "k_on", "k_off", "offset", "held_on", "held_off", "noise_left", "noise_k", "last_emit")


def _state(integ) -> dict:
    """The integrator's pixel state by name."""
    return {name: getattr(integ, name) for name in STATE if getattr(integ, name) is not None}


def _set_state(integ, state: dict) -> None:
    for name, value in state.items():
        setattr(integ, name, value)


@dataclass
class Chunk:
    """``B`` frames of every pixel from a state, as ``event_fill.fill`` takes crossings: stepping the pixels is
    cheap next to storing each (step, pixel) lane's brightness before and after, reference level and count
    (16 bytes a lane written, then read back by the fill), so the count pass keeps only the kept counts and the
    fill steps the pixels again from the same state (the same counters: the same draws; the same operations:
    the same values, bit for bit). Lanes: per step one a pixel, its crossings and then (with shot noise) its
    noise event, the per-step paths' slot order."""
    view: PixelView              # the pixel model and its per-pixel constants
    state: dict                  # STATE at times[0] (the names the pixel model has)
    frames: object
    times: np.ndarray | None     # the step boundaries in seconds, on the host (None inside the count pass)
    t_d: object                  # the same as Float64
    dts: object                  # each step's length as Float (None when the model does not read it)
    width: int
    n_pix: int
    intensity: bool = False      # frames are linear radiances (else log brightnesses)
    steps: int | None = None     # len(times) - 1 (given where times is not)
    pixels: object = None        # the pixels :meth:`run` steps (UInt32 indices; None: every pixel)

    # below this fraction of the pixels firing, the fill steps only those (gathered state, one compress)
    FIRING_SUBSET = 0.5

    def __post_init__(self):
        if self.steps is None:
            self.steps = len(self.times) - 1

    def only_firing(self, fired) -> None:
        """Let :meth:`write` step only the pixels with an event in the chunk (``fired``: each pixel's count),
        where they are few: a still pixel writes nothing, and the count pass already moved its state on. On
        the CPU only: the compress is a second sync a chunk, which on a GPU would cost more than stepping
        every pixel again (not measured there)."""
        if dr.backend_v(fired) == dr.JitBackend.CUDA:
            return
        pixels = dr.compress(fired > 0)
        if dr.width(pixels) < self.FIRING_SUBSET * self.n_pix:
            self.pixels = pixels

    def _at_pixels(self):
        """(pixel indices, lane count, the view, the start state) at :attr:`pixels` (every pixel when None)."""
        if self.pixels is None:
            return dr.arange(mi.UInt32, self.n_pix), self.n_pix, self.view, self.state
        idx = self.pixels
        sub = {k: dr.gather(type(v), v, idx) for k, v in self.state.items()}
        return idx, dr.width(idx), self.view.gather(idx), sub

    def run(self, each_step, carry=()) -> tuple:
        """One kernel: every pixel through the ``B`` steps (``pixel_step.step``, the per-step kernel's own
        definition, and ``event_select.select_events``, the per-step path's selection);
        ``each_step(lane, pixel, log_prev, step, selection, t0, t1, *carry)`` is traced into the loop body
        (``lane``: the (step, pixel) lane's frame-major index, ``b n_pix + pixel``) and returns the new
        ``carry`` (per-pixel values it keeps across steps). Returns the state after the last step and the last
        carry (lazy)."""
        cfg = self.view.config
        pixel, lanes, view, state = self._at_pixels()
        n_d = event_fill._opaque(self.n_pix, mi.UInt32)
        dts, t_d = self.dts, self.t_d
        period = event_fill._opaque(cfg.refractory_s, mi.Float64) if cfg.refractory_s else None
        names = list(state)
        start = [state[k] for k in names]
        n_state = len(names)

        def body(b, *values):
            s, carried = dict(zip(names, values[:n_state])), values[n_state:]
            lane = b * n_d + pixel                      # frame-major: the frame's value and the step's lane
            value = dr.gather(mi.Float, self.frames, lane)
            if self.intensity:
                intensity, log_in = value, pixel_model.linlog(dr, value, view.linlog_threshold)
            else:
                log_in = value
                intensity = pixel_model.linlog_inverse(dr, value, view.linlog_threshold) \
                    if pixel_step.needs_intensity(cfg) else None
            dt = dr.gather(mi.Float, dts, b) if dts is not None else None
            held = (s["held_on"], s["held_off"]) if "held_on" in s else None
            noise_state = (s["noise_left"], s["noise_k"]) if "noise_left" in s else None
            st = pixel_step.step(view, pixel, s["log_prev"], s["k_on"], s["k_off"], s.get("offset"), noise_state,
                                 log_in, intensity, dt, held)
            lv = st.levels
            t0, t1 = dr.gather(mi.Float64, t_d, b), dr.gather(mi.Float64, t_d, b + 1)
            sel = event_select.select_events(lv.n, s["log_prev"], lv.log_now, lv.log_ref, st.c_on, st.c_off, t0, t1,
                                           s.get("last_emit"), period, st.noise)
            carried = each_step(lane, pixel, s["log_prev"], st, sel, t0, t1, *carried)
            after = {"log_prev": lv.log_now, "k_on": lv.k_on, "k_off": lv.k_off, "offset": lv.offset,
                     "held_on": st.held[0] if st.held else None, "held_off": st.held[1] if st.held else None,
                     "noise_left": st.noise_state[0] if st.noise_state else None,
                     "noise_k": st.noise_state[1] if st.noise_state else None, "last_emit": sel.last_emit}
            return (b + 1,) + tuple(after[k] for k in names) + tuple(carried)

        bound = event_fill._opaque(self.steps, mi.UInt32)
        out = dr.while_loop((dr.zeros(mi.UInt32, lanes),) + tuple(start) + tuple(carry),
                            lambda b, *rest: b < bound, body)
        return dict(zip(names, out[1:1 + n_state])), tuple(out[1 + n_state:])

    def write(self, ends, slots) -> None:
        """``event_fill``'s crossing writer: the pixels stepped again, each step's crossings into their slots,
        then its noise events (only the firing pixels when :meth:`only_firing` chose them); one frozen
        function per model, chunk shape and slot capacity (:func:`_frozen`). It makes the slot arrays and
        returns them, replacing ``slots``' own: a frozen function copies any input it scatters into, and bakes
        the length of an array it makes, hence ``event_fill.slot_capacity`` in the key (docs/design.md)."""
        capacity, packed = event_fill.slot_capacity(dr.width(slots.key)), slots.packed
        shape = (self.width, self.n_pix, self.steps, self.intensity, dr.width(self.frames), packed, capacity)
        model, width, n_pix, intensity, steps = self.view.model(), self.width, self.n_pix, self.intensity, self.steps

        def make():     # the cached pass keeps the model and the shape, not this chunk's arrays
            def write_pass(arrays, state, frames, t_d, dts, ends, pixels, base, start):
                chunk = Chunk(model.bind(arrays), state, frames, None, t_d, dts, width, n_pix, intensity,
                              steps=steps, pixels=pixels)
                made = event_fill.Slots.allocate(capacity, packed, base, start)
                chunk._write(ends, made)
                return made.key, made.word
            return write_pass
        fn = _frozen("write", self.view, shape, make)
        slots.key, slots.word = fn(self.view.arrays(), self.state, self.frames, self.t_d, self.dts, ends,
                                   self.pixels, slots.base, slots.start)

    def _write(self, ends, slots) -> None:
        pixels = self.pixels if self.pixels is not None else dr.arange(mi.UInt32, self.n_pix)
        xy = event_fill.pixel_xy(pixels, self.width)       # once, not per step: a vector integer division

        def write_step(lane, pixel, log_prev, st, sel, t0, t1):      # carries nothing
            lv = st.levels
            end = dr.gather(mi.UInt32, ends, lane)                   # the lane: crossings, then the noise event
            event_fill.write_lane(lv.n, sel, end, log_prev, lv.log_now, lv.log_ref, st.c_on, st.c_off, t0, t1, xy,
                                  slots.put)
            return ()
        self.run(write_step)
