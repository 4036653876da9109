"""How many events one step, or one chunk of steps, may make before any is made: a guard against a threshold far
below any sensor's, on the device and on the host's NumPy path (``pixel_model.expand_crossings``) alike."""
from __future__ import annotations


# bytes an event holds while it is made, measured (2026-11-27, a review): on the device ~43 (slots, sort keys
# and order, the sorted copy, the result), on the host's NumPy path ~89 (the expanded crossings' float64 and
# int64 columns); and the most events one chunk may index (its slot ends are 32-bit)
BYTES_PER_EVENT_MADE = {"device": 48, "host": 96}
MAX_CHUNK_EVENTS = (1 << 31) - 1
MEMORY_SHARE = 0.5       # of the memory available, what one step's events may take (the rest: everything else)
SMALL_CHUNK_BYTES = 64 << 20    # a chunk's events below this are not checked against the memory


def check_event_count(count: float, t0: float, t1: float, pixels: int, path: str = "device") -> None:
    """Refuse, in one line, a step (or chunk of steps) from ``t0`` to ``t1`` s whose ``count`` events (the sum of
    its kept crossing counts, before any is made; ``path``: "device" or "host", what an event costs there) would
    take more than ``MEMORY_SHARE`` of the memory available: a threshold far below any sensor's (1e-6 asked
    for 4 G events in one step of a 64x48 film and crashed on a 32-bit size; 1e-9 exhausted the memory)."""
    if count * BYTES_PER_EVENT_MADE[path] < SMALL_CHUNK_BYTES:    # (no /proc read a step for what any machine holds)
        return
    from mitsuba_eventfield.errors import EventFieldError
    from mitsuba_eventfield.validate import available_memory
    most = min(MAX_CHUNK_EVENTS, int(MEMORY_SHARE * available_memory()) // BYTES_PER_EVENT_MADE[path])
    if count > most:
        many = f"at least {count:.3g}" if path == "device" and count >= 4e9 else f"{count:.3g}"   # (capped there)
        on = f"{pixels} firing pixels" if path == "host" else f"{pixels} pixels"
        raise EventFieldError(f"{many} events from {t0:.6g} s to {t1:.6g} s on {on} ({count / pixels:.3g} "
                              f"a pixel): more than memory holds ({most:.3g}); raise the contrast threshold (events "
                              "a pixel grow as 1 / threshold), or in a render take shorter steps")
