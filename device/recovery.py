"""Stopping a scan this process did not start: ``eventfield device stop`` after the process that started it
was killed (SIGKILL, a crash, a lost terminal), when the generator goes on at full amplitude.

The controller that started a scan ramps it down from what it sent (``GalvoController.stop``). Here nothing was
sent: the amplitude and offset each running channel reports are ramped down in the controller's steps and time,
every command through its guard, then both outputs go off. A channel whose settings do not read back as numbers
is switched off as it is, and so is everything when the guard refuses a step (the generator holds settings
beyond this galvo's limits): only the ramp is skipped, never the switch-off.
"""
from __future__ import annotations

import math
import time

from .dialects import toward_zero
from .signals import signals_held
from .spec import SafetyError

SETTINGS = ("function", "frequency", "vpp", "offset")


def _running_channels(ctl) -> dict:
    """{channel: read-back settings} of each output that reports on with numbers to ramp from."""
    running = {}
    for ch in (1, 2):
        got = ctl.read_channel(ch)
        needed = ("offset",) if got.get("function") == "DC" else ("frequency", "vpp", "offset")
        if got.get("output") is True and got.get("function") in ("SIN", "DC") and all(
                isinstance(got.get(k), float) and math.isfinite(got[k]) for k in needed):
            running[ch] = got
    return running


def ramp_off(ctl, sleep=time.sleep) -> str:
    """Ramp down whatever the generator of ``ctl`` (a ``GalvoController``) reports running, then switch both
    outputs off (confirmed, as ``outputs_off``). Ctrl-C and SIGTERM wait for it. Returns what was done, in one
    line."""
    running = _running_channels(ctl)
    note = ""
    with signals_held():
        try:
            # the guard checks each step against the state the instrument holds, as if this process had sent it
            ctl._commanded = {ch: {k: running[ch][k] for k in SETTINGS if k in running[ch]} if ch in running else {}
                              for ch in (1, 2)}
            for k in range(ctl.ramp_steps - 1, 0, -1) if running else ():
                fraction = k / ctl.ramp_steps
                for ch, got in running.items():
                    cmds = [] if got["function"] == "DC" else list(ctl.d.amplitude(ch, toward_zero(got["vpp"] * fraction)))
                    ctl._send(cmds + (list(ctl.d.offset(ch, toward_zero(got["offset"] * fraction)))
                                      if got["offset"] else []))
                sleep(ctl.ramp_time / ctl.ramp_steps)
        except SafetyError as e:
            note = f" (no ramp: {e})"
        finally:
            ctl.outputs_off()
    if not running:
        return "outputs off (none was scanning)" + note
    return (f"channel {', '.join(map(str, running))}: amplitude and offset ramped down from the read-back, "
            "outputs off" + note)
