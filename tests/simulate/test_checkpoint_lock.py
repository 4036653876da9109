"""A checkpointed render owns its resume folder while it runs, and a stop that a library swallowed is not a
success (a fault-injection audit, 2026-11-28): a second process told by the refusal to "add --resume" resumed
from the live render's checkpoint, overwrote its segments and state, and the first render then exited 0 with
2 to 3 thousand events missing; a Ctrl-C during the final merge published the file with exit status 0."""
import os

import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.errors import STOP_SIGNALS
from mitsuba_eventfield.simulate import checkpoint
from mitsuba_eventfield.simulate import render as render_mod

from test_checkpoint import DEMO, _same_file

KW = dict(duration=0.004, steps=8)


def test_a_live_checkpointed_render_refuses_a_second_render_of_its_output(tmp_path, monkeypatch):
    """While the render runs, a resume, a checkpointed and a plain render of the same output are each refused
    in one line naming the process; the first then finishes to the file of an undisturbed render."""
    timed = ef.load_scene(DEMO, width=16, height=12)
    ref, out = str(tmp_path / "ref.h5"), str(tmp_path / "out.h5")
    ef.render_events(timed, output=ref, **KW)
    other = ef.load_scene(DEMO, width=16, height=12)    # the second render's own scene, as in another process
    real, refusals = render_mod._Loop._step_events, []

    def step_events(self, *a):
        if len(refusals) == 0 and os.path.isfile(out + ".resume/checkpoint.json"):
            refusals.append("checked")
            for extra in (dict(resume=True), dict(checkpoint_s=1e-9), {}):
                with pytest.raises(ef.EventFieldError) as e:
                    ef.render_events(other, output=out, **KW, **extra)
                refusals.append(str(e.value))
        return real(self, *a)
    monkeypatch.setattr(render_mod._Loop, "_step_events", step_events)
    ef.render_events(timed, output=out, checkpoint_s=1e-9, **KW)
    monkeypatch.undo()
    assert len(refusals) == 4 and all(r == f"{out}.resume: another process (pid {os.getpid()}) is rendering this "
                                      "output now: wait for it to end, or render to another path"
                                      for r in refusals[1:]), refusals
    assert _same_file(ref, out) and not os.path.exists(out + ".resume")
    ef.render_events(timed, output=out, checkpoint_s=1e-9, **KW)         # the lock went with the render


def test_a_stop_swallowed_during_the_merge_publishes_nothing_and_keeps_the_checkpoint(tmp_path, monkeypatch):
    """The stop is recorded while the segments are merged into the output (not at a segment's cut): the
    output is not published, the checkpoint stays, and the resume gives the undisturbed file."""
    timed = ef.load_scene(DEMO, width=16, height=12)
    ref, out = str(tmp_path / "ref.h5"), str(tmp_path / "out.h5")
    ef.render_events(timed, output=ref, **KW)
    merges = []

    class Merging(checkpoint.H5EventWriter):
        def close(self, *a, **k):
            if self.path == os.path.abspath(out):         # the merged output, not a segment
                merges.append(self.path)
                STOP_SIGNALS.append(2)   # as if a Ctrl-C had been recorded and its exception lost in a library
            return super().close(*a, **k)
    monkeypatch.setattr(checkpoint, "H5EventWriter", Merging)
    try:
        with pytest.raises(KeyboardInterrupt):
            ef.render_events(timed, output=out, checkpoint_s=1e-9, **KW)
    finally:
        STOP_SIGNALS.clear()
        monkeypatch.undo()
    assert merges == [os.path.abspath(out)]
    assert not os.path.exists(out) and os.path.isfile(out + ".resume/checkpoint.json")
    assert [n for n in os.listdir(tmp_path) if n.startswith("out")] == ["out.h5.resume"]   # no partial file
    ef.render_events(timed, output=out, resume=True, **KW)
    assert _same_file(ref, out)


def test_a_file_system_without_flock_renders_unguarded(tmp_path, monkeypatch):
    """Only a held lock means another renderer: flock refused outright (ENOLCK: some FUSE and SMB mounts)
    was read as "another process is rendering" and refused every checkpointed render there."""
    import errno
    import fcntl

    def no_flock(fd, op):
        raise OSError(errno.ENOLCK, os.strerror(errno.ENOLCK))
    monkeypatch.setattr(fcntl, "flock", no_flock)
    timed = ef.load_scene(DEMO, width=16, height=12)
    ef.render_events(timed, output=str(tmp_path / "a.h5"), checkpoint_s=1e-9, **KW)
    assert os.listdir(tmp_path) == ["a.h5"]


def test_a_full_disk_says_the_checkpoint_is_kept(tmp_path, monkeypatch, capsys):
    """A checkpointed render that ran out of disk said "nothing was kept" while its work up to the last
    checkpoint waited in OUT.h5.resume/ for --resume."""
    import errno
    from mitsuba_eventfield.cli.main import main as cli
    monkeypatch.setattr(checkpoint, "KEPT", [])
    out = str(tmp_path / "c.h5")
    real, calls = render_mod._Loop._step_events, {"n": 0}

    def step_events(self, *a):
        calls["n"] += 1
        if calls["n"] == 5:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), out)
        return real(self, *a)
    monkeypatch.setattr(render_mod._Loop, "_step_events", step_events)
    code = cli(["render", DEMO, "-D", "width=16", "-D", "height=12", "--duration", "0.004", "--steps", "8",
                "--quiet", "-o", out, "--checkpoint-every", "1e-9"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err == (f"eventfield: error: disk full while writing {out} (no partial output kept); its "
                                 f"last checkpoint is kept in {out}.resume: run the same command with --resume to "
                                 "go on"), err
    assert os.path.isfile(out + ".resume/checkpoint.json")
