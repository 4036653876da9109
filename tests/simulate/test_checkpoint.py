"""Checkpoints and --resume: an interrupted render (an exception, SIGKILL) continued from its last checkpoint
gives the file of an uninterrupted one; the output path never holds a partial file."""
import os
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.cli.main import main as cli
from mitsuba_eventfield.simulate import render as render_mod

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DEMO = os.path.join(ROOT, "scenes", "demo", "demo.xml")
GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")


def _same_file(a, b):
    """Same events, same millisecond index, same metadata apart from what says when and how it ran."""
    ea, eb = ef.read_events(a), ef.read_events(b)
    with h5py.File(a, "r") as fa, h5py.File(b, "r") as fb:
        same_index = np.array_equal(fa["ms_to_idx"][:], fb["ms_to_idx"][:]) and \
            int(fa["t_offset"][()]) == int(fb["t_offset"][()])
    volatile = ("created_utc", "command", "render")
    meta_a = {k: v for k, v in ea.meta.items() if k not in volatile}
    meta_b = {k: v for k, v in eb.meta.items() if k not in volatile}
    return len(ea) > 0 and ea.equals(eb) and same_index and meta_a == meta_b


def _interrupt_at(monkeypatch, step):
    real = render_mod._Loop._step_events
    calls = {"n": 0}

    def step_events(self, *a):
        calls["n"] += 1
        if calls["n"] == step:
            raise KeyboardInterrupt
        return real(self, *a)
    monkeypatch.setattr(render_mod._Loop, "_step_events", step_events)


@pytest.mark.parametrize("scene, kw", [
    (DEMO, dict(duration=0.01, steps=20)),
    (DEMO, dict(duration=0.01, adaptive="log-change", max_log_change=0.5, min_step=2e-4, preset="davis346",
                pixel={"shot_noise_hz": 200.0})),
    (DEMO, dict(duration=0.01, adaptive="motion", px_per_step=0.1)),   # 24 steps placed by the objects' motion
    (GALVO, dict(duration=0.008, steps=64)),                        # a reused scan period, then copies
    (DEMO, dict(duration=0.1)),                     # the default steps (placed by the motion), chosen again alike on resume
    # uniform steps through the step batches with every effect (generator, last emissions, readout cap saved)
    (DEMO, dict(duration=0.01, steps=20, preset="davis346", pixel={"shot_noise_hz": 200.0, "readout_cap": 1.5e6})),
    # starting 12.5 ms in: the resumed file's segments keep the render's millisecond offset (/t_offset)
    (DEMO, dict(duration=0.01, steps=20, t_start=0.0125)),
    # a warm-up (4 of its 24 steps): interrupted after it, the counters read where it ended survive the resume
    (DEMO, dict(duration=0.01, steps=20, warmup=0.002, pixel={"shot_noise_hz": 200.0})),
    # interrupted during the warm-up (32 of 96 steps), a galvo's reused period and copies after it
    (GALVO, dict(duration=0.008, steps=64, warmup=0.004, preset="davis346")),
], ids=["uniform-ideal", "adaptive-davis346-noise", "adaptive-motion", "galvo-reuse", "default-steps",
        "uniform-davis346-batched", "late-start", "warmup-noise", "warmup-galvo-davis346"])
def test_interrupted_render_resumes_to_the_uninterrupted_file(tmp_path, monkeypatch, capsys, scene, kw):
    timed = ef.load_scene(scene, width=48, height=36)
    ref, out = str(tmp_path / "ref.h5"), str(tmp_path / "out.h5")
    ef.render_events(timed, output=ref, **kw)
    _interrupt_at(monkeypatch, 9)
    with pytest.raises(KeyboardInterrupt):
        ef.render_events(timed, output=out, checkpoint_s=1e-9, **kw)         # a checkpoint before every step
    monkeypatch.undo()
    folder = out + ".resume"
    assert not os.path.exists(out) and os.path.isfile(os.path.join(folder, "checkpoint.json"))
    assert cli(["info", folder]) == 0
    assert "partial render of" in capsys.readouterr().out
    summary = ef.render_events(timed, output=out, resume=True, **kw)
    assert any("resumed from checkpoint" in n for n in summary.notes)
    assert _same_file(ref, out) and not os.path.exists(folder)
    # the timing-accuracy estimate of the first steps survives the resume (it was lost with them), note and all
    ra, rb = (ef.read_events(p).meta["render"] for p in (ref, out))
    assert ra["timing_limit"] == rb["timing_limit"]
    counters = ("noise_events", "dropped_readout", "dropped_refractory", "events", "on")
    assert [ra[c] for c in counters] == [rb[c] for c in counters]
    assert [n for n in ra["notes"] if "timing accuracy" in n] == [n for n in rb["notes"] if "timing accuracy" in n]


def test_an_interrupted_command_says_its_checkpoint_is_kept(tmp_path, monkeypatch, capsys):
    """Ctrl-C on a checkpointed render printed only "interrupted (no partial output kept)": the user could not
    tell that the work up to the last checkpoint was kept and --resume goes on from it."""
    from mitsuba_eventfield.simulate import checkpoint
    monkeypatch.setattr(checkpoint, "KEPT", [])
    out = str(tmp_path / "c.h5")
    _interrupt_at(monkeypatch, 5)
    code = cli(["render", DEMO, "-D", "width=16", "-D", "height=12", "--duration", "0.004", "--steps", "8",
                "--quiet", "-o", out, "--checkpoint-every", "1e-9"])
    err = capsys.readouterr().err.strip()
    assert code == 130 and err == (f"eventfield: interrupted (no partial output kept); its last checkpoint is kept "
                                   f"in {out}.resume: run the same command with --resume to go on"), err
    _interrupt_at(monkeypatch, 5)
    code = cli(["render", DEMO, "-D", "width=16", "-D", "height=12", "--duration", "0.004", "--steps", "8",
                "--quiet", "-o", str(tmp_path / "plain.h5")])           # the next command, in the same process
    assert code == 130 and capsys.readouterr().err.strip() == "eventfield: interrupted (no partial output kept)"


