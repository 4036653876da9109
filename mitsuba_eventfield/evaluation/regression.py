"""Regression images: tiny reference renders and event frames of the bundled scenes, for CI.

Each case renders one frame (linear radiance, stored as EXR) and one event frame (net ON - OFF count per
pixel, stored as an 8-bit PNG centred on 128) at a few dozen pixels. Renders use a fixed sampler seed, so on
one machine they are bit-identical; the tolerances only absorb floating-point differences between machines
(LLVM versions, CPUs), while any real change of the optics, the pixel or the scene moves the images far
beyond them (a test perturbs a sensor parameter on purpose and checks that the comparison fails).

    eventfield regression            # compare with tests/regression/ (exit 1 on a difference)
    eventfield regression --bless    # re-render the references on purpose, after a deliberate change

The references are a folder the caller names (the repository keeps them in tests/regression/); the scenes are
the bundled ones (``scene.bundled_scene``), so this works from an installed package too.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..scene import bundled_scene, load_scene
from ..simulate.render import render_events, render_frames
from ..validate import DEFAULT_SPP

# frame: mean relative difference and its 99th percentile; events: total count and per-pixel net count
FRAME_MEAN_TOL, FRAME_P99_TOL = 0.005, 0.05
EVENT_TOTAL_TOL, EVENT_PIXEL_TOL = 0.03, 0.05
# events rendered on another backend than the references' (CUDA against LLVM): its float32 sin/cos and ray
# intersections round differently, and a galvo scene's event counts are sensitive to the last bit. Measured on
# LLVM by shifting every instant of the render by 1 ns to 0.1 us (0.0001-0.009 deg of a 250 Hz scan phase, the
# size of such rounding): the galvo cases' mean per-pixel difference reaches 0.080 and the total 3.2 % (a pixel
# near a threshold level at the last instant flips by one event); the demo and kaleidoscope cases do not move.
# These tolerances are twice that floor; a real change stays far beyond them (the scan 10 % larger: 0.30).
# Frames move by less than 0.0002 mean and 0.002 p99 under the same shifts: their tolerances hold as they are.
EVENT_TOTAL_TOL_OTHER_BACKEND, EVENT_PIXEL_TOL_OTHER_BACKEND = 0.065, 0.16
REFERENCE_BACKEND = "llvm"     # references blessed before their backend was recorded in them were made on LLVM


@dataclass(frozen=True)
class Case:
    name: str
    scene: str                 # bundled scene (scene.bundled_scene)
    defines: tuple             # XML <default> values
    frame_time: float
    duration: float
    steps: int


CASES = (
    Case("demo", "demo/demo.xml", (("width", 48), ("height", 36)), 0.01, 0.01, 10),
    Case("galvo_static", "galvo_static/galvo_static.xml", (("width", 48), ("height", 36)), 0.0, 0.004, 16),
    Case("fan", "fan/fan.xml", (("width", 48), ("height", 36)), 0.002, 0.004, 16),
    Case("kaleidoscope_grid", "moving_grid/kaleidoscope.xml", (("views_px", 60),), 0.0, 0.004, 8),
)


def render_case(case: Case, scene_path: str | None = None, shift_s: float = 0.0, **extra_defines):
    """(frame (H, W) linear radiance, net event counts (H, W)) of a case; ``shift_s`` moves every instant
    (the tolerances' test: a stand-in for another backend's rounding of the scan angle)."""
    timed = load_scene(scene_path or bundled_scene(case.scene), **dict(case.defines, **extra_defines))
    frame = render_frames(timed, [case.frame_time + shift_s], spp=DEFAULT_SPP, log=False)[0]   # the references'
    events = render_events(timed, case.duration, steps=case.steps, t_start=shift_s)
    return frame.astype(np.float32), events.signed_counts()


def _paths(case: Case, directory: str):
    return os.path.join(directory, f"{case.name}_frame.exr"), os.path.join(directory, f"{case.name}_events.png")


def bless(directory: str, cases=CASES) -> list:
    from .._version import __version__
    from ..images import write_exr, write_png
    os.makedirs(directory, exist_ok=True)
    written = []
    for case in cases:
        frame, net = render_case(case)
        fpath, epath = _paths(case, directory)
        write_exr(fpath, {"Y": frame}, {"case": case.name, "package_version": __version__,
                                        "backend": _backend()})
        write_png(epath, np.clip(net + 128, 0, 255).astype(np.uint8))
        written += [fpath, epath]
    return written


def _backend() -> str:
    """The active variant's backend: "llvm", "cuda" or "scalar"."""
    import mitsuba as mi
    return mi.variant().split("_")[0]


def compare(case: Case, frame: np.ndarray, net: np.ndarray, directory: str,
            other_backend: bool | None = None) -> list:
    """Differences beyond tolerance, as readable strings (empty: matches the reference). ``other_backend``:
    whether the render ran on another backend than the references (None: the active variant's backend against
    the one recorded in the reference); events then get the wider ``*_OTHER_BACKEND`` tolerances."""
    import cv2

    from ..images import read_exr
    fpath, epath = _paths(case, directory)
    if not (os.path.exists(fpath) and os.path.exists(epath)):
        return [f"{case.name}: no reference in {directory} (run `eventfield regression --bless`)"]
    channels, meta = read_exr(fpath)
    ref = channels["Y"]
    if other_backend is None:
        other_backend = _backend() != (meta or {}).get("backend", REFERENCE_BACKEND)
    total_tol, pixel_tol = (EVENT_TOTAL_TOL_OTHER_BACKEND, EVENT_PIXEL_TOL_OTHER_BACKEND) if other_backend else \
        (EVENT_TOTAL_TOL, EVENT_PIXEL_TOL)
    ref_net = cv2.imread(epath, cv2.IMREAD_UNCHANGED).astype(np.int64) - 128
    problems = []
    if ref.shape != frame.shape:
        return [f"{case.name}: frame is {frame.shape[::-1]}, reference {ref.shape[::-1]}"]
    rel = np.abs(frame - ref) / (np.abs(ref) + 0.05 * max(float(ref.mean()), 1e-6))
    if rel.mean() > FRAME_MEAN_TOL or np.percentile(rel, 99) > FRAME_P99_TOL:
        problems.append(f"{case.name}: frame differs (mean relative {rel.mean():.4f} > {FRAME_MEAN_TOL} or p99 "
                        f"{np.percentile(rel, 99):.4f} > {FRAME_P99_TOL})")
    clipped = np.clip(net, -128, 127)
    total, ref_total = np.abs(clipped).sum(), np.abs(ref_net).sum()
    if abs(total - ref_total) > total_tol * max(ref_total, 1) or np.abs(clipped - ref_net).mean() > pixel_tol:
        problems.append(f"{case.name}: events differ (|net| {total} vs {ref_total}, tolerance {total_tol:.1%}; "
                        f"mean per-pixel difference {np.abs(clipped - ref_net).mean():.3f}, tolerance {pixel_tol})")
    return problems


def check_all(directory: str, cases=CASES) -> list:
    problems = []
    for case in cases:
        problems += compare(case, *render_case(case), directory=directory)
    return problems
