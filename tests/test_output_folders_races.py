"""Output folders under races and failures at their edges (a second review, 2026-11-28): a live run's kept
files taken for a killed run's, a failed manifest write after the earlier files were gone, an interrupt
that hid the error that failed the run, an output folder inside another, parent folders a failed run made."""
import json
import os
import signal
import threading

import pytest

from mitsuba_eventfield.atomic import updating, write_json
from mitsuba_eventfield.errors import interrupts_held
from mitsuba_eventfield.output_folders import BACKUP, MANIFEST, output_dir_run


def _listed(folder):
    with open(os.path.join(folder, MANIFEST)) as f:
        return json.load(f)["files"]


def _sigint_soon():
    main = threading.main_thread().ident
    signal.pthread_kill(main, signal.SIGINT)


def test_a_held_signal_is_raised_after_cleanup_but_never_over_the_error_that_failed_the_run():
    with pytest.raises(KeyboardInterrupt):
        with interrupts_held():
            _sigint_soon()
    with interrupts_held(replay=False):      # a finished run's last steps: not called interrupted
        _sigint_soon()
    with pytest.raises(OSError, match="disk full"):      # the error stays the error
        try:
            raise OSError("disk full")
        except OSError:
            with interrupts_held():
                _sigint_soon()
            raise


def test_a_live_runs_kept_files_are_not_taken_for_a_killed_runs(tmp_path):
    """A folder of kept files whose lock another process holds is a live run's: left alone (a probe's failed
    lock used to count as "no flock here", and the process id decided)."""
    import fcntl
    out = tmp_path / "out"
    out.mkdir()
    live = out / f"{BACKUP}999999-livelive"
    live.mkdir()
    (live / "a.json").write_text("kept by a live run")
    fd = os.open(live, os.O_RDONLY)            # (a descriptor of its own stands for the other process: flock
    fcntl.flock(fd, fcntl.LOCK_EX)             # locks belong to open descriptions, not to processes)
    try:
        with output_dir_run(str(out), "test"):
            write_json(str(out / "b.json"), 1)
    finally:
        os.close(fd)
    assert (live / "a.json").read_text() == "kept by a live run" and not (out / "a.json").exists()


def test_a_failed_manifest_write_puts_the_folder_back(tmp_path, monkeypatch):
    from mitsuba_eventfield import output_folders
    out = tmp_path / "out"
    with output_dir_run(str(out), "test"):
        out.mkdir()
        write_json(str(out / "a.json"), 1)
        write_json(str(out / "old.json"), 1)
    real = output_folders.write_json

    def full(path, *a, **k):
        if path.endswith(MANIFEST):
            raise OSError(28, "No space left on device", path)
        return real(path, *a, **k)
    monkeypatch.setattr(output_folders, "write_json", full)
    with pytest.raises(OSError):
        with output_dir_run(str(out), "test"):
            write_json(str(out / "a.json"), 2)
            write_json(str(out / "new.json"), 2)
    assert json.loads((out / "a.json").read_text()) == 1 and (out / "old.json").exists()
    assert not (out / "new.json").exists() and _listed(out) == ["a.json", "old.json"]
    assert not [n for n in os.listdir(out) if n.startswith(MANIFEST + ".")]


def test_an_output_folder_inside_another_keeps_its_own_files(tmp_path):
    outer, inner = tmp_path / "a", tmp_path / "a" / "sub"
    with output_dir_run(str(outer), "outer"):
        outer.mkdir()
        write_json(str(outer / "a.json"), 1)
        with output_dir_run(str(inner), "inner"):
            inner.mkdir()
            write_json(str(inner / "b.json"), 1)
    assert _listed(outer) == ["a.json"] and _listed(inner) == ["b.json"]
    with output_dir_run(str(outer), "outer"):              # a rerun of the outer one leaves the inner one's
        write_json(str(outer / "c.json"), 1)
    assert (inner / "b.json").exists() and _listed(outer) == ["c.json"]


def test_a_failed_run_removes_the_parent_folders_it_made(tmp_path):
    out = tmp_path / "x" / "y" / "out"
    with pytest.raises(ValueError):
        with output_dir_run(str(out), "test"):
            out.mkdir(parents=True)
            write_json(str(out / "a.json"), 1)
            raise ValueError
    assert os.listdir(tmp_path) == []


def test_a_calibration_update_goes_on_without_flock_or_folder(tmp_path, monkeypatch):
    import errno
    import fcntl

    def no_flock(fd, op):
        raise OSError(errno.ENOLCK, os.strerror(errno.ENOLCK))
    monkeypatch.setattr(fcntl, "flock", no_flock)
    with updating(str(tmp_path / "cal.json")):
        pass
    with updating(str(tmp_path / "missing" / "cal.json")):    # the write itself then says the folder is missing
        pass
