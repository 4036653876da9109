"""An application's output folder (``atomic.output_dir_run``): a user's file in it is never replaced, and a run
that stops early (an error, an interrupt, a kill) leaves what it wrote listed in the folder's manifest, so the
next run replaces those files instead of refusing them as the user's."""
import json
import os
import subprocess
import sys

import pytest

from mitsuba_eventfield.atomic import CLAIMS, MANIFEST, output_dir_run, write_json
from mitsuba_eventfield.errors import EventFieldError


def _listed(folder):
    with open(os.path.join(folder, MANIFEST)) as f:
        return json.load(f)["files"]


@pytest.mark.parametrize("made_before", [False, True])
def test_an_interrupted_run_leaves_its_files_listed_and_the_next_run_replaces_them(tmp_path, made_before):
    out = tmp_path / "out"
    if made_before:
        out.mkdir()
    with pytest.raises(KeyboardInterrupt):
        with output_dir_run(str(out), "test"):
            out.mkdir(exist_ok=True)                      # an application makes its folder
            write_json(str(out / "a.json"), {"run": 1})
            raise KeyboardInterrupt
    assert _listed(out) == ["a.json"]
    with output_dir_run(str(out), "test"):
        write_json(str(out / "a.json"), {"run": 2})            # was refused as a file eventfield did not write
    assert json.loads((out / "a.json").read_text()) == {"run": 2} and _listed(out) == ["a.json"]


def test_a_killed_run_leaves_its_files_listed(tmp_path):
    """Listed before it is written: a process killed outright runs no cleanup at all."""
    out = tmp_path / "out"
    script = ("import os, sys\nfrom mitsuba_eventfield.atomic import output_dir_run, write_json\n"
              "with output_dir_run(sys.argv[1], 'test'):\n"
              "    os.mkdir(sys.argv[1])\n    write_json(os.path.join(sys.argv[1], 'a.json'), {})\n    os._exit(9)\n")
    r = subprocess.run([sys.executable, "-c", script, str(out)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 9, r.stderr
    assert (out / CLAIMS).read_text() == "a.json\n" and not (out / MANIFEST).exists()
    with output_dir_run(str(out), "test"):
        write_json(str(out / "a.json"), {"run": 2})
    assert _listed(out) == ["a.json"] and not (out / CLAIMS).exists()


def test_a_claim_is_a_line_appended_and_the_manifest_is_written_once(tmp_path):
    """Rewriting the whole manifest for every file made a run of 2,000 frames quadratic (3.6 s of listing):
    during the run each file is a line of the claims, and the manifest is written at its end."""
    out = tmp_path / "out"
    out.mkdir()
    with output_dir_run(str(out), "test"):
        for i in range(300):
            write_json(str(out / f"f{i:04d}.json"), {})
        assert not (out / MANIFEST).exists()
        assert (out / CLAIMS).read_text().splitlines() == [f"f{i:04d}.json" for i in range(300)]
    assert len(_listed(out)) == 300 and not (out / CLAIMS).exists()


def test_a_failed_run_into_a_new_folder_that_wrote_nothing_leaves_no_folder(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(ValueError):
        with output_dir_run(str(out), "test"):
            out.mkdir()
            raise ValueError
    assert not out.exists()


def test_a_users_file_is_kept_and_a_later_one_of_the_runs_replaced(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "mine.json").write_text("the user's")
    with pytest.raises(EventFieldError, match="a file eventfield did not write .* is kept, not replaced"):
        with output_dir_run(str(out), "test"):
            write_json(str(out / "ours.json"), {})
            write_json(str(out / "mine.json"), {})
    assert (out / "mine.json").read_text() == "the user's" and _listed(out) == ["ours.json"]
    assert not (out / CLAIMS).exists()
    assert "1 other files stay beside the new ones" in capsys.readouterr().err
    with output_dir_run(str(out), "test"):                  # the run's own file is replaced, the user's stays
        write_json(str(out / "ours.json"), {"run": 2})
    assert _listed(out) == ["ours.json"] and (out / "mine.json").read_text() == "the user's"


def test_a_reused_folder_is_announced_as_replaced_only_if_the_run_succeeds(tmp_path, capsys):
    """The warning said an earlier run's files "are replaced or removed" before a run that then failed and
    replaced nothing: it says "if this run succeeds", and a failed run leaves them as they were."""
    out = tmp_path / "out"
    with output_dir_run(str(out), "test"):
        out.mkdir(exist_ok=True)
        write_json(str(out / "a.json"), {"run": 1})
    capsys.readouterr()
    with pytest.raises(EventFieldError):
        with output_dir_run(str(out), "test"):
            raise EventFieldError("a bad argument")
    assert "1 files of an earlier run are replaced or removed if this run succeeds" in capsys.readouterr().err
    assert json.loads((out / "a.json").read_text()) == {"run": 1} and _listed(out) == ["a.json"]
