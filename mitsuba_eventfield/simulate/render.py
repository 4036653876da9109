"""The time-stepping loop: scene at time t -> radiance render -> event integrator -> events (memory or file).

Steps are uniform (``steps``) or adaptive: after each step the next one is sized so that the largest per-pixel
log-brightness change is predicted to stay under ``max_log_change`` x C; a step whose change exceeds twice
that is rendered again, shorter (only the render is repeated, the pixel state is untouched).

Every step renders with the same sampler seed by default: the Monte-Carlo noise pattern is then frozen, so a
static pixel never fires (independent seeds make noise fire events: docs/design.md, "Measured facts and pitfalls").
"""
from __future__ import annotations

import math
import os
import time

from .. import backend
from ..atomic import check_writable
from ..errors import EventFieldError, raise_if_stopped
from ..events.io import format_of
from ..plugins.event_fill import film_limit_error
from ..scene.timed import load_scene
from ..validate import DEFAULT_SPP, available_memory, flag, instance
from .periodic import period_blocks, phase_grid, reuse_plan
from .pixel_setup import event_integrator
from .warmup import kept_stepping, note_settling, warmup_seconds, warmup_window
from . import sample_allocation, static_pixels, step_batch
from .frames import FrameRenderer, frozen_render, render_frames  # noqa: F401  (render_frames: re-exported)
from .accuracy_limit import AccuracyLimit
from .checkpoint import checkpoints_for
from .device_stream import check_on_device
from .image_motion import note_image_motion
from .stepping import SEED_MODES, Stepping, default_steps, step_seed, stepping  # noqa: F401  (SEED_MODES: re-exported)
from .sink import DEFAULT_EVENT_BUFFER_MB, Sink
from .summary import RenderSummary, pixel_counters, run_metadata

mi, dr = backend.mi, backend.dr

# Memory model used to refuse a frame that cannot fit: bytes per Monte-Carlo sample in flight and per pixel
# (film, radiance tensor, pixel state). Conservative; measured peak is lower (benchmarks/bench_foundation.py).
BYTES_PER_SAMPLE = 64
BYTES_PER_PIXEL = 96
MAX_WAVEFRONT = 2**32 - 1


def check_memory(width: int, height: int, spp: int, where: str = "film") -> int:
    """Refuse a frame whose render buffers cannot fit, or whose events cannot be held; return the estimated
    bytes."""
    too_large = film_limit_error(width, height)
    if too_large:
        raise EventFieldError(f"{where}: {too_large}")
    samples = width * height * spp
    if samples > MAX_WAVEFRONT:
        raise EventFieldError(f"{where}: {width}x{height} pixels x {spp} spp = {samples} samples per frame exceeds "
                              f"Mitsuba's single-wavefront limit of {MAX_WAVEFRONT}; lower the resolution or spp")
    need = samples * BYTES_PER_SAMPLE + width * height * BYTES_PER_PIXEL
    avail = available_memory()
    if need > 0.8 * avail:
        raise EventFieldError(f"{where}: {width}x{height} pixels x {spp} spp needs about {need / 2**30:.1f} GiB of "
                              f"render buffers, more than 80% of the {avail / 2**30:.1f} GiB available")
    return need


def _advance(bar, elapsed_s: float) -> None:
    """Move the progress bar to ``elapsed_s`` of simulated time: set from the position, not summed steps, so
    float round-off never takes it past its total (tqdm warns then)."""
    bar.update(min(round(elapsed_s * 1e3, 6), bar.total) - bar.n)


