"""Depth from views that do not change (``focus.depth.MIN_EVIDENCE``): texture below the event threshold fires
no events, so every view reconstructed from the events is the start frame (here with a little noise of its own,
as rendered views have, so that the level-change count passes them). Their focus curves still peak where the
alignment warps spread least, at the near end. The views' spread against what the scan's parallax must give
(0.09 at most here) refuses every textured pixel for that reason, "no parallax evidence". Without it the
pixels were still refused, but as lying nearer than the range (1292 of 2238) or lacking texture of their own:
advice to search nearer, for a scene with no parallax in its views at all."""
import os

import numpy as np
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield.focus import depth as depth_module
from mitsuba_eventfield.lightfield.model import from_galvo, galvo_view_times

GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")


def test_views_that_never_change_give_no_confident_depth(monkeypatch):
    timed = ef.load_scene(GALVO, width=64, height=48)
    optics = timed.sensor.optics_metadata()
    start = ef.render_frames(timed, [0.0], spp=16)[0]                 # log, as the pixel sees it
    times = galvo_view_times(optics, 0.0, 16)
    # rendered views change a little at every view (Monte-Carlo noise), so the level-change count passes them:
    # here each view is the start frame with its own noise of 0.002 in log
    noise = np.random.default_rng(0).normal(0.0, 0.002, (len(times),) + start.shape)
    lf = from_galvo(start[None] + noise, times, optics)
    dm = ef.depth_from_focus(lf, 0.3, 4.0, planes=12)
    textured = np.hypot(*np.gradient(start)) > 0.05
    assert textured.mean() > 0.2
    assert float(dm.evidence.max()) < 0.15 and not (dm.confidence > 0).any()     # (the noise: 0.09 at most)
    assert np.mean(dm.reasons()[textured] == 1) > 0.95               # "no parallax evidence"
    # without the check, the reason given was the wrong one: "nearer than the range searched"
    monkeypatch.setattr(depth_module, "MIN_EVIDENCE", 0.0)
    unchecked = ef.depth_from_focus(lf, 0.3, 4.0, planes=12).reasons()[textured]
    assert np.mean(unchecked == 1) == 0 and np.mean(unchecked == 3) > 0.4
