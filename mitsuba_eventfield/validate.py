"""Checks of user-supplied numbers and sizes, with one message shape: what, the value, the allowed range.

The one place numbers are validated: the command line (argparse types built on ``number``, so a bad number is
refused before any work starts), library arguments (``number(..., strict=True)``, ``positive``, ``finite``:
text and booleans are refused there), scene and motion files, the scan envelope and the device layer (which
pass their own error class). Functions whose inputs decide how much memory or time a call takes use it too, so
``--fps 1e9`` or ``--views 1e8`` get a range error naming the limit instead of a MemoryError minutes later.
"""
from __future__ import annotations

import math
import numbers
import os

from .errors import ConfigError, EventFieldError

# Limits that are not physics but budgets: past them a call runs for hours or cannot fit in memory.
MAX_DURATION_S = 3600.0        # simulated seconds per render: the file's ms index and hours of rendering per second
MAX_CONVERT_S = 86400.0        # seconds of frames per conversion: a day (its HDF5 ms index alone is 0.7 GB)
MAX_STEPS = 10_000_000         # time steps per render (each costs a render of the whole film)
MAX_VIEWS = 4096               # views per scan period / frames per light field
MAX_PLANES = 1000              # depth planes searched
MAX_SPP = 65536
DEFAULT_SPP = 4                # a render's samples per pixel (each step) when none is given
# a frame's (render_frames, `eventfield frame`): its noise enters every view it anchors and every view a
# calibration registers (a kaleidoscope grid registered to 0.22 px at 4 spp, within 0.05 at 16); give
# spp=DEFAULT_SPP for the very image the event pixel saw
FRAME_SPP = 16
MAX_SEED = 2**32 - 1           # a render's seed reaches Mitsuba's sampler as an unsigned 32-bit word
MAX_THRESHOLD = 10.0           # contrast thresholds, log units (e^10: a 22,000x change for one event)


def number(value, name: str, lo=None, hi=None, *, integer: bool = False, lo_open: bool = False,
           strict: bool = False, error=ConfigError, inf_ok: bool = False):
    """``value`` as a float (or int) if finite and in [lo, hi] (``lo_open``: lo excluded); else ``error``
    naming ``name``, the value and the range. ``strict``: only real numbers (library arguments; the command
    line passes text, which is parsed). ``inf_ok``: the caller takes infinity itself (before calling this),
    so the range an error names is closed at inf (``describe_range``)."""
    kind = "a whole number" if integer else "a number"
    try:
        if isinstance(value, bool) or (strict and not isinstance(value, numbers.Real)):
            raise TypeError
        v = float(value)
        if integer:
            if not v.is_integer():
                raise ValueError
            v = int(v)
    except (TypeError, ValueError, OverflowError):
        raise error(f"{name} = {value!r}: must be {kind} {describe_range(lo, hi, lo_open, inf_ok)}") from None
    if not math.isfinite(v):
        bounded = lo is not None or hi is not None
        raise error(f"{name} = {value!r}: must be a finite number" +
                    (f" in {describe_range(lo, hi, lo_open, inf_ok)}" if bounded else ""))
    too_low = lo is not None and (v <= lo if lo_open else v < lo)
    if too_low or (hi is not None and v > hi):
        raise error(f"{name} = {value!r}: allowed range is {describe_range(lo, hi, lo_open, inf_ok)}")
    return v


def crop_window(window, width: int, height: int, name: str = "crop", error=ConfigError) -> tuple:
    """(x0, y0, w, h) of a window of whole pixels, at least one a side, inside a ``width`` x ``height`` sensor;
    else ``error`` naming ``name``, the window and the sensor."""
    parts = ("x0", "y0", "width", "height")
    if isinstance(window, (str, bytes)) or not hasattr(window, "__len__") or len(window) != 4:
        raise error(f"{name} = {window!r}: expected x0, y0, width, height in pixels")
    x0, y0, w, h = (number(v, f"{name} {part}", lo=0 if part in parts[:2] else 1, integer=True, strict=True,
                           error=error) for part, v in zip(parts, window))
    if x0 + w > width or y0 + h > height:
        raise error(f"{name} = {x0},{y0},{w},{h}: the window (x0, y0, width, height) must lie inside the "
                    f"{width}x{height} sensor (x0 + width <= {width}, y0 + height <= {height})")
    return x0, y0, w, h


def cut_window(frame, window):
    """The pixels of ``frame`` (H, W[, C]) inside ``window`` = (x0, y0, w, h) (``crop_window``)."""
    x0, y0, w, h = window
    return frame[y0:y0 + h, x0:x0 + w]


def flag(value, name: str, error=ConfigError) -> bool:
    """True or False (NumPy's too); anything else refused in one line naming ``name`` ("maybe" read as true)."""
    import numpy as np
    if not isinstance(value, (bool, np.bool_)):
        raise error(f"{name} = {value!r}: must be True or False")
    return bool(value)


def finite(value, name: str, error=ConfigError) -> float:
    """A real, finite number (not text, bool, NaN or inf)."""
    return number(value, name, strict=True, error=error)


def number_or_pair(value, name: str, error=ConfigError):
    """A number or an (x, y) pair of finite numbers, as given (a float or a float tuple)."""
    import numpy as np
    if np.iterable(value) and not isinstance(value, str):
        items = list(value)
        if len(items) != 2:
            raise error(f"{name} = {value!r}: expected a number or an (x, y) pair")
        return tuple(finite(v, name, error) for v in items)
    return finite(value, name, error)