class _Loop:
    """The time-stepping loop of one render: renders (or reuses) a frame per step, commits it to the event
    integrator, orders and reads out the step's events and hands them to the sink."""

    def __init__(self, timed, integ, st: Stepping, sink, summary, bar, reuse: bool, checkpoints=None,
                 allocation=None, noise=None, frozen=None, warmup: float = 0.0):
        self.timed, self.integ, self.st, self.sink, self.summary, self.bar = timed, integ, st, sink, summary, bar
        self.checkpoints, self.allocation = checkpoints, allocation
        self.warmup = warmup                              # seconds rendered before the kept start (warmup.py)
        self.counters_before = None if warmup else (0, 0, 0)   # the pixel counters once the warm-up is over
        sigma, first = noise if noise is not None else (None, None)   # stepping.default_steps' probe
        self.limit = AccuracyLimit.for_stepping(st, sigma, timed.scan_period)   # what limits timing: steps or noise
        if allocation is not None:                       # noise where it counts: in the pixels that change
            self.limit.spp = allocation.spp_changing
        self.width, self.height = timed.film_size
        # a moving scene under a periodic scan: the pixels no moving object can change rendered once a period
        self.static = None if not reuse or allocation is not None else \
            static_pixels.plan(timed, st, integ, summary.notes, checkpointed=checkpoints is not None)
        self.renderer = FrameRenderer(integ.inner, st.spp, allocation, summary.notes, self.static, frozen)
        self.overlap = backend.overlaps_steps()
        if self.overlap:
            summary.notes.append(backend.OVERLAP_NOTE)
        self.first_frame = first if allocation is None and self.static is None else None   # the probe's: step 0's
        self.reuse = None if st.steps is None or not reuse or st.seed_mode != "fixed" else \
            reuse_plan(timed, st.duration, st.steps, self.width, self.height, summary.notes)
        self.cache = []                                  # log-brightness frames of one period, for reuse
        # periodic view on a uniform grid: timestamps from the in-period phase plus whole periods (integers), so
        # an event copied from the previous period is bit-identical to one computed (not for pixel models with
        # state across steps, e.g. refractory: they need absolute times, and their events are never copied)
        self.grid = None if st.steps is None or not integ.deterministic else \
            phase_grid(timed, st.duration, st.steps, st.t_start)
        self.period_events, self.copy_from, self.prev_key, self.period_block = {}, None, None, None
        # steps committed to the pixels several at a time where nothing needs the state between them
        self.batch = step_batch.for_loop(integ, st, sink, summary, self.width * self.height,
                                         keeps_period_events=bool(self.reuse and self.grid))

    def render_at(self, t, step_index):
        integ, summary = self.integ, self.summary
        if self.reuse and step_index >= self.reuse:      # the view repeats: feed the cached frame, no render
            integ.stage_log(self.cache[step_index % self.reuse], (self.width, self.height))
            summary.reused_steps += 1
            return
        overlap = self.overlap
        t0 = time.perf_counter()
        moving = step_index or self.first_frame is None  # the probe's first frame needs no scene at this instant
        if moving:
            self.timed.set_time(t, apply=not overlap)
        t1 = time.perf_counter()
        if overlap:                                      # the step before rendered meanwhile: the render's time
            dr.sync_thread()
        t2 = time.perf_counter()
        if moving and overlap:
            self.timed.apply_time()
        t3 = time.perf_counter()
        self.render_frame(self.st.seed if self.st.seed_mode == "fixed" else step_seed(self.st.seed, step_index),
                          step=step_index)
        if not overlap or self.batch is None:            # (a step's own events read back would wait anyway)
            dr.sync_thread()
        t4 = time.perf_counter()
        summary.motion_s += (t1 - t0) + (t3 - t2)
        summary.render_s += (t2 - t1) + (t4 - t3)
        if self.reuse:
            frame = mi.Float(integ.staged)
            dr.eval(frame)
            integ.staged = frame                         # commit() uses the evaluated frame: no second evaluation
            self.cache.append(frame)

    def render_frame(self, seed: int, once: bool = False, step: int | None = None) -> None:
        """Render the scene as it is now and stage the frame in the event integrator (``frames.FrameRenderer``)."""
        if step == 0 and self.first_frame is not None:
            frame, self.first_frame = self.first_frame, None
            self.integ.stage(frame)
            return
        self.integ.stage(self.renderer.render(self.timed, seed, once, step))

    def run(self) -> int:
        """All steps; returns how many."""
        st, integ = self.st, self.integ
        t_end = st.t_start + st.duration
        if self.checkpoints is not None and self.checkpoints.saved:   # resume: frames rendered again, not reused
            (t, k, dt), self.reuse = self.checkpoints.restore(self), None
        else:
            self.render_at(st.t_start, 0)
            integ.commit(st.t_start, st.t_start)         # initialises every pixel's reference; fires nothing
            self.limit.first_frame(self, st.t_start)
            t, k = st.t_start, 0
            dt = (st.duration / st.steps) if st.steps else max(st.min_step, st.max_step / 16)
        c_min = min(integ.threshold_on, integ.threshold_off)
        while t < t_end - 1e-12:
            raise_if_stopped()                           # a Ctrl-C a library swallowed (errors.STOP_SIGNALS)
            if self.counters_before is None and t >= st.t_start + self.warmup - 1e-12:
                self._warmed_up()
            if self.checkpoints is not None and self.checkpoints.due():
                if self.batch is not None:
                    self.batch.flush()                   # the saved pixel state is that of every step so far
                self.checkpoints.save(self, t, k, dt)
            if self.copy_from is not None:               # the pixel state repeats: copy whole periods, shifted
                t, k = self._copy_periods(k)
                continue
            if st.adaptive:
                dt = min(dt, t_end - t)
                t_next = t + dt
            else:
                t_next = st.t_next(k)                    # uniform or scheduled by image motion
            self.render_at(t_next, k + 1)
            if st.adaptive:
                change = integ.staged_max_change()
                if change > 2 * st.max_log_change * c_min and dt > st.min_step * (1 + 1e-9):
                    dt = max(st.min_step, 0.9 * dt * st.max_log_change * c_min / change)
                    self.summary.rejected_steps += 1
                    continue
                dt = self._next_dt(change / dt, dt, c_min)
            self._step_events(t, t_next, k)
            if self.bar is not None:
                _advance(self.bar, t_next - st.t_start)
                self.bar.set_postfix_str(f"{self.summary.events + self.sink.device_events} events", refresh=False)
            t, k = t_next, k + 1
        if self.batch is not None:
            self.batch.flush()
        return k

    def _warmed_up(self) -> None:
        """The pixel counters where the warm-up ends (to the step), so that the summary's are the kept span's."""
        if self.batch is not None:
            self.batch.flush()
        self.counters_before = pixel_counters(self.integ)

    def _next_dt(self, rate, dt, c_min):
        """Adaptive stepping: the step that keeps the largest change near max_log_change x C at this rate."""
        grow = min(self.st.max_step, 2 * dt)
        return min(grow, max(self.st.min_step, 0.9 * self.st.max_log_change * c_min / rate)) if rate > 0 else grow

    def _emit(self, x, y, t_us, p, t_next) -> None:
        tw = time.perf_counter()
        self.sink.add(x, y, t_us, p, complete_until_us=int(math.floor(t_next * 1e6)))
        self.summary.write_s += time.perf_counter() - tw

    def _copy_periods(self, k):
        st = self.st
        steps_per_period, period_us, _ = self.grid
        p_idx, j = divmod(k, steps_per_period)           # j == 0 here: copying starts at a period boundary
        block = min(steps_per_period - j, st.steps - k)
        x, y, t_us, p = self.period_block(block)
        t_next = st.t_start + (k + block) * st.duration / st.steps
        self._emit(x, y, t_us + (p_idx - self.copy_from) * period_us, p, t_next)
        self.summary.copied_steps += block
        if self.bar is not None:
            _advance(self.bar, t_next - st.t_start)
        return t_next, k + block

    def _step_events(self, t, t_next, k) -> None:
        """The step's events (made on the device when the pixel model allows, and kept there until the sink's
        buffer is full; else on the host: the same events either way, tests/plugins/test_event_fill.py), or
        the step held for the next batch (``step_batch``: the same events again)."""
        st = self.st
        te = time.perf_counter()
        t0, t1, base_us = t, t_next, 0
        if self.grid:                                    # in-period phase + whole periods (exact copies)
            steps_per_period, period_us, grid_base_us = self.grid
            p_idx, j = divmod(k, steps_per_period)
            step = st.duration / st.steps
            t0, t1, base_us = j * step, (j + 1) * step, grid_base_us + p_idx * period_us
        self.limit.baseline_frame(self.integ, k + 1, t_next - st.t_start)
        if self.batch is not None:                       # held on the device, committed with the next steps
            self.limit.step_held(self.integ, t1 - t0)
            self.batch.add(t0, t1, base_us, complete_until_us=int(math.floor(t_next * 1e6)))
            return
        events = self.integ.commit_events(t0, t1, base_us)
        self.summary.events_s += time.perf_counter() - te
        self.limit.step_frame(self.integ.log_prev)
        if self.reuse and self.grid:                     # a period's events are kept on the host for copying
            host = events.numpy()
            self._remember_period(j, p_idx, host)
            self._emit(*host, t_next)
            return
        tw = time.perf_counter()
        self.sink.add_step(events, complete_until_us=int(math.floor(t_next * 1e6)))
        self.summary.write_s += time.perf_counter() - tw

    def _remember_period(self, j, p_idx, events) -> None:
        """Keep a period's events; at its end, if the pixel state came back, later periods are copies."""
        steps_per_period = self.grid[0]
        self.period_events[j] = events
        if j != steps_per_period - 1 or (p_idx + 1) * steps_per_period >= self.st.steps:   # none left to copy
            return
        key = self.integ.periodic_key()
        if key is not None and self.prev_key is not None and bool((key == self.prev_key).numpy().all()):
            self.copy_from = p_idx
            self.period_block = period_blocks([self.period_events[i] for i in range(steps_per_period)])
            self.summary.notes.append(f"pixel state repeated after period {p_idx + 1}: the events of the later "
                                      "periods are exact copies, shifted by whole periods")
        self.prev_key = key

    def finish(self, steps: int, meta: dict, wall0: float):
        """Totals and notes into the summary and the metadata; the sink closed. Returns the stream (or None
        when it went to an HDF5 file)."""
        summary, integ = self.summary, self.integ
        summary.steps = steps
        self.limit.note(summary)
        note_settling(summary, integ.config, self.timed, self.st.t_start, self.warmup)
        if self.static is not None:
            summary.static_pixels = self.static.note(min(integ.threshold_on, integ.threshold_off), summary.notes)
        if self.allocation is not None and integ.k_on is not None:
            summary.sample_allocation = dict(self.allocation.as_meta(),
                                             **self.allocation.check((integ.k_on + integ.k_off).numpy(), summary.notes))
        summary.wall_s = time.perf_counter() - wall0
        if self.timed.is_static and self.timed.scan_period == 0.0:
            pm = integ.pixel_model_metadata()
            own = [name for name, key in (("shot noise", "shot_noise_hz"), ("leak", "leak_rate_hz")) if pm.get(key)]
            summary.notes.append("static scene seen by a fixed view: events can only come from Monte-Carlo noise "
                                 "(none with a fixed seed)" + (f" and the pixel's own {' and '.join(own)} (drawn "
                                 "from the pixel model's seed)" if own else ""))
        tw = time.perf_counter()
        self.sink.drain()
        summary.write_s += time.perf_counter() - tw
        summary.take_pixel_counters(integ, self.counters_before or (0, 0, 0))
        self.sink.report(summary)
        meta["render"] = summary.as_dict()
        tw = time.perf_counter()
        stream = self.sink.finish(int(round((self.st.t_start + self.st.duration) * 1e6)), {"render": meta["render"]})
        summary.write_s += time.perf_counter() - tw
        summary.wall_s = time.perf_counter() - wall0    # the file's copy lacks only this final write
        if self.bar is not None:         # the last chunks reach the count only as the render finishes
            self.bar.set_postfix_str(f"{summary.events} events", refresh=False)
        return stream


