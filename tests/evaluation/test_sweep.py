"""Sweeps: local process pool and a local Dask cluster agree; an interrupted sweep resumes."""
import csv
import os

import pytest
from conftest import ROOT, needs

import mitsuba_eventfield as ef

GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")
OVER = {"xml.frequency": [250, 500], "render.threshold": [0.2, 0.3]}
BASE = {"xml.width": 32, "xml.height": 24, "render.duration": 0.004, "render.steps": 16}
DETERMINISTIC = ("xml.frequency", "render.threshold", "events", "on_fraction", "dropped_readout", "key")


def _strip(table):
    return [{k: r[k] for k in DETERMINISTIC} for r in table.rows]


def test_local_and_dask_give_identical_tables(tmp_path):
    needs("distributed", "sweep")
    from distributed import Client, LocalCluster
    local = ef.sweep(GALVO, OVER, BASE, processes=2)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        remote = ef.sweep(GALVO, OVER, BASE, client=client)
    assert len(local.rows) == 4 and _strip(local) == _strip(remote)
    events = {(r["xml.frequency"], r["render.threshold"]): r["events"] for r in local.rows}
    assert events[(250, 0.2)] > events[(250, 0.3)] > 0          # a higher threshold fires fewer events
    # twice the scan periods in the same time: more events (not quite 2x: 8 steps per period lose reversals)
    assert 1.5 * events[(250, 0.2)] < events[(500, 0.2)] < 2.0 * events[(250, 0.2)]


def test_interrupted_sweep_resumes_and_exports(tmp_path):
    out = str(tmp_path / "sweep")
    first = ef.sweep(GALVO, {"xml.frequency": [250], "render.threshold": [0.2, 0.3]}, BASE, out_dir=out)
    assert [r["resumed"] for r in first.rows] == [False, False]
    full = ef.sweep(GALVO, OVER, BASE, out_dir=out, keep_events=True)
    resumed = {(r["xml.frequency"], r["render.threshold"]): r["resumed"] for r in full.rows}
    assert resumed == {(250, 0.2): True, (250, 0.3): True, (500, 0.2): False, (500, 0.3): False}
    assert os.path.exists(next(r["events_path"] for r in full.rows if not r["resumed"]))
    full.to_csv(str(tmp_path / "t.csv"))
    with open(tmp_path / "t.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["events"]) for r in rows] == full.column("events")
    full.to_parquet(str(tmp_path / "t.parquet"))
    import pyarrow.parquet as pq
    assert pq.read_table(str(tmp_path / "t.parquet")).column("events").to_pylist() == full.column("events")


def test_bad_sweep_parameters():
    with pytest.raises(ef.EventFieldError, match="must start with one of xml., render., pixel."):
        ef.sweep(GALVO, {"frequency": [1, 2]})
    with pytest.raises(ef.EventFieldError, match="non-empty list"):
        ef.sweep(GALVO, {"xml.frequency": []})
    with pytest.raises(ef.EventFieldError, match="not a scene file"):
        ef.sweep("nowhere.xml", {"xml.frequency": [1]})
