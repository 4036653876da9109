"""What a rig user's walkthrough (2026-11-27) got through the device layer, each now refused or ramped: a spec
changed after its check, a spec wider than the galvo model, a Rigol left in Vrms, a Ctrl-C that switched the
outputs off at full amplitude. What the galvo sees is read from the simulated instrument's state after every
write (``history``), not from the controller."""
import re
import signal
import subprocess
import sys
import time

import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.device import GalvoController, GalvoSpec, SafetyError, simulated

NO_SLEEP = lambda s: None  # noqa: E731
GVS01X = ((35.0, 12.5), (130.0, 6.25), (1000.0, 0.2))


def _circle(freq=250.0, amplitude=0.5):
    return ef.make_curve("circle", frequency=freq, amplitude=amplitude)


def test_a_spec_keeps_the_envelope_it_checked():
    envelope = [list(p) for p in GVS01X]
    spec = GalvoSpec(envelope=envelope)
    envelope[2][1] = float("nan")
    envelope[1][1] = 12.5
    envelope.append([1e5, 12.5])
    assert spec.envelope == GVS01X and spec.max_amplitude_deg(900) < 0.25
    fast = ef.make_curve("circle", frequency=900, amplitude=5.0, max_angle_deg=12.5, galvo_model="ideal")
    with pytest.raises(SafetyError, match="derated limit of 0.2389 deg"):
        GalvoController(simulated("keysight"), "keysight", spec).plan(fast)


@pytest.mark.parametrize("kw, words", [
    (dict(max_volts=1000), "max_volts = 1000: allowed range is (0, 10]"),
    (dict(max_mech_deg=90), "max_mech_deg = 90: allowed range is (0, 12.5]"),
    (dict(envelope=((1e5, 90.0),)), "up to 100000 Hz, above the gvs01x galvo's 1000 Hz"),
    (dict(envelope=((35.0, 12.5), (500.0, 2.0), (1000.0, 0.2))), "2 deg at 500 Hz, above the gvs01x galvo's 0.644"),
    (dict(model="ideal"), "drives a real galvo"),
])
def test_a_rig_spec_may_narrow_the_galvo_model_never_widen_it(kw, words):
    with pytest.raises(SafetyError) as e:
        GalvoSpec(**kw)
    assert words in str(e.value) and "\n" not in str(e.value)
    GalvoSpec(max_volts=5.0, max_mech_deg=10.0, envelope=((35.0, 10.0), (900.0, 0.2)))      # narrower: taken


def test_a_rigol_left_in_vrms_is_set_to_vpp_and_one_that_stays_there_stays_dark():
    g = simulated("rigol", preset={1: {"unit": "VRMS"}, 2: {"unit": "DBM"}})
    with GalvoController(g, "rigol", GalvoSpec(), ramp_steps=2, ramp_time=0) as c:
        c.start(_circle(), sleep=NO_SLEEP)
        assert all(g.state[ch]["unit"] == "VPP" and g.state[ch]["output"] for ch in (1, 2))
    stuck = simulated("rigol", preset={1: {"unit": "VRMS"}}, refuse=lambda cmd: "VOLT:UNIT" in cmd)
    c = GalvoController(stuck, "rigol", GalvoSpec(), ramp_steps=2, ramp_time=0)
    with pytest.raises(SafetyError, match="channel 1 unit: requested VPP, instrument reports VRMS"):
        c.start(_circle(), sleep=NO_SLEEP)
    assert not any(state[ch]["output"] for _, state in stuck.history for ch in (1, 2))
    c.close()


def _amplitudes_before_off(history, off):
    """Channel 1's Vpp at every write up to the last write that switched it off (the first is the start's)."""
    last = max(i for i, (cmd, _) in enumerate(history) if re.fullmatch(off, cmd))
    vpp = [state[1]["vpp"] for _, state in history[:last + 1]]
    return [v for i, v in enumerate(vpp) if i == 0 or v != vpp[i - 1]]       # each level once


def test_leaving_a_scan_by_ctrl_c_ramps_the_amplitude_down_before_switching_off():
    g = simulated("keysight")
    with pytest.raises(KeyboardInterrupt):
        with GalvoController(g, "keysight", GalvoSpec(), ramp_steps=4, ramp_time=0) as c:
            c.start(_circle(), sleep=NO_SLEEP)
            raise KeyboardInterrupt
    vpp = _amplitudes_before_off(g.history, r"OUTP1 OFF")
    assert vpp[-4:] == pytest.approx([0.8, 0.6, 0.4, 0.2])       # full, then three steps down, then off
    assert not g.state[1]["output"] and not g.state[2]["output"]
    # any other error: the quick switch-off, at whatever amplitude (something is wrong: no more commands)
    g = simulated("keysight")
    with pytest.raises(ValueError):
        with GalvoController(g, "keysight", GalvoSpec(), ramp_steps=4, ramp_time=0) as c:
            c.start(_circle(), sleep=NO_SLEEP)
            raise ValueError("the user's own bug")
    assert _amplitudes_before_off(g.history, r"OUTP1 OFF")[-1] == pytest.approx(0.8)


