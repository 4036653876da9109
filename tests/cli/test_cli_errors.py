"""Bad input on every subcommand: one line naming the field and the allowed range, a non-zero exit, no traceback,
no output file, and nothing rendered first. Interrupts and leftovers of killed runs."""
import os
import re
import signal
import subprocess
import sys
import time

import pytest
from conftest import ROOT

from mitsuba_eventfield import cli

GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")
SMALL = ["-D", "width=32", "-D", "height=24"]


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """A tiny galvo capture and its start frame."""
    d = tmp_path_factory.mktemp("capture")
    h5 = str(d / "g.h5")
    assert cli.main(["render", GALVO, "-o", h5, *SMALL, "--duration", "0.004", "--steps", "32", "--quiet"]) == 0
    return h5


def _cases(g, blocked):
    """(argv, text the one-line error must contain). ``blocked``: a path under a regular file (as root, a
    read-only directory is still writable, so the unwritable case is a parent that is not a directory)."""
    out = os.path.dirname(g)
    return [
        # numbers out of range or not numbers (were: accepted, silently replaced, or a traceback)
        (["render", GALVO, "-o", f"{out}/a.h5", "--duration", "1e9"], "--duration"),
        (["render", GALVO, "-o", f"{out}/a.h5", "--duration", "nan"], "--duration"),
        (["render", GALVO, "-o", f"{out}/a.h5", "--steps", "1000000000000"], "--steps"),
        (["render", GALVO, "-o", f"{out}/a.h5", "--spp", "0"], "--spp"),
        (["render", GALVO, "-o", f"{out}/a.h5", "--threshold", "-1"], "--threshold"),
        (["render", GALVO, "-o", f"{out}/a.h5", "--preview-window", "-1"], "--preview-window"),
        (["render", GALVO, "-o", f"{out}/a.h5", "--adaptive", "--max-log-change", "nan"], "--max-log-change"),
        (["preview", g, "-o", f"{out}/p.png", "--scale", "100000"], "--scale"),
        (["preview", g, "-o", f"{out}/p.png", "--t0", "nan"], "--t0"),
        (["frame", GALVO, "-o", f"{out}/f.exr", "--times", "nan"], "--times"),
        (["frame", GALVO, "-o", f"{out}/f.exr", "--times", "1,,2"], "an empty item between commas"),
        (["compare-designs", "-o", f"{out}/cd", "--speeds", "1,1"], "1 given more than once"),
        (["reconstruct", g, "-o", f"{out}/rc", "--fps", "0"], "--fps"),
        (["reconstruct", g, "-o", f"{out}/rc", "--fps", "1e9"], "--fps"),
        # no frame interval within the stream (was: one frame at its end, as if asked for)
        (["reconstruct", g, "-o", f"{out}/rc", "--fps", "0.1"], "--fps 0.1: a frame every 10000 ms, longer than"),
        (["reconstruct", g, "-o", f"{out}/rc", "--method", "highpass", "--cutoff", "-1"], "--cutoff"),
        (["refocus", g, "-o", f"{out}/r.png", "--depth", "1", "--views", "100000000"], "--views"),
        (["refocus", g, "-o", f"{out}/r.png", "--depth", "1,abc"], "--depth"),
        (["depth", g, "-o", f"{out}/d.png", "--near", "0.5", "--far", "2", "--planes", "10000000"], "--planes"),
        (["depth", g, "-o", f"{out}/d.png", "--near", "0.5", "--far", "2", "--min-confidence", "nan"],
         "--min-confidence"),
        (["calibrate", "galvo", g, "--patch", "nan,10", "-o", f"{out}/c.json"], "--patch"),
        (["scanrate-depth", "-o", f"{out}/sd", "--planes", "10000000"], "--planes"),
        (["track-focus", "-o", f"{out}/tf", "--planes", "1e7"], "--planes"),
        (["slomorf", "-o", f"{out}/sm", "--fps", "0"], "--fps"),
        # output paths that cannot be written: refused before any work (were: tracebacks after rendering)
        (["render", GALVO, "-o", f"{blocked}/a.h5"], "not a directory"),
        (["render", GALVO, "-o", f"{out}/a.h5", "--preview", f"{blocked}/p.png"], "not a directory"),
        (["preview", g, "-o", f"{blocked}/p.png"], "not a directory"),
        (["frame", GALVO, "-o", f"{blocked}/f.exr"], "not a directory"),
        (["refocus", g, "-o", f"{blocked}/r.png", "--depth", "1"], "not a directory"),
        (["depth", g, "-o", f"{blocked}/d.png", "--near", "0.5", "--far", "2"], "not a directory"),
        (["calibrate", "galvo", g, "--patch", "10,10", "-o", f"{blocked}/c.json"], "not a directory"),
    ] + [([cmd, "-o", f"{blocked}/x"] + ([GALVO] if cmd == "bench" else []), "not a writable directory")
         for cmd in ("hdr", "highspeed", "track-focus", "slomorf", "scanrate-depth", "bench")] + [
        (["reconstruct", g, "-o", f"{blocked}/x"], "not a writable directory"),
        (["device", "scan", "--simulate", "--dialect", "rigol", "--freq", "100", "--amplitude-deg", "1",
          "--metadata", f"{blocked}/m.json"], "not a directory"),
    ]


