"""No unsafe byte reaches the galvo: adversarial requests, dangerous instrument presets, refused commands and
broken links, through every dialect's simulated instrument and through `eventfield device`.

The checks here do not reuse the controller's decoding: commands are parsed by this file's own regular
expressions, and what the galvo sees is the simulated instrument's state after every write."""
import math
import re
import signal
import subprocess
import sys
import threading

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import mitsuba_eventfield as ef
from mitsuba_eventfield import cli
from mitsuba_eventfield.device import GalvoController, GalvoSpec, SafetyError, simulated
from mitsuba_eventfield.device.spec import MIN_FREQUENCY_HZ
from mitsuba_eventfield.optics.scan import Lissajous

DIALECTS = ("keysight", "rigol", "siglent")
NO_SLEEP = lambda s: None  # noqa: E731
SPEC = GalvoSpec()

# ---------------------------------------------------------------- independent command parsing
_NUM = r"([-+0-9.eE]+|nan|inf|-inf)"
_SCPI = re.compile(r":?SOUR([12]):(FREQ|VOLT|VOLT:OFFS) " + _NUM + "$")
_SIGLENT_FIELD = re.compile(r"(FRQ|AMP|OFST),([^,]+)")


def sent_values(cmd):
    """{channel: {frequency|vpp|offset: float}} named in one written command."""
    m = _SCPI.match(cmd)
    if m:
        return {int(m.group(1)): {{"FREQ": "frequency", "VOLT": "vpp", "VOLT:OFFS": "offset"}[m.group(2)]:
                                  float(m.group(3))}}
    m = re.match(r"C([12]):BSWV (.*)$", cmd)
    if m:
        names = {"FRQ": "frequency", "AMP": "vpp", "OFST": "offset"}
        return {int(m.group(1)): {names[k]: float(v) for k, v in _SIGLENT_FIELD.findall(m.group(2))}}
    return {}


def within_envelope(frequency, vpp, offset, function="SIN", spec=SPEC, slack=1e-9):
    """What the galvo may be driven with (``slack``: the 10 significant digits commands carry)."""
    values = [offset] + ([frequency, vpp] if function == "SIN" else [])
    if not all(math.isfinite(v) for v in values):
        return False
    amp = vpp / (2 * spec.volts_per_deg) if function == "SIN" else 0.0
    off = abs(offset) / spec.volts_per_deg
    ok = off + amp <= spec.max_mech_deg * (1 + slack) and (off + amp) * spec.volts_per_deg <= spec.max_volts * (1 + slack)
    if function == "SIN":
        ok &= 0 < frequency <= spec.max_frequency and amp <= spec.max_amplitude_deg(frequency) * (1 + slack)
    return ok


def request_is_safe(curve, spec=SPEC):
    axes = ((curve.freq_x, curve.amplitude_x, curve.offset_x, curve.phase_x),
            (curve.freq_y, curve.amplitude_y, curve.offset_y, curve.phase_y))
    for f, a, off, ph in axes:
        if not all(isinstance(v, float) and math.isfinite(v) for v in (f, a, off, ph)):
            return False
        # any axis names a frequency; below MIN_FREQUENCY_HZ no scan (a generator's 1e-300 Hz): refused too
        if not (MIN_FREQUENCY_HZ <= f <= spec.max_frequency and a >= 0 and abs(ph) <= 720):
            return False
        if not within_envelope(f, 2 * a * spec.volts_per_deg, off * spec.volts_per_deg, "SIN" if a else "DC", spec, 0):
            return False
    return True


def assert_galvo_never_saw_unsafe(gen, spec=SPEC):
    """Every byte's values inside the envelope, and at every instant every switched-on channel's instrument
    state inside it (a refused command leaves the previous, possibly dangerous, setting: it must stay dark)."""
    known = {1: {}, 2: {}}
    for cmd, state in gen.history:
        for ch, vals in sent_values(cmd).items():
            known[ch].update(vals)
            k = known[ch]
            if "vpp" in k and "frequency" in k:
                assert within_envelope(k["frequency"], k["vpp"], k.get("offset", 0.0), spec=spec), cmd
            for v in vals.values():
                assert math.isfinite(v), cmd
        for ch, s in state.items():
            if s["output"]:
                assert within_envelope(s["frequency"], s["vpp"], s["offset"], s["function"], spec), (cmd, s)
                assert s["high_z"], (cmd, s)


def outputs_off(gen):
    return not gen.state[1]["output"] and not gen.state[2]["output"]


