"""A chunk writer on its own thread, so that compressing and writing events never holds up the render.

The render thread hands time-sorted chunks to :class:`BackgroundWriter`; a bounded queue keeps host memory
flat (at most ``depth`` chunks wait), and the time the render spends blocked on a full queue is the measure of
whether the disk (or the compression) is the bottleneck: ``wait_s`` near zero means it kept up. Draining the
queue, at a checkpoint or at the end (``tail_s``), is not: any render has a last chunk to write.

A bounded queue alone did not keep memory flat. The chunks (megabytes each) are made on the render thread and
freed on the writer's, and glibc's malloc raises its mmap threshold each time such a block is freed, up to 32 MB.
The chunks then come from the heap, where blocks freed by another thread fragment it: the fan (346x260, to HDF5)
peaked at 342 MB over 0.05 s and 421 MB over 0.5 s (1.23x). With the threshold held at 1 MiB
(:func:`hold_mmap_threshold`) every chunk is its own mapping, given back when freed: 300 and 312 MB (1.04x), in
98.7 against 96.8 s over 0.5 s (benchmarks/results/memory.md; within the run-to-run spread).

Chunks from a GPU arrive in Dr.Jit's pinned host memory, which must be freed on the thread that allocated it
(Dr.Jit returns a freed buffer to that thread's cache; freed on the writer's thread, the buffers were never
reused and an H200's host memory grew 5.8x over 10x the duration). :meth:`BackgroundWriter.append_borrowed`
takes such arrays without a copy on the caller's thread: a copier thread copies them into NumPy's memory, drops
its references, then tells the caller, who drops the last reference on its own thread (:meth:`release_copied`,
called at each hand-over and at the end). The copy (a page fault per fresh page: 0.35 s of the H200 fan's
render thread, 0.8 s on a busy writer's) then runs beside the render and the writing.
"""
from __future__ import annotations

import ctypes
import os
import queue
import sys
import threading
import time

import numpy as np

MMAP_THRESHOLD = 1 << 20          # bytes: larger blocks are mapped on their own and unmapped when freed
_M_MMAP_THRESHOLD = -3            # mallopt's parameter number (malloc.h)
# the environment's own malloc tuning (glibc reads these at start-up) is the user's choice and is left alone
_MALLOC_ENV = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_", "MALLOC_MMAP_MAX_")
_held: bool | None = None


def _startup_environment() -> set:
    """Names in the environment this process started with: what glibc read. ``os.environ`` may have gained
    names since (a Dask LocalCluster's nannies leave ``MALLOC_TRIM_THRESHOLD_`` in their parent's, for the
    workers they spawn), which this process's malloc never saw."""
    try:
        with open("/proc/self/environ", "rb") as f:
            return {item.split(b"=", 1)[0].decode(errors="replace") for item in f.read().split(b"\0") if item}
    except OSError:
        return set(os.environ)


def hold_mmap_threshold() -> bool:
    """Fix glibc's mmap threshold at :data:`MMAP_THRESHOLD` for this process (once; it stays: glibc has no way
    back to the adaptive threshold). True when it holds; False where there is no glibc ``mallopt`` (macOS,
    Windows, musl) or the environment the process started with tunes malloc itself. Process-wide, like any
    allocator setting: what it costs the rest of a program is a page fault per first touch of a large block,
    which reuse from the heap would have saved."""
    global _held
    if _held is None:
        _held = False
        if sys.platform.startswith("linux") and not _startup_environment().intersection(_MALLOC_ENV):
            try:
                mallopt = ctypes.CDLL(None).mallopt
            except (OSError, AttributeError):
                return False
            mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
            _held = mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1
    return _held


def _own(a):
    """``a`` in NumPy's own memory (a fresh C-ordered copy)."""
    return np.array(a, copy=True, order="C")


