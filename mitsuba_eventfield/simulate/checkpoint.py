"""Long renders that lose nothing: checkpoints, and ``--resume`` from the last one.

A render to an HDF5 file with checkpoints on writes its events in segments under ``<output>.resume/`` (each
segment a complete DSEC file, closed at a checkpoint) and, at every checkpoint, the state that fixes all later
events: the step index, time and adaptive step, the pixel state (``EventIntegrator.get_state``: levels, event
counts, thresholds, drift, the noise generator, last emissions, the readout limiter's counters) and the
summary's counters. A checkpoint is committed by replacing ``checkpoint.json`` (atomic rename) after its segment
and its state file are complete, so whatever kills the process (Ctrl-C, SIGTERM, a crash, SIGKILL, power loss),
the folder holds one consistent checkpoint. ``render_events(..., resume=True)`` (``eventfield render ...
--resume``) checks that the render is the same (scene, stepping, sampling, pixel model), restores the state and
goes on; at the end the segments are merged into the output and the folder is removed. The output path never
holds a partial file. Resumed, the events are those of an uninterrupted render: the frames are rendered again
from the same seeds (a reused period is rendered again once), and the pixel state is restored exactly.
"""
from __future__ import annotations

import json
import os
import shutil
import time

import numpy as np

from ..atomic import try_lock
from ..errors import EventFieldError
from ..events.hdf5 import H5EventWriter
from ..events.io import format_of
from ..validate import positive

SUFFIX = ".resume"
MERGE_CHUNK = 1 << 20
KEPT = []                        # checkpoint folders of renders stopped in this process, kept to resume from
DEFAULT_EVERY_S = 60.0           # wall seconds between checkpoints when only resume is asked for
# metadata that differs between an interrupted render and its resumption without changing any event
VOLATILE = ("created_utc", "command", "render", "python")


def _resumable(folder: str) -> EventFieldError:
    return EventFieldError(f"{folder}: an interrupted render of this output can be resumed: add --resume "
                           "(resume=True), or remove the folder to start afresh")


def folder_of(output: str) -> str:
    return os.path.abspath(output) + SUFFIX


# The process rendering into a resume folder holds an exclusive lock on this file in it (``flock``: released
# by the kernel however the process ends). Without it a second process on the same output, told by the refusal
# below to add --resume, resumed from the live render's checkpoint, wrote segments under the names the first
# was writing and removed its state files: the first render then merged the wrong events and exited 0.
LOCK_FILE = "lock"


def _busy(folder: str, pid: str) -> EventFieldError:
    return EventFieldError(f"{folder}: another process (pid {pid}) is rendering this output now: wait for it to "
                           "end, or render to another path")


def _lock(folder: str):
    """The open lock file of ``folder``, locked by this process (None where there is no ``flock``: unguarded, as
    before); raises when another process holds it."""
    path = os.path.join(folder, LOCK_FILE)
    state, fd = try_lock(path, create=True)
    if state == "held":
        with open(path, "rb") as f:
            pid = f.read(32).decode("ascii", "replace").strip() or "unknown"
        raise _busy(folder, pid)
    if fd is not None:
        os.ftruncate(fd, 0)
        os.write(fd, str(os.getpid()).encode())
    return fd


def check_not_busy(folder: str) -> None:
    """Raise when a live process renders into ``folder`` (holds its lock)."""
    if os.path.isfile(os.path.join(folder, LOCK_FILE)):
        fd = _lock(folder)
        if fd is not None:
            os.close(fd)


def fingerprint(meta: dict) -> dict:
    """What must be equal for a resumed render to continue the interrupted one."""
    return json.loads(json.dumps({k: v for k, v in meta.items() if k not in VOLATILE}, default=str))


def _first_difference(saved: dict, now: dict, prefix: str = "") -> str | None:
    for key in sorted(set(saved) | set(now)):
        a, b = saved.get(key), now.get(key)
        if isinstance(a, dict) and isinstance(b, dict):
            found = _first_difference(a, b, f"{prefix}{key}.")
            if found:
                return found
        elif a != b:
            return f"{prefix}{key} was {json.dumps(a)[:80]}, now {json.dumps(b)[:80]}"
    return None


