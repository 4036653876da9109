"""An application's output folder, changed as one piece (``output_dir_run``).

A folder carries ``.eventfield-outputs.json``, the files the last run wrote. A rerun into it warns; after it
succeeds the earlier run's files it did not rewrite are removed (40 frames then 24 left 16 stale frames mixed
in) and the manifest lists this run's files. A run that fails or is stopped puts back every file it replaced
and removes those it added and the folders it made, so the folder is the earlier run's again (a demo stopped
half-way mixed a new event file and depth map with the old metrics and figure). Files eventfield did not write
are never touched (only mentioned): a run that would write one of their names stops there with a one-line error.

How: ``atomic.publish`` (the one place an output file appears) asks :func:`before_replacing` first, which keeps
the file about to be replaced aside, as a hard link under ``.eventfield-outputs.json.previous-<pid>-<token>/``;
that folder is locked (``flock``) by its run, so a later run tells a killed run's folder (no lock: put back) from
a live one's, whatever process ids the system reuses. An application whose parts stand on their own (``paper``:
one result's failure does not cost the others) keeps what it has published so far with :func:`keep_outputs`.
Which files a run wrote is read from the files themselves (new, or another inode, time or size than before it
started): times alone counted an earlier run's files from the second before as this one's.
"""
from __future__ import annotations

import contextlib
import json
import os
import threading
import uuid

from .atomic import PARTIAL_TAG, _pid_alive, try_lock, write_json
from .errors import EventFieldError, interrupts_held

MANIFEST = ".eventfield-outputs.json"
CLAIMS = MANIFEST + ".claims"      # files a running application is about to write, a line each (``claim``)
BACKUP = MANIFEST + ".previous-"   # + "<pid>-<token>": the files a running application replaced

# files in an output folder in use that eventfield did not write: never replaced
_KEPT: set = set()
# output folders of running applications -> {"command", "files": listed, "published", "backed", "backup", ...}
_RUNS: dict = {}
_RUNS_LOCK = threading.Lock()


@contextlib.contextmanager
def output_dir_run(path: str, command: str, inputs=()):
    """An application writing into the folder ``path`` (module docstring). ``inputs``: files the run reads; one
    inside the folder that an earlier run wrote stays, and stays listed, when this run succeeds without rewriting
    it (``scanrate-depth --calibration out/scanrate/calibration.json``, as the README runs it after
    ``--calibrate``, removed the calibration it had just read)."""
    from .atomic import _nearest_existing
    from .errors import raise_if_stopped
    path = os.path.abspath(path)
    _put_back_stale(path)
    previous = [os.path.join(path, p) for p in _listed(path)]
    foreign = _reuse_warning(path, previous)
    run = {"command": command, "files": {os.path.relpath(p, path) for p in previous}, "published": set(),
           "backed": set(), "backup": f"{BACKUP}{os.getpid()}-{uuid.uuid4().hex[:8]}", "lock": None,
           "before": _snapshot(path), "dirs_before": _dirs_below(path), "above": _nearest_existing(path),
           "kept": {os.path.join(path, n) for n in foreign},
           "inputs": _inside(path, inputs)}
    _KEPT.update(run["kept"])
    with _RUNS_LOCK:                   # each file it writes is listed before it is written (``claim``)
        _RUNS[path] = run
    try:
        yield path
        raise_if_stopped()             # a stop a library swallowed: not a success
        with interrupts_held(replay=False):     # finished: its end is not cut short, nor called interrupted
            _succeeded(path, previous, run)
    except BaseException:
        with interrupts_held():        # a second Ctrl-C must not leave the folder half put back
            _failed(path, run)
        raise
    finally:
        _KEPT.difference_update(run["kept"])
        with _RUNS_LOCK:
            _RUNS.pop(path, None)


def _inside(path: str, files) -> set:
    """``files`` that lie in the folder ``path``, relative to it, through links too (the folder given as a link,
    an input named by a link to a file in it: matched by their real paths, which ``check_outputs`` uses too)."""
    real = os.path.realpath(path)
    found = (os.path.realpath(f) for f in files)
    return {os.path.relpath(f, real) for f in found if f.startswith(real + os.sep)}


def _succeeded(path: str, previous: list, run: dict) -> None:
    """A finished run: the manifest of what it wrote first (if that fails, the run fails and its folder is put
    back whole), then the earlier run's files it did not rewrite removed, then its kept files dropped."""
    if os.path.isdir(path):
        written = _changed(path, run["before"], run["kept"])
        read = sorted({os.path.relpath(p, path) for p in previous} & run["inputs"] - set(written))
        write_json(os.path.join(path, MANIFEST), {"command": run["command"], "files": written + read},
                   "output manifest")
        for old in previous:
            if os.path.relpath(old, path) not in written + read:
                with contextlib.suppress(OSError):
                    os.remove(old)
        with contextlib.suppress(OSError):
            os.remove(os.path.join(path, CLAIMS))
    _drop_backup(path, run)


