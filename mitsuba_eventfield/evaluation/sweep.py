"""Optics and pixel sweeps: every combination of parameter values, rendered in parallel, as one table.

    table = ef.sweep("scenes/galvo_static/galvo_static.xml",
                     over={"xml.frequency": [125, 250, 500], "pixel.threshold_on": [0.15, 0.2]},
                     base={"render.duration": 0.004, "render.steps": 32}, out_dir="out/sweep")
    table.to_csv("out/sweep/table.csv")

Parameter names say where a value goes: ``xml.<name>`` fills a ``<default name=...>`` of the scene XML,
``render.<name>`` is an argument of :func:`render_events` (duration, steps, spp, seed, threshold, preset, ...),
``pixel.<name>`` a pixel-model parameter. Each point runs in a fresh worker process (spawned, so Dr.Jit state
never forks): locally in a process pool, or on a Dask cluster when ``client`` is given. With ``out_dir`` every
finished point is kept (``point-<hash>.json``, plus its events when ``keep_events``), and a rerun skips them:
an interrupted sweep resumes where it stopped.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import os
import time
from dataclasses import dataclass, field

from ..errors import EventFieldError
from ..scene.timed import load_scene
from ..simulate.render import render_events

METRICS = ("events", "rate_ev_s", "on_fraction", "dropped_readout", "wall_s", "render_s")
_PREFIXES = ("xml.", "render.", "pixel.")


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
        if not isinstance(values, (list, tuple)) or not values:
            raise EventFieldError(f"sweep parameter {name!r}: give a non-empty list of values")
    names = list(over)
    return [dict(zip(names, combo)) for combo in itertools.product(*(over[n] for n in names))]


def point_key(scene: str, point: dict) -> str:
    blob = json.dumps({"scene": os.path.abspath(scene), "point": point}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def run_point(scene: str, point: dict, out_dir: str | None = None, keep_events: bool = False) -> dict:
    """Render one point (in whatever process this runs) and return its row: parameters, metrics, outputs."""
    xml = {k[4:]: v for k, v in point.items() if k.startswith("xml.")}
    render = {k[7:]: v for k, v in point.items() if k.startswith("render.")}
    pixel = {k[6:]: v for k, v in point.items() if k.startswith("pixel.")}
    t0 = time.perf_counter()
    timed = load_scene(scene, **xml)
    key = point_key(scene, point)
    out = os.path.join(out_dir, f"point-{key}.h5") if (out_dir and keep_events) else None
    duration = render.pop("duration", None)
    result = render_events(timed, duration, pixel=pixel or None, output=out, **render)
    r = result.meta["render"] if hasattr(result, "meta") else result.as_dict()
    row = dict(point, key=key, events=r["events"], rate_ev_s=r["rate_ev_per_s"],
               on_fraction=r["on"] / r["events"] if r["events"] else 0.0, dropped_readout=r["dropped_readout"],
               wall_s=time.perf_counter() - t0, render_s=r["render_s"], events_path=out)
    if out_dir:
        from ..atomic import atomic_output
        with atomic_output(os.path.join(out_dir, f"point-{key}.json"), "sweep point") as tmp, open(tmp, "w") as f:
            json.dump(row, f, default=str)
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
    points = [dict(base or {}, **p) for p in grid(over)]
    done, todo = {}, []
    if out_dir:
        os.makedirs(out_dir, exist_ok=True)
        for p in points:
            path = os.path.join(out_dir, f"point-{point_key(scene, p)}.json")
            if os.path.exists(path):
                with open(path) as f:
                    done[point_key(scene, p)] = dict(json.load(f), resumed=True)
    todo = [p for p in points if point_key(scene, p) not in done]
    results = {}
    if todo:
        if client is not None:                                  # Dask distributed
            futures = client.map(run_point, [scene] * len(todo), todo, [out_dir] * len(todo),
                                 [keep_events] * len(todo), pure=False)
            rows = client.gather(futures)
        else:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor
            with ProcessPoolExecutor(max_workers=max(1, processes),
                                     mp_context=multiprocessing.get_context("spawn")) as pool:
                futs = [pool.submit(run_point, scene, p, out_dir, keep_events) for p in todo]
                if progress:
                    from tqdm import tqdm
                    for _ in tqdm(futs, desc="sweep", unit="point"):
                        _.result()
                rows = [f.result() for f in futs]
        results = {r["key"]: dict(r, resumed=False) for r in rows}
    results.update(done)
    return SweepTable([results[point_key(scene, p)] for p in points])
