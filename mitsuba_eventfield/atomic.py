"""Output files appear whole or not at all: write to a hidden temporary name beside the target, then rename."""
from __future__ import annotations

import contextlib
import os
import uuid

from .errors import EventFieldError


def check_writable(path: str, what: str = "output") -> str:
    """Fail early (before any rendering) if ``path`` cannot be created; return its absolute path."""
    path = os.path.abspath(path)
    parent = os.path.dirname(path)
    if os.path.isdir(path):
        raise EventFieldError(f"{what} path {path}: is a directory")
    if not os.path.isdir(parent):
        raise EventFieldError(f"{what} path {path}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise EventFieldError(f"{what} path {path}: directory {parent} is not writable")
    return path


def temporary_name(path: str) -> str:
    head, tail = os.path.split(os.path.abspath(path))
    ext = os.path.splitext(tail)[1]  # keep the extension: some writers (OpenCV) choose the format by it
    return os.path.join(head, f".{tail}.{uuid.uuid4().hex[:8]}.part{ext}")


@contextlib.contextmanager
def atomic_output(path: str, what: str = "output"):
    """Yield a temporary path; on normal exit rename it to ``path``, on error delete it."""
    path = check_writable(path, what)
    tmp = temporary_name(path)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.remove(tmp)


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