class SegmentWriter:
    """The chunk writer of a checkpointed render (behind ``BackgroundWriter``): events go to the current
    segment; :meth:`cut` closes it at a checkpoint; :meth:`close` merges every segment into the output."""

    def __init__(self, output: str, width: int, height: int, meta: dict, segments: list):
        self.output, self.width, self.height, self.meta = output, width, height, meta
        self.folder = folder_of(output)
        self.segments = list(segments)          # [{"file", "events", "until_us"}] of the closed segments
        self.current, self.until, self.count = None, None, 0

    def append(self, x, y, t, p, complete_until_us=None):
        if self.current is None:
            name = f"segment_{len(self.segments):05d}.h5"
            self.current = H5EventWriter(os.path.join(self.folder, name), self.width, self.height, self.meta)
        self.current.append(x, y, t, p, complete_until_us)
        self.count += len(t)
        if complete_until_us is not None:
            self.until = int(complete_until_us)

    def cut(self) -> None:
        """Close the current segment (published complete); the next append opens a new one."""
        if self.current is None:
            return
        self.current.close(end_us=self.until)
        self.segments.append({"file": os.path.basename(self.current.path), "events": self.count,
                              "until_us": self.until})
        self.current, self.count = None, 0

    def close(self, end_us=None, meta=None):
        self.cut()
        with H5EventWriter(self.output, self.width, self.height, {**self.meta, **(meta or {})}) as out:
            import h5py
            for seg in self.segments:
                with h5py.File(os.path.join(self.folder, seg["file"]), "r") as f:
                    ev, n = f["events"], seg["events"]
                    offset = int(f["t_offset"][()])        # a segment's t counts from its own t_offset
                    for i in range(0, n, MERGE_CHUNK):
                        j = min(n, i + MERGE_CHUNK)
                        out.append(ev["x"][i:j], ev["y"][i:j], ev["t"][i:j] + offset, ev["p"][i:j],
                                   seg["until_us"] if j == n else None)
                if n == 0:
                    out.append(np.empty(0), np.empty(0), np.empty(0, np.int64), np.empty(0), seg["until_us"])
            out.close(end_us=end_us, meta=meta)
        shutil.rmtree(self.folder, ignore_errors=True)

    def abort(self):
        if self.current is not None:
            self.current.abort()                # the events after the last checkpoint: redone on resume


