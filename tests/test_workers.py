"""``workers.ordered_map``: per-item work on a shared thread pool, handed back in order, with bounded look-ahead,
errors at their item, OpenCV on one thread while a map runs; and the refocus and depth maps that use it equal,
bit for bit, what the calling thread alone makes."""
import math
import os
import threading
import time

import cv2
import numpy as np
import pytest

from mitsuba_eventfield import workers
from mitsuba_eventfield.focus.depth import depth_from_focus
from mitsuba_eventfield.focus.refocus import refocus
from mitsuba_eventfield.lightfield.model import Disparity, LightField
from mitsuba_eventfield.optics import galvo as galvo_optics


def _pool_workers():
    return workers._executor()[1]


@pytest.fixture
def several_cores(monkeypatch):
    """At least two workers in the map, also on a one-core machine (the pool is made with the machine's)."""
    monkeypatch.setattr(workers, "usable_cores", lambda: 2)


def test_results_come_in_order_and_from_the_pool(several_cores):
    rng = np.random.default_rng(0)
    delays = rng.uniform(0, 0.004, 40)
    threads = set()

    def slow_square(i):
        time.sleep(delays[i])               # later items finish first now and then
        threads.add(threading.get_ident())
        return i * i
    assert list(workers.ordered_map(slow_square, range(40))) == [i * i for i in range(40)]
    assert threading.get_ident() not in threads


def test_look_ahead_is_bounded(several_cores):
    """At most the pool's workers and two more are started beyond what the consumer has taken: a stack of large
    warped views never waits whole in memory."""
    started = []
    ahead = _pool_workers() + 2

    def note(i):
        started.append(i)
        return i
    for i in workers.ordered_map(note, range(60)):
        assert max(started) < i + ahead + 1, (i, max(started))
        time.sleep(0.001)                  # a slow consumer: the pool would run far ahead if it could


def test_an_error_surfaces_at_its_item_and_stops_the_rest(several_cores):
    ran = []

    def fails_at_5(i):
        ran.append(i)
        if i == 5:
            raise ValueError("item 5")
        return i
    got = []
    with pytest.raises(ValueError, match="item 5"):
        for v in workers.ordered_map(fails_at_5, range(100)):
            got.append(v)
    assert got == [0, 1, 2, 3, 4]
    assert len(ran) <= 6 + _pool_workers() + 2      # the items beyond the window never started


def test_a_map_inside_a_task_runs_on_that_task_s_thread(several_cores):
    """Every worker running a task that waits on a map of its own would wait on tasks queued behind it: a
    map from one of the pool's threads runs there instead."""
    def inner_sum(i):
        return sum(workers.ordered_map(lambda j: i * j, range(8)))
    tasks = 3 * _pool_workers()
    done = []
    runner = threading.Thread(target=lambda: done.append(list(workers.ordered_map(inner_sum, range(tasks)))),
                              daemon=True)
    runner.start()
    runner.join(timeout=60)
    assert done == [[28 * i for i in range(tasks)]], "the nested maps did not finish within 60 s"


def test_opencv_runs_on_one_thread_during_a_map_and_gets_its_count_back(several_cores):
    original = cv2.getNumThreads()
    cv2.setNumThreads(3)                     # a count that one thread is not (OpenCV's own default may be 1)
    before = cv2.getNumThreads()
    assert before == 3
    seen = list(workers.ordered_map(lambda i: cv2.getNumThreads(), range(6)))
    assert seen == [1] * 6
    assert cv2.getNumThreads() == before
    inner = workers.ordered_map(lambda i: i, range(3))
    outer = workers.ordered_map(lambda i: cv2.getNumThreads(), range(3))
    assert next(outer) == 1 and list(inner) == [0, 1, 2]         # one map ends while another runs
    assert cv2.getNumThreads() == 1
    assert list(outer) == [1, 1]
    assert cv2.getNumThreads() == before
    gen = workers.ordered_map(lambda i: i, range(10))            # a consumer that stops early
    assert next(gen) == 0
    gen.close()
    assert cv2.getNumThreads() == before
    running = workers.ordered_map(lambda i: i, range(10))        # a child forked while a map runs
    assert next(running) == 0 and cv2.getNumThreads() == 1
    child = os.fork()
    if child == 0:
        os._exit(0 if cv2.getNumThreads() == before else 1)
    assert os.waitpid(child, 0)[1] == 0, "the forked child kept OpenCV on one thread"
    running.close()
    assert cv2.getNumThreads() == before
    cv2.setNumThreads(original)


def test_one_core_runs_on_the_calling_thread(monkeypatch):
    monkeypatch.setattr(workers, "usable_cores", lambda: 1)
    assert set(workers.ordered_map(lambda i: threading.get_ident(), range(5))) == {threading.get_ident()}


def _galvo_lf(w=64, h=48, k=12):
    """Views of a textured image under a galvo's exact homographies (a plane at 0.7 m), on a circle."""
    rng = np.random.default_rng(3)
    ref = cv2.GaussianBlur(rng.random((h, w)).astype(np.float32), (0, 0), 1.5) + 0.1
    g = galvo_optics.GalvoGeometry(w, h, galvo_optics.focal_length_px(w, 40.0), 0.2, 0.21)
    phase = 2 * np.pi * np.arange(k) / k
    amp = math.radians(2.0)
    positions = 2 * np.stack([amp * np.cos(phase), amp * np.sin(phase)], axis=-1)
    lf = LightField(np.stack([ref] * k), positions, np.zeros(k), Disparity(*g.paraxial_disparity()), "galvo", {}, g)
    views = np.stack([cv2.warpPerspective(ref, m, (w, h), flags=cv2.INTER_LINEAR,
                                          borderMode=cv2.BORDER_REFLECT_101) for m in lf.alignments(0.7)])
    return LightField(views, positions, np.zeros(k), lf.disparity, "galvo", {}, g)


@pytest.mark.parametrize("measure", ["variance", "sml"])
def test_refocus_and_depth_equal_those_made_on_the_calling_thread(monkeypatch, measure):
    """The views are warped side by side and summed in their order: the same floats as one thread makes. The
    depth map also finds the plane (0.7 m) where the views are textured, so the comparison is not of two
    empty maps."""
    lf = _galvo_lf()
    monkeypatch.setattr(workers, "usable_cores", lambda: 2)
    pooled = refocus(lf, 0.7), depth_from_focus(lf, 0.4, 2.0, 12, measure)
    monkeypatch.setattr(workers, "usable_cores", lambda: 1)
    lf.cache.clear()
    alone = refocus(lf, 0.7), depth_from_focus(lf, 0.4, 2.0, 12, measure)
    assert np.array_equal(pooled[0], alone[0])
    assert np.array_equal(pooled[1].depth, alone[1].depth) and np.array_equal(pooled[1].confidence,
                                                                               alone[1].confidence)
    sure = alone[1].confidence >= 0.5
    assert sure.mean() > 0.3 and np.median(alone[1].depth[sure]) == pytest.approx(0.7, rel=0.05)
