"""The background writer's hold on glibc's mmap threshold (events/writer.py): a freed multi-megabyte chunk must
not leave the next one on the heap, where chunks freed on the writer's thread fragment it."""
import os
import subprocess
import sys

import pytest

CHILD = r"""
import sys
import numpy as np
from mitsuba_eventfield.events import writer

def resident_mb():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20

import os
held = writer.hold_mmap_threshold() if sys.argv[1] == "hold" else None
big = np.ones(16 << 20, np.uint8)      # a mapping; freeing it raises an adaptive threshold to 16 MB
del big
before = resident_mb()
chunk = np.ones(8 << 20, np.uint8)     # an 8 MB chunk: on the heap under the raised threshold, else mapped
del chunk
print(held, resident_mb() - before)
"""


# the chunk is 8 MB: kept on the heap it stays resident whole (> 6 MB below); given back, what stays is other
# allocations' noise, under 1 MB here and 2.15 MB once on the H200 machine's Python, with 14 test workers running
GIVEN_BACK_MB = 4.0


def _run(mode, code=CHILD, **env):
    """The child under this environment, less any malloc tuning it inherited (a Dask LocalCluster started by an
    earlier test leaves MALLOC_TRIM_THRESHOLD_ in this process's os.environ), plus ``env``."""
    inherited = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    r = subprocess.run([sys.executable, "-c", code, mode], capture_output=True, text=True, check=True,
                       env={**inherited, **env})
    held, kept_mb = r.stdout.split()[-2:]
    return held, float(kept_mb)


@pytest.mark.skipif(not sys.platform.startswith("linux") or os.environ.get("MALLOC_MMAP_THRESHOLD_") is not None,
                    reason="glibc's mallopt on Linux, with the environment not tuning malloc itself")
def test_a_freed_chunk_is_given_back_once_the_threshold_is_held():
    held, kept_mb = _run("hold")
    assert held == "True"
    assert kept_mb < GIVEN_BACK_MB        # its own mapping, unmapped when freed
    # the adaptive threshold keeps the same chunk resident on the heap: what the hold is for
    assert _run("adaptive")[1] > 6.0


def test_the_environments_malloc_tuning_is_left_alone():
    held, _ = _run("hold", MALLOC_MMAP_THRESHOLD_="2097152")
    assert held == "False"


def test_malloc_tuning_set_after_start_up_is_not_the_environments():
    """glibc read its tuning when the process started; a name os.environ gains later (Dask's nannies set
    MALLOC_TRIM_THRESHOLD_ in their parent for the workers they spawn) did not tune this process's malloc."""
    later = "import os, sys\nos.environ['MALLOC_TRIM_THRESHOLD_'] = '65536'\n" + CHILD
    held, kept_mb = _run("hold", code=later)
    assert held == "True" and kept_mb < GIVEN_BACK_MB


class _SlowTarget:
    """A writer target that takes ``delay`` seconds a chunk (``last_delay`` for the chunk closing the stream)."""

    def __init__(self, delay, last_delay=None):
        import threading
        self.delay, self.last_delay, self.chunks, self.closing = delay, last_delay, 0, threading.Event()

    def append(self, x, y, t, p, complete_until_us=None):
        import time
        time.sleep(self.last_delay if self.closing.is_set() and self.last_delay is not None else self.delay)
        self.chunks += 1

    def close(self, end_us=None, meta=None):
        pass

    def abort(self):
        pass


def _feed(target, chunks, between_s):
    """Hand ``chunks`` one-event chunks to a background writer, ``between_s`` apart (the render's steps)."""
    import time
    import numpy as np
    from mitsuba_eventfield.events.writer import BackgroundWriter
    w = BackgroundWriter(target)
    one = (np.zeros(1, np.uint16), np.zeros(1, np.uint16), np.zeros(1, np.int64), np.ones(1, np.int8))
    for i in range(chunks):
        if i == chunks - 1:
            target.closing.set()
        w.append(*one)
        time.sleep(between_s)
    w.drain()
    return w


def test_waiting_for_the_last_chunks_is_not_a_slow_disk():
    """A writer that keeps up with every step but takes long over the final chunk: the render's wait at the end
    is its tail, not time blocked on a full queue (which says the disk set the pace)."""
    w = _feed(_SlowTarget(0.001, last_delay=0.6), chunks=6, between_s=0.02)
    assert w.tail_s > 0.3 and w.wait_s < 0.05


def test_a_writer_slower_than_the_steps_blocks_the_render():
    """Chunks written more slowly than they come (0.05 s against 0.005 s a step): the two-chunk queue fills and
    the render waits on it while it runs."""
    w = _feed(_SlowTarget(0.05), chunks=10, between_s=0.005)
    assert w.wait_s > 0.2 and w.tail_s < 0.2