def positive(value, name: str, integer: bool = False, error=ConfigError):
    """A real number (or whole number) > 0."""
    return number(value, name, 0, integer=integer, lo_open=True, strict=True, error=error)


def instance(value, kinds, name: str, hint: str = "", error=ConfigError):
    """``value`` if it is one of ``kinds`` (a type or tuple of types); else ``error`` naming ``name``, the
    expected and the given type (``hint``: where the right thing comes from, e.g. "ef.read_events")."""
    if not isinstance(value, kinds):
        names = " or ".join(k.__name__ for k in (kinds if isinstance(kinds, tuple) else (kinds,)))
        raise error(f"{name}: expected {names}{f' ({hint})' if hint else ''}, got {type(value).__name__}")
    return value


def file_path(value, name: str, error=ConfigError) -> str:
    """A file path given as text or ``os.PathLike`` (not None, a number or a file descriptor), as ``str``."""
    if not isinstance(value, (str, os.PathLike)) or not os.fspath(value):
        raise error(f"{name} = {value!r}: expected a file path (text)")
    return str(os.fspath(value))


def array(value, name: str, ndim, min_len: int = 1, error=ConfigError):
    """``value`` as a finite float64 NumPy array with ``ndim`` dimensions (a number or tuple of allowed
    numbers) and at least ``min_len`` entries along each axis."""
    import numpy as np
    allowed = ndim if isinstance(ndim, tuple) else (ndim,)
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise error(f"{name}: expected a numeric array, got {type(value).__name__}") from None
    if a.ndim not in allowed or min(a.shape, default=min_len) < min_len:
        dims = " or ".join(f"{d}-D" for d in allowed)
        least = f" with at least {min_len} entr{'y' if min_len == 1 else 'ies'} along each axis" if min_len else ""
        raise error(f"{name}: shape {a.shape}: expected a {dims} array{least}")
    if not np.all(np.isfinite(a)):
        raise error(f"{name}: contains NaN or infinite values")
    return a


def json_file(path: str, what: str):
    """The JSON in the file ``path`` (a calibration, a set-up's optics, ...): a missing file or invalid JSON is
    one EventFieldError naming the file and ``what`` it should be."""
    import json
    try:
        with open(path) as f:
            return json.load(f)
    except FileNotFoundError:
        raise EventFieldError(f"{path}: {what} not found") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        article = "an" if what[:1] in "aeiou" else "a"
        raise EventFieldError(f"{path}: not {article} {what} (invalid JSON: {e})") from None


def describe_range(lo, hi, lo_open=False, inf_ok=False) -> str:
    """The interval [lo, hi] as an error message writes it; an open end where a bound is None (the value must
    be finite) unless ``inf_ok`` (infinity itself is accepted: "(0, inf]")."""
    left = "(" if lo_open or lo is None else "["
    right = "]" if hi is not None or inf_ok else ")"
    return f"{left}{'-inf' if lo is None else _bound(lo)}, {'inf' if hi is None else _bound(hi)}{right}"


def _bound(v) -> str:
    """A range's end as the user would type it: whole numbers past %g's six digits in full (a seed's
    4294967295 read 4.29497e+09, above the real bound)."""
    if isinstance(v, int) and float(f"{v:g}") != v:
        return str(v)
    return f"{v:g}"


def number_list(text: str, name: str, lo=None, hi=None, lo_open=False, allow_inf=False) -> list:
    """Comma-separated numbers (e.g. ``--times 0,1.5,3``), each checked as ``number``; "inf" where allowed."""
    out = []
    items = [item.strip() for item in str(text).split(",")]
    if items and not items[-1] and len(items) > 1:
        items.pop()                      # one trailing comma: "0,1.5,"
    for item in items:
        if not item:
            if any(items):
                raise ConfigError(f"{name} = {text!r}: an empty item between commas; give numbers only")
            continue
        if allow_inf and item.lower() == "inf":
            out.append(math.inf)
            continue
        out.append(number(item, name, lo, hi, lo_open=lo_open, inf_ok=allow_inf))
    if not out:
        raise ConfigError(f"{name} = {text!r}: expected one or more comma-separated numbers")
    return out


def available_memory() -> int:
    """Bytes the system can still hand out (MemAvailable), or the physical memory where that is unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def usable_cores() -> int:
    """CPU cores this process may run on (its affinity mask where the system has one: a pinned process or a
    container's CPU set is fewer than the host's cores)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, cores or 1)


def check_allocation(nbytes: float, what: str, fraction: float = 0.5) -> None:
    """Refuse an array of ``nbytes`` when it would take more than ``fraction`` of the available memory."""
    avail = available_memory()
    if nbytes > fraction * avail:
        raise EventFieldError(f"{what} needs about {nbytes / 2**30:.3g} GiB, more than {fraction:.0%} of the "
                              f"{avail / 2**30:.1f} GiB available; ask for fewer")


def keywords(fn, given: dict, where: str, bound: int = 0, error=ConfigError) -> None:
    """Refuse the keywords of ``given`` that ``fn`` does not take after its first ``bound`` parameters (which
    the caller passes itself), in one line naming them and what it takes: a keyword handed on to a method a
    generator runs later surfaced as a TypeError at its first step."""
    import inspect
    params = dict(list(inspect.signature(fn).parameters.items())[bound:])
    if any(p.kind == p.VAR_KEYWORD for p in params.values()):
        return
    unknown = [k for k in given if k not in params]
    if unknown:
        takes = [k for k, p in params.items() if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
        raise error(f"{where}: {', '.join(unknown)}: not a keyword it takes ({', '.join(takes)})")
