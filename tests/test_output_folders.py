"""An application's output folder (``output_folders.output_dir_run``): a user's file in it is never replaced; a run that
fails or is stopped leaves the folder as it found it (what it replaced put back, what it added removed), and a
run killed outright leaves what it wrote listed in the folder's claims, so the next run replaces those files
instead of refusing them as the user's, and puts back what it had replaced."""
import json
import os
import subprocess
import sys

import pytest

from mitsuba_eventfield.atomic import write_json
from mitsuba_eventfield.output_folders import CLAIMS, MANIFEST, output_dir_run
from mitsuba_eventfield.errors import EventFieldError


def _killed_run(out, *lines):
    """A run into ``out`` that does ``lines`` (Python, ``out`` the folder's path), then dies outright (no
    cleanup runs), in a process of its own."""
    script = ("import os, sys\nfrom mitsuba_eventfield.atomic import write_json\n"
              "from mitsuba_eventfield.output_folders import output_dir_run\nout = sys.argv[1]\n"
              "with output_dir_run(out, 'test'):\n" + "".join(f"    {line}\n" for line in lines) + "    os._exit(9)\n")
    r = subprocess.run([sys.executable, "-c", script, str(out)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 9, r.stderr


def _listed(folder):
    with open(os.path.join(folder, MANIFEST)) as f:
        return json.load(f)["files"]


@pytest.mark.parametrize("made_before", [False, True])
def test_an_interrupted_run_into_a_new_folder_leaves_nothing_new(tmp_path, made_before):
    """What a stopped run added goes with it (a folder it made too); the next run writes as if it had not run."""
    out = tmp_path / "out"
    if made_before:
        out.mkdir()
    with pytest.raises(KeyboardInterrupt):
        with output_dir_run(str(out), "test"):
            out.mkdir(exist_ok=True)                      # an application makes its folder
            write_json(str(out / "a.json"), {"run": 1})
            raise KeyboardInterrupt
    assert not (out / "a.json").exists() and out.exists() == made_before
    assert not made_before or os.listdir(out) == []           # (no manifest of nothing either)
    with output_dir_run(str(out), "test"):
        out.mkdir(exist_ok=True)
        write_json(str(out / "a.json"), {"run": 2})
    assert json.loads((out / "a.json").read_text()) == {"run": 2} and _listed(out) == ["a.json"]


def _run(out, files, fail=None):
    """A run writing ``files`` (name -> content) into ``out``, raising ``fail`` (an exception) at its end."""
    with output_dir_run(str(out), "test"):
        out.mkdir(exist_ok=True)
        for name, content in files.items():
            write_json(str(out / name), content)
        if fail is not None:
            raise fail


def _contents(out):
    return {n: json.loads((out / n).read_text()) for n in sorted(os.listdir(out)) if not n.startswith(MANIFEST)}


@pytest.mark.parametrize("stop", [KeyboardInterrupt(), EventFieldError("bad"), "swallowed"])
def test_a_failed_rerun_puts_the_earlier_runs_files_back(tmp_path, stop):
    """A demo stopped half-way left a new event file and depth map beside the old metrics and figure, and said
    "no partial output kept": the files it replaced are put back and those it added removed, so the folder is
    the earlier run's again, manifest included. A stop signal a library swallowed (only recorded,
    ``errors.STOP_SIGNALS``) fails the run the same way, and publishes nothing from then on."""
    from mitsuba_eventfield.errors import STOP_SIGNALS
    out = tmp_path / "out"
    _run(out, {"a.json": 1, "b.json": 1})
    first = _contents(out)
    try:
        with pytest.raises(type(stop) if stop != "swallowed" else KeyboardInterrupt):
            with output_dir_run(str(out), "test"):
                write_json(str(out / "a.json"), 2)
                write_json(str(out / "c.json"), 2)
                if stop == "swallowed":
                    STOP_SIGNALS.append(2)
                    write_json(str(out / "b.json"), 2)       # refused: nothing published after a stop
                else:
                    raise stop
    finally:
        STOP_SIGNALS.clear()
    assert _contents(out) == first == {"a.json": 1, "b.json": 1} and _listed(out) == ["a.json", "b.json"]
    assert sorted(os.listdir(out)) == [MANIFEST, "a.json", "b.json"]      # nothing kept aside is left
    assert not [n for n in os.listdir(tmp_path) if n != "out"]


def test_a_rerun_within_the_second_lists_only_its_own_files(tmp_path):
    """Runs back to back: the first run's files were newer than "the start minus a second" (the allowance for
    coarse file times) and counted as the second run's, which then kept 80 frames where it wrote 40."""
    out = tmp_path / "out"
    _run(out, {f"f{i:02d}.json": 1 for i in range(40)})
    _run(out, {f"f{i:02d}.json": 2 for i in range(20)})
    assert _listed(out) == [f"f{i:02d}.json" for i in range(20)] and _contents(out) == {
        f"f{i:02d}.json": 2 for i in range(20)}


def test_a_killed_reruns_replaced_files_are_put_back_by_the_next_run(tmp_path, capsys):
    """A rerun killed outright (no cleanup) leaves the earlier files it replaced kept aside: the next run puts
    them back before it starts, and says so."""
    out = tmp_path / "out"
    _run(out, {"a.json": 1})
    _killed_run(out, "write_json(os.path.join(out, 'a.json'), 2)")
    assert json.loads((out / "a.json").read_text()) == 2
    assert [n for n in os.listdir(out) if n.startswith(MANIFEST + ".previous-")]
    capsys.readouterr()
    with pytest.raises(ValueError):
        _run(out, {"b.json": 3}, fail=ValueError())
    assert "put back 1 files" in capsys.readouterr().err
    assert _contents(out) == {"a.json": 1} and sorted(os.listdir(out)) == [MANIFEST, "a.json"]


def test_a_killed_run_leaves_its_files_listed(tmp_path):
    """Listed before it is written: a process killed outright runs no cleanup at all."""
    out = tmp_path / "out"
    _killed_run(out, "os.mkdir(out)", "write_json(os.path.join(out, 'a.json'), {})")
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
    # the failed run's own file went with it
    assert (out / "mine.json").read_text() == "the user's" and os.listdir(out) == ["mine.json"]
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


def test_parts_an_application_keeps_stay_when_a_later_part_fails(tmp_path):
    """``paper``: one result's failure must not cost the others (its refusal says their outputs are there):
    what was published before ``keep_outputs`` stays, replaced files included, and is listed."""
    from mitsuba_eventfield.output_folders import keep_outputs
    out = tmp_path / "out"
    _run(out, {"a.json": 1, "b.json": 1})
    with pytest.raises(EventFieldError):
        with output_dir_run(str(out), "test"):
            write_json(str(out / "a.json"), 2)
            write_json(str(out / "n.json"), 2)
            keep_outputs(str(out))
            write_json(str(out / "b.json"), 2)
            write_json(str(out / "m.json"), 2)
            raise EventFieldError("the second result failed")
    assert _contents(out) == {"a.json": 2, "b.json": 1, "n.json": 2} and _listed(out) == ["a.json", "b.json", "n.json"]
    assert sorted(os.listdir(out)) == [MANIFEST, "a.json", "b.json", "n.json"]


def test_a_killed_runs_kept_files_are_put_back_whatever_process_has_its_id_now(tmp_path, capsys):
    """The kept files' folder was told stale by its process id: a new run with the same id (containers reuse
    small ids) never put it back, and overwrote the only copy of the earlier file. Now by its lock: a folder
    nobody holds is a killed run's, here one named with this very process's id."""
    out = tmp_path / "out"
    _run(out, {"a.json": 1})
    stale = out / f"{MANIFEST}.previous-{os.getpid()}-0badf00d"
    stale.mkdir()
    os.replace(out / "a.json", stale / "a.json")
    write_json(str(out / "a.json"), "the killed run's")
    capsys.readouterr()
    with pytest.raises(ValueError):
        _run(out, {"b.json": 2}, fail=ValueError())     # (failed: the folder is what it was before it)
    assert "put back 1 files" in capsys.readouterr().err
    assert _contents(out) == {"a.json": 1} and not stale.exists() and _listed(out) == ["a.json"]


def test_a_stopped_run_removes_the_folders_it_made(tmp_path):
    """slomorf writes into frames/ and refocus/: a stopped run left them empty."""
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        with output_dir_run(str(out), "test"):
            (out / "frames" / "deep").mkdir(parents=True)
            write_json(str(out / "frames" / "deep" / "f.json"), 1)
            (out / "refocus").mkdir()
            raise KeyboardInterrupt
    assert not out.exists()
    out.mkdir()
    (out / "mine").mkdir()
    with pytest.raises(KeyboardInterrupt):
        with output_dir_run(str(out), "test"):
            (out / "frames").mkdir()
            raise KeyboardInterrupt
    assert os.listdir(out) == ["mine"]


def test_a_file_the_run_reads_from_its_folder_stays(tmp_path, monkeypatch):
    """The README's scan-rate sequence: ``--calibrate`` writes OUT/calibration.json, then ``--calibration
    OUT/calibration.json`` into the same folder read it and, succeeding without rewriting it, removed it as an
    earlier run's file: the documented command then failed ("calibration file not found"). A file a run reads
    stays, and stays listed (a later run that does not read it replaces or removes it, as any earlier output)."""
    import importlib
    cli_main = importlib.import_module("mitsuba_eventfield.cli.main")
    out = tmp_path / "scan"
    _run(out, {"calibration.json": {"pivot": 1}, "depth.json": {"run": 1}})
    read = []

    def fake_scanrate(a):            # reads its calibration, writes its depth maps
        with open(a.calibration) as f:
            read.append(json.load(f))
        write_json(os.path.join(a.output, "depth.json"), {"run": 2})
        return 0
    monkeypatch.setitem(cli_main.COMMANDS, "scanrate-depth", fake_scanrate)
    for _ in range(2):               # the same command twice, as a user reruns it
        assert cli_main.main(["scanrate-depth", "-o", str(out), "--calibration", str(out / "calibration.json")]) == 0
    assert read == [{"pivot": 1}] * 2 and sorted(_listed(out)) == ["calibration.json", "depth.json"]


def test_inputs_kept_by_output_dir_run(tmp_path):
    out = tmp_path / "out"
    _run(out, {"a.json": 1, "b.json": 2})
    with output_dir_run(str(out), "test", inputs=[str(out / "a.json"), str(tmp_path / "elsewhere.json")]):
        write_json(str(out / "b.json"), 3)
    assert sorted(os.listdir(out)) == sorted(["a.json", "b.json", MANIFEST])
    assert sorted(_listed(out)) == ["a.json", "b.json"]
    _run(out, {"b.json": 4})                   # a run that does not read it: a.json was an earlier run's output
    assert sorted(os.listdir(out)) == sorted(["b.json", MANIFEST])


@pytest.mark.parametrize("how", ["link to the input", "link to the folder", "dot-dot"])
def test_an_input_named_through_a_link_stays_too(tmp_path, how):
    """The input and the folder are matched by their real paths: an input named by a link to a file in the
    folder, or the folder given as a link, removed the input as an earlier run's output."""
    out = tmp_path / "scan"
    _run(out, {"calibration.json": {"pivot": 1}, "depth.json": {"run": 1}})
    folder, given = out, out / "calibration.json"
    if how == "link to the input":
        given = tmp_path / "cal.json"
        given.symlink_to(out / "calibration.json")
    elif how == "link to the folder":
        folder = tmp_path / "scanlink"
        folder.symlink_to(out)
    else:
        (tmp_path / "sub").mkdir()
        given = tmp_path / "sub" / ".." / "scan" / "calibration.json"
    with output_dir_run(str(folder), "test", inputs=[str(given)]):
        write_json(str(folder / "depth.json"), {"run": 2})
    assert sorted(os.listdir(out)) == sorted(["calibration.json", "depth.json", MANIFEST])
    assert sorted(_listed(out)) == ["calibration.json", "depth.json"]
