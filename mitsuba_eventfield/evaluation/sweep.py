"""Optics and pixel sweeps: every combination of parameter values, rendered in parallel, as one table.

    table = ef.sweep("scenes/galvo_static/galvo_static.xml",
                     over={"xml.frequency": [125, 250, 500], "pixel.threshold_on": [0.15, 0.2]},
                     base={"render.duration": 0.004, "render.steps": 32}, out_dir="out/sweep")
    table.to_csv("out/sweep/table.csv")

Parameter names say where a value goes: ``xml.<name>`` fills a ``<default name=...>`` of the scene XML,
``render.<name>`` is an argument of :func:`render_events` (duration, steps, spp, seed, threshold, preset, ...),
``pixel.<name>`` a pixel-model parameter. Each point runs in a fresh worker process (spawned, so Dr.Jit state
never forks; in a script, call ``sweep`` under ``if __name__ == "__main__":``, as each worker imports the
script again): locally in a process pool, or on a Dask cluster when ``client`` is given. With ``out_dir``
every finished point is kept (``point-<hash>.json``, plus its events when ``keep_events``), and a rerun skips
them: an interrupted sweep resumes where it stopped. The hash covers the scene's path, the point's
parameters and ``inputs_digest`` (the scene's files), so an edited scene is rendered again; a point whose
events are asked for (``keep_events``) and were not kept runs again too.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import os
import re
import threading
import time
from dataclasses import dataclass, field

from .._version import __version__
from ..errors import EventFieldError
from ..scene.timed import load_scene
from ..simulate.render import render_events

METRICS = ("events", "rate_ev_s", "on_fraction", "dropped_readout", "wall_s", "render_s")
_PREFIXES = ("xml.", "render.", "pixel.")
# one point at a time in a process: Mitsuba's scene loading and its file resolver are process-wide, and a Dask
# worker with two threads (Dask's default layout) failed on a texture's I/O or crashed Dr.Jit, loading two
# scenes at once (plain Mitsuba too); processes, not threads, give a sweep its parallelism
_ONE_POINT_AT_A_TIME = threading.Lock()


@dataclass
class SweepTable:
    rows: list = field(default_factory=list)

    @property
    def columns(self) -> list:
        cols = []
        for r in self.rows:
            cols += [k for k in r if k not in cols]
        return cols

    def column(self, name) -> list:
        return [r.get(name) for r in self.rows]

    def to_csv(self, path: str) -> str:
        import csv

        from ..atomic import atomic_output
        with atomic_output(path, "sweep table") as tmp, open(tmp, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=self.columns)
            w.writeheader()
            w.writerows(self.rows)
        return path

    def to_parquet(self, path: str) -> str:
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError:
            raise EventFieldError("Parquet export needs pyarrow (pip install pyarrow); CSV needs nothing") from None
        from ..atomic import atomic_output
        with atomic_output(path, "sweep table") as tmp:
            pq.write_table(pa.Table.from_pylist(self.rows), tmp)
        return path


def grid(over: dict) -> list:
    if not isinstance(over, dict) or not over:
        raise EventFieldError(f"sweep: over = {over!r}: give a dict of parameter -> list of values, e.g. "
                              "{'render.spp': [4, 16]}")
    for name, values in over.items():
        if not name.startswith(_PREFIXES):
            raise EventFieldError(f"sweep parameter {name!r}: must start with one of {', '.join(_PREFIXES)}")
        if isinstance(values, (str, bytes, dict, set, frozenset)) or not hasattr(values, "__iter__"):
            raise EventFieldError(f"sweep parameter {name!r} = {values!r}: give a non-empty list of values (a "
                                  "list, tuple, range or 1-D NumPy array)")
    # np.linspace(...) and range(...) are how sweeps are written: any 1-D sequence, its NumPy numbers as Python's
    columns = {name: [plain(v) for v in values] if getattr(values, "ndim", 1) == 1 else []
               for name, values in over.items()}
    for name, values in columns.items():
        if not values:
            raise EventFieldError(f"sweep parameter {name!r}: give a non-empty list of values (a list, tuple, "
                                  "range or 1-D NumPy array)")
        twice = [v for i, v in enumerate(values) if v in values[:i]]
        if twice:                # (4 and 4.0 too) the same render twice, one row each
            raise EventFieldError(f"sweep parameter {name!r}: {twice[0]!r} given more than once; give each value once")
    names = list(over)
    return [dict(zip(names, combo)) for combo in itertools.product(*(columns[n] for n in names))]


# load_scene's own keyword arguments: an ``xml.`` parameter of these names would not reach the XML
RESERVED_XML = ("motion", "variant", "color", "sampler")
# render_events' arguments a sweep sets itself (the scene, where a kept point's events go, the pixel.* dict)
RESERVED_RENDER = ("scene", "output", "pixel")


def plain(value):
    """A NumPy scalar as the Python number it holds (other values as they are): a point's values are keyed,
    saved as JSON and read back on resume, where ``np.int64(250)`` came back as the string '250'."""
    item = getattr(value, "item", None)
    return item() if callable(item) and getattr(value, "ndim", None) == 0 else value


def inputs_digest(scene: str) -> str:
    """SHA-256 of what a point's render reads besides its parameters: the scene XML, the motion file that
    ``load_scene`` takes next to it (``<scene>.motion.toml``), every file the XML names (meshes, textures,
    includes; relative to the XML's folder), and the package's version. A resumed point
    whose inputs changed is rendered again instead of returning the old numbers."""
    folder, h = os.path.dirname(scene), hashlib.sha256(__version__.encode())
    with open(scene, "rb") as f:
        xml = f.read()
    # files: <string name="filename" value="mesh.ply"/>, <include filename="..."/>; a value naming no file is
    # not one (a "$name" default is resolved by Mitsuba, and its value is in the point's parameters)
    names = [m.decode(errors="replace") for m in re.findall(rb'(?:value|filename)\s*=\s*"([^"$]+)"', xml)]
    for path in [scene, os.path.splitext(scene)[0] + ".motion.toml", *(os.path.join(folder, n) for n in names)]:
        if os.path.isfile(path):
            h.update(path.encode())
            with open(path, "rb") as f:
                h.update(hashlib.sha256(f.read()).digest())
    return h.hexdigest()


def point_key(scene: str, point: dict, inputs: str = "") -> str:
    """The point's file name key: the scene's path, its parameters and its inputs' digest (``inputs_digest``)."""
    blob = json.dumps({"scene": os.path.abspath(scene), "point": point, "inputs": inputs}, sort_keys=True,
                      default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def run_point(scene: str, point: dict, out_dir: str | None = None, keep_events: bool = False,
              inputs: str = "", quiet: bool = False) -> dict:
    """Render one point (in whatever process this runs) and return its row: parameters, metrics, outputs.
    ``inputs``: the scene's ``inputs_digest``, part of the point's key. ``quiet``: Mitsuba's quiet log here too
    (the sweeping process had it: a spawned worker starts with Mitsuba's own, which printed the monochrome
    film's warning once a point)."""
    if quiet:
        from ..backend import quiet_mitsuba_log
        quiet_mitsuba_log()
    xml = {k[4:]: v for k, v in point.items() if k.startswith("xml.")}
    render = {k[7:]: v for k, v in point.items() if k.startswith("render.")}
    pixel = {k[6:]: v for k, v in point.items() if k.startswith("pixel.")}
    t0 = time.perf_counter()
    key = point_key(scene, point, inputs)
    out = os.path.join(out_dir, f"point-{key}.h5") if (out_dir and keep_events) else None
    duration = render.pop("duration", None)
    try:
        with _ONE_POINT_AT_A_TIME:
            result = render_events(load_scene(scene, **xml), duration, pixel=pixel or None, output=out, **render)
    except EventFieldError as e:     # which point: an xml.* or render.* refusal named only its value
        raise EventFieldError(f"sweep point {', '.join(f'{k}={v}' for k, v in point.items())}: {e}") from None
    r = result.meta["render"] if hasattr(result, "meta") else result.as_dict()
    row = dict(point, key=key, events=r["events"], rate_ev_s=r["rate_ev_per_s"],
               on_fraction=r["on"] / r["events"] if r["events"] else 0.0, dropped_readout=r["dropped_readout"],
               wall_s=time.perf_counter() - t0, render_s=r["render_s"], events_path=out)
    if out_dir:
        from ..atomic import atomic_output
        with atomic_output(os.path.join(out_dir, f"point-{key}.json"), "sweep point") as tmp, open(tmp, "w") as f:
            json.dump(dict(row, inputs_sha256=inputs), f, default=str)
    return row


def sweep(scene: str, over: dict, base: dict | None = None, out_dir: str | None = None, client=None,
          processes: int = 2, keep_events: bool = False, progress: bool = False) -> SweepTable:
    """Run every combination of ``over`` (plus the fixed ``base`` values); see the module docstring."""
    if not isinstance(scene, (str, os.PathLike)) or not os.path.isfile(scene):
        raise EventFieldError(f"sweep: {scene!r} is not a scene file (workers load the scene by path)")
    scene = os.path.abspath(os.fspath(scene))
    if base is not None and (not isinstance(base, dict) or any(not str(k).startswith(_PREFIXES) for k in base)):
        raise EventFieldError(f"sweep: base = {base!r}: give a dict whose keys start with {', '.join(_PREFIXES)}")
    if isinstance(processes, bool) or not isinstance(processes, int) or processes < 1:
        raise EventFieldError(f"sweep: processes = {processes!r}: allowed range is whole numbers >= 1")
    if client is not None and not all(callable(getattr(client, m, None)) for m in ("map", "gather")):
        raise EventFieldError(f"sweep: client = {client!r}: expected a dask.distributed Client (None: local processes)")
    both = sorted(set(base or {}) & set(over if isinstance(over, dict) else {}))
    if both:                     # over's values replaced base's without a word
        raise EventFieldError(f"sweep: {', '.join(both)} in both over and base: sweep it or fix it, not both")
    points = [{k: plain(v) for k, v in dict(base or {}, **p).items()} for p in grid(over)]
    check_names(points[0], scene)
    for point in points:          # every point's pixel values too (a bad one failed in a worker, after spawning)
        check_pixel(point)
    inputs = inputs_digest(scene)
    keys = [point_key(scene, p, inputs) for p in points]
    done = {}
    if out_dir:
        os.makedirs(out_dir, exist_ok=True)
        for key in keys:
            row = _done_row(out_dir, key, keep_events)
            if row is not None:
                done[key] = row
    todo = [p for p, key in zip(points, keys) if key not in done]
    results = {}
    from ..backend import mitsuba_log_is_quiet
    quiet = mitsuba_log_is_quiet()                # the workers follow this process's choice
    if todo:
        if client is not None:                                  # Dask distributed
            futures = client.map(run_point, [scene] * len(todo), todo, [out_dir] * len(todo),
                                 [keep_events] * len(todo), [inputs] * len(todo), [quiet] * len(todo), pure=False)
            rows = client.gather(futures)
        else:
            rows = _local(scene, todo, out_dir, keep_events, inputs, quiet, processes, progress)
        results = {r["key"]: dict(r, resumed=False) for r in rows}
    results.update(done)
    return SweepTable([results[key] for key in keys])


def _worker_start() -> None:
    """A local sweep worker: Ctrl-C is the sweeping process's to handle (a terminal sends it to the whole
    group, and workers interrupted mid-point were replaced by the pool, which went on with the queue), and the
    worker ends when that process does (SIGTERM to it left the workers idle for ever: Linux's parent-death
    signal, where there is one)."""
    import multiprocessing
    import signal
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))        # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
    # a parent that died while this worker was still starting (importing for seconds) sent it no signal, and
    # the orphan held the sweep's output pipes open (seen once in the full suite): checked after the prctl
    parent = multiprocessing.parent_process()
    if parent is not None and os.getppid() != parent.pid:
        os._exit(1)