def _new_summary(timed, st: Stepping, output) -> RenderSummary:
    """The render's summary before it starts, with the notes the stepping alone decides (coarse steps)."""
    width, height = timed.film_size
    summary = RenderSummary(width=width, height=height, duration_s=st.duration,
                            output=os.path.abspath(output) if output else None)
    if st.steps is not None or st.chosen:          # uniform steps, or the default's placed by the motion
        note_image_motion(timed, st.t_start, st.duration, st.steps, summary, st.chosen, st.schedule)
    return summary


def _progress_bar(duration):
    from .summary import progress_bar
    return progress_bar(total=round(duration * 1e3, 6), unit="ms", unit_scale=False, desc="rendering",
                        bar_format="{l_bar}{bar}| {n:.3f}/{total:.3f} ms sim [{elapsed}<{remaining}]{postfix}")


def _steps_and_samples(timed, st: Stepping, integ, spp_changing):
    """(stepping, probe or None, sample allocation or None, frozen step render or None): the default steps
    where none were asked for (``stepping.default_steps``: the loop reuses its probe, a noise map and the first
    frame, and the frozen render it recorded), and with ``spp_changing`` the pixels that get more samples."""
    integ.reset()
    noise = frozen = None
    if spp_changing is not None:
        spp_changing = sample_allocation.checked_spp_changing(spp_changing)
    if st.needs_default_steps:
        frozen = frozen_render(integ.inner, st.spp) if spp_changing is None else None
        st, noise = default_steps(st, timed, integ, probe_spp=spp_changing, frozen=frozen)
    allocation = None if spp_changing is None else sample_allocation.plan(timed, st, integ, spp_changing)
    return st, noise, allocation, frozen


