"""A later scan period's prior is the previous period's image carried forward through the events between the
two (``focus.galvo_periods.reconstruct_periods``): the solver's equations tie a period's pixels only to each
other, so the level of its image (up to the capture's one constant) comes from that prior. One extra ON event
at every pixel halfway through period 0 (a whole-image brightness step of C_on = 0.2, after period 0's start)
must raise period 1's image by C_on and leave period 0's. Fan scene, 96x72, a 2 deg scan with its mirrors
0.2 m out, two periods. Measured median change against the unmodified stream: period 0 -0.002, period 1 +0.202;
a prior that skipped the events between the periods left period 1 where it was (-0.0004)."""
import os

import numpy as np
import pytest
from conftest import ROOT

from mitsuba_eventfield.events.stream import EventStream
from mitsuba_eventfield.focus.galvo_periods import reconstruct_periods
from mitsuba_eventfield.scene import load_scene
from mitsuba_eventfield.simulate.render import render_events

FAN = os.path.join(ROOT, "scenes", "fan", "fan.xml")


def _log_starts(events):
    return [solved.log_start for _, solved in reconstruct_periods(events, views=16, periods=[0, 1])]


def test_events_between_periods_carry_into_the_next_periods_image():
    timed = load_scene(FAN, width=96, height=72, amplitude=2, mirror_distance=0.2)
    period = timed.scan_period
    ev = render_events(timed, 2 * period, steps=146, spp=4)       # under 1 px of image motion a step
    c_on = ev.meta["pixel_model"]["threshold_on"]
    w, h = ev.width, ev.height
    xs, ys = np.meshgrid(np.arange(w), np.arange(h))
    t_mid = int(round(period / 2 * 1e6))                           # microseconds
    x, y = np.concatenate([ev.x, xs.ravel()]), np.concatenate([ev.y, ys.ravel()])
    t, p = np.concatenate([ev.t, np.full(w * h, t_mid)]), np.concatenate([ev.p, np.ones(w * h)])
    order = np.argsort(t, kind="stable")                           # time order kept
    stepped = EventStream(x[order].astype(ev.x.dtype), y[order].astype(ev.y.dtype), t[order].astype(ev.t.dtype),
                          p[order].astype(ev.p.dtype), w, h, dict(ev.meta))
    base, moved = _log_starts(ev), _log_starts(stepped)
    change = [float(np.median(b - a)) for a, b in zip(base, moved)]
    print(f"C_on {c_on}; median change of the period images: {change[0]:+.4f}, {change[1]:+.4f}")
    assert change[0] == pytest.approx(0.0, abs=0.02)
    assert change[1] == pytest.approx(c_on, abs=0.02)
