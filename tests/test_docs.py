"""Docs that cannot rot: every command and Python snippet in README.md and docs/*.md runs as written, in file
order, in a scratch folder that sees the bundled scenes, at the reduced film size EVENTFIELD_FILM (README,
"Docs test"). A command must exit 0 within COMMAND_LIMIT_S and leave the files it names with -o; a Python
block must run (the blocks of one file share one namespace, as a reader's session would).

A line (or Python block) marked ``# docs-test: film WxH`` runs at that size instead (focus tracking loses the
small dart at 64x48). Not run, by design (each line says why with ``# docs-test: not run (...)``): ``./run`` itself (CI runs it),
re-blessing the repository's regression images. Hardware lines (``--resource``, ``VisaTransport(...)``) run
against the simulated instrument instead.
"""
import glob
import os
import re
import shutil
import subprocess
import sys
import time

import pytest
from conftest import ROOT

FILM = "64x48"
COMMAND_LIMIT_S = 240          # per command or Python block, at the reduced size on 2 cores
NOT_RUN = "# docs-test: not run"
FILM_MARK = re.compile(r"docs-test: film (\d+x\d+)")      # a larger reduced size where a scene needs it


def _blocks(path):
    """(language, first line number, text) of every bash and python block."""
    text = open(path).read()
    for m in re.finditer(r"```(bash|python)\n(.*?)```", text, re.S):
        yield m.group(1), text[:m.start()].count("\n") + 2, m.group(2)


def _commands(block: str):
    """Shell commands of a bash block: continuations joined, comments and blank lines dropped."""
    joined = re.sub(r"\\\n\s*", " ", block)
    for line in joined.splitlines():
        if not line.strip() or line.strip().startswith("#"):
            continue
        yield line


def _simulated(command: str) -> str:
    """A hardware command as it runs here: against the simulated instrument, for half a second."""
    command = re.sub(r"--resource\s+\S+", "--simulate", command)
    if " device scan " in f" {command} " and "--duration" not in command:
        command = command.split("#")[0] + " --duration 0.5"
    return command


def _outputs(command: str):
    return re.findall(r"(?:-o|--output|--metadata|--preview)\s+(\S+)", command.split(" #")[0])


@pytest.fixture()
def scratch(tmp_path, monkeypatch):
    os.symlink(os.path.join(ROOT, "scenes"), tmp_path / "scenes")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("EVENTFIELD_FILM", FILM)
    monkeypatch.setenv("PATH", os.path.dirname(sys.executable) + os.pathsep + os.environ["PATH"])
    return tmp_path


def _variant_missing(command: str) -> bool:
    """A command that forces a backend this Mitsuba build lacks (the GPU machine's bundle has the CUDA variants
    only: ../shared/gpu, docs/design.md); it runs wherever that backend is installed, CI included."""
    import importlib.util
    forced = re.search(r"--variant\s+(llvm|cuda)\b", command)
    return bool(forced) and importlib.util.find_spec(f"mitsuba.{forced[1]}_ad_mono") is None


def _run_bash(path, line_no, block, scratch):
    for command in _commands(block):
        if command.startswith("./run") or NOT_RUN in command or _variant_missing(command):
            continue
        command = _simulated(command)
        film = FILM_MARK.search(command)
        env = dict(os.environ, EVENTFIELD_FILM=film[1] if film else FILM)
        t0 = time.perf_counter()
        r = subprocess.run(command, shell=True, cwd=scratch, capture_output=True, text=True, timeout=COMMAND_LIMIT_S,
                           env=env)
        took = time.perf_counter() - t0
        where = f"{os.path.relpath(path, ROOT)} (block at line {line_no}): {command}"
        assert r.returncode == 0, f"{where}\nexit {r.returncode}: {r.stderr[-1500:]}"
        assert took < COMMAND_LIMIT_S, f"{where}: {took:.0f} s"
        for out in _outputs(command):
            root, ext = os.path.splitext(str(scratch / out))
            written = [p for p in [root + ext] + glob.glob(root + "_*" + ext) if os.path.exists(p)]  # _<suffix>: several
            assert written and all(os.path.isdir(p) or os.path.getsize(p) > 0 for p in written), f"{where}: no {out}"


def _run_python(path, line_no, block, namespace):
    code = block.replace('VisaTransport("TCPIP0::...::INSTR")', 'simulated("keysight")')   # hardware: simulated
    code = "\n".join(line for line in code.splitlines() if NOT_RUN not in line)
    film = FILM_MARK.search(code)
    os.environ["EVENTFIELD_FILM"] = film[1] if film else FILM       # restored by the fixture's monkeypatch
    t0 = time.perf_counter()
    try:
        exec(compile(code, f"{os.path.relpath(path, ROOT)}:{line_no}", "exec"), namespace)
    except Exception as e:
        pytest.fail(f"{os.path.relpath(path, ROOT)} (python block at line {line_no}): {type(e).__name__}: {e}")
    assert time.perf_counter() - t0 < COMMAND_LIMIT_S


DOCS = [os.path.join(ROOT, "README.md")] + sorted(glob.glob(os.path.join(ROOT, "docs", "**", "*.md"), recursive=True))


@pytest.mark.parametrize("path", [p for p in DOCS if any(True for _ in _blocks(p))],
                         ids=lambda p: os.path.relpath(p, ROOT))
def test_every_example_runs_as_written(path, scratch):
    namespace = {"__name__": "__main__"}      # as a script runs them: a block's `if __name__ == "__main__":` too
    for lang, line_no, block in _blocks(path):
        if lang == "bash":
            _run_bash(path, line_no, block, scratch)
        else:
            _run_python(path, line_no, block, namespace)
    shutil.rmtree(scratch / "out", ignore_errors=True)