def render_events(scene, duration: float | None = None, *, steps: int | None = None, adaptive=False,
                  max_log_change: float = 0.5, min_step: float | None = None, max_step: float | None = None,
                  spp: int = DEFAULT_SPP, seed: int = 0, seed_mode: str = "fixed", threshold: float | None = None,
                  threshold_on: float | None = None, threshold_off: float | None = None,
                  linlog_threshold: float | None = None, output: str | None = None, fmt: str | None = None,
                  progress: bool = False, t_start: float = 0.0, reuse: bool = True, preset: str | None = None,
                  pixel: dict | None = None, extra_meta: dict | None = None,
                  event_buffer_mb: float = DEFAULT_EVENT_BUFFER_MB, checkpoint_s: float | None = None,
                  resume: bool = False, px_per_step: float = 1.0, spp_changing: int | None = None, on_device=False,
                  warmup: float = 0.0):
    """Render the event stream of ``scene`` over [t_start, t_start + duration] seconds.

    Returns an :class:`EventStream` when ``output`` is None (``on_device``: a :class:`DeviceEventStream`, the
    events left on the device); otherwise streams to ``output`` (by extension: HDF5, npz, text, AEDAT4 in
    chunks, RAW, DAT at the end) and returns a :class:`RenderSummary` (``meta["render"]``).
    ``reuse``: a static scene under a periodic view renders one period and feeds its frames again; a moving one
    renders the pixels no moving object can change once per period (``static_pixels.py``); False: every pixel
    at every step. ``steps``: uniform steps; default: as many as the known image motion needs (``stepping``).
    ``adaptive``: False (``steps`` uniform steps), True, "motion" or "log-change" (``stepping``: by the known
    image motion, at most ``px_per_step`` pixels per step, or by the per-pixel log change). ``preset``
    ("ideal", "davis346", "prophesee_gen4") and ``pixel`` (PixelConfig fields, e.g. ``{"refractory_s": 1e-4,
    "shot_noise_hz": 2}``) choose the event pixel; default: the scene's own.

    ``event_buffer_mb``: device memory for events before they move to the host (and the file writer) in one
    chunk, and the most that crosses at once (a larger kernel batch crosses in pieces of it).
    ``checkpoint_s``: save the render's state every so many wall seconds (HDF5 output), so that an
    interrupted render goes on with ``resume=True`` to the events of an uninterrupted one (``checkpoint.py``).
    ``spp_changing``: samples where they matter: pixels whose brightness changes (found by probe renders) get
    this many samples per step, the others ``spp`` (``sample_allocation.py``). ``warmup``: seconds rendered
    before ``t_start`` whose events are dropped: a pixel that has been running (``warmup.py``).
    """
    check_on_device(on_device, output)
    reuse, extra_meta = flag(reuse, "render_events: reuse"), instance(extra_meta or {}, dict, "extra_meta")
    timed = load_scene(scene)
    st = stepping(timed, duration, steps, adaptive, max_log_change, min_step, max_step, spp, seed, seed_mode,
                  t_start, px_per_step)
    width, height = timed.film_size
    check_memory(width, height, st.spp, where=f"{timed.path or 'scene'}: film")
    if output is not None:                          # "" refused, not taken for "in memory"
        check_writable(output, "event file")
        format_of(output, fmt, t_first_s=st.t_start)
    start, span = st.t_start, st.duration          # the caller's: recorded, and where events are kept from
    warm, all_steps = warmup_window(warmup_seconds(warmup, on_device), st.steps, span, timed.scan_period)
    if warm:
        st = stepping(timed, span + warm, all_steps, adaptive, max_log_change, min_step, max_step, spp, seed,
                      seed_mode, start - warm, px_per_step)
    integ = event_integrator(timed, threshold, threshold_on, threshold_off, linlog_threshold, preset, pixel, st.seed)
    st, noise, allocation, frozen = _steps_and_samples(timed, st, integ, spp_changing)
    summary = _new_summary(timed, st, output)
    summary.duration_s = span                      # (rates over the events kept)
    meta = run_metadata(timed, integ, duration=span, t_start=start, spp=st.spp, seed=st.seed,
                        seed_mode=st.seed_mode, stepping=kept_stepping(st.as_meta(), st, warm),
                        sample_allocation=allocation.as_meta() if allocation else None)
    if warm:
        meta["warmup_s"] = warm
    meta.update(extra_meta or {})
    checkpoints = checkpoints_for(output, fmt, meta, checkpoint_s, resume)
    bar = _progress_bar(st.duration) if progress else None
    return _run(lambda: Sink(output, fmt, width, height, meta, count=summary.count, buffer_mb=event_buffer_mb,
                             segments=checkpoints.segments if checkpoints else None, on_device=on_device,
                             emit_from_us=int(round(start * 1e6)) if warm else None),
                lambda sink: _Loop(timed, integ, st, sink, summary, bar, reuse, checkpoints, allocation, noise,
                                   frozen, warm), checkpoints, bar, meta, output)


def _run(make_sink, make_loop, checkpoints, bar, meta: dict, output):
    """The sink and loop made and run to its end: the stream (in memory, on the device, or a format written at
    the end: RAW, DAT) or, written to ``output``, the summary; on any failure (the sink's own making too) the
    sink and checkpoints abandoned."""
    wall0, sink = time.perf_counter(), None
    try:
        sink = make_sink()
        loop = make_loop(sink)
        stream = loop.finish(loop.run(), meta, wall0)
    except BaseException:
        if sink is not None:
            sink.abort()
        if checkpoints is not None:
            checkpoints.abandon()
        raise
    finally:
        if bar is not None:
            bar.close()
    if checkpoints is not None:
        checkpoints.release()        # its folder is gone with the merge
    if stream is not None:
        stream.meta = {**meta, "render": loop.summary.as_dict()}
    return stream if output is None else loop.summary
