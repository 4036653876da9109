"""Output files appear whole or not at all: write to a hidden temporary name beside the target, then rename."""
from __future__ import annotations

import contextlib
import json
import os
import threading
import uuid

from .errors import EventFieldError


def _nearest_existing(path: str) -> str:
    parent = path
    while not os.path.exists(parent):
        parent = os.path.dirname(parent)
    return parent


# files in an output folder in use (``output_dir_run``) that eventfield did not write: never replaced
_KEPT: set = set()
# output folders of running applications -> {"command", "files": what the folder's manifest lists}
_RUNS: dict = {}
_RUNS_LOCK = threading.Lock()


def check_not_input(output: str, inputs, what: str = "output") -> None:
    """Refuse an output that is one of the ``inputs`` (paths; others ignored) under any name: the same file
    through a symbolic or hard link too (``os.path.samefile``; comparing absolute paths let a link's target
    be replaced by events)."""
    for given in inputs:
        if isinstance(given, (str, os.PathLike)) and os.path.exists(output) and os.path.exists(given):
            try:
                same = os.path.samefile(output, given)
            except OSError:
                same = False
            if same:
                raise EventFieldError(f"{what} path {output}: the output is the input {given}: choose another "
                                      "file")


def check_writable(path: str, what: str = "output") -> str:
    """Fail early (before any rendering) if the file ``path`` cannot be created; return its absolute path."""
    if not str(path).strip():
        raise EventFieldError(f"{what} path {str(path)!r}: empty: name a file")
    path = os.path.abspath(path)
    parent = os.path.dirname(path)
    if path in _KEPT:
        raise EventFieldError(f"{what} path {path}: a file eventfield did not write (the folder's {MANIFEST} does "
                              "not list it) is kept, not replaced: move it, or choose another output folder")
    _claim(path)
    if os.path.isdir(path):
        raise EventFieldError(f"{what} path {path}: is a directory")
    if not os.path.isdir(parent):
        existing = _nearest_existing(parent)
        if os.path.isfile(existing):
            raise EventFieldError(f"{what} path {path}: {existing} is a file, not a directory")
        below = parent.startswith(os.path.join(os.getcwd(), ""))     # short where it lies below here
        raise EventFieldError(f"{what} path {path}: directory {parent} does not exist (create it first, e.g. "
                              f"mkdir -p {os.path.relpath(parent) if below else parent})")
    if not os.access(parent, os.W_OK | os.X_OK) or _stores_nothing(parent):
        raise EventFieldError(f"{what} path {path}: directory {parent} is not writable")
    return path


def _stores_nothing(directory: str) -> bool:
    """A file system with no storage at all (/proc, /sys): root passes ``os.access`` there, and the free-space
    check then called it a full disk. (Any other file system reporting no blocks was refused as full anyway.)"""
    try:
        st = os.statvfs(directory)
    except OSError:
        return False
    return st.f_blocks == 0 and st.f_bavail == 0


def check_output_dir(path: str, what: str = "output directory") -> str:
    """Before any work: ``path`` is a directory or can be made one (nearest existing parent a writable
    directory). Returns the absolute path."""
    path = os.path.abspath(path)
    if os.path.exists(path) and not os.path.isdir(path):
        raise EventFieldError(f"{what} {path}: exists and is not a directory")
    parent = _nearest_existing(path)
    if not (os.path.isdir(parent) and os.access(parent, os.W_OK | os.X_OK)):
        raise EventFieldError(f"{what} {path}: {parent} is not a writable directory")
    return path


PARTIAL_TAG = ".partial-"


def temporary_name(path: str) -> str:
    """``out.h5`` -> ``out.partial-<pid>-<random>.h5``: visible (a user sees what a killed run left), named as
    partial, owned by a process id (so a later run can tell a dead writer's leftover from a live one), with the
    extension kept (some writers, OpenCV, choose the format by it)."""
    head, tail = os.path.split(os.path.abspath(path))
    root, ext = os.path.splitext(tail)
    return os.path.join(head, f"{root}{PARTIAL_TAG}{os.getpid()}-{uuid.uuid4().hex[:6]}{ext}")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:       # someone else's live process
        return True
    return True