# ---------------------------------------------------------------- the property test
_finite_or_not = st.one_of(st.floats(min_value=-50, max_value=3000), st.sampled_from([math.nan, math.inf, -math.inf]))
_preset = st.fixed_dictionaries({"vpp": st.sampled_from([0.1, 4.0, 18.0]),
                                 "frequency": st.sampled_from([10.0, 1000.0, 5e4]),
                                 "offset": st.sampled_from([0.0, 1.5, -1.5])})


@settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(dialect=st.sampled_from(DIALECTS),
       kind=st.sampled_from(["circle", "line", "lissajous"]),
       f=_finite_or_not, ratio=st.sampled_from([1.0, 1.5, 2.0]),
       amp=st.one_of(st.floats(min_value=0, max_value=20), st.sampled_from([math.nan, -1.0, math.inf])),
       offset=st.one_of(st.floats(min_value=-15, max_value=15), st.just(math.nan)),
       phase=st.one_of(st.floats(min_value=-1000, max_value=1000), st.just(math.nan)),
       preset=_preset,
       fault=st.one_of(st.none(), st.tuples(st.sampled_from(["refuse", "raise"]), st.integers(0, 30))))
# found by the property test (2026-11-27): the link dropped one command of close()'s confirmation, which was not
# tried again, so close() could not confirm the outputs off
@example(dialect="siglent", kind="circle", f=1.0, ratio=1.0, amp=1.0, offset=0.0, phase=0.0,
         preset={"vpp": 0.1, "frequency": 10.0, "offset": 0.0}, fault=("raise", 16))
def test_no_unsafe_byte_whatever_the_request_preset_or_fault(dialect, kind, f, ratio, amp, offset, phase, preset,
                                                             fault):
    # built directly, past the scan module's own checks: the device must not rely on them
    curve = Lissajous(freq_x=f, freq_y=f * ratio if kind == "lissajous" else f, amplitude_x=amp,
                      amplitude_y=0.0 if kind == "line" else amp, phase_x=phase, phase_y=0.0, offset_x=offset,
                      kind=kind, max_angle_deg=90.0)
    writes = [0]           # raise_on sees every write first (queries end in "?"), refuse sees it next

    def raise_on(cmd):
        if cmd.endswith("?"):
            return None
        writes[0] += 1
        return ConnectionError("link lost") if fault == ("raise", writes[0] - 1) else None
    gen = simulated(dialect, preset={1: dict(preset), 2: dict(preset)}, raise_on=raise_on,
                    refuse=lambda cmd: fault == ("refuse", writes[0] - 1))
    ctl = GalvoController(gen, dialect, ramp_steps=3, ramp_time=0)
    safe = request_is_safe(curve)
    try:
        ctl.start(curve, sleep=NO_SLEEP)
        started = True
    except SafetyError as e:
        started = False
        # a safe request on a healthy instrument is refused only where the instrument itself refuses a value
        # (a transitional peak beyond its own limit), or where it would: a sine below its 1 mVpp minimum at the
        # first ramp step, refused by the plan since 2026-11-27
        assert fault is not None or not safe or "did not confirm" in str(e) or "smallest sine" in str(e)
    except ConnectionError:
        started = False
        assert fault is not None and fault[0] == "raise"
    if not safe:
        assert not started and gen.history == []          # refused before the first byte
    if not started:
        assert outputs_off(gen)
    assert_galvo_never_saw_unsafe(gen)
    ctl.close()
    assert outputs_off(gen) and gen.closed                 # nothing scans once the controller is closed


# ---------------------------------------------------------------- the reported defects, one by one
def test_line_scan_over_a_dangerous_preset_never_drives_it():
    """`--curve line` used to send 0 Vpp to the idle axis; refused, the channel kept 18 Vpp and went on."""
    for dialect in DIALECTS:
        gen = simulated(dialect, preset={1: {"vpp": 18.0}, 2: {"vpp": 18.0, "frequency": 100.0}})
        with GalvoController(gen, dialect, ramp_steps=2, ramp_time=0) as ctl:
            ctl.start(ef.make_curve("line", frequency=100.0, amplitude=2.0), sleep=NO_SLEEP)
            assert gen.state[2]["function"] == "DC" and gen.state[2]["offset"] == 0.0 and gen.state[2]["output"]
            assert not any(re.search(r"(VOLT|AMP,)\s*0(\.0)?$", c) for c, _ in gen.history)   # no 0 Vpp sine
            assert_galvo_never_saw_unsafe(gen)
        assert outputs_off(gen)


