"""Full disks and quotas, before and during a write: every event writer checks the free space before each chunk
and turns a refused write met anyway (ENOSPC, a user quota's EDQUOT, a file-size limit's EFBIG) into one
``EventFieldError``, because HDF5 and dv-processing do not recover from it (a segfault, an abort from dv's writer
thread). A quota is not in the free-space figure: the AEDAT4 writer reserves each chunk's bytes first
(:func:`check_room`)."""
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


def _disk_full(path: str, free: int | None, need: int, cause: BaseException | None = None) -> EventFieldError:
    """The one-line error of a write of about ``need`` bytes the file system refused (``cause``, when known, says
    which refusal); a full disk's names the free space asked for, DISK_MARGIN included."""
    code, text = getattr(cause, "errno", None), str(cause or "").lower()     # a library may say it in words only
    if code == errno.EDQUOT or "quota exceeded" in text:
        return EventFieldError(f"{path}: disk quota exceeded: the file system refused about {_size(need)} more "
                               "(a user or group quota; `quota -s` shows it)")
    if code == errno.EFBIG or "file too large" in text:      # (faery: "File too large (os error 27)")
        return EventFieldError(f"{path}: file too large: the file system or the process's file-size limit "
                               f"(ulimit -f) refused about {_size(need)} more")
    have = "unknown" if free is None else _size(free)
    return EventFieldError(f"{path}: disk full: {have} free, need about {_size(need + DISK_MARGIN)}")


def check_space(path: str, need: int) -> None:
    """Refuse a write of about ``need`` bytes beside ``path`` unless that much (plus DISK_MARGIN) is free, before
    HDF5 or dv-processing meet ENOSPC: neither recovers from it (segfault, abort)."""
    free, need = _free_bytes(path), int(need)
    if free is not None and free < need + DISK_MARGIN:
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
    # ``need`` holds the headers' allowance already; the free-space margin (1 MiB) refused a 10-event file
    # under a 1 MiB limit, saying "830 bytes written, about 65696 more"
    if size + int(need) > limit:
        raise EventFieldError(f"{path}: the process's file-size limit (ulimit -f) is {limit} bytes: this file "
                              f"would pass it ({size} bytes written, about {int(need)} more); raise the limit or "
                              "write a shorter render")


_REFUSED = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
_REFUSED_TEXT = ("No space left on device", "Disk quota exceeded", "File too large")


def _no_space(e: BaseException) -> bool:
    """Whether ``e`` is the file system refusing more bytes: a full disk, a quota, a file-size limit (h5py and
    Python set errno; dv-processing and faery only say it in the message text)."""
    return getattr(e, "errno", None) in _REFUSED or any(t in str(e) for t in _REFUSED_TEXT)


def _reserve(fd: int, size: int) -> int:
    """fallocate(2) of ``size`` bytes: 0, or the errno (EOPNOTSUPP where the file system cannot reserve; -1
    where the call does not exist). The system call, not glibc's posix_fallocate, which on such a file system
    writes a byte into every block instead (NFS: a network write each)."""
    import ctypes
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fallocate = libc.fallocate64
    except (OSError, AttributeError):
        return -1
    fallocate.argtypes = (ctypes.c_int, ctypes.c_int, ctypes.c_int64, ctypes.c_int64)
    return 0 if fallocate(fd, 0, 0, size) == 0 else ctypes.get_errno()


def check_room(path: str, partial: str, need: int) -> None:
    """Refuse a chunk of about ``need`` bytes for ``partial`` (the file being written for ``path``) unless the
    file system grants them now: they are reserved in a probe file beside it and released at once. A user quota
    (a cluster's home or project space) is not in the free-space figure, and dv-processing's writer thread,
    meeting EDQUOT, aborted the process (exit 134) and left the partial file. The probe is named after
    ``partial``, so a run killed while it exists leaves a file the next run removes (``remove_stale_partials``)."""
    probe = partial + ".room"
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except OSError:
        return                   # cannot tell (odd file system): the write itself will say
    try:
        code = _reserve(fd, int(need))       # (need holds the headers' allowance: no free-space margin here)
    finally:
        os.close(fd)
        with contextlib.suppress(OSError):
            os.remove(probe)
    if code in _REFUSED:
        raise _disk_full(path, _free_bytes(path), int(need), OSError(code, os.strerror(code)))


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
        raise _disk_full(path, _free_bytes(path), int(need), e) from None


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
