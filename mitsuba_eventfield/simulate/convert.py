"""Frames to events: the renderer's event pixel run on frames a user already has (the job of v2e and ESIM).

Each frame is staged into the same ``eventfield`` integrator a render uses (same pixel model, same presets,
same device-side count / prefix-sum / fill, same sink and background writer), so a converted video and a
rendered scene are events of one model. Frames are streamed: memory is one frame plus the event buffer.
Between two frames the log brightness is taken as linear in time (the renderer's assumption between steps),
so timestamps are exact for brightness that is log-linear between frames, and frames must be dense enough for
the motion they show (as for any frame-based emulator).
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import replace

import numpy as np

from .. import backend
from .._version import __version__
from ..atomic import check_not_input, check_writable
from ..errors import EventFieldError, raise_if_stopped
from ..events.io import format_of
from ..plugins import event_batch, event_fill, pixel_model, pixel_step
from ..validate import MAX_THRESHOLD, number, positive
from .device_stream import check_on_device
from .frame_sources import (FrameSource, check_span, from_array, from_device, is_device_array, open_frames,
                            read_times)
from .frame_times import note_interval
from .sink import DEFAULT_EVENT_BUFFER_MB, Sink
from .summary import RenderSummary

mi, dr = backend.mi, backend.dr


def pixel_integrator(preset: str | None = None, pixel: dict | None = None, threshold: float | None = None,
                     threshold_on: float | None = None, threshold_off: float | None = None):
    """An ``eventfield`` integrator with this pixel model, for feeding frames (no scene needed): ``preset``
    (None: the one ``pixel`` names, else "ideal"); ``threshold_on`` / ``threshold_off`` override ``threshold``
    (``pixel_model.explicit_thresholds``). A bad preset or parameter is one ``EventFieldError`` naming it
    (checked before the plugin is built)."""
    preset, overrides = pixel_model.preset_and_overrides(preset, pixel)
    thr = None if threshold is None else number(threshold, "threshold", 0, MAX_THRESHOLD, lo_open=True, strict=True)
    explicit = pixel_model.explicit_thresholds(thr, threshold_on, threshold_off)
    pixel_model.given_once(explicit, overrides)
    for name, value in explicit.items():
        if value is not None:
            overrides.setdefault(name, value)
    config = pixel_model.pixel_config(preset or "ideal", "pixel model", **overrides)   # ConfigError if bad
    integ = mi.load_dict({"type": "eventfield"})
    integ.configure(config)
    return integ


def events_from_frames(frames, times=None, *, fps: float | None = None, preset: str | None = None,
                       pixel: dict | None = None, threshold: float | None = None,
                       threshold_on: float | None = None, threshold_off: float | None = None, srgb: bool = False,
                       output: str | None = None, fmt: str | None = None, progress: bool = False,
                       event_buffer_mb: float = DEFAULT_EVENT_BUFFER_MB, meta: dict | None = None,
                       frames_per_kernel: int | None = None, on_device: bool = False):
    """Events of a frame sequence through the event pixel model.

    ``frames``: a (T, H, W[, C]) array (intensity: floats linear, integers scaled by their maximum), a path
    (folder of images, ``.npz`` with ``frames`` and ``times``, or a video), or a ``FrameSource``; a (T, H, W)
    float stack already on the device (a Dr.Jit tensor, or PyTorch / CuPy through DLPack) stays there
    (``frame_sources.from_device``; with ``on_device`` nothing crosses to the host at all). ``times``:
    seconds per frame (an array, or a timestamps file: ``.npy`` or text, one time a line), or ``fps`` (not
    both; an ``.npz`` with its own times takes neither). ``preset`` / ``pixel`` / ``threshold`` /
    ``threshold_on`` / ``threshold_off``: the pixel model, as for :func:`render_events`. ``srgb=True`` decodes
    gamma-encoded frames to linear light first.
    ``frames_per_kernel``: frames the pixel model takes per kernel where it can (``event_batch``; the events
    are the same, only the speed changes); None picks by film size and backend.

    ``on_device=True`` (no ``output``): the events stay on the device and come back as a
    :class:`DeviceEventStream` (columns for PyTorch and the like through DLPack, no copy; ``.numpy()`` is the
    EventStream this returns otherwise).

    Returns the :class:`EventStream` (``output`` None) or, writing to ``output``, the :class:`RenderSummary`.
    """
    backend.ensure_variant()
    check_on_device(on_device, output)
    group = None if frames_per_kernel is None else positive(frames_per_kernel, "frames_per_kernel", integer=True)
    source = _with_known_start(frame_source(frames, times, fps, srgb))
    too_large = event_fill.film_limit_error(source.width, source.height)
    if too_large:
        raise EventFieldError(f"{source.name}: {too_large}")
    check_span(source.name, source.span_s)
    if output is not None:
        check_writable(output, "event file")
        format_of(output, fmt, t_first_s=source.start_s)
        check_not_input(output, (frames, times), "event file")
    integ = pixel_integrator(preset, pixel, threshold, threshold_on, threshold_off)
    integ.config.check_film(source.width * source.height, f"{source.name}: pixel model")
    summary = RenderSummary(width=source.width, height=source.height, output=os.path.abspath(output) if output else None)
    meta = {"package": "mitsuba-eventfield", "package_version": __version__, "variant": mi.variant(),
            "width": source.width, "height": source.height, "optics": {"design": "frames (converted)"},
            "pixel_model": integ.pixel_model_metadata(), "source": source.describe, **(meta or {}),
            # known before the first event: /t_offset is the first frame's millisecond, as a render's is its
            # start's (it was the first event's: DSEC's slicer failed on the first frame interval)
            **({} if source.start_s is None else {"t_start_us": int(round(source.start_s * 1e6))})}
    sink = Sink(output, fmt, source.width, source.height, meta, count=summary.count,
                buffer_mb=event_buffer_mb, on_device=on_device)
    wall0 = time.perf_counter()
    try:
        t_first, t_last = _feed(source, integ, sink, summary, progress, group)
        summary.duration_s = t_last - t_first
        tw = time.perf_counter()
        sink.drain()
        summary.write_s += time.perf_counter() - tw
        summary.take_pixel_counters(integ)
        sink.report(summary)
        summary.wall_s = time.perf_counter() - wall0
        meta.update({"t_start_us": int(round(t_first * 1e6)), "duration_us": int(round(summary.duration_s * 1e6))})
        meta["render"] = summary.as_dict()
        stream = sink.finish(int(round(t_last * 1e6)), {k: meta[k] for k in ("t_start_us", "duration_us", "render")})
    except BaseException:
        sink.abort()
        raise
    return summary if output else stream


def frame_source(frames, times, fps, srgb: bool) -> FrameSource:
    """The reader of ``frames`` (a FrameSource, a path, a device array or an array), with ``times`` (an array
    or a timestamps file, read here for every kind of input) or ``fps``."""
    times = read_times(times)
    if isinstance(frames, FrameSource):
        if times is not None or fps is not None:
            raise EventFieldError(f"{frames.name}: a FrameSource yields its frames' times: times and fps are for "
                                  "arrays, paths and device arrays")
        return frames
    if isinstance(frames, (str, os.PathLike)):
        return open_frames(frames, fps, srgb, times)
    return from_device(frames, times, fps, srgb) if is_device_array(frames) else from_array(frames, times, fps, srgb)


def _with_known_start(source: FrameSource) -> FrameSource:
    """``source`` with its first frame's time known before the event file opens: a caller's FrameSource that
    does not say it has its first frame read here and yielded again (its file's /t_offset was the first
    event's millisecond, not the first frame's, so a streamed file and the same events written from memory
    were indexed differently)."""
    if source.start_s is not None:
        return source
    frames = iter(source.frames())
    first = next(frames, None)
    if first is None:
        return replace(source, frames=lambda: iter(()))
    t = first[0]
    known = isinstance(t, (int, float, np.integer, np.floating)) and math.isfinite(t)   # else _feed says why

    def again():
        yield first
        yield from frames
    return replace(source, frames=again, start_s=float(t) if known else None)


def _feed(source: FrameSource, integ, sink: Sink, summary: RenderSummary, progress: bool,
          frames_per_kernel: int | None):
    """Every frame through the pixel: the first sets the references, each later one ends a step. Pixel models
    that allow it take ``frames_per_kernel`` frames per kernel (``event_batch``; same events)."""
    bar = None
    if progress:
        from .summary import progress_bar
        bar = progress_bar(total=source.count, unit="frame", desc="converting")
    group, batched = frames_per_kernel, integ.batchable
    pending, times = None, []      # the group's frames (_Group) and their times
    t_first = t_prev = t_last_committed = None
    try:
        for index, (t, frame) in enumerate(_frames(source)):
            raise_if_stopped()                # a Ctrl-C a library swallowed (errors.STOP_SIGNALS)
            if not source.device and frame.shape != (source.height, source.width):
                raise EventFieldError(f"{source.name}: frame size {frame.shape[1]}x{frame.shape[0]} differs from "
                                      f"{source.width}x{source.height}")
            if t_prev is not None and not t > t_prev:
                raise EventFieldError(f"{source.name}: frame times must increase ({t} s after {t_prev} s)")
            if t_first is not None:           # where the span was not known before (a video's own count)
                check_span(source.name, t - t_first)
            if index == 1:
                note_interval(source.name, t - t_first)
            if batched and t_first is not None and group is None:     # the first interval sets the default
                group = event_batch.default_frames_per_kernel(source.width * source.height, t - t_first)
            if batched and t_first is not None and group > 1:     # one frame a kernel: the per-step kernel
                if pending is None:
                    pending = _Group(source, group)
                pending.put(len(times), frame, index)
                times.append(t)
                if len(times) == group:
                    _commit_group(integ, sink, summary, pending.values(len(times)), [t_last_committed] + times)
                    t_last_committed, times = t, []
            else:
                _commit_one(integ, sink, summary, source.block(index, 1) if frame is None else frame, t_prev, t,
                            source)
                t_last_committed = t
            t_first = t if t_first is None else t_first
            t_prev = t
            if bar is not None:
                bar.update(1)
        if times:
            _commit_group(integ, sink, summary, pending.values(len(times)), [t_last_committed] + times)
    finally:
        if bar is not None:
            bar.close()
    if t_first is None or t_first == t_prev:
        raise EventFieldError(f"{source.name}: fewer than 2 frames: no step to make events from")
    return t_first, t_prev


def _frames(source: FrameSource):
    """(t, frame) of every frame; from a source with ``block`` the frame is None (taken by ``block`` where it is
    needed: tracing a gather a frame cost more host time than the whole group's kernels, issue 15)."""
    if source.block is None or source.times is None:
        return source.frames()
    return ((float(t), None) for t in source.times)


def _commit_one(integ, sink: Sink, summary: RenderSummary, frame, t_prev, t, source: FrameSource) -> None:
    t0 = time.perf_counter()
    values = frame if source.device else mi.Float(frame.ravel())
    integ.stage_log(pixel_model.linlog(dr, values, integ.config.linlog_threshold), (source.width, source.height),
                    intensity=values if pixel_step.needs_intensity(integ.config) else None)
    events = integ.commit_events(t_prev if t_prev is not None else t, t)
    summary.events_s += time.perf_counter() - t0
    if t_prev is not None:
        tw = time.perf_counter()
        sink.add_step(events, complete_until_us=int(math.floor(t * 1e6)))
        summary.write_s += time.perf_counter() - tw
        summary.steps += 1


class _Group:
    """The frames of one kernel: copied into one host buffer (a source may reuse its own); from a device
    source that holds its frames in one buffer, one gather of the group's consecutive frames (``block``: on an
    H200 a kernel a frame was the converter's most launched kernel, 199 of 287 for 200 frames); from another
    device source, joined on the device (``concat_arrays``: one cached kernel)."""

    def __init__(self, source: FrameSource, size: int):
        self.device, self.block, self.first = source.device, source.block, None
        self.frames = [] if self.device else np.empty((size, source.height, source.width), np.float32)

    def put(self, i: int, frame, index: int) -> None:
        """Frame ``index`` of the source as the group's ``i``-th (the group's frames are consecutive)."""
        if i == 0:
            self.first = index
        if self.device:
            del self.frames[i:]
            self.frames.append(frame)
        else:
            self.frames[i] = frame

    def values(self, count: int):
        """The first ``count`` frames as one flat Float of the active backend."""
        if self.block is not None:
            return self.block(self.first, count)
        if self.device:
            return event_fill.concat_arrays(self.frames[:count], mi.Float)
        return mi.Float(self.frames[:count].ravel())


def _commit_group(integ, sink: Sink, summary: RenderSummary, values, times: list) -> None:
    t0 = time.perf_counter()
    if pixel_step.needs_intensity(integ.config):    # the kernels take the log: no exp back to the radiance
        events = event_batch.commit_frames(integ, values, times, intensity=True)
    else:
        events = integ.commit_frames(pixel_model.linlog(dr, values, integ.config.linlog_threshold), times)
    summary.events_s += time.perf_counter() - t0
    tw = time.perf_counter()
    sink.add_step(events, complete_until_us=int(math.floor(times[-1] * 1e6)))
    summary.write_s += time.perf_counter() - tw
    summary.steps += len(times) - 1
