"""How far the image moves in one time step, a note when that is more than a pixel, and the adaptive step
instants that keep it under one (``motion_schedule``).

Events between two rendered instants are placed by linear interpolation of each pixel's log brightness; when
the image moves by more than about a pixel per step, an edge skips pixels between instants and their events
are interpolated rather than resolved (timing error, missed crossings). Two sources of image motion are known
before rendering: the galvo scan (analytic, ``optics.galvo.scan_image_path_px``) and the moving objects (their
bounding-box corners projected through the camera at times one step apart). The per-pixel log change is no
measure of this: moving edges over a dark background change a pixel by tens of thresholds at any step size
(docs/design.md, "A measured dead end").
"""
from __future__ import annotations

import math
import sys

import numpy as np

from ..errors import EventFieldError
from ..optics.galvo import focal_length_px
from ..scene.timed import TimedScene
from ..validate import MAX_STEPS

MAX_PX_PER_STEP = 1.0
MOTION_SAMPLES = 257           # instants per render at which moving objects are projected
SPEED_CHUNK = 200_000          # instants projected at once by largest_image_speed and sampled_motion
SCHEDULE_SAMPLES = 2_000_000   # instants a schedule's motion is sampled at (64 a scan period) before thinning
MIN_SAMPLES_PER_PERIOD = 8     # never fewer a scan period: a circle's path by 8 chords is 2.6 % short
MAX_SCHEDULE_SAMPLES = 8_000_000   # 64 MB a sample array: 1,000,000 scan periods a render


def _cameras(timed: TimedScene) -> list | None:
    """Every pinhole the sensor's views look through, as (world-to-camera 4x4, focal length in pixels of one
    view), or None when the views are not pinholes (the microlens layout, validation modes).

    A perspective sensor or the galvo at rest: one pinhole. The kaleidoscope: one per view. In the thin-lens
    model a view sees the scene through its sub-aperture on the main lens; a ray from a point through the
    sub-aperture centre ``a`` lands on the image plane at ``-s' (X - a) / z`` plus a shift that is constant per
    view, so the view moves like a pinhole at ``a`` with focal length ``s'`` (the lens-to-image-plane distance),
    in pixels ``s'`` times its tile's width over the image plane's width."""
    sensor = timed.sensor
    optics = sensor.optics_metadata() if hasattr(sensor, "optics_metadata") else {}
    to_world = getattr(sensor, "m_to_world", None) or sensor.world_transform()
    world_to_cam = np.linalg.inv(np.array(to_world.matrix.numpy()).reshape(4, 4))
    if optics.get("design") == "kaleidoscope" and optics.get("mode") == "lenses":
        cams = []
        for view in optics["views"]:
            focal = optics["lens_to_image_plane"] * view["tile"][2] / optics["image_plane_size"][0]
            shift = np.eye(4)
            shift[:2, 3] = -np.asarray(view["subaperture"], dtype=np.float64)   # sensor-local sub-aperture
            cams.append((shift @ world_to_cam, focal))
        return cams
    fov = optics.get("fov_x_deg")
    if fov is None and optics.get("design") is None:
        keys = [k for k in timed.params.keys() if k.endswith(".x_fov") and k.count(".") == 1]
        fov = float(timed.params[keys[0]][0]) if keys else None
    if fov is None:
        return None
    return [(world_to_cam, focal_length_px(timed.film_size[0], float(fov)))]


def object_displacements(timed: TimedScene, times) -> np.ndarray | None:
    """Largest image displacement of any moving object's bounding-box corners between consecutive ``times``,
    in pixels, (len(times) - 1,), over every view; None without moving objects, and None when some motion is
    not known (views that are not pinholes, or a moving object that is no shape: a moving sensor or
    instance), so that no caller mistakes an unknown motion for a small one."""
    cameras = _cameras(timed)
    if cameras is None or timed.motion is None or timed.is_static:
        return None
    shapes = {s.id(): s for s in timed.scene.shapes()}
    if any(name not in shapes for name in timed.motion.objects):
        return None
    rows = np.stack([m for m, _ in cameras], axis=-1)        # (4, 4, V): camera x, y, z rows of every view
    focal = np.array([f for _, f in cameras])
    worst = np.zeros(len(times) - 1)
    for name, obj in timed.motion.objects.items():
        box = shapes[name].bbox()
        lo, hi = np.array(box.min).ravel(), np.array(box.max).ravel()
        corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        now = np.linalg.inv(obj.matrix(timed.time))          # the shape sits at its pose of the scene's time
        world = np.einsum("tij,kj->tki", obj.matrices(times) @ now, corners).reshape(-1, 4)   # (n+1) x 8 points
        # every view in one product per camera axis, contiguous (n+1, 8 V) arrays: 5 ms -> 1.5 ms for 9 views
        x, y, z = ((world @ rows[axis]).reshape(len(times), -1) for axis in range(3))
        z = np.where(np.abs(z) > 1e-9, z, 1e-9)
        scale = np.tile(focal, 8) / z
        u, v = x * scale, y * scale
        ahead = (z[1:] > 0) & (z[:-1] > 0)                   # (n, 8 V): both ends in front of the camera
        step = np.where(ahead, np.hypot(np.diff(u, axis=0), np.diff(v, axis=0)), 0.0)
        worst = np.maximum(worst, step.max(axis=1))
    return worst


