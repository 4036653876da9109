"""``device scan | stop | status``: drive the galvo through a function generator (``device/``). Every check
of a scan request happens before a connection is opened; the controller switches the outputs off on every
way out."""
from __future__ import annotations

import argparse
import sys

from ..device.spec import MAX_DURATION_S as MAX_SCAN_S
from ..device.spec import PHASE_RANGE_DEG, VOLTS_PER_DEG_RANGE
from .args import num


def add_parsers(sub) -> None:
    dev = sub.add_parser("device", help="drive the galvo through a function generator (SCPI/VISA)")
    dsub = dev.add_subparsers(dest="action", required=True)
    conn = argparse.ArgumentParser(add_help=False)
    conn.add_argument("--resource", help="VISA resource, e.g. TCPIP0::192.0.2.7::inst0::INSTR")
    conn.add_argument("--dialect", required=True, choices=("keysight", "rigol", "siglent"), help="generator dialect")
    conn.add_argument("--simulate", action="store_true", help="a simulated instrument (in memory), no hardware")
    conn.add_argument("--volts-per-deg", type=num(*VOLTS_PER_DEG_RANGE), default=0.8,
                      help="galvo driver scaling, V per mechanical degree (default 0.8)")
    ds = dsub.add_parser("scan", parents=[conn], help="start a scan (ramped), keep it running, stop on exit")
    ds.add_argument("--curve", default="circle", choices=("circle", "line", "lissajous"), help="sine scans only")
    # frequency and amplitude limits are the galvo envelope's (device/spec.py), checked with the whole request
    ds.add_argument("--freq", type=num(0, lo_open=True), required=True, help="Hz (x axis for lissajous)")
    ds.add_argument("--freq-y", type=num(0, lo_open=True), help="lissajous: y frequency")
    ds.add_argument("--amplitude-deg", type=num(0), required=True, help="mechanical degrees (x for lissajous)")
    ds.add_argument("--amplitude-y-deg", type=num(0), help="lissajous: y amplitude")
    ds.add_argument("--phase", type=num(*PHASE_RANGE_DEG),
                    help="degrees: the curve's phase (lissajous: the x axis's; default 0, lissajous 90: the "
                         "scene plugin's and make_curve's defaults)")
    ds.add_argument("--axis", choices=("x", "y"), help="line: x (default) or y")
    ds.add_argument("--duration", type=num(0, MAX_SCAN_S), default=0.0,
                    help="seconds to scan, then stop (default 0: until Ctrl-C or SIGTERM)")
    ds.add_argument("--metadata", help="write the capture metadata (instrument, read-back, scan) to this JSON")
    dsub.add_parser("stop", parents=[conn],
                    help="ramp down whatever the generator is scanning (read back), then switch both outputs off")
    dsub.add_parser("status", parents=[conn], help="identity, settings read back, error queue")


def scan_curve(a, spec):
    """The scan curve a ``device scan`` request names (validated by the scan module)."""
    from ..errors import EventFieldError
    from ..optics.scan import make_curve
    # options a curve does not take were taken silently before, as if the scan were what was asked
    given = [f for f, v in (("--freq-y", a.freq_y), ("--amplitude-y-deg", a.amplitude_y_deg)) if v is not None]
    if given and a.curve != "lissajous":
        raise EventFieldError(f"{' and '.join(given)}: a lissajous scan's y axis; a {a.curve} takes --freq and "
                              "--amplitude-deg" + (" (and --axis)" if a.curve == "line" else ""))
    if a.axis is not None and a.curve != "line":
        raise EventFieldError(f"--axis {a.axis}: a line scan's axis; a {a.curve} scans both axes")
    # the phase when not given: make_curve's own default (a lissajous 90 deg on x: the circle-like figure a
    # scene renders; the command line's 0 drove the diagonal line instead)
    phase = {} if a.phase is None else {"phase_x" if a.curve == "lissajous" else "phase": a.phase}
    limit = {"envelope": spec.scan_envelope, "where": "device scan"}     # the rig's own, with its driver scaling
    if a.curve == "lissajous":
        return make_curve("lissajous", freq_x=a.freq, freq_y=a.freq_y or a.freq, amplitude_x=a.amplitude_deg,
                          amplitude_y=a.amplitude_y_deg if a.amplitude_y_deg is not None else a.amplitude_deg,
                          **limit, **phase)
    if a.curve == "line":
        return make_curve("line", frequency=a.freq, amplitude=a.amplitude_deg, axis=a.axis or "x", **limit, **phase)
    return make_curve(a.curve, frequency=a.freq, amplitude=a.amplitude_deg, **limit, **phase)


def _status(ctl) -> None:
    print(f"instrument: {ctl.identity()}")
    for ch in (1, 2):
        print(f"channel {ch}: " + ", ".join(f"{k} {v}" for k, v in ctl.read_channel(ch).items()))
    errs = ctl.errors()
    print("error queue: " + ("; ".join(f"{c}: {m}" for c, m in errs) if errs else "empty"))


def _scan(a, ctl, curve, duration) -> None:
    import time

    from ..atomic import write_json
    ctl.start(curve)               # a failed start has switched the outputs off itself (no ramp to undo)
    try:
        print(f"scanning {curve.name} at {a.freq:g} Hz, {a.amplitude_deg:g} deg on {ctl.identity()}; read-back "
              "matches", flush=True)
        if a.metadata:
            write_json(a.metadata, ctl.metadata(curve), "metadata")
        end = time.monotonic() + duration if duration > 0 else float("inf")
        while time.monotonic() < end:
            time.sleep(max(0.0, min(0.2, end - time.monotonic())))
    except BaseException as e:     # Ctrl-C or SIGTERM (the usual end of a scan without a duration), or an error
        if ctl.running:            # ramped down as at the end of a duration (a second Ctrl-C waits for it)
            ctl.stop()
            if isinstance(e, (KeyboardInterrupt, SystemExit)):   # (an error says itself, in its one line)
                print("interrupted: amplitude ramped down, outputs off", file=sys.stderr)
        raise
    ctl.stop()
    print("stopped: amplitude ramped down, outputs off")


def run_device(a) -> int:
    from ..device import GalvoController, GalvoSpec, dialect, open_transport
    from ..device.spec import check_duration
    from ..errors import EventFieldError
    spec = GalvoSpec(volts_per_deg=a.volts_per_deg)
    dialect(a.dialect)
    if a.simulate and a.resource:      # the simulation ran, silently, instead of the named instrument
        raise EventFieldError(f"--resource {a.resource} and --simulate: give one (--simulate drives no hardware)")
    curve = duration = None
    if a.action == "scan":      # every check happens before a connection is even opened
        curve = scan_curve(a, spec)
        duration = check_duration(a.duration)
        GalvoController(None, a.dialect, spec).plan(curve)
    # The context manager switches the outputs off before the connection closes, on every way out of this
    # block: a refusal, a failed metadata write, Ctrl-C, SIGTERM (main turns it into an exception).
    with GalvoController(open_transport(a.dialect, a.resource, a.simulate), a.dialect, spec) as ctl:
        if a.action == "status":
            _status(ctl)
        elif a.action == "stop":       # a scan a killed process left on: ramped down from what it reports
            from ..device.recovery import ramp_off
            print(ramp_off(ctl))
        else:
            _scan(a, ctl, curve, duration)
    return 0


COMMANDS = {"device": run_device}