@pytest.mark.parametrize("dialect", DIALECTS)
def test_refused_amplitude_leaves_outputs_off(dialect):
    gen = simulated(dialect, preset={1: {"vpp": 18.0, "frequency": 100.0}},
                    refuse=lambda cmd: bool(re.search(r"(SOUR1:VOLT |C1:BSWV WVTP)", cmd)))
    ctl = GalvoController(gen, dialect, ramp_steps=2, ramp_time=0)
    with pytest.raises(SafetyError, match="did not confirm"):
        ctl.start(ef.make_curve("circle", frequency=100.0, amplitude=1.0), sleep=NO_SLEEP)
    assert outputs_off(gen) and not any(s[1]["output"] for _, s in gen.history)
    ctl.close()


@pytest.mark.parametrize("bad", [math.nan, -0.8, math.inf, 0.0, 50.0])
def test_volts_per_degree_is_validated(bad):
    with pytest.raises(SafetyError, match="volts_per_deg"):
        GalvoSpec(volts_per_deg=bad)


@pytest.mark.parametrize("phase", [math.nan, math.inf, 1e9])
def test_phase_is_validated(phase):
    gen = simulated("keysight")
    with pytest.raises(SafetyError, match="phase"):
        GalvoController(gen, "keysight").start(Lissajous(phase_x=phase, amplitude_x=0.5, amplitude_y=0.5))
    assert gen.history == []


# ---------------------------------------------------------------- through the CLI
@pytest.fixture
def instrument(monkeypatch):
    """The generator `eventfield device` connects to, kept by the test; writes after close are an error."""
    holder = {}

    def open_transport(dialect, resource=None, simulate=False):
        holder["gen"] = simulated(dialect)
        return holder["gen"]
    monkeypatch.setattr("mitsuba_eventfield.device.open_transport", open_transport)
    return holder


SCAN = ["device", "scan", "--simulate", "--dialect", "rigol", "--freq", "100", "--amplitude-deg", "1"]


@pytest.mark.parametrize("extra, message", [
    (["--duration", "-1"], "--duration"), (["--duration", "nan"], "--duration"), (["--duration", "inf"], "--duration"),
    (["--volts-per-deg", "nan"], "--volts-per-deg"), (["--volts-per-deg", "-0.8"], "--volts-per-deg"),
    (["--phase", "nan"], "--phase"), (["--amplitude-deg", "9"], "derated limit"),
    (["--metadata", "/nonexistent-dir/m.json"], "does not exist")])
def test_cli_refuses_bad_requests_before_connecting(instrument, capsys, extra, message):
    with pytest.raises(SystemExit) if message.startswith("--") else _no_raise():
        rc = cli.main(SCAN + extra)
        assert rc == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and "gen" not in instrument


class _no_raise:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def test_cli_failed_metadata_write_switches_off_before_closing(instrument, monkeypatch, tmp_path, capsys):
    def broken(*a, **k):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr("mitsuba_eventfield.atomic.write_json", broken)
    rc = cli.main(SCAN + ["--metadata", str(tmp_path / "m.json"), "--duration", "5"])
    gen = instrument["gen"]
    assert rc == 2 and gen.closed and outputs_off(gen)
    assert [c for c, _ in gen.history][-2:] == [":OUTP1 OFF", ":OUTP2 OFF"]
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_cli_sigterm_while_scanning_switches_off(instrument, capsys):
    timer = threading.Timer(0.8, lambda: signal.raise_signal(signal.SIGTERM))
    timer.start()
    rc = cli.main(SCAN + ["--duration", "30"])
    gen = instrument["gen"]
    assert rc == 128 + signal.SIGTERM and gen.closed and outputs_off(gen)
    assert "terminated" in capsys.readouterr().err
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL      # the handler was put back


def test_library_controller_switches_off_on_sigterm():
    """Outside the CLI, a controller with outputs on turns SIGTERM into SystemExit: the process switches off
    before it exits (the simulated generator prints its state when closed)."""
    script = """
import os, signal, threading, time
from mitsuba_eventfield.device import GalvoController, simulated
import mitsuba_eventfield as ef
gen = simulated("siglent")
close = gen.close
def report():
    print("outputs", gen.state[1]["output"], gen.state[2]["output"], flush=True)
    close()
gen.close = report
ctl = GalvoController(gen, "siglent", ramp_steps=1, ramp_time=0)
ctl.start(ef.make_curve("circle", frequency=200.0, amplitude=0.5))
threading.Timer(0.3, lambda: os.kill(os.getpid(), signal.SIGTERM)).start()
time.sleep(30)
"""
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert r.returncode == 128 + signal.SIGTERM and "outputs False False" in r.stdout, r.stderr
