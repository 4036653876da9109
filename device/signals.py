"""SIGINT and SIGTERM held while the galvo's outputs go to rest (a ramp, a fade, a switch-off), then delivered:
one home for the controller's and the NI-DAQmx output's."""
from __future__ import annotations

import contextlib
import signal
import threading


@contextlib.contextmanager
def signals_held():
    """SIGINT and SIGTERM held back while the outputs are being ramped down or switched off, then delivered as
    they would have been. Python-level handlers that only record the signal: a process mask set from the main
    thread left the other threads (BLAS's, NumPy's) to take the signal, and Python still raised it in the main
    thread, cutting a ramp short at 75 % of the amplitude (a review, 2026-11-27). Outside the main thread (no
    handlers can be set there) nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught = []

    def record(signum, frame):
        caught.append(signum)
    previous = {sig: signal.signal(sig, record) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            if signal.getsignal(sig) is record:  # (a handler set inside, e.g. SIGTERM's release, stays)
                signal.signal(sig, handler)
        for sig in dict.fromkeys(caught):        # each held signal once, to the handler now in place
            signal.raise_signal(sig)
