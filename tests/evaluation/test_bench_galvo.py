"""benchmarks/bench_galvo.py's camera comparison: the perspective twin it times the galvo against must see the
scene the galvo sees (the bench once built it by editing the XML and crashed when the galvo gained a parameter)."""
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _bench():
    sys.path.insert(0, os.path.join(ROOT, "benchmarks"))
    import bench_galvo
    return bench_galvo


def test_a_stopped_galvo_renders_what_its_perspective_twin_renders():
    import mitsuba as mi
    bench = _bench()
    images = {}
    for amplitude in ("0.0001", "0.5"):          # mechanical degrees: the mirror at rest, then the demo's scan
        scene = mi.load_file(bench.SCENE, width="64", height="48", amplitude=amplitude)
        galvo = scene.sensors()[0]
        twin = bench.perspective_twin(galvo)
        assert tuple(twin.film().size()) == (64, 48)
        images[amplitude] = [np.array(mi.render(scene, sensor=s, spp=16, seed=1)).ravel() for s in (galvo, twin)]
    still, scanning = (np.corrcoef(*images[a])[0, 1] for a in ("0.0001", "0.5"))
    # at rest the two mirrors fold the path back onto the camera's own axis: the same pinhole view (only
    # Monte-Carlo noise differs, the same seed for both); a 0.5 deg scan moves the view by ~8 px and decorrelates
    assert still > 0.999 and scanning < 0.9
    assert abs(images["0.0001"][0].mean() - images["0.0001"][1].mean()) < 0.002


def test_the_camera_comparison_runs_on_a_tiny_film():
    cam = _bench().galvo_vs_perspective(width=32, height=24, spp=1, reps=1)
    assert cam["resolution"] == "32x24" and cam["galvo_ms"] > 0 and cam["perspective_ms"] > 0
    assert np.isfinite(cam["ratio"])     # a ratio, not a target: targets are the bench's, never a test's
