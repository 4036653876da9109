"""Samples where they matter: pixels whose brightness changes during the render get ``spp_changing`` samples per
step, the others ``spp`` (``render_events(spp_changing=...)``, ``eventfield render --spp-changing N``).

Where Monte-Carlo noise limits timing (the render summary says when), a crossing's time moves by about
sigma_L / |dL/dt|, so the samples pay off only in pixels that cross thresholds. A pixel that never changes
fires nothing with a fixed seed whatever its noise, so it needs few samples. The split is fixed for the whole
render: with a fixed seed a pixel's samples must be the same every step (frozen noise), and a pixel whose sample
count changed mid-render would jump by its noise and fire events that are not in the scene.

Which pixels change is measured before rendering, by ``PROBES`` probe renders at ``spp`` spread over the render:
a pixel whose log brightness spans more than ``CHANGE_OF_C`` x C across them, dilated by the largest image
motion between two probes (moving objects' projected bounds and the galvo scan, ``image_motion``) plus one
pixel, so that an object between two probes is covered. After the render the crossings of the pixels given
``spp`` are counted: when they hold more than ``MISSED_SHARE`` of all crossings the summary says the probes
missed change (check, not silence).

The frame is rendered as two wavefronts, one per sample count, through the sensor's ``sample_ray`` and the
radiance integrator's ``sample`` (what ``mi.render`` does, box filter): the same estimator as ``mi.render``
(tests/simulate/test_sample_allocation.py compares the two against 1024 spp), with its own noise pattern.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import backend
from ..errors import EventFieldError
from ..validate import MAX_SPP, positive

mi, dr = backend.mi, backend.dr

PROBES = 16
CHANGE_OF_C = 0.5
MISSED_SHARE = 0.05
MAX_DILATE_PX = 16


def render_pixels(scene, sensor, inner, pixels, spp: int, seed: int, size) -> "mi.Float":
    """Sum of ``spp`` radiance samples for each pixel of ``pixels`` (flat indices, mi.UInt32), as a flat film
    (zero elsewhere). The sampler is the sensor's, seeded for this wavefront alone: a fixed pixel list and seed
    give the same samples every call."""
    width, height = size
    lanes = len(pixels) * spp
    out = dr.zeros(mi.Float, width * height)
    if lanes == 0:
        return out
    sampler = sensor.sampler().fork()
    sampler.set_sample_count(spp)
    sampler.set_samples_per_wavefront(spp)
    sampler.seed(seed, lanes)
    pix = dr.gather(mi.UInt32, pixels, dr.arange(mi.UInt32, lanes) // spp)
    pos = mi.Vector2f(mi.Float(pix % width), mi.Float(pix // width)) + sampler.next_2d()
    time = mi.Float(sensor.shutter_open())
    if sensor.shutter_open_time() > 0:
        time += sampler.next_1d() * sensor.shutter_open_time()
    wavelength = sampler.next_1d()
    aperture = sampler.next_2d() if sensor.needs_aperture_sample() else mi.Point2f(0.5)
    ray, weight = sensor.sample_ray(time, wavelength, pos / mi.ScalarVector2f(width, height), aperture)
    radiance, _, _ = inner.sample(scene, sampler, ray, None, True)
    value = mi.luminance(radiance * weight) if dr.size_v(radiance) == 3 else (radiance * weight)[0]
    dr.scatter_reduce(dr.ReduceOp.Add, out, value, pix)
    return out


@dataclass
class SampleAllocation:
    """Which pixels get ``spp_changing`` samples (``changing``, (H, W) bool) and which ``spp_rest``."""
    changing: np.ndarray
    spp_changing: int
    spp_rest: int
    probes: int
    dilate_px: int

    def __post_init__(self):
        flat = self.changing.ravel()
        self.size = (self.changing.shape[1], self.changing.shape[0])
        self.pixels_changing = mi.UInt32(np.flatnonzero(flat).astype(np.uint32))
        self.pixels_rest = mi.UInt32(np.flatnonzero(~flat).astype(np.uint32))
        self.divisor = mi.Float(np.where(flat, self.spp_changing, self.spp_rest).astype(np.float32))

    @property
    def changing_share(self) -> float:
        return float(self.changing.mean())

    def render(self, scene, sensor, inner, seed: int):
        """The frame as an (H, W, 1) tensor, each pixel the mean of its own samples."""
        total = render_pixels(scene, sensor, inner, self.pixels_changing, self.spp_changing, seed, self.size) + \
            render_pixels(scene, sensor, inner, self.pixels_rest, self.spp_rest, seed, self.size)
        width, height = self.size
        return mi.TensorXf(total / self.divisor, shape=(height, width, 1))

    def samples_per_frame(self) -> int:
        return int(self.changing.sum()) * self.spp_changing + int((~self.changing).sum()) * self.spp_rest

    def as_meta(self) -> dict:
        return {"spp_changing": self.spp_changing, "spp_rest": self.spp_rest, "probes": self.probes,
                "changing_share": round(self.changing_share, 4), "dilate_px": self.dilate_px,
                "samples_per_frame": self.samples_per_frame()}

    def check(self, crossings: np.ndarray, notes: list) -> dict:
        """Share of the render's crossings (per pixel, flat) in pixels given ``spp_rest``; a note when the
        probes missed change there."""
        total = float(crossings.sum())
        missed = float(crossings[~self.changing.ravel()].sum()) / total if total else 0.0
        notes.append(f"samples where they matter: {100 * self.changing_share:.1f} % of pixels changed in the "
                     f"probes and got {self.spp_changing} spp, the rest {self.spp_rest} spp "
                     f"({self.samples_per_frame() / self.changing.size:.2f} spp on average); "
                     f"{100 * missed:.1f} % of the crossings fell outside them")
        if missed > MISSED_SHARE:
            notes.append(f"warning: {100 * missed:.1f} % of the crossings were in pixels the probes saw as still "
                         f"(more than {100 * MISSED_SHARE:g} %): their timing is at {self.spp_rest} spp; render with "
                         "uniform --spp or more steps between probes")
        return {"crossings_outside_share": round(missed, 4)}


def _dilation_px(timed, times) -> int:
    """The largest image motion between two probes (objects and scan), rounded up, plus one pixel."""
    from .image_motion import object_displacements, scan_displacements
    motions = [m for m in (object_displacements(timed, times), scan_displacements(timed, times)) if m is not None]
    worst = max((float(np.max(m)) for m in motions if len(m)), default=0.0)
    return min(MAX_DILATE_PX, int(math.ceil(worst)) + 1)


def checked_spp_changing(spp_changing) -> int:
    """``spp_changing`` validated (a whole number in [1, MAX_SPP]), before anything renders with it."""
    spp_changing = positive(spp_changing, "spp_changing", integer=True)
    if spp_changing > MAX_SPP:
        raise EventFieldError(f"spp_changing = {spp_changing}: allowed range is [1, {MAX_SPP}]")
    return spp_changing


def plan(timed, st, integ, spp_changing: int, probes: int = PROBES) -> SampleAllocation:
    """Probe renders at the render's ``spp``: which pixels change by more than CHANGE_OF_C x C."""
    import cv2

    from ..plugins import pixel_model
    spp_changing = checked_spp_changing(spp_changing)
    width, height = timed.film_size
    sensor, inner = timed.scene.sensors()[0], integ.inner
    times = np.linspace(st.t_start, st.t_start + st.duration, probes)
    every = mi.UInt32(np.arange(width * height, dtype=np.uint32))
    low, high = None, None
    for t in times:
        timed.set_time(float(t))
        frame = (render_pixels(timed.scene, sensor, inner, every, st.spp, st.seed, (width, height)) / st.spp).numpy()
        log = pixel_model.linlog_np(frame, integ.linlog_threshold)
        low, high = (log, log.copy()) if low is None else (np.minimum(low, log), np.maximum(high, log))
    timed.set_time(st.t_start)
    c = min(integ.threshold_on, integ.threshold_off)
    changing = ((high - low) > CHANGE_OF_C * c).reshape(height, width).astype(np.uint8)
    dilate = _dilation_px(timed, times)
    changing = cv2.dilate(changing, np.ones((2 * dilate + 1, 2 * dilate + 1), np.uint8)) > 0
    return SampleAllocation(changing, spp_changing, st.spp, probes, dilate)
