"""``eventfield``: the parser built from the command modules, and one way out for every failure: a one-line
error (exit 2), an unexpected error in one line (exit 3; EVENTFIELD_DEBUG=1 shows the traceback), or an
interrupt (130 / 143) after every ``finally`` has run (outputs off, temporary files removed)."""
from __future__ import annotations

import errno
import os
import signal
import sys
import threading

from . import apps, calibrate, designs, device, evaluate, events, lightfield, paper, scan_frequency
from ..errors import STOP_SIGNALS
from .args import OUTPUT_DIRS, Parser, check_outputs, one_line
from .inputs import StartFrameWarning

MODULES = (events, lightfield, calibrate, evaluate, apps, designs, scan_frequency, paper, device)
COMMANDS = {name: run for module in MODULES for name, run in module.COMMANDS.items()}


def build_parser() -> Parser:
    from .._version import __version__
    ap = Parser(prog="eventfield", description="Render and inspect event fields.")
    ap.add_argument("--version", action="version", version=f"mitsuba-eventfield {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    for module in MODULES:
        module.add_parsers(sub)
    return ap


received = STOP_SIGNALS      # the signals this command received (errors.STOP_SIGNALS: the loops check it too)


def _signals_as_interrupts():
    """SIGINT and SIGTERM raise KeyboardInterrupt, so every ``finally`` runs (outputs off, temporary files
    removed); the signal is remembered because a library between us and the handler (Dr.Jit calling a Python
    plugin) may hand it back wrapped in another exception, or swallow it (``errors.raise_if_stopped``). Returns
    the previous handlers, or {} off the main thread (where Python allows no handlers, and the record belongs
    to the main thread's command, if one runs)."""
    def on_signal(signum, frame):
        received.append(signum)
        raise KeyboardInterrupt(signal.Signals(signum).name)
    if threading.current_thread() is not threading.main_thread():
        return {}
    received.clear()
    return {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}


def _restore_signals(previous: dict) -> list:
    """Put back the handlers ``previous`` held and return the signals this command received, the record
    cleared (also when a second signal interrupts the restoring: a stale record would stop every later render
    in the process at its first step)."""
    try:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    finally:
        stopped = list(received)
        if threading.current_thread() is threading.main_thread():     # the record is the main thread's
            received.clear()
    return stopped


def _run(args) -> int:
    check_outputs(args)
    if args.command in OUTPUT_DIRS:
        from ..output_folders import output_dir_run
        with output_dir_run(args.output, args.command, _input_files(args)):
            return COMMANDS[args.command](args)
    return COMMANDS[args.command](args)


def _input_files(args) -> list:
    """The existing files the command's options name (its inputs: a calibration, an event file), which its output
    folder's clean-up must leave (``output_dir_run``)."""
    return [v for k, v in vars(args).items() if k != "output" and isinstance(v, str) and os.path.isfile(v)]


def _os_error(e: OSError) -> int | None:
    """The exit status of an OSError, or None when it came from an interrupt."""
    if e.errno == errno.ENOSPC:
        print(f"eventfield: error: disk full while writing {e.filename or 'the output'} (no partial output kept)"
              f"{_kept_checkpoint()}", file=sys.stderr)
        return 2
    if received:
        return None
    print(f"eventfield: error: {e.filename or ''}{': ' if e.filename else ''}{e.strerror or one_line(e)}"
          f"{_kept_checkpoint()}", file=sys.stderr)
    return 2


def _kept_checkpoint() -> str:
    """The end of a failure's line when a checkpointed render kept its last checkpoint (a full disk said
    "nothing was kept" while the work up to it waited in OUT.h5.resume/)."""
    from ..simulate.checkpoint import KEPT
    return (f"; its last checkpoint is kept in {KEPT[-1]}: run the same command with --resume to go on"
            if KEPT else "")


DEFERRED = []        # warnings said once the command has succeeded (``_warning_line``)


def _warning_line(message, category, filename, lineno, file=None, line=None):
    """A Python warning from the library (e.g. refocus's MotionBlurWarning) as one line of ours, no source line.
    A start frame's (``inputs.StartFrameWarning``) waits in ``DEFERRED`` until the command has succeeded: said
    while the inputs are read, it came before a refused command's one-line error."""
    text = f"eventfield: warning: {one_line(message) if isinstance(message, BaseException) else message}"
    if issubclass(category, StartFrameWarning):
        DEFERRED.append(text)
    else:
        print(text, file=sys.stderr)


def main(argv=None) -> int:
    import warnings

    from ..backend import quiet_mitsuba_log
    from ..errors import EventFieldError, raise_if_stopped
    from ..simulate.checkpoint import KEPT
    KEPT.clear()                     # this command's kept checkpoints only (main may run many in one process)
    show_warning, was_quiet, previous = warnings.showwarning, True, {}
    try:
        previous = _signals_as_interrupts()     # before the parser: a Ctrl-C there printed a traceback
        args = build_parser().parse_args(argv)
        # our lines only: no Mitsuba notes (monochrome film, "winding down" on Ctrl-C); restored when main returns
        was_quiet = quiet_mitsuba_log()
        warnings.showwarning = _warning_line
        DEFERRED.clear()
        with warnings.catch_warnings():   # (said at every run: main may run many commands in one process)
            warnings.showwarning = _warning_line
            warnings.simplefilter("always", StartFrameWarning)
            status = _run(args)
        raise_if_stopped()                # a stop a library swallowed: said, with the signal's exit status
        for text in DEFERRED:
            print(text, file=sys.stderr)
        return status
    except EventFieldError as e:
        print(f"eventfield: error: {one_line(e)}{_kept_checkpoint()}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        pass                                  # reported below, with the signal's exit status
    except BrokenPipeError:          # e.g. `eventfield info f.h5 | head`: the reader left; not an error of ours
        sys.stderr.close()
        return 0
    except OSError as e:
        status = _os_error(e)
        if status is not None:
            return status
    except Exception as e:  # noqa: BLE001  (no traceback reaches the user; EVENTFIELD_DEBUG=1 shows it)
        if not received:
            if os.environ.get("EVENTFIELD_DEBUG"):
                raise
            print(f"eventfield: error: unexpected {type(e).__name__}: {one_line(e)[:300]} "
                  "(EVENTFIELD_DEBUG=1 shows the traceback)", file=sys.stderr)
            return 3
    finally:
        stopped = _restore_signals(previous)     # first: a later render in this process goes on
        warnings.showwarning = show_warning
        if not was_quiet:
            quiet_mitsuba_log(False)
    signum = stopped[0] if stopped else signal.SIGINT
    print(f"eventfield: {'terminated' if signum == signal.SIGTERM else 'interrupted'} (no partial output kept)"
          f"{_kept_checkpoint()}", file=sys.stderr)
    return 128 + int(signum)
