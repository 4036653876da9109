"""The speed-vs-accuracy bench: Pareto front and a tiny run against its reference."""
import math
import os

from conftest import ROOT

from mitsuba_eventfield.evaluation import bench


def test_pareto_front():
    pts = [(1, 5), (2, 3), (3, 4), (0.5, 9), (4, 1)]
    assert sorted(bench.pareto(pts)) == [0, 1, 3, 4]          # (3, 4) is beaten by (2, 3)


def test_tiny_bench_run(tmp_path):
    settings = [{"name": "1 spp", "spp": 1, "steps_factor": 1}, bench.DEFAULT,
                {"name": "16 spp", "spp": 16, "steps_factor": 1}]
    rows = bench.run(os.path.join(ROOT, "scenes", "fan", "fan.xml"), 0.004, 16, {"width": 32, "height": 24},
                     settings=settings)
    by = {r["setting"]: r for r in rows}
    assert by["reference"]["product_error"] == 0 and by["reference"]["count_error"] == 0
    assert all(math.isfinite(r["product_error"]) and math.isfinite(r["timing_error"]) for r in rows)
    assert by["16 spp"]["timing_error"] < by["1 spp"]["timing_error"]      # more samples, closer to converged
    path = bench.chart(rows, str(tmp_path / "c.png"))
    assert os.path.getsize(path) > 1000
