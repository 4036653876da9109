"""The one exception type users see for bad input; the CLI prints it as a single line."""
from __future__ import annotations

import contextlib


class EventFieldError(Exception):
    """Invalid input or unmet precondition, with a message that names the file/field and the allowed range."""


class ConfigError(EventFieldError, ValueError):
    """A value in a file or argument is outside what is allowed."""


def plugin_message(e: Exception) -> str | None:
    """The message of the Python exception a plugin raised inside a Mitsuba load (the last ``...Error: ...`` line
    of the traceback Mitsuba embeds in its own error), or None when the error came from Mitsuba itself."""
    import re
    if "Traceback (most recent call last)" not in str(e):
        return None
    errors = re.findall(r"^\s*(?:\w+\.)*\w*(?:Error|Exception): (.+)$", str(e), flags=re.M)
    return errors[-1] if errors else None


def interrupt_in(e: BaseException):
    """The KeyboardInterrupt or SystemExit in ``e``'s chain of causes, or None: a library (Dr.Jit, Mitsuba) that
    wraps what our Python raised inside it wraps the user's Ctrl-C too, and a stop must stay a stop."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, (KeyboardInterrupt, SystemExit)):
            return e
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return None


# The signals that asked this process to stop, in order: the ``eventfield`` command's handler adds each before
# it raises KeyboardInterrupt, and clears them when the command ends. Why a record as well as the exception: an
# interrupt raised while a library runs our Python (Dr.Jit recording a frozen render, Mitsuba calling a plugin)
# can be swallowed there, and the render then ran to its end and published its output with exit status 0 (the
# CLI's Ctrl-C / SIGTERM test, about 1 run in 40 on a loaded machine). The loops of long jobs call
# :func:`raise_if_stopped` once a step, and the sink before it publishes anything.
STOP_SIGNALS: list[int] = []


def raise_if_stopped() -> None:
    """Raise KeyboardInterrupt when a stop signal was received (``STOP_SIGNALS``) and its own exception may
    have been lost on the way: a cheap check for every step of a render or conversion."""
    if STOP_SIGNALS:
        import signal
        raise KeyboardInterrupt(signal.Signals(STOP_SIGNALS[0]).name)


@contextlib.contextmanager
def interrupts_held(replay: bool = True):
    """SIGINT and SIGTERM held while cleanup runs that must not be cut short (a partial file removed, a folder
    put back). A signal that came meanwhile is then handed to the handler that was in place (so a Ctrl-C still
    stops, after the cleanup), unless ``replay`` is False (a finished run's last steps: its outputs are whole)
    or an exception was already on its way when the block began (the error that failed the run says more than
    the interrupt: a full disk read as "interrupted"). Off the main thread nothing changes: Python takes
    signals on the main thread only."""
    import signal
    import sys
    import threading
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    replay = replay and sys.exc_info()[1] is None
    came = []
    previous = {sig: signal.signal(sig, lambda signum, frame: came.append(signum))
                for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if came and replay:
            handler = previous[came[0]]
            if callable(handler):
                handler(came[0], None)
            elif handler == signal.SIG_DFL:      # the default action (SIGTERM: the process ends)
                signal.raise_signal(came[0])