def remove_stale_partials(path: str) -> list:
    """Delete the partial files of ``path`` whose writing process no longer exists (SIGKILL, power loss: no
    ``finally`` ran); each one is reported on stderr. Returns the removed paths."""
    import re
    import sys
    head, tail = os.path.split(os.path.abspath(path))
    root, ext = os.path.splitext(tail)
    # (a library's own temporary name after ours: faery writes <partial>.write and renames it when done)
    pattern = re.compile(re.escape(root + PARTIAL_TAG) + r"(\d+)-[0-9a-f]+" + re.escape(ext) + r"(\.\w+)?$")
    removed = []
    try:
        names = os.listdir(head)
    except OSError:
        return removed
    for name in names:
        m = pattern.match(name)
        if m and not _pid_alive(int(m.group(1))):
            with contextlib.suppress(OSError):
                os.remove(os.path.join(head, name))
                removed.append(os.path.join(head, name))
                print(f"eventfield: removed {os.path.join(head, name)}, left by an interrupted run (process "
                      f"{m.group(1)} no longer exists)", file=sys.stderr)
    return removed


@contextlib.contextmanager
def atomic_output(path: str, what: str = "output"):
    """Yield a temporary path; on normal exit rename it to ``path``, on error delete it. Leftovers of killed
    earlier runs for the same ``path`` are removed first."""
    path = check_writable(path, what)
    remove_stale_partials(path)
    tmp = temporary_name(path)
    try:
        yield tmp
        publish(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.remove(tmp)


def publish(tmp: str, path: str) -> None:
    """Rename the finished ``tmp`` to ``path``: the one place an output file appears (``atomic_output``, the
    event writers). A stop signal that a library swallowed on the way stops it here (``errors.STOP_SIGNALS``:
    a Ctrl-C during a checkpointed render's merge published the file with exit status 0). Inside a running
    application's folder (``output_dir_run``) the file it replaces is first kept aside, so that a run that
    fails can put the folder back as it was."""
    from .errors import raise_if_stopped
    raise_if_stopped()
    path = os.path.abspath(path)
    folder, run = _run_of(path)
    rel = None if run is None else os.path.relpath(path, folder)
    if run is not None and rel not in run["published"] and os.path.isfile(path):
        keep = os.path.join(folder, _backup_name(os.getpid()), rel)
        os.makedirs(os.path.dirname(keep), exist_ok=True)
        try:
            os.link(path, keep)            # the old file stays in place until the new one replaces it
        except OSError:                    # no hard links here: moved aside instead
            os.replace(path, keep)
        run["backed"].add(rel)
    os.replace(tmp, path)
    if run is not None:
        run["published"].add(rel)


def _run_of(path: str):
    """(folder, run record) of the running application whose output folder holds ``path``, or (None, None)."""
    with _RUNS_LOCK:
        for folder, run in _RUNS.items():
            if path.startswith(folder + os.sep):
                return folder, run
    return None, None


def _backup_name(pid: int) -> str:
    return f"{MANIFEST}.previous-{pid}"


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


def json_safe(value):
    """``value`` with every non-finite float (NaN, inf: "no pixel", "never") as None, numpy scalars and arrays
    as Python ones, anything else unknown as its string: strict JSON that every reader accepts."""
    import math

    import numpy as np
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, (bool, int, str)):
        return value
    return str(value)


def write_json(path: str, payload, what: str = "metrics") -> str:
    """Strict JSON (``json_safe``), indented, written atomically."""
    import json
    with atomic_output(path, what) as tmp, open(tmp, "w") as f:
        json.dump(json_safe(payload), f, indent=2, allow_nan=False)
    return path


MANIFEST = ".eventfield-outputs.json"


@contextlib.contextmanager
def output_dir_run(path: str, command: str):
    """An application writing into the folder ``path``, as one change: after a successful run the files an
    earlier run listed in the folder's manifest and this run did not rewrite are removed (40 frames then 24 left
    16 stale frames mixed in), and the manifest lists this run's files; a run that fails or is stopped puts
    back every file it replaced (``publish`` kept them aside) and removes those it added, so the folder is the
    earlier run's again (a demo stopped half-way mixed a new event file and depth map with the old metrics and
    figure). Which files a run wrote is read from the files themselves (new, or another inode, time or size
    than before it started): times alone counted an earlier run's files from the second before as this one's.
    Files eventfield did not write are never touched (only mentioned): a run that would write one of their
    names stops there with a one-line error (``check_writable``)."""
    path = os.path.abspath(path)
    _put_back_stale(path)
    previous = [os.path.join(path, p) for p in _listed(path)]
    foreign = _reuse_warning(path, previous)
    before = _snapshot(path)
    existed = os.path.isdir(path)
    kept = {os.path.join(path, n) for n in foreign}
    _KEPT.update(kept)
    with _RUNS_LOCK:                   # each file it writes is listed before it is written (``_claim``)
        _RUNS[path] = run = {"command": command, "files": {os.path.relpath(p, path) for p in previous},
                             "published": set(), "backed": set()}
    try:
        yield path
        from .errors import raise_if_stopped
        raise_if_stopped()             # a stop a library swallowed: not a success
    except BaseException:
        _failed(path, command, run, before, kept, existed)
        raise
    finally:
        _KEPT.difference_update(kept)
        with _RUNS_LOCK:
            _RUNS.pop(path, None)
    if not os.path.isdir(path):
        return
    written = _changed(path, before, kept)
    for old in previous:
        if os.path.relpath(old, path) not in written:
            with contextlib.suppress(OSError):
                os.remove(old)
    _drop_backup(path)
    write_json(os.path.join(path, MANIFEST), {"command": command, "files": written}, "output manifest")
    with contextlib.suppress(OSError):
        os.remove(os.path.join(path, CLAIMS))


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


