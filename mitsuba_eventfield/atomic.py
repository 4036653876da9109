"""Output files appear whole or not at all: write to a hidden temporary name beside the target, then rename."""
from __future__ import annotations

import contextlib
import json
import os
import uuid

from .errors import EventFieldError


def _nearest_existing(path: str) -> str:
    parent = path
    while not os.path.exists(parent):
        parent = os.path.dirname(parent)
    return parent


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
    from . import output_folders
    path = os.path.abspath(path)
    parent = os.path.dirname(path)
    output_folders.claim(path, what)             # (a user's file in an application's folder is refused)
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
    application's folder the file it replaces is first kept aside (``output_folders``), so that a run that
    fails can put the folder back as it was."""
    from . import output_folders
    from .errors import raise_if_stopped
    raise_if_stopped()
    path = os.path.abspath(path)
    run = output_folders.before_replacing(path)
    os.replace(tmp, path)
    if run is not None:
        output_folders.replaced(run, path)


def try_lock(path: str, create: bool = False):
    """(state, descriptor) of an exclusive ``flock`` tried, without waiting, on ``path`` (a folder, or a file,
    made if ``create``): ("locked", an open descriptor holding it: closing it, or the process ending, lets go),
    ("held", None) where another process holds it, or ("none", None) without ``flock`` (Windows, some FUSE and
    SMB mounts). The one way a lock tells a live process from a dead one: by it, not by process ids, which the
    system reuses."""
    try:
        import fcntl
    except ImportError:
        return "none", None
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644) if create else os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        return "held", None
    except OSError:
        os.close(fd)
        return "none", None
    return "locked", fd


@contextlib.contextmanager
def updating(path: str):
    """Hold an exclusive lock while ``path`` is read, changed and written again (a calibration file that two
    ``calibrate`` runs extend at once: each read the file before the other wrote it, and one part was lost). The
    lock is the folder's (``flock`` on its directory: the file itself is replaced by a rename, so a lock on it
    would not outlive the first write). Where there is no ``flock`` (Windows, a file system that refuses it) or
    no folder yet (the write then says why), the update is not serialised."""
    try:
        import fcntl
        fd = os.open(os.path.dirname(os.path.abspath(path)), os.O_RDONLY)
    except (ImportError, OSError):
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:                # ENOLCK and the like: unguarded, as without flock
            pass
        yield
    finally:
        os.close(fd)                   # (closing releases the lock)


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
