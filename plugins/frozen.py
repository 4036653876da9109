"""Dr.Jit frozen functions (``dr.freeze``) as this project uses them: :class:`FrozenOrTraced` (recorded once,
replayed; traced where Dr.Jit refuses to record) and the switch :func:`freezing` (``EVENTFIELD_FREEZE=0``
traces every call). In the plugins' layer because a chunk's event passes (``event_batch``) freeze as a step's
render does (``simulate/frames.py``); ``mitsuba_eventfield.backend`` re-exports both."""
from __future__ import annotations

import gc
import os
import threading

import drjit as dr

from mitsuba_eventfield.errors import interrupt_in, raise_if_stopped

FREEZE_ENV = "EVENTFIELD_FREEZE"


def freezing() -> bool:
    """Whether repeated Dr.Jit work is frozen (``dr.freeze``): a step's render (``simulate/frames.py``) and a
    chunk's event passes (``plugins/event_batch.py``); ``EVENTFIELD_FREEZE=0`` traces them at every call, and
    so does any thread but the main one. Why: a frozen call traverses its inputs, and the traversal of a
    Python plugin (ours: the event integrator, the galvo sensor) takes the GIL while Dr.Jit 1.5 holds its own
    lock; a thread holding the GIL that then needs Dr.Jit's lock (any array freed) deadlocks against it. Seen
    once in the full suite (2026-11-26): a Dask worker rendering a sweep point on its task thread, in
    ``Scene::traverse_1_cb_ro`` waiting for the GIL, while its event-loop thread, holding the GIL, spun in
    ``jit_var_dec_ref_impl`` freeing an array (the lock inversion of Dr.Jit issue 524). On the main thread
    nothing else in this package uses Dr.Jit concurrently (the event writer's thread takes NumPy arrays)."""
    return os.environ.get(FREEZE_ENV, "1") != "0" and threading.current_thread() is threading.main_thread()


class FrozenOrTraced:
    """``fn`` as a Dr.Jit frozen function (``dr.freeze``: recorded once, replayed), traced from then on when
    Dr.Jit refuses to record it (a virtual call on an object that is not among the inputs, e.g. a textured
    area emitter); ``refused`` then says why, in one line. Whatever a call changes must reach it as a Dr.Jit
    input: a replay does not redo the host-side arithmetic of its recording (docs/design.md, static pixels),
    so Python values the function reads belong in the key of the instance (one instance per key, as
    ``event_batch._frozen``). A new input layout (which inputs are literals, share a width, or sit on NumPy's
    memory with its alignment) makes Dr.Jit record again: correct, but a recording costs a trace."""

    def __init__(self, fn):
        # auto_opaque=False: every literal input is made opaque at each call. With Dr.Jit's default a literal that
        # changes between calls (a moving shape's to_world, built from host scalars so that Mitsuba need not read
        # it back: scene/timed.py) is found by recording again: the fan's render was recorded 5 times, not 2
        self.fn, self.frozen, self.refused = fn, dr.freeze(fn, auto_opaque=False), None

    @property
    def n_recordings(self) -> int:
        """How many times Dr.Jit recorded the function (bounded, then replayed: tests/simulate/test_frozen_render.py)."""
        return self.frozen.n_recordings

    def __call__(self, *args):
        if self.refused is None:
            # Python's cycle collector must not run inside a recording or replay: it may destroy Mitsuba and
            # Dr.Jit objects left in cycles by earlier code (a failed render's traceback), and one such destructor
            # aborted the process there (the full test suite, in mi.render under dr.freeze: "Garbage-collecting")
            collecting = gc.isenabled()
            gc.disable()
            try:
                return self.frozen(*args)
            except RuntimeError as e:
                # Dr.Jit wraps whatever the recorded function raised, a KeyboardInterrupt too (Ctrl-C or the
                # CLI's SIGTERM landing inside a recording, or in its traversal of the arguments: "FlatVariables::
                # assign()", which reached a library user as a RuntimeError): that is the user stopping, not a
                # refusal to freeze, and tracing on would swallow it (the render ran to its end: pytest-xdist)
                stop = interrupt_in(e)
                if stop is not None:
                    raise stop from e
                if "frozen function" not in str(e):
                    raise
                raise_if_stopped()      # the interrupt's own exception lost in Dr.Jit's wrapping: still a stop
                why = " ".join(str(e.__cause__ or e).split()).split("validate(): ")[-1].split(". ")[0][:160]
                self.refused = why or "refused"
            finally:
                if collecting:
                    gc.enable()
        return self.fn(*args)


class FrozenCache(dict):
    """Functions by key, each made on first use (``make()``) and frozen unless ``EVENTFIELD_FREEZE=0``; at
    most ``size`` kept, the oldest dropped first (a key per film and model: a process meets few)."""

    def __init__(self, size: int = 64):
        super().__init__()
        self.size = size

    def made(self, key, make):
        """The function for ``key``: frozen where :func:`freezing` says so, else traced (kept apart)."""
        key = (key, freezing())
        fn = self.get(key)
        if fn is None:
            fn = FrozenOrTraced(make()) if key[1] else make()
            if len(self) >= self.size:
                self.pop(next(iter(self)))
            self[key] = fn
        return fn
