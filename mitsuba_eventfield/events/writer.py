"""A chunk writer on its own thread, so that compressing and writing events never holds up the render.

The render thread hands time-sorted chunks to :class:`BackgroundWriter`; a bounded queue keeps host memory
flat (at most ``depth`` chunks wait), and the time the render spends blocked on a full queue is the measure of
whether the disk (or the compression) is the bottleneck: ``wait_s`` near zero means it kept up.
"""
from __future__ import annotations

import queue
import threading
import time


class BackgroundWriter:
    """Runs ``writer.append`` (any object with ``append(x, y, t, p, complete_until_us)``, ``close(end_us,
    meta)`` and ``abort()``, e.g. ``H5EventWriter``) on a worker thread. An error raised there (a full disk, an
    out-of-order chunk) is raised again in the caller's thread at the next ``append`` or at ``close``; chunks
    after it are dropped and ``abort`` removes the partial file."""

    def __init__(self, writer, depth: int = 2):
        self.writer = writer
        self.queue: queue.Queue = queue.Queue(maxsize=max(1, int(depth)))
        self.error: BaseException | None = None
        self.wait_s = 0.0      # the caller's time blocked on a full queue: the writer did not keep up
        self.busy_s = 0.0      # the worker's time writing
        self.thread = threading.Thread(target=self._work, name="eventfield-writer", daemon=True)
        self.thread.start()

    def _work(self):
        while True:
            item = self.queue.get()
            if item is None:
                return
            if self.error is None:            # after an error keep draining: the caller never blocks on it
                t0 = time.perf_counter()
                try:
                    self.writer.append(*item)
                except BaseException as e:    # noqa: BLE001 - handed to the caller's thread
                    self.error = e
                self.busy_s += time.perf_counter() - t0
            self.queue.task_done()

    def _raise(self):
        if self.error is not None:
            raise self.error

    def append(self, x, y, t, p, complete_until_us: int | None = None):
        self._raise()
        t0 = time.perf_counter()
        self.queue.put((x, y, t, p, complete_until_us))
        self.wait_s += time.perf_counter() - t0

    def _stop(self):
        if self.thread.is_alive():
            t0 = time.perf_counter()
            self.queue.put(None)
            self.thread.join()
            self.wait_s += time.perf_counter() - t0

    def wait(self):
        """Wait until every queued chunk is written, keeping the worker for more (a checkpoint)."""
        t0 = time.perf_counter()
        self.queue.join()
        self.wait_s += time.perf_counter() - t0
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
        self._stop()
        self.writer.abort()
