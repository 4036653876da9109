"""Full disks, before and during a write: every event writer checks the free space before each chunk and
turns an ENOSPC met anyway into one ``EventFieldError``, because HDF5 and dv-processing do not recover from it
(a segfault, an abort from dv's writer thread)."""
from __future__ import annotations

import contextlib
import errno
import io
import os
import shutil

from ..errors import EventFieldError

# Free-space estimates (bytes). They are upper bounds: uncompressed sizes, since the compressed size is not
# known before writing. DISK_MARGIN is kept free on top, for what libraries write when they choose: HDF5's
# metadata and the attributes written at close, dv-processing's packet headers and file table.
DISK_MARGIN = 1 << 20
HEADER_BYTES = 64 << 10        # file headers, the JSON metadata aside
WRITE_CHUNK = 1 << 16          # events per write (and per free-space check) of the one-shot writers


class BadFile(Exception):
    """What is wrong with an event file, found by our own checks (read_events adds the path and format)."""


def _size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if abs(n) < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.3g} {unit}"
        n /= 1024


def _free_bytes(path: str) -> int | None:
    try:
        return shutil.disk_usage(os.path.dirname(os.path.abspath(path))).free
    except OSError:  # cannot tell (directory gone, odd file system): the write itself will say
        return None


def _disk_full(path: str, free: int | None, need: int) -> EventFieldError:
    have = "unknown" if free is None else _size(free)
    return EventFieldError(f"{path}: disk full: {have} free, need about {_size(need)}")


def check_space(path: str, need: int) -> None:
    """Refuse a write of about ``need`` bytes beside ``path`` unless that much (plus DISK_MARGIN) is free, before
    HDF5 or dv-processing meet ENOSPC: neither recovers from it (segfault, abort)."""
    free, need = _free_bytes(path), int(need) + DISK_MARGIN
    if free is not None and free < need:
        raise _disk_full(path, free, need)


def check_file_limit(path: str, partial: str, need: int) -> None:
    """Refuse growing ``partial`` (the file being written for ``path``) by about ``need`` bytes past the
    process's file-size limit (``ulimit -f``, RLIMIT_FSIZE): dv-processing's writer thread met it as EFBIG and
    aborted the whole process (a quota it cannot see: the free-space check is all there is)."""
    try:
        import resource
        limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    except (ImportError, OSError, ValueError):
        return
    if limit == resource.RLIM_INFINITY:
        return
    size = os.path.getsize(partial) if os.path.exists(partial) else 0
    if size + int(need) + DISK_MARGIN > limit:
        raise EventFieldError(f"{path}: the process's file-size limit (ulimit -f) is {limit} bytes: this file "
                              f"would pass it ({size} bytes written, about {int(need)} more); raise the limit or "
                              "write a shorter render")


def _no_space(e: BaseException) -> bool:
    # h5py and Python set errno; dv-processing only says it in the message text
    return getattr(e, "errno", None) == errno.ENOSPC or "No space left on device" in str(e)


@contextlib.contextmanager
def disk_errors(path: str, need: int):
    """Turn ENOSPC raised inside (the disk filled between our check and the write) into the one-line error."""
    try:
        yield
    except EventFieldError:
        raise
    except Exception as e:
        if not _no_space(e):
            raise
        raise _disk_full(path, _free_bytes(path), int(need) + DISK_MARGIN) from None


class GuardedFile(io.FileIO):
    """The HDF5 file as HDF5 sees it (h5py's file-object driver). HDF5 must never see a failed write: after one
    it crashes the process when it closes the dataset or the file (segfault, even at exit), and it then can
    neither finish nor discard the file. So a write that meets a full disk is recorded in ``failed`` and
    reported to HDF5 as done; the writer checks ``failed`` after each step and throws the file away."""

    failed: OSError | None = None
    _write_some = io.FileIO.write   # the system call (tests replace it to fill the disk)

    def write(self, data) -> int:
        view = memoryview(data).cast("B")
        done = 0
        while self.failed is None and done < len(view):   # h5py ignores short writes: finish them here
            try:
                done += self._write_some(view[done:]) or 0
            except OSError as e:
                if not _no_space(e):
                    raise
                self.failed = e
        return len(view)

    def readinto(self, buffer) -> int:
        view = memoryview(buffer).cast("B")
        n = super().readinto(view) or 0
        view[n:] = bytes(len(view) - n)    # past the end of the file reads as zeros, as in HDF5's own driver
        return len(view)