def _failed(path: str, command: str, run: dict, before: dict, kept: set, existed: bool) -> None:
    """A run that failed or was stopped: the files it replaced put back, those it added removed; what it wrote
    past ``publish`` (none of ours does) stays listed, so that the next run replaces it."""
    _put_back(path, _backup_name(os.getpid()), run["published"] - run["backed"])
    with contextlib.suppress(OSError):
        os.remove(os.path.join(path, CLAIMS))
    if not existed:                # a failed run leaves no folder it made, when nothing was written into it
        with contextlib.suppress(OSError):
            os.rmdir(path)         # only an empty folder goes
    if os.path.isdir(path):
        files = set(run["files"]) | set(_changed(path, before, kept))
        files = [f for f in files if os.path.exists(os.path.join(path, f))]
        if files or os.path.exists(os.path.join(path, MANIFEST)):
            _write_manifest(path, command, files)


def _drop_backup(path: str) -> None:
    import shutil
    shutil.rmtree(os.path.join(path, _backup_name(os.getpid())), ignore_errors=True)


def _put_back_stale(path: str) -> None:
    """Files kept aside by a run that was killed (no ``finally`` ran: SIGKILL, power loss) put back."""
    import re
    import sys
    with contextlib.suppress(OSError):
        for name in os.listdir(path):
            m = re.fullmatch(re.escape(MANIFEST) + r"\.previous-(\d+)", name)
            if m and not _pid_alive(int(m[1])):
                back = _put_back(path, name)
                print(f"eventfield: put back {back} files of {path} that a killed run (process {m[1]}) had "
                      "replaced", file=sys.stderr)


def _snapshot(path: str) -> dict:
    """relative path -> (inode, modification time, size) of every file below ``path``."""
    out = {}
    for n in _files_below(path) if os.path.isdir(path) else ():
        with contextlib.suppress(OSError):
            st = os.stat(os.path.join(path, n))
            out[n] = (st.st_ino, st.st_mtime_ns, st.st_size)
    return out


CLAIMS = MANIFEST + ".claims"      # files a running application is about to write, a line each (``_claim``)


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


def _claim(path: str) -> None:
    """``path``, about to be written in a running application's output folder, listed before it is written (a
    line appended to the folder's ``CLAIMS``, which the run's end folds into the manifest): a run stopped after
    this (an error, an interrupt, a kill, a full disk) leaves its files listed, so the next run replaces them
    instead of taking them for the user's and refusing them. Appending a line a file keeps a run writing
    thousands of frames linear (rewriting the manifest each time took 3.6 s for 2,000 files)."""
    with _RUNS_LOCK:
        for folder, run in _RUNS.items():
            if path.startswith(folder + os.sep):
                rel = os.path.relpath(path, folder)
                if not rel.startswith(MANIFEST) and rel not in run["files"]:
                    run["files"].add(rel)
                    with contextlib.suppress(OSError):
                        with open(os.path.join(folder, CLAIMS), "a") as f:
                            f.write(rel + "\n")


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


def _changed(path: str, before: dict, kept: set) -> list:
    """The files below ``path`` new or changed since ``before`` (``_snapshot``), but for the ``kept`` ones."""
    now = _snapshot(path)
    return sorted(n for n, sig in now.items() if before.get(n) != sig and os.path.join(path, n) not in kept)


def _files_below(path: str) -> list:
    """The files below ``path``, relative to it, but for the manifest and its temporary copies."""
    out = []
    for root, dirs, names in os.walk(path):
        if root == path:               # nor the files a running application keeps aside (``publish``)
            dirs[:] = [d for d in dirs if not d.startswith(MANIFEST)]
        out += [os.path.relpath(os.path.join(root, n), path) for n in names
                if not (root == path and n.startswith(MANIFEST))]
    return out