def claim(path: str, what: str) -> None:
    """``path`` (absolute), about to be written: refused if it is a user's file in a running application's
    folder; else, inside one, listed before it is written (a line appended to the folder's ``CLAIMS``, folded
    into the manifest at the run's end): a run stopped after this (an error, an interrupt, a kill, a full disk)
    leaves its files listed, so the next run replaces them instead of taking them for the user's and refusing
    them. A line a file keeps a run writing thousands of frames linear (rewriting the manifest each time took
    3.6 s for 2,000 files)."""
    if path in _KEPT:
        raise EventFieldError(f"{what} path {path}: a file eventfield did not write (the folder's {MANIFEST} does "
                              "not list it) is kept, not replaced: move it, or choose another output folder")
    with _RUNS_LOCK:
        for folder, run in _RUNS.items():
            if path.startswith(folder + os.sep):
                rel = os.path.relpath(path, folder)
                if not rel.startswith(MANIFEST) and rel not in run["files"]:
                    run["files"].add(rel)
                    with contextlib.suppress(OSError):
                        with open(os.path.join(folder, CLAIMS), "a") as f:
                            f.write(rel + "\n")


def before_replacing(path: str):
    """Called by ``atomic.publish`` before ``path`` appears: inside a running application's folder (the
    innermost, where folders nest) the file it replaces, if any, is kept aside the first time; returns what
    :func:`replaced` needs afterwards, or None outside every application's folder."""
    with _RUNS_LOCK:
        inside = [(folder, run) for folder, run in _RUNS.items() if path.startswith(folder + os.sep)]
    if not inside:
        return None
    folder, run = max(inside, key=lambda item: len(item[0]))
    rel = os.path.relpath(path, folder)
    if rel not in run["published"] and os.path.isfile(path):
        keep = os.path.join(_backup_folder(folder, run), rel)
        os.makedirs(os.path.dirname(keep), exist_ok=True)
        try:
            os.link(path, keep)            # the old file stays in place until the new one replaces it
        except OSError:                    # no hard links here: moved aside instead
            os.replace(path, keep)
        run["backed"].add(rel)
    return run, rel


def replaced(info, path: str) -> None:
    """``path`` has appeared (``before_replacing``'s ``info``)."""
    run, rel = info
    run["published"].add(rel)


def keep_outputs(folder: str) -> None:
    """What the running application has published into ``folder`` so far stays, however the run ends (the
    files it replaced are gone for good): for applications whose parts stand on their own."""
    with _RUNS_LOCK:
        run = _RUNS.get(os.path.abspath(folder))
    if run is None:
        return
    for rel in run["backed"]:
        with contextlib.suppress(OSError):
            os.remove(os.path.join(folder, run["backup"], rel))
    run["published"], run["backed"] = set(), set()


def _backup_folder(folder: str, run: dict) -> str:
    """The run's folder for the files it replaces, made and locked on first use: made under a name no other
    run looks at, locked, then renamed into sight, so that no other run can take it for a killed run's before
    its lock is held."""
    root = os.path.join(folder, run["backup"])
    if run["lock"] is None and not os.path.isdir(root):
        making = os.path.join(folder, MANIFEST + ".making-" + run["backup"][len(BACKUP):])
        os.makedirs(making)
        run["lock"] = try_lock(making)[1]
        os.rename(making, root)
    return root


def _abandoned(folder: str, name: str) -> bool:
    """A kept-files folder whose run is gone: its lock is free (or, without ``flock``, its process is dead)."""
    state, fd = try_lock(os.path.join(folder, name))
    if state == "locked":
        os.close(fd)
        return True
    if state == "held":
        return False
    try:
        return not _pid_alive(int(name[len(BACKUP):].split("-")[0]))
    except ValueError:
        return True


def _put_back(folder: str, backup: str, new=()) -> int:
    """The files kept aside in ``folder``'s ``backup`` moved back over what replaced them, and the ``new``
    files (relative: a failed run's, which replaced nothing) removed. Returns how many were put back."""
    import shutil
    root, back = os.path.join(folder, backup), 0
    for here, _, names in os.walk(root):
        for name in names:
            rel = os.path.relpath(os.path.join(here, name), root)
            with contextlib.suppress(OSError):
                os.replace(os.path.join(here, name), os.path.join(folder, rel))
                back += 1
    for rel in new:
        with contextlib.suppress(OSError):
            os.remove(os.path.join(folder, rel))
    shutil.rmtree(root, ignore_errors=True)
    return back


def _drop_backup(path: str, run: dict) -> None:
    import shutil
    shutil.rmtree(os.path.join(path, run["backup"]), ignore_errors=True)
    if run["lock"] is not None:
        os.close(run["lock"])
        run["lock"] = None


def _put_back_stale(path: str) -> None:
    """Files kept aside by a run that was killed (no ``finally`` ran: SIGKILL, power loss) put back."""
    import sys
    with contextlib.suppress(OSError):
        for name in sorted(os.listdir(path)):
            if name.startswith(BACKUP) and os.path.isdir(os.path.join(path, name)) and _abandoned(path, name):
                back = _put_back(path, name)
                print(f"eventfield: put back {back} files of {path} that a killed run had replaced",
                      file=sys.stderr)


