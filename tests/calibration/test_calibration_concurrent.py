"""Two ``calibrate`` runs extending one calibration file at once (a fault-injection audit, 2026-11-28): each
read the file before the other wrote it, and one part was lost. ``save_calibration`` now reads, extends and
writes under one lock (``atomic.updating``)."""
import json
import os
import threading
import time

import numpy as np
from conftest import ROOT

from mitsuba_eventfield.atomic import updating
from mitsuba_eventfield.calibration import fit_depth, optics_record, save_calibration
from mitsuba_eventfield.optics import galvo as galvo_optics
from mitsuba_eventfield.scene import load_scene
from mitsuba_eventfield.simulate.summary import sensor_optics

GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")


def test_an_update_waits_for_the_one_under_way_and_keeps_what_it_wrote(tmp_path):
    optics = sensor_optics(load_scene(GALVO, width=16, height=12))
    record = optics_record(optics, 16, 12)
    z = np.array([0.4, 0.7, 1.0, 1.6, 2.5])
    depth = fit_depth(z, 2 * galvo_optics.focal_length_px(16, record["fov_x_deg"]) * (1 - 0.1 / z))
    cal = str(tmp_path / "cal.json")
    done = []
    with updating(cal):                    # another run, part-way through its own update of the file
        saver = threading.Thread(target=lambda: done.append(save_calibration(cal, record, depth=depth)))
        saver.start()
        time.sleep(0.3)
        assert saver.is_alive() and not os.path.exists(cal)       # it waits
        with open(cal, "w") as f:          # the other run's part (any key a reader keeps)
            json.dump({"format": "mitsuba-eventfield calibration", "version": 2, "note": "the first run's"}, f)
    saver.join(30)
    with open(cal) as f:
        data = json.load(f)
    assert done == [cal] and data["note"] == "the first run's" and "depth" in data
