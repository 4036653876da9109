"""How far the image moves in one time step, and a note when that is more than a pixel.

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

import numpy as np

from ..scene.timed import TimedScene

MAX_PX_PER_STEP = 1.0
MOTION_SAMPLES = 257           # instants per render at which moving objects are projected


def _camera(timed: TimedScene):
    """(world-to-camera 4x4, focal length in pixels) of a pinhole-like sensor (perspective, or the galvo at rest),
    or None (the kaleidoscope: its views are not one pinhole)."""
    sensor = timed.sensor
    optics = sensor.optics_metadata() if hasattr(sensor, "optics_metadata") else {}
    fov = optics.get("fov_x_deg")
    if fov is None and optics.get("design") is None:
        keys = [k for k in timed.params.keys() if k.endswith(".x_fov") and k.count(".") == 1]
        fov = float(timed.params[keys[0]][0]) if keys else None
    if fov is None:
        return None
    focal = timed.film_size[0] / (2 * math.tan(math.radians(float(fov)) / 2))
    to_world = getattr(sensor, "m_to_world", None) or sensor.world_transform()
    return np.linalg.inv(np.array(to_world.matrix.numpy()).reshape(4, 4)), focal


def object_px_per_step(timed: TimedScene, t_start: float, duration: float, steps: int) -> float | None:
    """Largest image displacement of any moving object's bounding-box corners over one step, in pixels (None
    without moving objects or without a pinhole-like camera)."""
    camera = _camera(timed)
    if camera is None or timed.motion is None or timed.is_static:
        return None
    world_to_cam, focal = camera
    shapes = {s.id(): s for s in timed.scene.shapes()}
    n = min(steps, MOTION_SAMPLES - 1)
    times = t_start + np.linspace(0.0, duration, n + 1)
    worst = 0.0
    for name, obj in timed.motion.objects.items():
        if name not in shapes:
            continue
        box = shapes[name].bbox()
        lo, hi = np.array(box.min).ravel(), np.array(box.max).ravel()
        corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        now = np.linalg.inv(obj.matrix(timed.time))          # the shape sits at its pose of the scene's time
        cam = np.stack([(world_to_cam @ obj.matrix(t) @ now @ corners.T).T for t in times])   # (n+1, 8, 4)
        z = np.where(np.abs(cam[..., 2]) > 1e-9, cam[..., 2], 1e-9)
        px = focal * cam[..., :2] / z[..., None]
        ahead = z[..., None] > 0
        step = np.linalg.norm(np.diff(px, axis=0), axis=-1)[(ahead[1:] & ahead[:-1])[..., 0]]
        if step.size:
            worst = max(worst, float(step.max()) * n / steps)   # samples may span several steps
    return worst


def scan_px_per_step(timed: TimedScene, duration: float, steps: int) -> float | None:
    """The galvo scan's image motion per step, in pixels (None without a periodic scan)."""
    period = timed.scan_period
    sensor = timed.sensor
    if not period or not hasattr(sensor, "optics_metadata"):
        return None
    from ..optics.galvo import scan_image_path_px
    width, height = timed.film_size
    return scan_image_path_px(sensor.optics_metadata(), width, height) * (duration / steps) / period


def note_image_motion(timed: TimedScene, t_start: float, duration: float, steps: int, summary) -> None:
    """Record the image motion per step in the summary (and so the metadata), and say so in a note when it is
    more than :data:`MAX_PX_PER_STEP` pixels."""
    scan = scan_px_per_step(timed, duration, steps)
    objects = object_px_per_step(timed, t_start, duration, steps)
    summary.image_motion_px_per_step = {"scan": scan, "objects": objects}
    worst = max(v for v in (scan, objects, 0.0) if v is not None)
    if worst > MAX_PX_PER_STEP:
        what = " and ".join(f"the {k} {v:.3g} px" for k, v in (("scan", scan), ("objects", objects))
                            if v is not None and v > MAX_PX_PER_STEP)
        need = int(math.ceil(steps * worst / MAX_PX_PER_STEP))
        summary.notes.append(f"steps coarser than the image motion: per step {what} (more than "
                             f"{MAX_PX_PER_STEP:g} px: events between rendered instants are interpolated, not "
                             f"resolved); --steps {need} keeps it under {MAX_PX_PER_STEP:g} px")