def object_px_per_step(timed: TimedScene, t_start: float, duration: float, steps: int) -> float | None:
    """Largest image displacement of any moving object's bounding-box corners over one step, in pixels (None
    without moving objects or without a pinhole-like camera)."""
    n = min(steps, MOTION_SAMPLES - 1)
    timed.set_time(t_start)            # the shapes' bounds at the render's start: the same answer on every call
    d = object_displacements(timed, t_start + np.linspace(0.0, duration, n + 1))
    return None if d is None else float(d.max()) * n / steps      # samples may span several steps


def scan_displacements(timed: TimedScene, times) -> np.ndarray | None:
    """The galvo scan's image displacement between consecutive ``times`` (pixels; the largest over the image
    centre and corners, at infinity: ``optics.galvo``), or None without a periodic scan."""
    period, sensor = timed.scan_period, timed.sensor
    if not period or not hasattr(sensor, "optics_metadata"):
        return None
    from ..optics.galvo import GalvoGeometry, field_step_shifts
    from ..optics.scan import curve_from_dict
    optics = sensor.optics_metadata()
    geometry = GalvoGeometry.from_optics(optics, *timed.film_size)
    ax, ay = curve_from_dict(optics["scan"]).angles(np.asarray(times, np.float64))
    return field_step_shifts(geometry, ax, ay).max(axis=0)


def image_displacements(timed: TimedScene, times) -> np.ndarray | None:
    """The image motion between consecutive ``times``, in pixels (len(times) - 1,): the scan's and the moving
    objects' added (a point on a moving object moves by both); zeros when nothing moves; None when some motion
    is not known before rendering (an aperiodic view, objects seen through views that are not pinholes, a
    moving sensor)."""
    n = len(times) - 1
    period = timed.scan_period
    if period is None:
        return None
    scan = scan_displacements(timed, times) if period else np.zeros(n)
    moving = timed.motion is not None and not timed.is_static
    objects = object_displacements(timed, times) if moving else np.zeros(n)
    return None if scan is None or objects is None else scan + objects


def _motion_times(timed: TimedScene, t_start: float, duration: float) -> np.ndarray:
    """The instants at which a schedule's image motion is sampled: 64 per scan period and at least 1024 over the
    render, at most SCHEDULE_SAMPLES unless that leaves fewer than MIN_SAMPLES_PER_PERIOD a period (the cap of
    200,000 this replaced left 2 a period at 100,000 periods: the samples fell on the same phases, and the scan's
    path came out a fraction of itself). Beyond MAX_SCHEDULE_SAMPLES: refused, one line."""
    period = timed.scan_period or 0.0
    periods = duration / period if period else 0.0
    n = max(1024, int(math.ceil(64 * periods)))
    if n > SCHEDULE_SAMPLES:
        n = max(SCHEDULE_SAMPLES, int(math.ceil(MIN_SAMPLES_PER_PERIOD * periods)))
    if n > MAX_SCHEDULE_SAMPLES:
        raise EventFieldError(f"duration = {duration:g} s is {periods:.0f} scan periods: steps placed by image motion "
                              f"sample each period {MIN_SAMPLES_PER_PERIOD} times, allowed at most "
                              f"{MAX_SCHEDULE_SAMPLES // MIN_SAMPLES_PER_PERIOD} periods a render (use uniform "
                              "--steps, or split the render)")
    return t_start + np.linspace(0.0, duration, n + 1)


def largest_image_speed(timed: TimedScene, t_start: float, duration: float) -> float | None:
    """The fastest the image moves anywhere during the render, pixels per second (scan plus objects, sampled
    64 times a scan period and at least 1024 times a render, in chunks of SPEED_CHUNK instants: without a cap
    on the samples, so that a render of thousands of scan periods does not alias its scan); 0.0 when nothing
    moves; None when some motion is not known."""
    period = timed.scan_period or 0.0
    n = max(1024, int(math.ceil(64 * duration / period)) if period else 0)
    dt = duration / n
    timed.set_time(t_start)            # the shapes' bounds at the render's start: the same answer on every call
    worst = 0.0
    for d in _displacement_chunks(timed, n, lambda i0, i1: t_start + dt * np.arange(i0, i1 + 1)):
        if d is None:
            return None
        worst = max(worst, float(d.max()))
    return worst / dt