class BackgroundWriter:
    """Runs ``writer.append`` (any object with ``append(x, y, t, p, complete_until_us)``, ``close(end_us,
    meta)`` and ``abort()``, e.g. ``H5EventWriter``) on a worker thread. An error raised there (a full disk, an
    out-of-order chunk) is raised again in the caller's thread at the next ``append`` or at ``close``; chunks
    after it are dropped and ``abort`` removes the partial file.

    From the first borrowed chunk (:meth:`append_borrowed`) on, chunks pass a copier thread on their way (in
    order): it copies the borrowed ones and passes the others on. Copying on the writer's own thread made it the
    GPU fan's bottleneck (an H200: busy 3.5 s against 2.7 s, the render waiting 0.9 s for it); on a thread of
    its own it runs beside both. Up to ``depth`` chunks wait for each of the two threads then."""

    def __init__(self, writer, depth: int = 2):
        hold_mmap_threshold()                 # chunks freed on another thread must not fragment the heap
        self.writer = writer
        depth = max(1, int(depth))
        self.inbox: queue.Queue = queue.Queue(maxsize=depth)     # to the copier
        self.queue: queue.Queue = queue.Queue(maxsize=depth)     # to the writer
        self.error: BaseException | None = None
        self.aborting = False  # abort() called: queued chunks are dropped, not written
        self.wait_s = 0.0      # the caller's time blocked on a full queue: the writer did not keep up
        self.tail_s = 0.0      # the caller's time draining the queue: at checkpoints and at the end
        self.busy_s = 0.0      # the worker's time writing
        self.copy_s = 0.0      # the copier's time copying borrowed chunks
        # borrowed chunks by hand-over number, held here until the copier has copied them: the caller's
        # thread drops them (release_copied), so the last reference never goes on another thread
        self._borrowed: dict[int, tuple] = {}
        self._copied: queue.SimpleQueue = queue.SimpleQueue()
        self._handed = 0
        self.copier: threading.Thread | None = None       # started by the first borrowed chunk
        self.thread = threading.Thread(target=self._work, name="eventfield-writer", daemon=True)
        self.thread.start()

    def _copy(self):
        while True:
            item = self.inbox.get()
            end = item is None
            if not end and item[0] is not None:   # borrowed: copied, every reference dropped, the caller told
                t0 = time.perf_counter()
                number, x, y, t, p, until = item
                del item
                owned = None
                if self.error is None and not self.aborting:
                    try:
                        owned = (None, _own(x), _own(y), _own(t), _own(p), until)
                    except BaseException as e:    # noqa: BLE001 - handed to the caller's thread (a MemoryError)
                        self.error = e
                del x, y, t, p
                self._copied.put(number)
                self.copy_s += time.perf_counter() - t0
                item = owned
            if end or item is not None:
                self.queue.put(item)
            del item
            self.inbox.task_done()
            if end:
                return

    def _work(self):
        while True:
            item = self.queue.get()
            if item is None:
                return
            # after an error, or once aborted, keep draining: the caller never blocks on it
            if self.error is None and not self.aborting:
                t0 = time.perf_counter()
                try:
                    self.writer.append(*item[1:])
                except BaseException as e:    # noqa: BLE001 - handed to the caller's thread
                    self.error = e
                self.busy_s += time.perf_counter() - t0
            del item
            self.queue.task_done()

    def _raise(self):
        if self.error is not None:
            raise self.error

    def append(self, x, y, t, p, complete_until_us: int | None = None):
        self._put((None, x, y, t, p, complete_until_us))    # through the copier once it runs: in order

    def append_borrowed(self, x, y, t, p, complete_until_us: int | None = None):
        """Like :meth:`append` for arrays whose memory must be freed on this thread (Dr.Jit's pinned host
        buffers): the copier copies them, and this thread drops them at a later hand-over or at the end."""
        self.release_copied()
        if self.copier is None and self.thread.is_alive():
            self.copier = threading.Thread(target=self._copy, name="eventfield-copier", daemon=True)
            self.copier.start()
        self._handed += 1
        self._borrowed[self._handed] = (x, y, t, p)
        try:
            self._put((self._handed, x, y, t, p, complete_until_us))
        except BaseException:            # refused (the worker's error): not lent, so not kept either
            del self._borrowed[self._handed]
            raise

    def release_copied(self) -> None:
        """Drop, on the calling thread, the borrowed chunks the copier has copied."""
        while True:
            try:
                del self._borrowed[self._copied.get_nowait()]
            except queue.Empty:
                return

    def _put(self, item):
        self._raise()
        t0 = time.perf_counter()
        (self.queue if self.copier is None else self.inbox).put(item)
        del item
        self.wait_s += time.perf_counter() - t0

    def _stop(self):
        if self.thread.is_alive():
            t0 = time.perf_counter()
            if self.copier is None:
                self.queue.put(None)
            else:
                self.inbox.put(None)          # passed on to the writer after the copies
                self.copier.join()
            self.thread.join()
            self.tail_s += time.perf_counter() - t0     # the last chunks: written after any render, not a pace
        self.release_copied()

    def wait(self):
        """Wait until every queued chunk is written, keeping the worker for more (a checkpoint: a drain the
        render asked for, counted with the final one in ``tail_s``, not a pace)."""
        t0 = time.perf_counter()
        if self.copier is not None:
            self.inbox.join()
        self.queue.join()
        self.tail_s += time.perf_counter() - t0
        self.release_copied()
        self._raise()

    def drain(self):
        """Wait until every queued chunk is written (raising the worker's error, if any)."""
        self._stop()
        self._raise()

    def close(self, end_us: int | None = None, meta: dict | None = None):
        """Wait for every queued chunk, then finish and publish the file (in the caller's thread)."""
        self.drain()
        self.writer.close(end_us=end_us, meta=meta)

    def abort(self):
        """Drop the queued chunks (the threads write and copy nothing more) and remove the partial file. A
        second Ctrl-C meanwhile is held until the file is gone (``errors.interrupts_held``): escaping the wait
        for the threads, or the file writer's own abort (its compression pool), left the partial file (or an
        .npz's column files) beside the output under "no partial output kept"."""
        from ..errors import interrupts_held
        self.aborting = True
        with interrupts_held():
            self._stop()
            self.writer.abort()