def _local(scene, todo, out_dir, keep_events, inputs, quiet, processes, progress) -> list:
    """The points ``todo`` in a pool of spawned processes; their rows. Interrupted (Ctrl-C, or SIGTERM turned
    into an exception), the points not started are cancelled and the workers ended at once: the pool's own
    exit waited for the whole queue (a second Ctrl-C then hung it). What finished is kept for a resume."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    pool = ProcessPoolExecutor(max_workers=max(1, processes), mp_context=multiprocessing.get_context("spawn"),
                               initializer=_worker_start)
    try:
        futs = [pool.submit(run_point, scene, p, out_dir, keep_events, inputs, quiet) for p in todo]
        if progress:
            from ..simulate.summary import progress_bar
            for _ in progress_bar(futs, desc="sweep", unit="point"):
                _.exception()
        rows = [f.result() for f in futs if f.exception() is None]
    except BaseException:
        workers = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for w in workers:                       # a point in flight: its partial file is removed on the next run
            w.terminate()
        for w in workers:
            w.join(timeout=10)
        raise
    pool.shutdown(wait=True)
    failed = [(p, f.exception()) for p, f in zip(todo, futs) if f.exception() is not None]
    if failed:       # every other point ran (and is kept in out_dir): one line for the first refusal
        raise _failed_points(failed, len(todo), out_dir)
    return rows


def _failed_points(failed: list, total: int, out_dir) -> EventFieldError:
    """One line for a sweep whose points ``failed`` ((point, exception), of ``total``): the first point's
    parameters and why, and where the others are (a resumed sweep renders only what is missing)."""
    kept = f"; the other {total - len(failed)} are kept in {out_dir} (run again to resume)" if out_dir else ""
    message = " ".join(str(failed[0][1]).split()) or type(failed[0][1]).__name__    # run_point names its point
    return EventFieldError(f"{message} ({len(failed)} of {total} points failed{kept})")


def _done_row(out_dir: str, key: str, keep_events: bool) -> dict | None:
    """The kept row of a finished point, or None where it must run (again): none kept, or events wanted
    (``keep_events``) that the earlier run did not keep."""
    path = os.path.join(out_dir, f"point-{key}.json")
    if not os.path.exists(path):
        return None
    with open(path) as f:
        row = json.load(f)
    row.pop("inputs_sha256", None)
    if keep_events and not (row.get("events_path") and os.path.isfile(row["events_path"])):
        return None
    return dict(row, resumed=True)


def check_pixel(point: dict) -> None:
    """The point's ``pixel.`` values (with its ``render.preset``) as the pixel model checks them, refused in one
    line naming the point's parameters. Thresholds the point does not set come from the scene (unknown until a
    worker loads it): the largest allowed stands in for them, so that only what no scene could make valid
    (a spread beyond half of it) is refused here."""
    from ..plugins import pixel_model
    from ..validate import MAX_THRESHOLD
    pixel = {k[6:]: v for k, v in point.items() if k.startswith("pixel.")}
    if pixel:
        where = "sweep point " + ", ".join(f"{k}={v}" for k, v in point.items() if k.startswith("pixel."))
        preset, overrides = pixel_model.preset_and_overrides(point.get("render.preset"), pixel, where)
        for side in ("threshold_on", "threshold_off"):
            if overrides.get(side) is None:          # None, as absent: the scene's
                overrides[side] = MAX_THRESHOLD
        pixel_model.pixel_config(preset or "ideal", where, **overrides)


def check_names(point: dict, scene: str | None = None) -> None:
    """Refuse, before any worker starts, parameter names that cannot reach their target: an ``xml.`` name
    that is one of load_scene's own arguments or that the scene file does not declare (a typo failed in every
    worker, after spawning), a ``render.`` name render_events does not take or the sweep sets itself."""
    import inspect

    from ..scene.timed import settable_parameters
    takes = set(inspect.signature(render_events).parameters) - set(RESERVED_RENDER)
    declared = None
    if scene is not None and os.path.isfile(scene):
        with open(scene, encoding="utf-8", errors="replace") as f:
            declared = settable_parameters(f.read())
    for name in point:
        kind, _, arg = name.partition(".")
        if kind == "xml" and arg in RESERVED_XML:
            raise EventFieldError(f"sweep parameter {name!r}: {arg!r} is an argument of load_scene, not a scene "
                                  f"default; xml.* names may not be {', '.join(RESERVED_XML)}")
        if kind == "xml" and declared is not None and arg not in declared:
            raise EventFieldError(f"sweep parameter {name!r}: {scene} declares no <default name={arg!r}> and uses "
                                  f"no ${arg}; it takes {', '.join(declared) or 'none'}")
        if kind == "render" and arg not in takes:
            raise EventFieldError(f"sweep parameter {name!r}: render_events takes no {arg!r} here; allowed: "
                                  f"{', '.join(sorted(takes))}")
