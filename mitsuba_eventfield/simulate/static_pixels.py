"""Static pixels under a periodic scan: render once a period what moving objects cannot change, every step the rest.

Under a periodic galvo scan, a pixel that no moving object can affect sees a periodic radiance: its frame at
step k equals its frame one scan period earlier. So the first period renders every pixel and keeps the static
pixels' frames (one per in-period step); later steps render only the dynamic pixels and take the static ones
from that cache (``render_events(reuse=True)``, the default; issue 18 part 4, "no more than a scene needs, in
space too").

Which pixels are dynamic (``plan``):

* **Direct view, bounded.** The moving shapes' pixels (``scene.coverage``: Mitsuba's shape-index AOV)
  at poses sampled over the render (over one turn for objects that only spin) with at most ``POSE_STEP_PX``
  of image motion between samples, all cast from one scan phase; then dilated by the scan (the convex hull of
  the image shifts from that phase to every other, at infinity, where a two-mirror scan shifts most: at a finite
  depth the shifts are those scaled towards zero, inside the hull) and by the largest image motion between
  pose samples plus one pixel (a pixel partly covered).
* **Shadows and reflections, probed.** The other pixels rendered at ``PROBE_SPP`` samples (one seed) at every
  pose sample ``PROBE_STEP_PX`` of image motion apart, from the same scan phase: a pixel whose log brightness
  spans more than ``CHANGE_OF_C`` x C across them (3 x 3 median: shadows are coherent, sample flicker is not)
  is dynamic too, dilated like the direct mask (scan hull, and the objects' image motion between two probes:
  a shadow moves about as its object does). Sampled, not bounded: hence the check.
* **The check.** At ``CHECKS`` instants after the first period the static pixels are rendered at ``CHECK_SPP``
  with one seed, at that instant and at the same scan phase in the first period, and compared: the largest log
  difference and the share of static pixels beyond ``CHANGE_OF_C`` x C go into the summary and the metadata,
  with a warning when that share is above ``CHECK_SHARE``.

What counts is the change of the converged radiance, not of a few samples: at 4 spp a blade that blocks one
shading ray of a wall pixel changes it by a quarter (measured on the fan: 7 % of the wall right of the fan
changed by more than C/2 between two instants one period apart at 4 spp, none at 64 spp, where the largest
change was 0.07 in log). Rendering such a pixel every step fires those Monte-Carlo events (the frozen-noise
rule cannot hold when the occluders move); reusing it does not. Hence probes and check at many samples.

Each wavefront (dynamic pixels every step, static pixels in the first period) keeps its own fixed samples
(``sample_allocation.render_pixels``), so a pixel's Monte-Carlo noise is the same at every step (the
frozen-noise rule) and a pixel never switches between sample patterns mid-render.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .. import backend
from ..validate import available_memory
from .sample_allocation import render_pixels
from .stepping import whole_number

mi, dr = backend.mi, backend.dr

POSE_STEP_PX = 2.0           # image motion between two pose samples of the direct mask
MAX_POSES = 2048
PROBE_STEP_PX, PROBE_SPP = 16.0, 16    # shadow probes: every 16 px of object motion; spp a power of 4 (every sampler)
CHANGE_OF_C = 0.5            # probes and check: a log change this many thresholds counts
CHECKS, CHECK_SPP = 3, 64
CHECK_SHARE = 1e-3           # the check warns above this share of static pixels changed
MAX_DYNAMIC_SHARE = 0.85     # above it, two wavefronts cost more than the reuse saves
# The masks cost about 200 frames (pose AOVs, shadow probes) and each later period saves (1 - dynamic share)
# frames a step. Measured (benchmarks/results/fan_steps.md): the fan (78 % dynamic, 32 steps a period, masks
# 3.45 s) saves 92 ms a period, so it breaks even after ~38 periods (190 against 178 s per simulated second
# over 25 periods, 176 against 181 over 50); the dart (62 %, 40 steps, masks 1.25 s) after ~21. So it waits
# for 40 periods, where neither loses.
MIN_PERIODS = 40
CACHE_MEMORY_SHARE = 0.25    # of the available memory, for one period of static frames


@dataclass
class StaticPixels:
    """The split of one render: ``dynamic`` (H, W) bool, rendered every step; the rest once a period."""
    dynamic: np.ndarray
    steps_per_period: int
    spp: int
    direct_share: float
    dilate_px: int
    poses: int
    probe_dilate_px: int = 0
    checks_at: list = field(default_factory=list)
    plan_s: float = 0.0          # wall seconds the masks took (a fixed cost of the render)

    def __post_init__(self):
        flat = self.dynamic.ravel()
        self.size = (self.dynamic.shape[1], self.dynamic.shape[0])
        self.pixels_dynamic = mi.UInt32(np.flatnonzero(flat).astype(np.uint32))
        self.pixels_static = mi.UInt32(np.flatnonzero(~flat).astype(np.uint32))
        self.cache = {}              # in-period step index -> the static pixels' sample sums (flat film)
        self.checks = []
        self._frozen = {}            # "dynamic" / "static" -> its wavefront (backend.FrozenOrTraced)

    @property
    def dynamic_share(self) -> float:
        return float(self.dynamic.mean())

    def _render(self, timed, inner, which: str, seed):
        """The ``which`` ("dynamic" or "static") pixels' wavefront, frozen (``dr.freeze``: recorded once,
        replayed) like the full-frame render; traced when Dr.Jit cannot record the scene.

        One frozen function per pixel list: a replay does not redo the host-side arithmetic of the recording
        (here the wavefront's width, pixels x spp), so one function fed lists of two lengths replayed the first
        one's width for the second (measured: a static wavefront summed to 289 instead of 392)."""
        pixels = self.pixels_dynamic if which == "dynamic" else self.pixels_static
        if which not in self._frozen:
            spp, size = self.spp, self.size
            self._frozen[which] = backend.FrozenOrTraced(
                lambda scene, sensor, pixels, seed: render_pixels(scene, sensor, inner, pixels, spp, seed, size))
        return self._frozen[which](timed.scene, timed.sensor, pixels, dr.opaque(mi.UInt32, seed))

    def render(self, timed, inner, seed: int, step: int):
        """The frame of step ``step`` (counted from the render's start) as an (H, W, 1) tensor."""
        phase = step % self.steps_per_period
        total = self._render(timed, inner, "dynamic", seed)
        if phase not in self.cache:                   # first period: the static pixels too, kept
            static = self._render(timed, inner, "static", seed)
            dr.eval(static)
            self.cache[phase] = static
        elif step in self.checks_at:
            self._check(timed, inner, seed, step)
        width, height = self.size
        return mi.TensorXf((total + self.cache[phase]) / self.spp, shape=(height, width, 1))

    def _check(self, timed, inner, seed, step):
        """The static pixels at CHECK_SPP now and at the same scan phase in the first period (log difference);
        the scene is left at this step's time."""
        t_now, t_then = timed.time, timed.time - (step // self.steps_per_period) * timed.scan_period
        logs = []
        for t in (t_then, t_now):
            timed.set_time(t)
            frame = render_pixels(timed.scene, timed.sensor, inner, self.pixels_static, CHECK_SPP, seed, self.size)
            logs.append(np.log(np.maximum(frame.numpy()[~self.dynamic.ravel()] / CHECK_SPP, 1e-6)))
        diff = np.abs(logs[1] - logs[0])
        self.checks.append((step, float(diff.max()) if diff.size else 0.0, diff))

    def note(self, threshold: float, notes: list) -> dict:
        """The split and its check, for the summary's notes and the metadata."""
        changed = [float(np.mean(d > CHANGE_OF_C * threshold)) if d.size else 0.0 for _, _, d in self.checks]
        worst = max((m for _, m, _ in self.checks), default=None)
        notes.append(f"static pixels reused: {100 * (1 - self.dynamic_share):.1f} % of the pixels rendered once "
                     f"per scan period, {100 * self.dynamic_share:.1f} % every step"
                     + (f"; checked at {len(self.checks)} instants: largest log change {worst:.3g}, "
                        f"{100 * max(changed):.3f} % of static pixels beyond {CHANGE_OF_C:g} C"
                        if self.checks else ""))
        if changed and max(changed) > CHECK_SHARE:
            notes.append(f"warning: {100 * max(changed):.2f} % of the pixels taken as static changed by more than "
                         f"{CHANGE_OF_C:g} C when rendered again (a moving object's shadow or reflection the probes "
                         "missed): render with reuse=False (--no-reuse) for exact frames")
        return {"dynamic_share": round(self.dynamic_share, 4), "direct_share": round(self.direct_share, 4),
                "dilate_px": self.dilate_px, "poses": self.poses, "probe_dilate_px": self.probe_dilate_px,
                "plan_s": round(self.plan_s, 3),
                "check_max_log_change": None if worst is None else round(worst, 4),
                "check_changed_share": round(max(changed), 6) if changed else None}


def _moving_ids(timed):
    return [name for name, obj in timed.motion.objects.items() if not obj.is_static] if timed.motion else []


def _pose_times(timed, t_start, duration):
    """Pose samples with at most POSE_STEP_PX of image motion between two (over one turn when the moving
    objects only spin, at one rate), and the largest image motion between two samples."""
    from .image_motion import object_displacements
    objs = [timed.motion.objects[n] for n in _moving_ids(timed)]
    rpms = {abs(o.spin_rpm) for o in objs}
    spin_only = all(o.velocity is None and o.key_times is None for o in objs) and len(rpms) == 1
    span = min(duration, 60.0 / rpms.pop()) if spin_only else duration
    trial = t_start + np.linspace(0.0, span, 257)
    d = object_displacements(timed, trial)
    if d is None:
        return None, 0.0
    n = int(min(MAX_POSES, max(2, math.ceil(float(d.sum()) / POSE_STEP_PX))))
    times = t_start + np.linspace(0.0, span, n + 1)
    d = object_displacements(timed, times)
    return times, float(d.max()) if d is not None and d.size else 0.0


def _scan_kernel(timed, times_in_period, view_time):
    """Structuring element of the scan: where the image of a point seen at ``view_time`` goes at the other
    phases (offsets at the image centre and corners, at infinity), filled to its convex hull, reflected for
    ``cv2.dilate``."""
    import cv2

    from ..optics.galvo import GalvoGeometry
    from ..optics.scan import curve_from_dict
    optics = timed.sensor.optics_metadata()
    width, height = timed.film_size
    geometry = GalvoGeometry.from_optics(optics, width, height)
    curve = curve_from_dict(optics["scan"])
    ax, ay = curve.angles(np.append(times_in_period, view_time))
    offsets = []
    for x, y in ((width / 2, height / 2), (0.0, 0.0), (width, 0.0), (0.0, height), (width, height)):
        shifts = geometry.image_shift(ax, ay, math.inf, x, y)
        offsets.append(shifts[:-1] - shifts[-1])
    pts = -np.concatenate(offsets)                       # reflected: dst(q) = max src(q - offset)
    r = int(math.ceil(np.abs(pts).max())) + 1
    kernel = np.zeros((2 * r + 1, 2 * r + 1), np.uint8)
    hull = cv2.convexHull(np.round(pts + r).astype(np.int32))
    cv2.fillConvexPoly(kernel, hull, 1)
    return kernel


def _grow(mask, kernel, gap_px):
    """``mask`` dilated by the scan (``kernel``) and by ``gap_px`` plus one pixel."""
    import cv2
    grow = int(math.ceil(gap_px)) + 1
    mask = cv2.dilate(mask.astype(np.uint8), kernel)
    return cv2.dilate(mask, np.ones((2 * grow + 1, 2 * grow + 1), np.uint8)) > 0, grow


def _shadow_probes(timed, st, times, covered, inner, threshold, linlog):
    """Pixels outside ``covered`` whose log brightness spans more than CHANGE_OF_C x C across the objects'
    poses at ``times`` (shadows, reflections), all seen from the render's first scan phase, same samples."""
    import cv2

    from ..plugins import pixel_model
    height, width = covered.shape
    rest = np.flatnonzero(~covered.ravel())
    pixels = mi.UInt32(rest.astype(np.uint32))
    low = high = None
    for t in times:
        timed.set_time(float(t), view_time=st.t_start)
        frame = render_pixels(timed.scene, timed.sensor, inner, pixels, PROBE_SPP, st.seed, (width, height))
        log = pixel_model.linlog_np(frame.numpy()[rest] / PROBE_SPP, linlog)
        low, high = (log, log.copy()) if low is None else (np.minimum(low, log), np.maximum(high, log))
    timed.set_time(st.t_start)
    span = np.zeros(width * height, np.float32)
    span[rest] = high - low
    # a 3 x 3 median keeps a shadow (coherent over pixels) and drops single pixels that a few of their samples'
    # shading rays hitting a blade flicker (at 16 spp, 2 of 16 blocked is 0.13 in log: the fan's wall)
    span = cv2.medianBlur(span.reshape(height, width), 3)
    return span > CHANGE_OF_C * threshold


def _dynamic_masks(timed, st, steps_per_period, inner, threshold, linlog):
    """(direct mask, its dilation, shadow mask, its dilation, poses), all cast from the render's first scan
    phase (module docstring); None when some moving object is not a shape the shape-index AOV sees (an
    instance, the sensor)."""
    import cv2

    from ..scene.coverage import covered_over_time, unseen
    moving = _moving_ids(timed)
    if unseen(timed, moving):
        return None
    times, gap_px = _pose_times(timed, st.t_start, st.duration)
    if times is None:
        return None
    covered = covered_over_time(timed, times, moving, view_time=st.t_start)
    every = max(1, int(PROBE_STEP_PX // POSE_STEP_PX))
    # the probes skip the pixels the shapes partly cover (where the one AOV sample missed the shape)
    footprint = cv2.dilate(covered.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    found = _shadow_probes(timed, st, list(times[::every]) + [times[-1]], footprint, inner, threshold, linlog)
    step = st.duration / st.steps
    kernel = _scan_kernel(timed, st.t_start + step * np.arange(steps_per_period), st.t_start)
    direct, grow = _grow(covered, kernel, gap_px)
    shadows, probe_grow = _grow(found, kernel, gap_px * every)
    return direct, grow, shadows, probe_grow, len(times)


def plan(timed, st, integ, notes: list, checkpointed: bool = False) -> StaticPixels | None:
    """The static/dynamic split of a render of a moving scene under a periodic scan, or None (not such a render,
    or the split would not pay, or the render is ``checkpointed``: then a note says why)."""
    if st.steps is None or st.seed_mode != "fixed" or timed.is_static or not timed.scan_period \
            or "scan" not in getattr(timed.sensor, "optics_metadata", dict)():
        return None
    k = whole_number(timed.scan_period / (st.duration / st.steps))   # step i and i + k see the same scan phase
    if not k or st.steps < 2 * k:
        return None                                   # steps off the scan's phase grid, or under two periods
    if st.steps < MIN_PERIODS * k:
        notes.append(f"static pixels not reused: {st.steps / k:g} scan periods are too few to pay for the masks "
                     f"(at least {MIN_PERIODS})")
        return None
    if checkpointed:        # its cache of a period's static frames is not in a checkpoint: said, not silent
        notes.append("static pixels not reused: a checkpointed render renders every pixel at every step (the "
                     "reuse's cache of one period's frames is not checkpointed), so its events differ from an "
                     "uncheckpointed render's by Monte-Carlo noise, as --no-reuse's do")
        return None
    t0 = time.perf_counter()
    width, height = timed.film_size
    if k * width * height * 4 > CACHE_MEMORY_SHARE * available_memory():
        notes.append(f"static pixels not reused: one period of frames ({k} steps) needs more than "
                     f"{100 * CACHE_MEMORY_SHARE:g} % of the available memory")
        return None
    threshold = min(integ.threshold_on, integ.threshold_off)
    masks = _dynamic_masks(timed, st, k, integ.inner, threshold, integ.linlog_threshold)
    if masks is None:
        notes.append("static pixels not reused: a moving object is not a shape the shape-index AOV sees")
        return None
    covered, grow, shadows, probe_grow, poses = masks
    dynamic = covered | shadows
    if dynamic.mean() > MAX_DYNAMIC_SHARE:
        notes.append(f"static pixels not reused: moving objects can change {100 * dynamic.mean():.0f} % of the "
                     f"pixels (more than {100 * MAX_DYNAMIC_SHARE:g} %)")
        return None
    checks = sorted({k + (i * (st.steps - k)) // CHECKS for i in range(1, CHECKS + 1)})
    return StaticPixels(dynamic, k, st.spp, float(covered.mean()), grow, poses, probe_grow, checks,
                        time.perf_counter() - t0)