def sampled_motion(timed: TimedScene, t_start: float, duration: float) -> tuple:
    """(instants, image displacement between consecutive ones or None where unknown): the motion a schedule
    is placed by (``_motion_times``; for a render without a scan also what ``largest_image_speed`` samples)."""
    times = _motion_times(timed, t_start, duration)
    timed.set_time(t_start)            # the shapes' bounds at the render's start: the same answer on every call
    parts = list(_displacement_chunks(timed, len(times) - 1, lambda i0, i1: times[i0:i1 + 1]))
    return times, None if any(d is None for d in parts) else np.concatenate(parts)


def _displacement_chunks(timed: TimedScene, n: int, instants):
    """``image_displacements`` over instants 0..n, SPEED_CHUNK intervals at a time (bounded temporaries for
    renders of many scan periods); ``instants(i0, i1)``: the instants i0..i1. Stops after a None (unknown)."""
    for i0 in range(0, n, SPEED_CHUNK):
        d = image_displacements(timed, instants(i0, min(n, i0 + SPEED_CHUNK)))
        yield d
        if d is None:
            return


def motion_schedule(timed: TimedScene, t_start: float, duration: float, px_per_step: float = MAX_PX_PER_STEP,
                    max_step: float | None = None, min_step: float | None = None,
                    sampled: tuple | None = None) -> np.ndarray | None:
    """Render instants from ``t_start`` to ``t_start + duration`` such that the known image motion (scan plus
    moving objects, added: a point on a moving object moves by both) is at most ``px_per_step`` pixels between
    consecutive instants, no step longer than ``max_step`` or (unless the motion demands a finer grid than
    the samples resolve) shorter than ``min_step``. None when no motion is known (nothing to go by: a static
    scene before a fixed view, or motion that is not known before rendering).

    The motion is sampled finely (``_motion_times``), its cumulative path is inverted at multiples of
    ``px_per_step``: as many steps as the path needs, placed where it happens. ``sampled``: ``sampled_motion``'s
    result where it is already known."""
    times, d = sampled if sampled is not None else sampled_motion(timed, t_start, duration)
    if d is None or (timed.scan_period == 0.0 and timed.is_static):
        return None
    path = np.concatenate([[0.0], np.cumsum(d)])
    steps = max(1, int(math.ceil(path[-1] / px_per_step * (1 - 1e-6))))    # 50.0000001 px at 0.5: 100 steps
    if steps > MAX_STEPS:                        # refused before the instants are built
        raise EventFieldError(f"adaptive by image motion needs {steps} steps of at most {px_per_step:g} px: allowed "
                              f"at most {MAX_STEPS} (raise px_per_step or shorten the render)")
    instants = np.interp(np.linspace(0.0, path[-1], steps + 1), path, times) if path[-1] > 0 else times[[0, -1]]
    if max_step is not None:                     # split steps longer than max_step (nothing moves there)
        splits = int(np.maximum(1, np.ceil(np.diff(instants) / max_step - 1e-9)).sum())
        if splits > MAX_STEPS:
            raise EventFieldError(f"max_step = {max_step:g} s makes {splits} steps: allowed at most {MAX_STEPS}")
        out = [instants[0]]
        for t0, t1 in zip(instants[:-1], instants[1:]):
            k = max(1, int(math.ceil((t1 - t0) / max_step - 1e-9)))
            out.extend(t0 + (t1 - t0) * np.arange(1, k + 1) / k)
        instants = np.array(out)
    if min_step is not None and len(instants) > 2:   # merge steps shorter than min_step into their successor
        keep = [instants[0]]
        for t in instants[1:-1]:
            if t - keep[-1] >= min_step:
                keep.append(t)
        instants = np.array(keep + [instants[-1]])
    instants[0], instants[-1] = t_start, t_start + duration
    return instants


def scan_px_per_step(timed: TimedScene, duration: float, steps: int) -> float | None:
    """The galvo scan's image motion per step, in pixels (None without a periodic scan)."""
    period = timed.scan_period
    sensor = timed.sensor
    if not period or not hasattr(sensor, "optics_metadata"):
        return None
    from ..optics.galvo import scan_image_path_px
    width, height = timed.film_size
    return scan_image_path_px(sensor.optics_metadata(), width, height) * (duration / steps) / period