def test_every_bad_input_is_one_line_and_writes_nothing(capture, tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    before = set(os.listdir(os.path.dirname(capture)))
    failures = []
    for argv, must_say in _cases(capture, str(blocker)):
        t = time.perf_counter()
        try:
            rc = cli.main(argv)
        except SystemExit as e:          # argparse: the number never reaches the command
            rc = e.code
        err = capsys.readouterr().err.strip().splitlines()
        elapsed = time.perf_counter() - t
        if rc != 2 or len(err) != 1 or must_say not in err[0] or "Traceback" in err[0] or elapsed > 5:
            failures.append((argv, rc, err, round(elapsed, 1)))
    assert failures == []
    assert set(os.listdir(os.path.dirname(capture))) == before      # no output, no partial file


def test_unexpected_errors_are_one_line_too(monkeypatch, capsys, capture):
    def broken(*a, **k):
        raise ZeroDivisionError("a bug somewhere")
    monkeypatch.setattr("mitsuba_eventfield.events.io.summarize_events", broken)
    monkeypatch.delenv("EVENTFIELD_DEBUG", raising=False)
    assert cli.main(["info", capture]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "ZeroDivisionError: a bug somewhere" in err[0] and "EVENTFIELD_DEBUG" in err[0]


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.startswith("mitsuba-eventfield ")


def test_coarse_scan_steps_are_flagged(tmp_path, capsys):
    """4 steps per 4 ms scan period move the image more than a pixel a step: stderr, the summary and the
    file's metadata say so, with the steps that suffice (which then say nothing)."""
    import mitsuba_eventfield as ef
    out = str(tmp_path / "coarse.h5")
    assert cli.main(["render", GALVO, "-o", out, *SMALL, "--duration", "0.008", "--steps", "8", "--quiet"]) == 0
    assert "steps coarser than the image motion: per step the scan" in capsys.readouterr().err
    notes = [n for n in ef.read_events(out).meta["render"]["notes"] if "steps coarser" in n]
    need = int(re.search(r"; (\d+) steps \(render --steps", notes[0])[1])
    assert 8 < need <= 32
    assert cli.main(["render", GALVO, "-o", out, *SMALL, "--duration", "0.008", "--steps", str(need), "--quiet"]) == 0
    assert "steps coarser" not in capsys.readouterr().err


def _render_process(out, *extra):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-c", "import signal, sys; signal.signal(signal.SIGINT, "
                             "signal.default_int_handler); from mitsuba_eventfield.cli import main; "
                             "sys.exit(main(sys.argv[1:]))", "render", os.path.join(ROOT, "scenes", "fan", "fan.xml"),
                             "-o", out, "-D", "width=64", "-D", "height=48", "--duration", "0.02", "--steps", "2000",
                             *extra], stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)


def _wait_for_rendering(proc):
    """Until the progress bar shows (the render loop runs), so the signal lands inside Dr.Jit/Mitsuba."""
    buf = ""
    while "rendering" not in buf:
        ch = proc.stderr.read(1)
        assert ch, "the render ended before it started"
        buf += ch


def _messages(err):
    """The lines of stderr without the progress bar. Strict: the bar is removed by its exact format, not by
    dropping every line that mentions it, because tqdm redraws with \\r and a log line printed mid-render (Mitsuba's
    "Received interrupt signal, winding down..") lands glued to the end of a bar."""
    text = re.sub(r"rendering: [^\r\n|]*\|[^\r\n|]*\| [\d.]+/[\d.]+ ms sim \[[^\]\r\n]*\](, \d+ events)?", "", err)
    return [line for line in text.replace("\r", "\n").splitlines() if line.strip()]


@pytest.mark.parametrize("sig, rc, word", [(signal.SIGINT, 130, "interrupted"), (signal.SIGTERM, 143, "terminated")])
def test_interrupt_mid_render_is_one_line_and_leaves_nothing(tmp_path, sig, rc, word):
    out = tmp_path / "fan.h5"
    proc = _render_process(str(out))
    _wait_for_rendering(proc)
    time.sleep(0.5)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == rc and _messages(err) == [f"eventfield: {word} (no partial output kept)"], err[-2000:]
    assert os.listdir(tmp_path) == []


INSIDE_MITSUBA_RENDER = """
import os, signal, sys
signal.signal(signal.SIGINT, signal.default_int_handler)
from mitsuba_eventfield.plugins import galvo_sensor
traced = galvo_sensor._GalvoSensorMethods.sample_ray_differential
calls = []
def sample_ray_differential(self, *args, **kwargs):   # runs while Mitsuba traces, inside its render call
    calls.append(1)
    if len(calls) == 5:                               # a few steps in: Mitsuba's own SIGINT handler catches it
        os.kill(os.getpid(), signal.SIGINT)
    return traced(self, *args, **kwargs)
galvo_sensor._GalvoSensorMethods.sample_ray_differential = sample_ray_differential
from mitsuba_eventfield.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_interrupt_inside_mitsuba_render_is_one_line(tmp_path):
    """Ctrl-C while Mitsuba's render runs (not between steps, as the test above mostly lands): Mitsuba logs
    "Received interrupt signal, winding down.." before the KeyboardInterrupt reaches us; only our line shows."""
    r = subprocess.run([sys.executable, "-c", INSIDE_MITSUBA_RENDER, "render", os.path.join(ROOT, "scenes", "fan",
                        "fan.xml"), "-o", str(tmp_path / "fan.h5"), "-D", "width=64", "-D", "height=48",
                        "--duration", "0.02", "--steps", "200"], capture_output=True, text=True, timeout=300,
                       # the interrupt is raised from the sensor's Python ray generation, which a frozen (replayed)
                       # render no longer calls after recording: trace every step (simulate/frames.py)
                       env=dict(os.environ, EVENTFIELD_FREEZE="0"))
    assert r.returncode == 130 and _messages(r.stderr) == ["eventfield: interrupted (no partial output kept)"], \
        r.stderr[-2000:]
    assert os.listdir(tmp_path) == []


def _swallowed_stop(monkeypatch, module, name, at_call, sig=signal.SIGTERM):
    """Wrap ``module.name`` so that its ``at_call``-th call records ``sig`` as the CLI's handler does, while its
    KeyboardInterrupt is lost (as inside a library that swallows it: the flaky test above, 1 run in ~40)."""
    from mitsuba_eventfield import errors
    original, calls = getattr(module, name), []

    def wrapped(*args, **kwargs):
        out = original(*args, **kwargs)
        calls.append(1)
        if len(calls) == at_call:
            errors.STOP_SIGNALS.append(sig)
        return out
    monkeypatch.setattr(module, name, wrapped)
    return calls


def test_a_swallowed_interrupt_still_stops_the_render_and_keeps_nothing(tmp_path, monkeypatch, capsys):
    from mitsuba_eventfield import errors
    from mitsuba_eventfield.simulate import render as render_module
    calls = _swallowed_stop(monkeypatch, render_module._Loop, "_step_events", 3)
    out = tmp_path / "g.h5"
    rc = cli.main(["render", GALVO, "-o", str(out), *SMALL, "--duration", "0.004", "--steps", "32", "--quiet"])
    assert rc == 143 and len(calls) == 3          # stopped at the next step, not at the end (32 steps)
    assert _messages(capsys.readouterr().err) == ["eventfield: terminated (no partial output kept)"]
    assert os.listdir(tmp_path) == [] and errors.STOP_SIGNALS == []     # cleared: the next command runs
    monkeypatch.undo()
    assert cli.main(["render", GALVO, "-o", str(out), *SMALL, "--duration", "0.004", "--steps", "32",
                     "--quiet"]) == 0


def test_a_swallowed_interrupt_at_the_last_frame_publishes_nothing(tmp_path, monkeypatch, capsys):
    """The signal lands in the last step of a conversion: no step follows to notice it, the sink does before it
    publishes the file."""
    import numpy as np
    from mitsuba_eventfield.simulate import convert as convert_module
    frames = np.random.default_rng(0).uniform(0.1, 1.0, (6, 12, 16)).astype(np.float32)
    np.savez(tmp_path / "clip.npz", frames=frames, times=np.arange(6) * 1e-3)
    # the six frames are one kernel's group, committed after the frame loop
    calls = _swallowed_stop(monkeypatch, convert_module, "_commit_group", 1, signal.SIGINT)
    out = tmp_path / "out" / "c.h5"
    os.makedirs(out.parent)
    rc = cli.main(["convert", str(tmp_path / "clip.npz"), "-o", str(out), "--quiet"])
    assert rc == 130 and len(calls) == 1
    assert _messages(capsys.readouterr().err) == ["eventfield: interrupted (no partial output kept)"]
    assert os.listdir(out.parent) == []


def test_sigkill_leftover_is_named_and_removed_by_the_next_run(tmp_path):
    out = tmp_path / "fan.h5"
    proc = _render_process(str(out))
    _wait_for_rendering(proc)
    time.sleep(0.5)
    proc.kill()
    proc.communicate(timeout=60)
    left = os.listdir(tmp_path)
    assert len(left) == 1 and left[0].startswith("fan.partial-") and left[0].endswith(".h5")   # visible, named
    r = subprocess.run([sys.executable, "-m", "mitsuba_eventfield.cli", "render", GALVO, "-o", str(out), *SMALL,
                        "--duration", "0.004", "--steps", "32", "--quiet"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and f"removed {tmp_path / left[0]}" in r.stderr
    assert os.listdir(tmp_path) == ["fan.h5"]


def test_reused_output_folder_warns_and_keeps_no_stale_files(capture, tmp_path, capsys):
    out = tmp_path / "frames"
    assert cli.main(["reconstruct", capture, "-o", str(out), "--fps", "2500", "--method", "galvo"]) == 0
    first = sorted(os.listdir(out))
    (out / "mine.txt").write_text("a file of the user's")
    capsys.readouterr()
    assert cli.main(["reconstruct", capture, "-o", str(out), "--fps", "1000", "--method", "galvo"]) == 0
    err = capsys.readouterr().err
    assert "is reused" in err and "1 other files stay" in err
    frames = sorted(n for n in os.listdir(out) if n.startswith("frame_"))
    assert len(first) > len(frames) > 0 and frames == [f"frame_{k:04d}.{e}" for k in range(len(frames) // 2)
                                                       for e in ("exr", "png")]
    assert (out / "mine.txt").exists()


def test_a_users_file_named_like_an_output_is_kept_and_the_run_stops(capture, tmp_path, capsys):
    """A file in a reused folder that eventfield did not write was replaced when the run wrote that name, under
    a warning that it stayed. Now the run stops in one line before any frame is made, and the file is
    untouched; the next run, the file moved away, writes every frame."""
    out = tmp_path / "frames"
    out.mkdir()
    mine = out / "frame_0001.png"
    mine.write_text("a file of the user's")
    assert cli.main(["reconstruct", capture, "-o", str(out), "--fps", "1000", "--method", "galvo"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "1 other files stay" in err[0] and len(err) == 2, err
    assert f"{mine}: a file eventfield did not write" in err[1] and "is kept, not replaced" in err[1], err
    assert mine.read_text() == "a file of the user's"
    assert os.listdir(out) == ["frame_0001.png"]          # nothing written, no manifest of nothing
    mine.rename(tmp_path / "mine.png")
    assert cli.main(["reconstruct", capture, "-o", str(out), "--fps", "1000", "--method", "galvo"]) == 0
    err = capsys.readouterr().err
    assert "other files stay" not in err
    assert (out / "frame_0001.png").stat().st_size > 100
    assert (tmp_path / "mine.png").read_text() == "a file of the user's"


def test_a_preview_window_outside_the_stream_is_refused(tmp_path, capsys):
    """A window past the stream's end wrote an empty PNG and exited 0; a reversed one named the library's
    t0_us / t1_us instead of the options given."""
    events = str(tmp_path / "d.h5")
    assert cli.main(["render", os.path.join(ROOT, "scenes", "demo", "demo.xml"), "-D", "width=16", "-D", "height=12",
                     "--duration", "0.01", "--steps", "4", "--quiet", "-o", events]) == 0
    capsys.readouterr()
    for window, message in ((["--t0", "400", "--t1", "450"], "the window --t0 400 --t1 450 is outside the stream, "
                                                             "which covers 0 to 10 ms"),
                            (["--t0", "5", "--t1", "3"], "--t0 5 --t1 3: the window [t0, t1) holds no time"),
                            (["--t0", "1", "--t1", "1"], "--t0 1 --t1 1: the window [t0, t1) holds no time"),
                            (["--t1", "0"], "the window --t1 0 is outside the stream")):
        assert cli.main(["preview", events, "-o", str(tmp_path / "p.png"), *window]) == 2
        err = capsys.readouterr().err.strip()
        assert message in err and "\n" not in err, err
    assert not (tmp_path / "p.png").exists()
    assert cli.main(["preview", events, "-o", str(tmp_path / "p.png"), "--t0", "2", "--t1", "6"]) == 0


@pytest.mark.parametrize("instances", ["0", "1"])
def test_scene_value_errors_name_the_users_file_and_the_declared_values(tmp_path, capsys, monkeypatch, instances):
    """-D width=abc named a temporary copy of the scene; -D widht=96 gave Mitsuba's "Found unused parameters".
    With moving shapes as instances (CUDA's default) the loaded text is rewritten without the file's comments:
    the line is still the user's file's (it was 20, not 24, there)."""
    monkeypatch.setenv("EVENTFIELD_INSTANCES", instances)
    demo = os.path.join(ROOT, "scenes", "demo", "demo.xml")
    for define, message in (("width=abc", f"Error while loading {demo} (line 24, col 14): could not parse integer "
                                          'value "abc"'),
                            ("widht=96", "scene value widht (-D, or a keyword of load_scene): not a value the scene "
                                         "declares; its <default> values are width, height, max_depth")):
        code = cli.main(["render", demo, "-o", str(tmp_path / "x.h5"), "-D", define,
                         "--duration", "0.001", "--steps", "2"])
        err = capsys.readouterr().err.strip()
        # no temporary copy named (the clone itself may live under /tmp)
        assert code == 2 and message in err and "/tmp" not in err.replace(ROOT, "").replace(str(tmp_path), ""), err


def test_a_missing_output_folder_is_named_as_the_user_can_create_it(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    os.makedirs("here")
    for target, shown in (("here/out/x.h5", "mkdir -p here/out)"),
                          ("/nonexistent_dir/x.h5", "mkdir -p /nonexistent_dir)")):
        code = cli.main(["render", os.path.join(ROOT, "scenes", "demo", "demo.xml"), "-o", target, "--duration",
                         "0.001", "--steps", "2"])
        err = capsys.readouterr().err.strip()
        assert code == 2 and err.endswith(shown), err


def test_the_progress_bar_into_a_log_is_a_few_lines(tmp_path):
    """Into a pipe or file the progress bar redraws every LOG_PROGRESS_INTERVAL_S, not every step: the fan's
    --auto render left 3,000 updates (1.5 MB) in a captured stderr, one per step."""
    r = subprocess.run([sys.executable, "-m", "mitsuba_eventfield.cli", "render",
                        os.path.join(ROOT, "scenes", "demo", "demo.xml"), "-o", str(tmp_path / "d.h5"), "-D",
                        "width=32", "-D", "height=24", "--duration", "0.05", "--steps", "200"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert 1 <= r.stderr.count("rendering:") <= 4, r.stderr.count("rendering:")
    total = re.match(r"(\d+) events", r.stdout).group(1)        # the bar's last count is the render's total
    assert r.stderr.rstrip().endswith(f", {total} events"), r.stderr[-300:]


def test_frames_asked_for_with_no_time_left_are_one_line():
    """--fps from a start at the stream's very end (--start-time there) or on a stream of no length: no frame
    interval fits, and the refusal divided by the time left (a ZeroDivisionError)."""
    import types

    import mitsuba_eventfield as ef
    from mitsuba_eventfield.cli.lightfield import _reconstruct_times
    ev = ef.EventStream([1, 2], [1, 2], [1000, 2000], [1, -1], 8, 6, {"t_start_us": 0, "duration_us": 4000})
    a = types.SimpleNamespace(times=None, fps=250.0, file="s.h5")
    assert _reconstruct_times(a, ev, None).tolist() == [0.004]                 # one whole interval: one frame
    a.fps = 100.0
    with pytest.raises(ef.EventFieldError, match=r"--fps 100: a frame every 10 ms, longer than the stream's 4\.000 "
                                                 r"ms from 0\.000 ms: ask for at least 250 fps, or give --times"):
        _reconstruct_times(a, ev, None)
    with pytest.raises(ef.EventFieldError, match="from 4.000 ms: no time is left after it for a frame"):
        _reconstruct_times(a, ev, 0.004)


def test_a_recording_without_contrast_or_optics_names_both(tmp_path, capsys):
    """A camera recording carries neither contrast thresholds nor optics: refocus and depth name both missing
    options in their one line (they named the contrast, then on the next run the optics)."""
    import mitsuba_eventfield as ef
    rec = str(tmp_path / "rec.npz")
    ef.write_events(rec, ef.EventStream([1, 2], [1, 2], [10, 20], [1, -1], 8, 6))
    for argv in (["refocus", rec, "-o", str(tmp_path / "r.png"), "--depth", "1"],
                 ["depth", rec, "-o", str(tmp_path / "d.png"), "--near", "0.5", "--far", "2"]):
        assert cli.main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert "pass --contrast ON[,OFF]" in err and "nor optics: pass --calibration" in err and "\n" not in err, err
    assert cli.main(["refocus", rec, "-o", str(tmp_path / "r.png"), "--depth", "1", "--contrast", "0.2"]) == 2
    assert "the recording carries no optics" in capsys.readouterr().err         # the other one, alone
    assert not list(tmp_path.glob("*.png"))
