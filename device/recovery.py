"""Stopping a scan this process did not start: ``eventfield device stop`` after the process that started it
was killed (SIGKILL, a crash, a lost terminal), when the generator goes on at full amplitude.

The controller that started a scan ramps it down from what it sent (``GalvoController.stop``). Here nothing was
sent: the amplitude and offset each running channel reports are ramped down in the controller's steps and time,
every command through its guard, then both outputs go off. A generator left in Vrms or dBm is first told to
show its amplitude in Vpp (its output stays; the ramp scales Vpp: scaling a dBm figure switched off at 91 % of
the amplitude). A step that comes down from what the instrument already runs is taken even while it is still
beyond the galvo's derated amplitude (an overdriven scan is ramped, not cut: at 1.3x the whole ramp was
refused); a frequency beyond the galvo's is never ramped at. A channel whose settings do not read back as
numbers is switched off as it is, and so is everything when the guard refuses a step: only the ramp is
skipped, never the switch-off.
"""
from __future__ import annotations

import math
import time

from .dialects import toward_zero
from .signals import signals_held
from .spec import SafetyError

SETTINGS = ("function", "frequency", "vpp", "offset")


def _running_channels(ctl) -> tuple:
    """({channel: read-back settings} of each output that reports on with numbers to ramp from, [channels that
    report on, or do not answer, without them])."""
    running, as_is = {}, []
    for ch in (1, 2):
        try:
            got = ctl.read_channel(ch)
            if got.get("output") is not False and got.get("unit", "VPP") != "VPP":
                ctl._send(ctl.d.vpp_unit(ch))        # the output stays; its amplitude now reads in Vpp
                got = ctl.read_channel(ch)
        except Exception:  # noqa: BLE001  (a timeout, a dropped link: that channel goes off as it is)
            as_is.append(ch)
            continue
        needed = ("offset",) if got.get("function") == "DC" else ("frequency", "vpp", "offset")
        readable = got.get("function") in ("SIN", "DC") and got.get("unit", "VPP") == "VPP" and all(
            isinstance(got.get(k), float) and math.isfinite(got[k]) for k in needed)
        if readable and got.get("output") is True:
            running[ch] = got
        elif got.get("output") is not False:          # on, or not clearly off
            as_is.append(ch)
    return running, as_is


def _coming_down(ctl, running):
    """The guard's exception for a ramp step: channel settings no larger than the read-back ones (amplitude,
    offset's magnitude), at the function and frequency the channel runs, that frequency within the galvo's."""
    def descends(ch, state) -> bool:
        got = running.get(ch)
        if got is None or state.get("function") != got["function"]:
            return False
        if got["function"] == "SIN" and not (state.get("frequency") == got["frequency"]
                                             and 0 < got["frequency"] <= ctl.spec.max_frequency
                                             and 0 <= state.get("vpp", math.inf) <= got["vpp"]):
            return False
        return abs(state.get("offset", math.inf)) <= abs(got["offset"])
    return descends


def ramp_off(ctl, sleep=time.sleep) -> str:
    """Ramp down whatever the generator of ``ctl`` (a ``GalvoController``) reports running, then switch both
    outputs off (confirmed, as ``outputs_off``) whatever happens on the way (a read-back that times out
    included). Ctrl-C and SIGTERM wait for it. Returns what was done, in one line."""
    running, as_is, refused = {}, [], None
    ctl.running = True          # until confirmed off: a failed switch-off here is tried again by ``close``
    with signals_held():
        try:
            running, as_is = _running_channels(ctl)
            # the guard checks each step against the state the instrument holds, as if this process had sent it
            ctl._commanded = {ch: {k: running[ch][k] for k in SETTINGS if k in running[ch]} if ch in running else {}
                              for ch in (1, 2)}
            descent = _coming_down(ctl, running)
            for k in range(ctl.ramp_steps - 1, 0, -1) if running else ():
                fraction = k / ctl.ramp_steps
                for ch, got in running.items():
                    cmds = [] if got["function"] == "DC" else \
                        list(ctl.d.amplitude(ch, toward_zero(got["vpp"] * fraction)))
                    ctl._send(cmds + (list(ctl.d.offset(ch, toward_zero(got["offset"] * fraction)))
                                      if got["offset"] else []), descent=descent)
                sleep(ctl.ramp_time / ctl.ramp_steps)
        except SafetyError as e:
            refused = " ".join(str(e).split())
        finally:
            ctl.outputs_off()
    said = []
    if running and refused is None:
        said.append(f"channel {', '.join(map(str, running))}: ramped down from the read-back amplitude and offset")
    elif running:
        said.append(f"channel {', '.join(map(str, running))}: switched off without a ramp ({refused})")
    if as_is:
        said.append(f"channel {', '.join(map(str, as_is))}: settings unreadable, switched off without a ramp")
    return "; ".join(said + ["outputs off"]) if said else "outputs off (none was scanning)"
