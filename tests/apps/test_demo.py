"""The main job (eventfield demo, ./run demo): a galvo event field of the off-axis cards, refocused on each and
a depth map, from the events alone, scored against Mitsuba's depth."""
import os
import subprocess
import sys

import numpy as np

from mitsuba_eventfield.apps import demo
from mitsuba_eventfield.images import read_exr


def test_demo_measures_both_cards_from_events_alone():
    r = demo.run(width=96, height=72, views=24)
    assert r.meta["inputs"].startswith("events only")
    for name, card in r.cards.items():          # measured: 0.3-0.8 % at this size
        assert card["error"] < 0.03 and card["confident"] > 0.5, (name, card)
    near, far = (r.refocused[z] for z in sorted(r.refocused))
    assert near.shape == far.shape == (72, 96) and np.all(np.isfinite(near))


def test_demo_command_writes_what_it_says(tmp_path):
    out = tmp_path / "demo"
    run = subprocess.run([sys.executable, "-m", "mitsuba_eventfield.cli", "demo", "-o", str(out), "--width", "64",
                          "--height", "48", "--views", "16"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "near card: depth from focus" in run.stdout and "wrote" in run.stdout
    for name in ("demo.png", "preview.png", "refocus_0.5m.png", "refocus_1.2m.png", "depth.png", "events.h5",
                 "metrics.json"):
        assert os.path.getsize(out / name) > 0, name
    channels, _ = read_exr(str(out / "depth.exr"))
    assert channels["depth"].shape == (48, 64) and set(channels) == {"depth", "confidence"}