def test_sigkill_then_resume_from_the_command_line(tmp_path):
    """A render killed with SIGKILL (no ``finally`` runs) leaves the last checkpoint; --resume finishes it."""
    out, ref = str(tmp_path / "k.h5"), str(tmp_path / "ref.h5")
    args = [DEMO, "-D", "width=48", "-D", "height=36", "--duration", "0.03", "--steps", "300", "--quiet"]
    assert cli(["render", *args, "-o", ref]) == 0
    cmd = [sys.executable, "-m", "mitsuba_eventfield.cli", "render", *args, "-o", out, "--checkpoint-every", "0.02"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    state = os.path.join(out + ".resume", "checkpoint.json")
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None:
        if os.path.isfile(state) and '"number": 2' in open(state).read():
            break
        time.sleep(0.01)
    assert proc.poll() is None, "the render finished before it could be killed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not os.path.exists(out)
    assert cli(["render", *args, "-o", out, "--resume", "--checkpoint-every", "0.02"]) == 0
    assert _same_file(ref, out) and not os.path.exists(out + ".resume")


def test_resume_refusals_are_one_line(tmp_path, capsys):
    out = str(tmp_path / "r.h5")
    args = ["render", DEMO, "-D", "width=16", "-D", "height=12", "--duration", "0.002", "--steps", "4", "--quiet"]
    assert cli([*args, "-o", out, "--resume"]) == 2
    err = capsys.readouterr().err
    assert "nothing to resume (no checkpoint here); render without --resume" in err
    assert cli([*args, "-o", out]) == 0 and os.path.exists(out)                  # finished: its output is there
    capsys.readouterr()
    assert cli([*args, "-o", out, "--resume"]) == 2
    assert f"nothing to resume: no checkpoint, and {out} is there (that render finished)" in capsys.readouterr().err
    assert cli([*args, "-o", str(tmp_path / "r.npz"), "--checkpoint-every", "5"]) == 2
    assert "need an HDF5 output" in capsys.readouterr().err
    os.makedirs(out + ".resume")
    assert cli([*args, "-o", out]) == 2
    assert "add --resume" in capsys.readouterr().err


def test_resume_with_other_options_names_the_difference(tmp_path, monkeypatch, capsys):
    timed = ef.load_scene(DEMO, width=16, height=12)
    out = str(tmp_path / "d.h5")
    _interrupt_at(monkeypatch, 3)
    with pytest.raises(KeyboardInterrupt):
        ef.render_events(timed, 0.004, steps=8, output=out, checkpoint_s=1e-9)
    monkeypatch.undo()
    with pytest.raises(ef.EventFieldError, match=r"another render: spp was 4, now 8"):
        ef.render_events(timed, 0.004, steps=8, spp=8, output=out, resume=True)
    assert not os.path.exists(out)


def test_a_resume_with_another_define_is_refused(tmp_path, monkeypatch):
    """The scene's -D values are part of what a resume must repeat (a changed max_depth was resumed into a
    file that matched neither render); the file's metadata records them."""
    out = str(tmp_path / "d.h5")
    _interrupt_at(monkeypatch, 3)
    with pytest.raises(KeyboardInterrupt):
        ef.render_events(ef.load_scene(DEMO, width=16, height=12), 0.004, steps=8, output=out, checkpoint_s=1e-9)
    monkeypatch.undo()
    other = ef.load_scene(DEMO, width=16, height=12, max_depth=3)
    with pytest.raises(ef.EventFieldError, match=r"another render: scene\.defines\.max_depth was null, now \"3\""):
        ef.render_events(other, 0.004, steps=8, output=out, resume=True)
    ef.render_events(ef.load_scene(DEMO, width=16, height=12), 0.004, steps=8, output=out, resume=True)
    assert ef.read_events(out).meta["scene"]["defines"] == {"height": "12", "width": "16"}


def test_interrupt_before_any_checkpoint_leaves_nothing(tmp_path, monkeypatch):
    timed = ef.load_scene(DEMO, width=16, height=12)
    _interrupt_at(monkeypatch, 2)
    with pytest.raises(KeyboardInterrupt):
        ef.render_events(timed, 0.004, steps=8, output=str(tmp_path / "n.h5"), checkpoint_s=3600)
    assert os.listdir(tmp_path) == []


def test_a_checkpointed_render_says_it_renders_the_static_pixels_every_step(tmp_path):
    """The fan under its 250 Hz scan reuses its static pixels a period at a time; a checkpointed render does
    not (the cache is not in a checkpoint) and its events differed without a word. The summary and the file's
    metadata now say so, and the plain render says it reused them."""
    fan = os.path.join(ROOT, "scenes", "fan", "fan.xml")
    kw = dict(duration=0.16, steps=320)                 # 40 scan periods of 8 steps: the fewest the reuse takes
    plain = ef.render_events(ef.load_scene(fan, width=64, height=48), output=str(tmp_path / "plain.h5"), **kw)
    saved = ef.render_events(ef.load_scene(fan, width=64, height=48), output=str(tmp_path / "saved.h5"),
                             checkpoint_s=1e6, **kw)
    assert plain.as_dict()["static_pixels"] is not None and saved.as_dict()["static_pixels"] is None
    said = [n for n in saved.notes if "static pixels not reused: a checkpointed render" in n]
    assert said and said[0] in ef.read_events(str(tmp_path / "saved.h5")).meta["render"]["notes"]
    assert not any("checkpointed" in n for n in plain.notes)
