"""Sweeps as a data maker runs them (a helper's walkthrough, 2026-11-27): one point at a time in a process
(Dask's threaded workers loaded two scenes at once and crashed), Ctrl-C cancelling the queue at once (the
pool rendered every queued point first, and a second Ctrl-C hung it), and no worker outliving the sweeping
process (SIGTERM to it left the workers idle for ever)."""
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
import uuid
from types import SimpleNamespace

from conftest import ROOT

from mitsuba_eventfield.evaluation import sweep as sweep_module

GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")


def test_points_in_one_process_run_one_at_a_time(monkeypatch):
    """Two threads of one worker (a Dask worker's default) call run_point: the scene loads and renders never
    overlap (the stand-ins record every entry and exit)."""
    inside, overlaps = [], []

    def load(scene, **xml):
        if inside:
            overlaps.append(scene)
        inside.append(scene)
        time.sleep(0.05)
        return scene

    def render(timed, duration, **kw):
        time.sleep(0.05)
        inside.pop()
        return SimpleNamespace(meta={"render": {"events": 1, "rate_ev_per_s": 1.0, "on": 1, "dropped_readout": 0,
                                                "render_s": 0.1}})
    monkeypatch.setattr(sweep_module, "load_scene", load)
    monkeypatch.setattr(sweep_module, "render_events", render)
    threads = [threading.Thread(target=sweep_module.run_point, args=(GALVO, {"render.seed": k})) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert overlaps == [] and inside == []


SCRIPT = textwrap.dedent("""
    import sys
    import mitsuba_eventfield as ef
    if __name__ == "__main__":
        ef.sweep(sys.argv[1], {"render.seed": list(range(60))},
                 {"xml.width": 32, "xml.height": 24, "render.duration": 0.004, "render.steps": 16},
                 out_dir=sys.argv[2], processes=2)
""")


def _marked(marker):
    """PIDs of live processes whose environment holds ``marker`` (the sweep and its spawned workers)."""
    pids = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/environ", "rb") as f:
                if marker.encode() in f.read():
                    with open(f"/proc/{pid}/stat") as s:
                        if s.read().split(")")[-1].split()[0] != "Z":
                            pids.append(int(pid))
        except OSError:
            continue
    return pids


def _sweep_until_points(tmp_path, how_many):
    script = tmp_path / "sweep_script.py"
    script.write_text(SCRIPT)
    out = tmp_path / "points"
    marker = f"EF_SWEEP_TEST_{uuid.uuid4().hex}"
    env = dict(os.environ, **{marker: "1"})
    proc = subprocess.Popen([sys.executable, str(script), GALVO, str(out)], env=env, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        if out.is_dir() and sum(n.endswith(".json") for n in os.listdir(out)) >= how_many:
            break
        time.sleep(0.1)
    assert proc.poll() is None, proc.communicate()
    return proc, out, marker


def test_ctrl_c_cancels_the_queue_and_ends_the_workers(tmp_path):
    """SIGINT to the whole process group (a terminal's Ctrl-C) after two points: the sweep raises
    KeyboardInterrupt with most of the 60 points never started, and no worker is left."""
    proc, out, marker = _sweep_until_points(tmp_path, 2)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode != 0 and "KeyboardInterrupt" in err, err[-2000:]
    assert sum(n.endswith(".json") for n in os.listdir(out)) < 30
    time.sleep(1)
    assert _marked(marker) == []


def test_no_worker_outlives_a_terminated_sweep(tmp_path):
    """SIGTERM to the sweeping process alone (no handler: it ends at once): its workers end too."""
    proc, out, marker = _sweep_until_points(tmp_path, 1)
    os.kill(proc.pid, signal.SIGTERM)
    proc.communicate(timeout=60)
    deadline = time.monotonic() + 30
    while _marked(marker) and time.monotonic() < deadline:
        time.sleep(0.2)
    left = _marked(marker)
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    assert left == []


def test_a_local_sweep_worker_leaves_ctrl_c_to_the_sweeping_process():
    """A terminal's Ctrl-C reaches every process of the group: a worker interrupted mid-point was replaced by the
    pool, which went on with the queue. The workers ignore SIGINT (``sweep._worker_start``): one sent to a
    worker in the middle of a task leaves that task to finish."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn"),
                             initializer=sweep_module._worker_start) as pool:
        pid = pool.submit(os.getpid).result(timeout=120)
        task = pool.submit(time.sleep, 1.0)
        time.sleep(0.3)
        os.kill(pid, signal.SIGINT)
        assert task.result(timeout=60) is None
        assert pool.submit(signal.getsignal, signal.SIGINT).result(timeout=60) == signal.SIG_IGN


ORPHAN = """
import multiprocessing, os, sys, time

def child(out):
    time.sleep(1.0)                      # still starting (a worker imports for seconds) when the parent dies
    with open(out + ".started", "w") as f:
        f.write(str(os.getpid()))
    from mitsuba_eventfield.evaluation.sweep import _worker_start
    _worker_start()
    open(out + ".continued", "w").close()

if __name__ == "__main__":
    multiprocessing.get_context("spawn").Process(target=child, args=(sys.argv[1],)).start()
    os._exit(0)                          # dies without waiting: no parent-death signal reaches a child yet to ask
"""


def test_a_worker_whose_sweep_died_while_it_started_ends():
    """The parent-death signal is asked for when the worker starts: a sweep killed before that sent none, and
    the orphan held the sweep's output pipes (a full-suite run hung on them). It ends on finding its parent
    gone."""
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        script, out = os.path.join(d, "orphan.py"), os.path.join(d, "marker")
        with open(script, "w") as f:
            f.write(ORPHAN)
        subprocess.run([sys.executable, script, out], timeout=120, check=True)
        deadline = time.monotonic() + 120
        while not os.path.exists(out + ".started") and time.monotonic() < deadline:
            time.sleep(0.1)
        assert os.path.exists(out + ".started")
        time.sleep(0.2)
        pid = int(open(out + ".started").read())
        while time.monotonic() < deadline:          # until the orphan has ended, one way or the other
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                break
            time.sleep(0.2)
        assert not os.path.exists(out + ".continued")