def _failed(path: str, run: dict) -> None:
    """A run that failed or was stopped: the files it replaced put back, those it added removed, and the
    folders it made (its own and their parents too) where empty then; what it wrote past ``publish`` (none of
    ours does) stays listed, so that the next run replaces it."""
    _put_back(path, run["backup"], run["published"] - run["backed"])
    _drop_backup(path, run)
    with contextlib.suppress(OSError):
        os.remove(os.path.join(path, CLAIMS))
    for made in sorted(_dirs_below(path) - run["dirs_before"], key=len, reverse=True):
        with contextlib.suppress(OSError):
            os.rmdir(os.path.join(path, made))      # only an empty folder goes
    folder = path
    while folder != run["above"] and len(folder) > len(run["above"]):    # the run made these: empty, they go
        try:
            os.rmdir(folder)
        except OSError:
            break
        folder = os.path.dirname(folder)
    if os.path.isdir(path):
        files = [f for f in set(run["files"]) | set(_changed(path, run["before"], run["kept"]))
                 if os.path.exists(os.path.join(path, f))]
        if files or os.path.exists(os.path.join(path, MANIFEST)):
            _write_manifest(path, run["command"], files)


def _reuse_warning(path: str, previous: list) -> list:
    """The files in a reused folder that eventfield did not write (relative), after one warning line."""
    import sys
    if not (os.path.isdir(path) and os.listdir(path)):
        return []
    foreign = [n for n in _files_below(path) if os.path.join(path, n) not in previous]
    print(f"eventfield: warning: output folder {path} is reused: "
          + (f"{len(previous)} files of an earlier run are replaced or removed if this run succeeds"
             if previous else "")
          + ("; " if previous and foreign else "")
          + (f"{len(foreign)} other files stay beside the new ones" if foreign else ""), file=sys.stderr)
    return foreign


def _listed(folder: str) -> list:
    """What the folder's manifest lists, and the claims of a run that never finished (killed): eventfield's."""
    files = []
    with contextlib.suppress(OSError, ValueError, AttributeError):
        with open(os.path.join(folder, MANIFEST)) as f:
            files = list(json.load(f).get("files", []))
    with contextlib.suppress(OSError, UnicodeDecodeError):
        with open(os.path.join(folder, CLAIMS)) as f:
            files += [line.rstrip("\n") for line in f if line.strip() and line.rstrip("\n") not in files]
    return files


def _write_manifest(folder: str, command: str, files) -> None:
    """The manifest in place at once (a temporary file renamed over it); where it cannot be written, the write
    that follows fails too and says why."""
    tmp = os.path.join(folder, f"{MANIFEST}{PARTIAL_TAG}{os.getpid()}")
    with contextlib.suppress(OSError):
        with open(tmp, "w") as f:
            json.dump({"command": command, "files": sorted(files)}, f, indent=2)
        os.replace(tmp, os.path.join(folder, MANIFEST))
    with contextlib.suppress(FileNotFoundError):
        os.remove(tmp)


def _snapshot(path: str) -> dict:
    """relative path -> (inode, modification time, size) of every file below ``path``."""
    out = {}
    for n in _files_below(path) if os.path.isdir(path) else ():
        with contextlib.suppress(OSError):
            st = os.stat(os.path.join(path, n))
            out[n] = (st.st_ino, st.st_mtime_ns, st.st_size)
    return out


def _changed(path: str, before: dict, kept: set) -> list:
    """The files below ``path`` new or changed since ``before`` (``_snapshot``), but for the ``kept`` ones."""
    now = _snapshot(path)
    return sorted(n for n, sig in now.items() if before.get(n) != sig and os.path.join(path, n) not in kept)


def _walk(path: str):
    """``os.walk`` below ``path`` without the manifests' own folders (the files runs keep aside) and without
    the output folders of other applications (running now, or with a manifest of their own: an output folder
    inside this one holds their files, not this run's)."""
    with _RUNS_LOCK:
        others = {folder for folder in _RUNS if folder != path}
    for root, dirs, names in os.walk(path):
        dirs[:] = [d for d in dirs if not d.startswith(MANIFEST) and os.path.join(root, d) not in others
                   and not os.path.isfile(os.path.join(root, d, MANIFEST))]
        yield root, dirs, names


def _files_below(path: str) -> list:
    """The files below ``path``, relative to it, but for the manifest and its temporary copies."""
    return [os.path.relpath(os.path.join(root, n), path) for root, _, names in _walk(path) for n in names
            if not (root == path and n.startswith(MANIFEST))]


def _dirs_below(path: str) -> set:
    """The folders below ``path``, relative to it."""
    return {os.path.relpath(os.path.join(root, d), path) for root, dirs, _ in _walk(path) for d in dirs}
