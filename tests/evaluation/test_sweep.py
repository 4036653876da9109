"""Sweeps: local process pool and a local Dask cluster agree; an interrupted sweep resumes."""
import csv
import os
import shutil

import numpy as np
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
    """A rerun skips the points done, but not one whose events are now wanted and were not kept; NumPy values
    come back as the numbers they were (they came back as strings, and Parquet refused the mixed column)."""
    out = str(tmp_path / "sweep")
    first = ef.sweep(GALVO, {"xml.frequency": [np.int64(250)], "render.threshold": [0.2, 0.3]}, BASE, out_dir=out)
    assert [r["resumed"] for r in first.rows] == [False, False]
    again = ef.sweep(GALVO, {"xml.frequency": [250], "render.threshold": list(np.array([0.2, 0.3]))}, BASE,
                     out_dir=out)
    assert [r["resumed"] for r in again.rows] == [True, True]
    assert _strip(again) == _strip(first) and all(type(r["xml.frequency"]) is int for r in again.rows)
    full = ef.sweep(GALVO, OVER, BASE, out_dir=out, keep_events=True)      # (250, *): events not kept before
    assert [r["resumed"] for r in full.rows] == [False] * 4
    assert all(os.path.exists(r["events_path"]) for r in full.rows)
    assert {r["key"]: r["events"] for r in full.rows if r["xml.frequency"] == 250} == \
        {r["key"]: r["events"] for r in first.rows}
    kept = ef.sweep(GALVO, OVER, BASE, out_dir=out, keep_events=True)
    assert [r["resumed"] for r in kept.rows] == [True] * 4 and _strip(kept) == _strip(full)
    kept.to_csv(str(tmp_path / "t.csv"))
    with open(tmp_path / "t.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["events"]) for r in rows] == kept.column("events")
    kept.to_parquet(str(tmp_path / "t.parquet"))
    import pyarrow.parquet as pq
    table = pq.read_table(str(tmp_path / "t.parquet"))
    assert table.column("events").to_pylist() == kept.column("events")
    assert table.column("xml.frequency").to_pylist() == [250, 250, 500, 500]


def test_resume_renders_again_when_the_scene_or_its_files_changed(tmp_path):
    """A point's key holds a digest of the scene XML, its motion file and the files it names: editing the
    scene's threshold or replacing its texture renders the point again (it returned the old count, marked
    resumed)."""
    scene_dir = tmp_path / "scene"
    shutil.copytree(os.path.dirname(GALVO), scene_dir)
    scene = str(scene_dir / os.path.basename(GALVO))
    over, out = {"xml.frequency": [250]}, str(tmp_path / "sweep")
    before = ef.sweep(scene, over, BASE, out_dir=out).rows[0]
    text = open(scene).read()
    assert 'name="threshold" value="0.2"' in text
    with open(scene, "w") as f:
        f.write(text.replace('name="threshold" value="0.2"', 'name="threshold" value="0.4"'))
    after = ef.sweep(scene, over, BASE, out_dir=out).rows[0]
    assert not after["resumed"] and after["key"] != before["key"]
    assert 0 < after["events"] < 0.7 * before["events"]          # twice the threshold: far fewer events
    assert '"letters.png"' in text and '"text.png"' in text
    shutil.copy(scene_dir / "text.png", scene_dir / "letters.png")     # another texture under the same name
    assert not ef.sweep(scene, over, BASE, out_dir=out).rows[0]["resumed"]


def test_bad_sweep_parameters(tmp_path):
    with pytest.raises(ef.EventFieldError, match="must start with one of xml., render., pixel."):
        ef.sweep(GALVO, {"frequency": [1, 2]})
    with pytest.raises(ef.EventFieldError, match="non-empty list"):
        ef.sweep(GALVO, {"xml.frequency": []})
    with pytest.raises(ef.EventFieldError, match="not a scene file"):
        ef.sweep("nowhere.xml", {"xml.frequency": [1]})
    # names that cannot reach their target are refused before any worker starts
    with pytest.raises(ef.EventFieldError, match="'motion' is an argument of load_scene"):
        ef.sweep(GALVO, {"xml.motion": [None, "auto"]})
    with pytest.raises(ef.EventFieldError, match="render_events takes no 'stepz'.*allowed: .*steps"):
        ef.sweep(GALVO, {"render.stepz": [8]})
    with pytest.raises(ef.EventFieldError, match="takes no 'output'"):
        ef.sweep(GALVO, {"render.output": ["x.h5"]})
    # a typo in an xml.* name failed in every worker, after spawning them
    with pytest.raises(ef.EventFieldError, match=r"'xml.frequncy'.*declares no <default name='frequncy'> and "
                                                 r"uses no \$frequncy; it takes width, height, frequency, "
                                                 r"amplitude, phase$"):
        ef.sweep(GALVO, {"xml.frequncy": [125, 250]})
    from mitsuba_eventfield.evaluation.sweep import check_names    # a $name without a <default> is settable
    scene = tmp_path / "nodefault.xml"
    scene.write_text('<scene version="3.0.0"><integer name="w" value="$w"/></scene>')
    check_names({"xml.w": 16}, str(scene))


def test_a_sweep_refuses_what_it_would_run_twice_or_drop_and_names_a_failing_point(tmp_path):
    """A value given twice rendered twice (4 and 4.0 too); a name in both over and base lost base's value
    silently; client="local" failed on an attribute; one bad point lost the whole table, its error naming only
    the value. Now: refused before any worker; a failing point is named, the others run and are kept."""
    with pytest.raises(ef.EventFieldError, match=r"'render.spp': 4.0 given more than once"):
        ef.sweep(GALVO, {"render.spp": [4, 4.0]}, base=BASE)
    with pytest.raises(ef.EventFieldError, match=r"render.steps in both over and base"):
        ef.sweep(GALVO, {"render.steps": [8]}, base=BASE)
    with pytest.raises(ef.EventFieldError, match=r"client = 'local': expected a dask.distributed Client"):
        ef.sweep(GALVO, {"render.spp": [4]}, base=BASE, client="local")
    with pytest.raises(ef.EventFieldError, match=r"sweep point .*render.seed_mode=nope: seed_mode = 'nope': allowed "
                                                 r"values are .* \(1 of 2 points failed; the other 1 are kept in "):
        ef.sweep(GALVO, {"render.seed_mode": ["fixed", "nope"]}, base=BASE, out_dir=str(tmp_path))
    kept = [n for n in os.listdir(tmp_path) if n.endswith(".json")]
    assert len(kept) == 1
    again = ef.sweep(GALVO, {"render.seed_mode": ["fixed"]}, base=BASE, out_dir=str(tmp_path))
    assert [r["resumed"] for r in again.rows] == [True]
    with pytest.raises(ef.EventFieldError, match=r"render_events: reuse = 'maybe': must be True or False"):
        ef.render_events(GALVO, 0.004, steps=2, reuse="maybe")