def test_borrowed_chunks_are_copied_in_order_and_freed_by_the_caller():
    """Borrowed chunks (append_borrowed) mixed with ordinary ones reach the target in the order handed over, as
    NumPy's own memory, copied on the copier's thread; the borrowed buffers are freed on the caller's thread
    (freed on another, Dr.Jit's pinned buffers were never reused on a GPU), none before its copy."""
    import threading
    import time

    import numpy as np
    from conftest import FreedOn

    from mitsuba_eventfield.events.writer import BackgroundWriter

    class Target:
        def __init__(self):
            self.seen = []

        def append(self, x, y, t, p, complete_until_us=None):
            own = all(c.base is None for c in (x, y, t, p))
            self.seen.append((int(t[0]), own, threading.current_thread().name))
            time.sleep(0.002)

    freed, target = [], Target()
    w = BackgroundWriter(target)

    def chunk(i, lent):
        cols = (np.full(3, i, np.uint16), np.full(3, i, np.uint16), np.full(3, i, np.int64), np.ones(3, np.int8))
        return tuple(np.asarray(FreedOn(c, freed)) for c in cols) if lent else cols
    for i in range(12):
        if i % 3 == 2:
            w.append(*chunk(i, False))
        else:
            w.append_borrowed(*chunk(i, True))
    w.drain()
    assert [s[0] for s in target.seen] == list(range(12))
    assert all(own for _, own, _ in target.seen) and {s[2] for s in target.seen} == {"eventfield-writer"}
    assert len(freed) == 4 * 8 and set(freed) == {threading.get_ident()}
    assert w.copy_s > 0 and w.copier is not None and not w.copier.is_alive()


def test_a_failing_writer_with_borrowed_chunks_raises_in_the_caller_and_frees_there():
    """The target fails on its second chunk (a full disk): the error reaches the caller's thread at a later
    hand-over or at the drain, nothing hangs, and every borrowed buffer is still freed on the caller's thread."""
    import threading
    import time

    import numpy as np
    import pytest
    from conftest import FreedOn

    from mitsuba_eventfield.events.writer import BackgroundWriter

    class Failing:
        def __init__(self):
            self.calls = 0

        def append(self, x, y, t, p, complete_until_us=None):
            self.calls += 1
            if self.calls >= 2:                       # every chunk from the second on would fail
                raise OSError(f"no space left on device (chunk {self.calls})")

        def abort(self):
            pass

    freed, failing = [], Failing()
    w = BackgroundWriter(failing)
    with pytest.raises(OSError, match=r"no space left on device \(chunk 2\)"):     # the first error
        for i in range(50):
            cols = (np.full(3, i, np.uint16), np.full(3, i, np.uint16), np.full(3, i, np.int64), np.ones(3, np.int8))
            w.append_borrowed(*(np.asarray(FreedOn(c, freed)) for c in cols))
            time.sleep(0.002)
        w.drain()
    w.abort()
    assert not w.thread.is_alive() and not w.copier.is_alive() and not w._borrowed
    assert freed and len(freed) % 4 == 0 and set(freed) == {threading.get_ident()}
    assert failing.calls == 2                         # the chunks queued after the failure were dropped, unwritten


def test_a_write_needs_its_bytes_and_the_margin_free(tmp_path, monkeypatch):
    """``disk.check_space``: a write of N bytes is refused unless N plus DISK_MARGIN are free (HDF5 and
    dv-processing do not recover from ENOSPC), and taken with exactly that much."""
    import pytest

    import mitsuba_eventfield as ef
    from mitsuba_eventfield.events import disk
    need = 10_000_000
    for free, refused in ((need + disk.DISK_MARGIN // 2, True), (need + disk.DISK_MARGIN, False)):
        monkeypatch.setattr(disk, "_free_bytes", lambda path, free=free: free)
        if refused:
            with pytest.raises(ef.EventFieldError, match="disk full"):
                disk.check_space(str(tmp_path / "e.h5"), need)
        else:
            disk.check_space(str(tmp_path / "e.h5"), need)


@pytest.mark.parametrize("borrowed, during", [(False, "threads"), (True, "threads"), (False, "file")])
def test_a_second_ctrl_c_while_aborting_still_removes_the_partial_file(tmp_path, borrowed, during):
    """A second Ctrl-C while ``abort`` waited for the writer's thread, or while the file writer's own abort
    waited for its compression pool, escaped before the partial file was removed (an .h5.partial, or an .npz's
    column files, left beside the output under "no partial output kept"): it is held until the file is gone,
    then raised; the queued chunks are dropped, not written."""
    import signal
    import threading
    import time

    import numpy as np
    from mitsuba_eventfield.events.writer import BackgroundWriter

    class Slow:
        appended, removed = 0, False

        def append(self, *a):
            time.sleep(0.3 if during == "threads" else 0.0)
            self.appended += 1

        def abort(self):
            time.sleep(0.3 if during == "file" else 0.0)      # (H5EventWriter's pool of deflate tasks)
            self.removed = True
    target = Slow()
    w = BackgroundWriter(target)
    one = (np.zeros(1, np.uint16), np.zeros(1, np.uint16), np.zeros(1, np.int64), np.ones(1, np.int8))
    for _ in range(3):                        # one being written, two queued
        (w.append_borrowed if borrowed else w.append)(*one)
    time.sleep(0.05)
    main = threading.main_thread().ident
    timer = threading.Timer(0.1, lambda: signal.pthread_kill(main, signal.SIGINT))
    timer.start()
    t0 = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):    # said once the file is gone
        w.abort()
    timer.join()
    assert target.removed and not w.thread.is_alive()
    assert target.appended == (1 if during == "threads" else 3) or during == "file"
    assert time.perf_counter() - t0 < 0.6     # queued chunks dropped, not written (0.3 s each)