def note_image_motion(timed: TimedScene, t_start: float, duration: float, steps: int | None, summary,
                      chosen: dict | None = None, schedule=None) -> None:
    """Record the image motion per step in the summary (and so the metadata), and warn (a note, and on stderr)
    when the scan's and the objects' together are more than :data:`MAX_PX_PER_STEP` pixels. This is the one
    coarse-step check, galvo or not: a fixed count of steps per scan period (the fan lost 29 % of its events
    at 4 a period, 346x260) says nothing at another film size or scan amplitude; the pixels a step do.
    ``chosen``: the default steps' reasons (``stepping.default_steps``): steps it made coarser than a pixel
    because Monte-Carlo noise limits the render are noted with that reason, not warned about. ``schedule``:
    the instants of the default's steps placed by the motion (``steps`` None), whose largest image path a step
    ``chosen["largest_px_per_step"]`` holds."""
    if schedule is not None:           # the default's steps placed by the motion (no scan): their largest path
        steps, scan, objects = len(schedule) - 1, None, chosen["largest_px_per_step"]
    else:
        scan = scan_px_per_step(timed, duration, steps)
        objects = object_px_per_step(timed, t_start, duration, steps)
    summary.image_motion_px_per_step = {"scan": scan, "objects": objects}
    worst = (scan or 0.0) + (objects or 0.0)            # a point on a moving object moves by both
    if worst <= MAX_PX_PER_STEP * (1 + 1e-9):
        return
    parts = [f"the {k} {_px(v)} px" for k, v in (("scan", scan), ("objects", objects)) if v]
    what = " and ".join(parts) + (f", together {_px(worst)} px" if len(parts) > 1 else "")   # the check is on the sum
    allowed = allowed_px_per_step(chosen)
    if worst <= allowed * (1 + 1e-6):
        # what decided the count, in the words of the metadata's stepping.chosen.by: "not accuracy", said when a
        # floor (the light-field views) had set the steps, contradicted the timing note that followed ("limited
        # by the time step ... twice the steps quarter it")
        by = chosen.get("by")
        why = "the image motion at" if by == "image motion" else f"the {by}, within"
        summary.notes.append(f"steps of about {worst:.3g} px of image motion (per step {what}): as many as {why} "
                             f"the {allowed:g} px a step the default allows where Monte-Carlo noise "
                             f"({chosen['noise_over_threshold']:.2g} C) limits this render, as each step's render "
                             "adds noise events; with more samples (e.g. --spp 16) the default steps are finer")
        return
    need = int(math.ceil(steps * worst / MAX_PX_PER_STEP))
    # not "--steps N": the applications choose their own steps and take no such option
    fix = (f"{need} steps (render --steps, render_events(steps=)) keep it under {MAX_PX_PER_STEP:g} px"
           if schedule is None else
           "the steps are placed by the motion, and the fastest moments would need steps shorter than "
           "--min-step (default 1 us)")
    note = (f"warning: steps coarser than the image motion: per step {what} (more than {MAX_PX_PER_STEP:g} "
            f"px: events between rendered instants are interpolated, not resolved, and missed); {fix}")
    summary.notes.append(note)
    print(f"eventfield: {note}", file=sys.stderr)


def _px(v: float) -> str:
    """Pixels to three digits, or to as many as tell it from the bound (1.0004 px printed as "1", more than 1)."""
    text = f"{v:.3g}"
    return f"{v:.5g}" if float(text) == MAX_PX_PER_STEP and v != MAX_PX_PER_STEP else text


def allowed_px_per_step(chosen: dict | None) -> float:
    """The image motion a step may have without a warning: ``MAX_PX_PER_STEP``, or more where the default steps
    chose it (``chosen``: ``stepping.default_steps``' reasons, in the metadata as ``stepping.chosen``) because
    Monte-Carlo noise limits the render. The render's own note and the light-field commands' warning read this
    one bound: the commands warned "render it with more steps" on the default render of galvo_static. The
    default steps record their bound whichever floor decides (steps >= those for motion keep it): recorded
    only where the motion decided, galvo_static's 160 steps (set by the light-field views, 1.8 px a step under
    the noise-limited 2) were warned about again."""
    return max(MAX_PX_PER_STEP, (chosen or {}).get("px_per_step") or 0.0)


def largest_px_per_step(meta: dict) -> float | None:
    """The image motion of one step an event file's metadata records (``note_image_motion``: the scan's and the
    objects' together, as the coarse-step note and the default steps bound it); None where the render noted
    none (adaptive steps, unknown motion)."""
    motion = (meta.get("render") or {}).get("image_motion_px_per_step") or {}
    values = [v for v in motion.values() if v is not None]
    return sum(values) if values else None