def test_the_cli_scan_ramps_down_on_ctrl_c_and_says_so():
    p = subprocess.Popen([sys.executable, "-m", "mitsuba_eventfield.cli", "device", "scan", "--simulate",
                          "--dialect", "keysight", "--freq", "250", "--amplitude-deg", "0.5"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    line = ""
    while "scanning" not in line and time.monotonic() < deadline:
        line = p.stdout.readline()
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=60)
    assert "scanning" in line and "interrupted: amplitude ramped down, outputs off" in err, (line, out, err)


@pytest.mark.parametrize("argv, words", [
    (["--freq", "1e-300", "--amplitude-deg", "0.5"], "frequency 1e-300 Hz: allowed range is 0.001 to 1000 Hz"),
    (["--freq", "100", "--amplitude-deg", "1e-320"], "below the generators' smallest sine"),
    (["--curve", "circle", "--freq", "100", "--freq-y", "50", "--amplitude-deg", "0.5"], "--freq-y: a lissajous"),
])
def test_what_no_generator_plays_and_options_a_curve_ignores_are_refused_before_a_byte(argv, words, capsys):
    from mitsuba_eventfield import cli
    assert cli.main(["device", "scan", "--simulate", "--dialect", "keysight", "--duration", "0.1", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err, err


def test_an_offset_goes_on_and_off_in_the_ramps_steps_not_at_once():
    from mitsuba_eventfield.optics.scan import Lissajous
    line = Lissajous(freq_x=100.0, freq_y=100.0, amplitude_x=0.5, amplitude_y=0.0, phase_x=0.0, phase_y=0.0,
                     offset_x=2.0, kind="line", max_angle_deg=12.5)
    for dialect in ("keysight", "rigol", "siglent"):
        g = simulated(dialect)
        with GalvoController(g, dialect, GalvoSpec(), ramp_steps=4, ramp_time=0) as c:
            c.start(line, sleep=NO_SLEEP)
            c.stop(sleep=NO_SLEEP)
        # channel 1's offset (1.6 V in full) at every write while its output was on: four steps up, three down
        seen = [state[1]["offset"] for _, state in g.history if state[1]["output"]]
        levels = [v for i, v in enumerate(seen) if i == 0 or v != seen[i - 1]]
        assert levels == pytest.approx([0.4, 0.8, 1.2, 1.6, 1.2, 0.8, 0.4]), (dialect, levels)


def test_a_second_ctrl_c_during_the_ramp_down_waits_for_it():
    """Held by Python-level handlers: a process mask left BLAS's threads to take the signal, and Python still
    raised it in the main thread, switching channel 1 off at 75 % of its amplitude (a review)."""
    g = simulated("keysight")
    c = GalvoController(g, "keysight", GalvoSpec(), ramp_steps=4, ramp_time=0)
    c.start(_circle(), sleep=NO_SLEEP)
    with pytest.raises(KeyboardInterrupt):
        c.stop(sleep=lambda s: signal.raise_signal(signal.SIGINT))     # Ctrl-C at every ramp step
    assert _amplitudes_before_off(g.history, r"OUTP1 OFF")[-4:] == pytest.approx([0.8, 0.6, 0.4, 0.2])
    assert not g.state[1]["output"] and not g.state[2]["output"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    c.close()


def test_leaving_the_block_closes_even_when_the_ramp_down_is_interrupted():
    g = simulated("keysight")
    with pytest.raises(KeyboardInterrupt):
        with GalvoController(g, "keysight", GalvoSpec(), ramp_steps=4, ramp_time=0) as c:
            c.start(_circle(), sleep=NO_SLEEP)

            def cut(sleep=None):
                raise KeyboardInterrupt
            c.stop = cut
    assert c._closed and not g.state[1]["output"] and not g.state[2]["output"]


def test_a_stop_ramps_down_from_the_step_the_start_reached():
    """A start that failed at ramp step 3 of 4 and could not confirm the outputs off leaves them at step 2: a
    later stop ramped down from step 3 (4.5x the amplitude there, in a review's case), now from below step 2."""
    failing = {"SOUR1:VOLT 0.6"}

    def link(cmd):                  # step 3 fails, and from then on every "off" too
        if cmd in failing:
            failing.update({"OUTP1 OFF", "OUTP2 OFF"})
            return ConnectionError("link lost")
        return None
    g = simulated("keysight", raise_on=link)
    c = GalvoController(g, "keysight", GalvoSpec(), ramp_steps=4, ramp_time=0)
    with pytest.raises(SafetyError, match="could not be confirmed off"):
        c.start(_circle(), sleep=NO_SLEEP)
    before = len(g.history)
    with pytest.raises(Exception):
        c.stop(sleep=NO_SLEEP)
    sent = [cmd for cmd, _ in g.history[before:] if re.fullmatch(r"SOUR[12]:VOLT [0-9.]+", cmd)]
    assert sent == ["SOUR1:VOLT 0.2", "SOUR2:VOLT 0.2"], sent
    failing.clear()
    c.close()
    assert not g.state[1]["output"] and not g.state[2]["output"]


def test_a_daq_start_that_fails_after_the_fade_in_fades_back_to_rest(monkeypatch):
    import types

    import numpy as np

    from mitsuba_eventfield.device.daq import DAQmxOutput
    writes, modes = [], []

    class Task:
        def __init__(self):
            self.mode = None
            self.ao_channels = types.SimpleNamespace(add_ao_voltage_chan=lambda name, **kw: None)
            self.timing = types.SimpleNamespace(cfg_samp_clk_timing=lambda rate, **kw: setattr(
                self, "mode", kw.get("sample_mode")))

        def write(self, data, auto_start=False):
            writes.append(np.asarray(data))

        def start(self):
            modes.append(self.mode)
            if self.mode == "continuous":
                raise RuntimeError("DAQmx error -200479: the task could not start")

        def wait_until_done(self, timeout):
            pass

        def stop(self):
            pass

        def close(self):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *a):
            pass
    fake = types.ModuleType("nidaqmx")
    fake.Task = Task
    fake.constants = types.SimpleNamespace(AcquisitionType=types.SimpleNamespace(CONTINUOUS="continuous",
                                                                                  FINITE="finite"))
    monkeypatch.setitem(sys.modules, "nidaqmx", fake)
    monkeypatch.setitem(sys.modules, "nidaqmx.constants", fake.constants)
    out = DAQmxOutput(rate=50_000)
    with pytest.raises(RuntimeError, match="could not start"):
        out.start(_circle())
    period = out.waveform(_circle())
    fade_in, _, fade_out = writes
    assert modes == ["finite", "continuous", "finite"] and out.task is None
    # back from the held sample (the period's last) by the next one, down to 0 V
    assert np.allclose(fade_in[:, -1], period[:, -1]) and np.allclose(fade_out[:, 0], period[:, 0], rtol=1e-4)
    assert fade_out[:, -1].tolist() == [0.0, 0.0]


def test_an_offset_and_an_amplitude_together_stay_inside_the_travel():
    """The mirror swings to |offset| + amplitude: each alone inside the travel (and the derating) is not
    enough. gvs01x: +-12.5 mechanical deg, 0.8 V/deg, +-10 V input; at 30 Hz the derating allows the full
    travel, so only the sum decides."""
    spec = GalvoSpec()
    spec.check_axis("x", 30.0, 6.0, 6.0)                                       # 12 deg: inside
    with pytest.raises(SafetyError, match=r"axis x: \|offset\| \+ amplitude = 13 deg exceeds the mechanical travel "
                                          r"of \+-12\.5 deg"):
        spec.check_axis("x", 30.0, 6.5, -6.5)
    # as a channel: a 10 Vpp sine (6.25 deg) around 4 V (5 deg) reaches 11.25 deg, inside; around 6 V, 13.75
    spec.check_channel(1, "SIN", 30.0, 10.0, 4.0)
    with pytest.raises(SafetyError, match=r"axis 1: \|offset\| \+ amplitude = 13\.75 deg exceeds"):
        spec.check_channel(1, "SIN", 30.0, 10.0, 6.0)
    narrow = GalvoSpec(max_volts=8.0)                                           # the input range decides
    with pytest.raises(SafetyError, match=r"axis y: \|offset\| \+ amplitude = 8\.8 V exceeds the \+-8 V command"):
        narrow.check_axis("y", 30.0, 5.5, 5.5)


def test_a_generator_that_keeps_another_phase_never_switches_on():
    """The read-back compares every setting before the outputs go on: a generator that takes the phase command
    but keeps 0 deg on both channels would draw the circle as a diagonal line (x and y in phase)."""
    g = simulated("keysight", refuse=lambda cmd: ":PHAS " in cmd and not cmd.endswith(" 0.0"))
    c = GalvoController(g, "keysight", GalvoSpec(), ramp_steps=2, ramp_time=0)
    with pytest.raises(SafetyError, match=r"channel 1 phase: requested 90\.0, instrument reports 0\.0"):
        c.start(_circle(), sleep=NO_SLEEP)
    assert not any(state[ch]["output"] for _, state in g.history for ch in (1, 2))
    c.close()
