"""A process-wide pool of threads for per-item work that releases the GIL (OpenCV's warps, NumPy's array
operations), handed out in order: ``ordered_map``.

Why: a refocus warps every view of a light field, one small image at a time (160 x 120 Lanczos warps of
0.5-0.9 ms each on the demo), and OpenCV splits each warp over its own threads, which pays little for images
this small. Warping several views at once, each on one thread, uses the cores where the per-image split does
not, and the results come back in the views' order, so sums over them are made in the same order and are the
same, bit for bit (docs/design.md, "Views warped side by side"). While a map runs on the pool, OpenCV runs on
one thread, for the whole process (its own threads would compete with the pool's: the demo's depth map took
1.24 s with both, 0.75 s with OpenCV on one, 1.16 s before, on 2 cores); the count it had comes back when the
last map ends, also after an interrupt, and in a child forked meanwhile.
"""
from __future__ import annotations

import collections
import os
import threading
from concurrent.futures import ThreadPoolExecutor

from .validate import usable_cores

MAX_WORKERS = 16     # threads at most: small images gain little beyond, and each holds a result in memory
_pool: tuple | None = None        # (executor, workers), made on first use
_lock = threading.Lock()
_opencv = {"maps": 0, "threads": None}    # maps running on the pool, and OpenCV's thread count before the first
_on_pool = threading.local()      # set on the pool's threads: a map from one of them runs there (no nesting)


def _forget_pool() -> None:
    """A forked child has none of the parent's threads: its first map makes a pool of its own, and OpenCV gets
    back the thread count a map running at the fork had taken from it."""
    global _pool, _lock
    _pool, _lock = None, threading.Lock()
    if _opencv["maps"] and _opencv["threads"] is not None:
        import cv2
        cv2.setNumThreads(_opencv["threads"])
    _opencv.update(maps=0, threads=None)


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pool)


def _executor() -> tuple:
    global _pool
    with _lock:
        if _pool is None:
            workers = min(MAX_WORKERS, usable_cores())
            _pool = (ThreadPoolExecutor(workers, thread_name_prefix="eventfield-worker",
                                        initializer=setattr, initargs=(_on_pool, "worker", True)), workers)
    return _pool


def ordered_map(fn, items):
    """``fn(item)`` for each of ``items``, yielded in the items' order, computed on the pool's threads at most
    two items beyond its workers ahead of the consumer (so at most that many results wait in memory), or on the
    calling thread where there is one core, one item, or the caller is itself one of the pool's threads (a map
    inside a task would wait on tasks queued behind its own: with every worker waiting so, none would run).
    ``fn`` must not share mutable state between items: whatever depends on their order belongs to the caller,
    who consumes the results in order."""
    items = list(items)
    if len(items) <= 1 or usable_cores() == 1 or getattr(_on_pool, "worker", False):
        yield from (fn(item) for item in items)
        return
    pool, workers = _executor()
    window = collections.deque()
    ahead = iter(items)
    _opencv_single(True)
    try:
        for item in ahead:
            window.append(pool.submit(fn, item))
            if len(window) >= workers + 2:
                break
        while window:
            done = window.popleft()
            nxt = next(ahead, _END)
            if nxt is not _END:
                window.append(pool.submit(fn, nxt))
            yield done.result()
    finally:                       # a consumer that stops early (or an error) leaves nothing running
        try:
            for f in window:
                f.cancel()
            for f in window:
                if not f.cancelled():
                    f.exception()  # waits: OpenCV's threads come back only once no task of this map runs
        finally:                   # also when a second interrupt cuts that wait short
            _opencv_single(False)


_END = object()


def _opencv_single(entering: bool) -> None:
    """OpenCV on one thread from the first running map's start to the last one's end (counted: one map may be
    consumed while another is, and maps may run from several threads at once)."""
    import cv2
    with _lock:
        if entering:
            if _opencv["maps"] == 0:
                _opencv["threads"] = cv2.getNumThreads()
                cv2.setNumThreads(1)
            _opencv["maps"] += 1
        else:
            _opencv["maps"] -= 1
            if _opencv["maps"] == 0:
                cv2.setNumThreads(_opencv["threads"])
