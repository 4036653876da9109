"""What a render did (``RenderSummary``: counts, timings split by stage, notes, where the events went) and the
metadata every event file carries (``run_metadata``: optics, pixel model, sampling, stepping, versions)."""
from __future__ import annotations

import platform
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from .. import backend
from .._version import __version__
from ..scene.timed import TimedScene


def pixel_counters(integ) -> tuple:
    """(readout drops, refractory drops, noise events) the integrator has counted so far."""
    return integ.readout_dropped(), integ.refractory_dropped, integ.noise_events


@dataclass
class RenderSummary:
    """What a render did: counts, timings split by stage, and where the events went."""
    events: int = 0
    on: int = 0
    off: int = 0
    duration_s: float = 0.0
    steps: int = 0
    rejected_steps: int = 0
    reused_steps: int = 0       # steps whose frame came from the one-period cache
    copied_steps: int = 0       # steps whose events were copied from the previous period (state repeated)
    dropped_readout: int = 0    # events the readout cap dropped
    dropped_refractory: int = 0  # crossings suppressed by the refractory period
    noise_events: int = 0       # shot-noise events emitted
    wall_s: float = 0.0
    render_s: float = 0.0
    events_s: float = 0.0
    motion_s: float = 0.0
    write_s: float = 0.0        # the render thread's time handing events over (device-to-host copy, queue)
    writer_busy_s: float = 0.0  # the background writer's time compressing and writing (overlaps the render)
    writer_copy_s: float = 0.0  # its copier's time copying chunks out of Dr.Jit's memory (a GPU's; overlaps too)
    writer_wait_s: float = 0.0  # the render thread's time blocked on the writer: > 0 means the disk set the pace
    writer_tail_s: float = 0.0  # the render thread's drains of the queue, checkpoints and the end (not a pace)
    image_motion_px_per_step: dict | None = None  # scan and objects, pixels per step (uniform stepping)
    timing_limit: dict | None = None            # what limits timestamp accuracy, with both estimates (us)
    sample_allocation: dict | None = None       # samples where they matter: the split and its check
    static_pixels: dict | None = None           # pixels rendered once a scan period: the split and its check
    width: int = 0
    height: int = 0
    output: str | None = None
    notes: list = field(default_factory=list)

    def count(self, p) -> None:
        """Add one batch of events (their polarities: NumPy, or an array of the active Dr.Jit backend, counted
        there so that one number crosses, not a byte an event) to the counts."""
        if isinstance(p, np.ndarray):
            n, n_on = len(p), int(np.count_nonzero(p > 0))
        else:
            import drjit as dr
            n = dr.width(p)
            n_on = int(dr.count(p > 0)[0]) if n else 0
        self.events += n
        self.on += n_on
        self.off += n - n_on

    def take_pixel_counters(self, integ, before=(0, 0, 0)) -> None:
        """The pixel model's drop and noise counters from the integrator, less ``before`` (``pixel_counters``
        at a warm-up's end), and the readout cap's note: a render and a conversion both, after the sink's drain
        (its events are counted by then); the converter used to record 0 for each."""
        now = pixel_counters(integ)
        self.dropped_readout, self.dropped_refractory, self.noise_events = (a - b for a, b in zip(now, before))
        if self.dropped_readout:
            total = self.events + self.dropped_readout
            self.notes.append(f"readout cap dropped {self.dropped_readout} of {total} events "
                              f"({100 * self.dropped_readout / total:.1f}%)")

    @property
    def rate(self) -> float:
        return self.events / self.duration_s if self.duration_s > 0 else 0.0

    def as_dict(self) -> dict:
        d = {k: getattr(self, k) for k in self.__dataclass_fields__}
        d["rate_ev_per_s"] = self.rate
        return d

    def format(self) -> str:
        overhead = self.events_s + self.motion_s + self.write_s
        lines = [f"{self.events} events ({self.on} ON, {self.off} OFF) in {self.duration_s * 1e3:.3f} ms simulated "
                 f"on {self.width}x{self.height}: {self.rate:.4g} ev/s"]
        if self.render_s:
            lines.append(f"{self.steps} steps ({self.rejected_steps} re-rendered shorter), wall {self.wall_s:.2f} s: "
                         f"render {self.render_s:.2f} s, events {self.events_s:.2f} s, motion {self.motion_s:.2f} s, "
                         f"write {self.write_s:.2f} s (overhead {100 * overhead / self.render_s:.1f}% of render)")
        else:                                            # frames given, not rendered (events_from_frames)
            lines.append(f"{self.steps} frame steps, wall {self.wall_s:.2f} s: events {self.events_s:.2f} s, "
                         f"write {self.write_s:.2f} s")
        if self.writer_busy_s:
            pace = "the disk writer set the pace" if self.writer_wait_s > 0.05 * self.wall_s else "it kept up"
            copier = f" (and {self.writer_copy_s:.2f} s copying chunks from the GPU on another)" \
                if self.writer_copy_s else ""
            work = "render" if self.render_s else "conversion"
            drains = "checkpoints, the last chunks" if self.render_s else "the last chunks"
            lines.append(f"file writer: {self.writer_busy_s:.2f} s on its own thread{copier}, the {work} waited "
                         f"{self.writer_wait_s:.2f} s for it ({pace}), and {self.writer_tail_s:.2f} s for its queue "
                         f"to drain ({drains})")
        if self.output:
            lines.append(f"wrote {self.output}")
        lines += self.notes
        return "\n".join(lines)


