"""AEDAT4 event files read through dv-processing, the reader where faery (a dependency, which decodes them
in-process: ``recordings.read_aedat4_faery``) is absent: in a child process that is stopped when a damaged packet
leaves it making no progress. They are written by faery's encoder (``streaming.Aedat4EventWriter``)."""
from __future__ import annotations

import json
import os

import numpy as np

from ..errors import EventFieldError
from .disk import BadFile
from .stream import EventStream

def write_aedat4(path, events):
    """A whole stream to AEDAT4 (``streaming.Aedat4EventWriter``, as a render streams it)."""
    from .io import write_events
    return write_events(path, events, "aedat4")


# AEDAT4 is decoded by dv-processing in a child process: on some damaged packets (a valid header and data
# table, bytes of a packet overwritten) its decoder spins forever inside one C++ call, which no thread of ours
# could stop. The child sends each batch as it decodes it; no batch for AEDAT4_STALL_S (a healthy packet takes
# milliseconds) means it is stuck, and it is killed.
AEDAT4_STALL_S = 10.0
_AEDAT4_DTYPE = np.dtype([("timestamp", "<i8"), ("x", "<i2"), ("y", "<i2"), ("polarity", "i1")])
_AEDAT4_READER = r"""
import json, sys
import numpy as np
out = sys.stdout.buffer
try:
    import dv_processing as dv
    dtype = np.dtype([("timestamp", "<i8"), ("x", "<i2"), ("y", "<i2"), ("polarity", "i1")])
    rec = dv.io.MonoCameraRecording(sys.argv[1])
    w, h = rec.getEventResolution()
    out.write((json.dumps({"width": int(w), "height": int(h), "camera": rec.getCameraName()}) + "\n").encode())
    out.flush()
    while True:
        batch = rec.getNextEventBatch()
        if batch is None:
            break
        a = batch.numpy()
        b = np.empty(len(a), dtype)
        for k in dtype.names:
            b[k] = a[k]
        out.write(b.tobytes())
        out.flush()
except BaseException as e:
    sys.stderr.write(str(e) or type(e).__name__)
    sys.exit(1)
"""


def read_aedat4(path):
    import importlib.util
    import queue
    import signal
    import subprocess
    import sys
    import threading
    if importlib.util.find_spec("dv_processing") is None:
        raise EventFieldError(f"{path}: reading AEDAT4 needs dv-processing (pip install dv-processing)")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))   # the same dv-processing
    proc = subprocess.Popen([sys.executable, "-c", _AEDAT4_READER, path], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    chunks, errors = queue.Queue(), []

    def pump():
        while True:
            data = proc.stdout.read1(1 << 20)
            chunks.put(data)
            if not data:
                return
    readers = [threading.Thread(target=pump, daemon=True),
               threading.Thread(target=lambda: errors.append(proc.stderr.read()), daemon=True)]
    for r in readers:
        r.start()
    stuck = BadFile(f"damaged AEDAT4 file: dv-processing stopped making progress decoding it (nothing for "
                     f"{AEDAT4_STALL_S:g} s; a corrupt packet?)")
    received = bytearray()
    try:
        while True:
            try:
                data = chunks.get(timeout=AEDAT4_STALL_S)
            except queue.Empty:
                raise stuck from None
            if not data:
                break
            received += data
        try:
            rc = proc.wait(timeout=AEDAT4_STALL_S)
        except subprocess.TimeoutExpired:
            raise stuck from None
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for r in readers:
            r.join(timeout=5)
    if rc < 0:
        try:
            name = signal.Signals(-rc).name
        except ValueError:
            name = f"signal {-rc}"
        raise BadFile(f"damaged AEDAT4 file: dv-processing crashed decoding it ({name})")
    if rc != 0:
        raise RuntimeError((errors[0] if errors else b"").decode("utf-8", "replace") or f"exit status {rc}")
    head, _, body = bytes(received).partition(b"\n")
    info = json.loads(head)
    if len(body) % _AEDAT4_DTYPE.itemsize:
        raise BadFile("damaged AEDAT4 file: an incomplete event from dv-processing")
    arr = np.frombuffer(body, _AEDAT4_DTYPE)
    return EventStream(arr["x"], arr["y"], arr["timestamp"], np.where(arr["polarity"] > 0, 1, -1), info["width"],
                       info["height"], {"camera": info["camera"]})