class Checkpoints:
    """Saves the state of a render every ``every_s`` seconds of wall time, and restores it on resume."""

    def __init__(self, output: str, meta: dict, every_s: float, resume: bool):
        self.folder, self.every_s = folder_of(output), float(every_s)
        self.fingerprint, self.last_save, self.saved = fingerprint(meta), time.perf_counter(), None
        self.command = meta.get("command")
        path = os.path.join(self.folder, "checkpoint.json")
        check_not_busy(self.folder)
        if resume:
            if not os.path.isfile(path):       # a finished render removes its checkpoint: say which case this is
                if os.path.exists(output):
                    raise EventFieldError(f"{self.folder}: nothing to resume: no checkpoint, and {output} is there "
                                          "(that render finished); render without --resume to render it again")
                raise EventFieldError(f"{self.folder}: nothing to resume (no checkpoint here); render without --resume")
        elif os.path.exists(self.folder):
            raise _resumable(self.folder)
        os.makedirs(self.folder, exist_ok=True)
        self._lock_fd = _lock(self.folder)     # held until the render ends (``release``) or the process does
        if resume:
            try:                               # read under the lock: no other process changes it now
                with open(path) as f:
                    self.saved = json.load(f)
                diff = _first_difference(self.saved["fingerprint"], self.fingerprint)
            except BaseException:
                self.release()
                raise
            if diff:
                self.release()
                raise EventFieldError(f"{self.folder}: the checkpoint is of another render: {diff} (render "
                                      "without --resume after removing the folder, or resume with the same options)")

    def release(self) -> None:
        """Let go of the folder's lock (the render ended, or never started)."""
        fd, self._lock_fd = getattr(self, "_lock_fd", None), None
        if fd is not None:
            os.close(fd)

    @property
    def segments(self) -> list:
        return self.saved["segments"] if self.saved else []

    def abandon(self) -> None:
        """The render stopped: keep the folder if it holds a checkpoint to resume from (listed in ``KEPT``, which
        the command line's interrupt line names), else leave nothing."""
        if self.saved is None:
            shutil.rmtree(self.folder, ignore_errors=True)
        else:
            KEPT.append(self.folder)
        self.release()

    def due(self) -> bool:
        return time.perf_counter() - self.last_save >= self.every_s

    def save(self, loop, t: float, k: int, dt: float) -> None:
        """Commit a checkpoint: segment closed, pixel state and counters written, then the JSON replaced."""
        loop.sink.wait_for_writer()
        writer = loop.sink.writer.writer
        writer.cut()
        number = (self.saved or {}).get("number", -1) + 1
        state_file = f"state_{number:05d}.npz"
        tmp = os.path.join(self.folder, state_file + ".tmp")
        with open(tmp, "wb") as f:
            np.savez(f, **loop.integ.get_state(), **loop.limit.state())
        os.replace(tmp, os.path.join(self.folder, state_file))
        summary = {k_: v for k_, v in loop.summary.as_dict().items() if k_ not in ("output",)}
        # the timing-accuracy estimate so far; the frames behind it go into the state file (limit_*), from which a
        # resumed process estimates again as it goes on
        summary["timing_limit"] = (loop.limit.estimate() if loop.limit.active else None) or summary.get("timing_limit")
        record = {"number": number, "fingerprint": self.fingerprint, "command": self.command, "t": t, "k": k, "dt": dt,
                  "state": state_file, "segments": writer.segments, "summary": summary,
                  # the pixel counters where a warm-up ended (None: not yet), subtracted at the end
                  "counters_before": None if loop.counters_before is None else [int(v) for v in loop.counters_before],
                  "saved_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        tmp = os.path.join(self.folder, "checkpoint.json.tmp")
        with open(tmp, "w") as f:
            json.dump(record, f)
        os.replace(tmp, os.path.join(self.folder, "checkpoint.json"))
        if self.saved and self.saved["state"] != state_file:
            os.remove(os.path.join(self.folder, self.saved["state"]))
        self.saved, self.last_save = record, time.perf_counter()

    def restore(self, loop):
        """The saved (t, k, dt); the integrator and the summary put back as they were."""
        s = self.saved
        with np.load(os.path.join(self.folder, s["state"]), allow_pickle=False) as z:
            loop.integ.set_state({k: z[k] for k in z.files if not k.startswith("limit_")})
            loop.limit.restore({k: z[k] for k in z.files if k.startswith("limit_")})
        for key, value in s["summary"].items():
            if key == "notes":
                loop.summary.notes[:0] = [n for n in value if n not in loop.summary.notes]
            elif hasattr(loop.summary, key) and key not in ("wall_s", "rate_ev_per_s"):
                setattr(loop.summary, key, value)
        loop.summary.notes.append(f"resumed from checkpoint {s['number'] + 1} (step {s['k']}, "
                                  f"t = {s['t'] * 1e3:.6g} ms, saved {s['saved_utc']}): the stage times add both "
                                  "processes' work, the wall time is this process's")
        before = s.get("counters_before")
        loop.counters_before = None if before is None else tuple(before)
        return s["t"], s["k"], s["dt"]


def describe(folder: str) -> str:
    """What ``eventfield info`` says about a resume folder."""
    path = os.path.join(folder, "checkpoint.json")
    if not os.path.isfile(path):
        return f"{folder}: resume folder without a checkpoint (the render stopped before its first): remove it"
    with open(path) as f:
        s = json.load(f)
    fp, summary = s["fingerprint"], s["summary"]
    output = folder[:-len(SUFFIX)] if folder.endswith(SUFFIX) else folder
    return (f"{folder}: partial render of {output} (not an event file): {summary['events']} events up to "
            f"t = {s['t'] * 1e3:.6g} ms of {fp.get('duration_us', 0) / 1e3:g} ms, step {s['k']}, "
            f"{len(s['segments'])} segment(s), checkpoint {s['number'] + 1} saved {s['saved_utc']}; continue "
            f"with the same render command plus --resume: {s.get('command') or ''}".rstrip(": "))


def checkpoints_for(output, fmt, meta: dict, checkpoint_s: float | None, resume: bool) -> Checkpoints | None:
    """The render's checkpoints (None when neither asked for nor resumed); HDF5 output only."""
    if checkpoint_s is None and not resume:
        if output and os.path.isdir(folder_of(output)):     # starting afresh would orphan that work
            check_not_busy(folder_of(output))               # (or it is a live render's: not to be resumed)
            raise _resumable(folder_of(output))
        return None
    if not output or format_of(output, fmt) != "h5":
        raise EventFieldError(f"{output or 'output'}: checkpoints and --resume need an HDF5 output (.h5)")
    every = positive(checkpoint_s, "checkpoint_s") if checkpoint_s is not None else DEFAULT_EVERY_S
    return Checkpoints(output, meta, every, resume)