def sensor_optics(timed: TimedScene) -> dict:
    """The scene's optics as outputs record them (``meta["optics"]`` of an event file, an EXR frame's
    metadata): a light-field sensor's own ``optics_metadata``, else a conventional camera with its first-level
    parameters worth recording (e.g. ``x_fov``)."""
    sensor = timed.sensor
    optics = sensor.optics_metadata() if hasattr(sensor, "optics_metadata") else {"design": "conventional camera",
                                                                                   "sensor": type(sensor).__name__}
    for key in timed.params.keys():  # first-level sensor parameters worth recording (e.g. sensor.x_fov)
        name = key.split(".")[-1]
        if key.count(".") == 1 and name in ("x_fov", "focus_distance", "aperture_radius") \
                and key.startswith(_sensor_id(timed)):
            optics[name] = float(timed.params[key][0])
    return optics


def run_metadata(timed: TimedScene, integ, **run) -> dict:
    optics = sensor_optics(timed)
    return {"package": "mitsuba-eventfield", "package_version": __version__, "mitsuba_version": backend.mi.__version__,
            "drjit_version": backend.dr.__version__, "variant": backend.mi.variant(), "python": platform.python_version(),
            "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "width": timed.film_size[0],
            "height": timed.film_size[1], "duration_us": int(round(run["duration"] * 1e6)),
            "t_start_us": int(round(run["t_start"] * 1e6)), "optics": optics,
            "pixel_model": integ.pixel_model_metadata(), "spp": run["spp"], "seed": run["seed"],
            "seed_mode": run["seed_mode"], "sampler": _sampler(timed), "stepping": run["stepping"],
            "sample_allocation": run.get("sample_allocation"),
            "scene": timed.describe(),
            "command": " ".join(sys.argv) if sys.argv and sys.argv[0] else None}


def _sampler(timed: TimedScene) -> dict:
    """The sensor's sampler and why it is the one (the scene's own, chosen, or the default: scene/sampler.py)."""
    sampler = timed.sensor.sampler()
    return {"type": sampler.class_name(), "chosen_by": timed.sampler_choice}


def _sensor_id(timed: TimedScene) -> str:
    sid = timed.sensor.id()
    return sid + "." if sid else "sensor."


# seconds between progress-bar updates written to a file or pipe: a terminal redraws one line, but a log keeps
# every update (a 20 ms fan render at --auto left 3,000 of them, 1.5 MB, in a captured stderr)
LOG_PROGRESS_INTERVAL_S = 10.0


def progress_bar(iterable=None, **kw):
    """tqdm on stderr, for renders, conversions and sweeps alike: redrawn ten times a second on a terminal, once
    every ``LOG_PROGRESS_INTERVAL_S`` into a log."""
    from tqdm import tqdm
    tty = hasattr(sys.stderr, "isatty") and sys.stderr.isatty()
    return tqdm(iterable, file=sys.stderr, mininterval=0.1 if tty else LOG_PROGRESS_INTERVAL_S, **kw)
