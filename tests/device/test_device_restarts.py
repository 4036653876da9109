"""A rig user's second walkthrough (2026-11-27, twenty-fifth session): a scan started over a running one, the
recovery after a killed process (``device stop``) and a card's small amplitudes. What the galvo sees is read
from the simulated instrument's state after every write (``history``), never from the controller."""
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield import cli
from mitsuba_eventfield.device import GalvoController, GalvoSpec, simulated

NO_SLEEP = lambda s: None  # noqa: E731


def _on_levels(history, ch, key):
    """Channel ``ch``'s ``key`` at every write while its output was on, each level once."""
    seen = [state[ch][key] for _, state in history if state[ch]["output"]]
    return [v for i, v in enumerate(seen) if i == 0 or v != seen[i - 1]]


def test_a_second_start_ramps_the_running_scan_down_before_the_new_one():
    """start() over a running 6 deg circle offset by 4 deg switched both outputs off at 9.6 Vpp and 3.2 V: the
    step the ramps exist to avoid. Now the first scan goes down in the ramp's steps, then the second one up."""
    slow = ef.make_curve("circle", frequency=20.0, amplitude=6.0, offset_x=4.0)
    fast = ef.make_curve("circle", frequency=250.0, amplitude=0.5)
    g = simulated("keysight")
    with GalvoController(g, "keysight", GalvoSpec(), ramp_steps=4, ramp_time=0) as c:
        c.start(slow, sleep=NO_SLEEP)
        c.start(fast, sleep=NO_SLEEP)
        assert c.running and g.state[1]["vpp"] == pytest.approx(0.8)
        c.stop(sleep=NO_SLEEP)
    # up to 9.6 Vpp in four steps, down in three, off; then the new scan up to 0.8 Vpp and down
    assert _on_levels(g.history, 1, "vpp") == pytest.approx([2.4, 4.8, 7.2, 9.6, 7.2, 4.8, 2.4,
                                                               0.2, 0.4, 0.6, 0.8, 0.6, 0.4, 0.2])
    assert _on_levels(g.history, 1, "offset") == pytest.approx([0.8, 1.6, 2.4, 3.2, 2.4, 1.6, 0.8, 0.0])


@pytest.mark.parametrize("dialect", ["keysight", "rigol", "siglent"])
def test_device_stop_ramps_down_what_a_killed_process_left_running(dialect, capsys, monkeypatch):
    """After a SIGKILL the generator scans on at full amplitude: `device stop` switched it off in one step.
    It now ramps the read-back amplitude and offset down in the controller's steps, then switches off."""
    import mitsuba_eventfield.device.transport as transport
    g = simulated(dialect, preset={1: {"function": "SIN", "frequency": 20.0, "vpp": 9.6, "offset": 3.2,
                                       "high_z": True, "output": True},
                                   2: {"function": "SIN", "frequency": 20.0, "vpp": 9.6, "offset": 0.0,
                                       "high_z": True, "output": True}})
    monkeypatch.setattr(transport, "open_transport", lambda *a, **k: g)
    monkeypatch.setattr("mitsuba_eventfield.device.open_transport", lambda *a, **k: g)
    assert cli.main(["device", "stop", "--simulate", "--dialect", dialect]) == 0
    assert "channel 1, 2: ramped down from the read-back amplitude and offset; outputs off" in capsys.readouterr().out
    # (the preset's 9.6 Vpp and 3.2 V are not in the history, which holds the writes)
    assert _on_levels(g.history, 1, "vpp") == pytest.approx([7.68, 5.76, 3.84, 1.92])
    assert _on_levels(g.history, 1, "offset") == pytest.approx([3.2, 2.56, 1.92, 1.28, 0.64])
    assert _on_levels(g.history, 2, "vpp")[-1] == pytest.approx(1.92)
    assert not g.state[1]["output"] and not g.state[2]["output"]


def test_device_stop_beyond_the_galvos_limits_switches_off_without_a_ramp(capsys, monkeypatch):
    """A generator left at 5 kHz (beyond this galvo's 1 kHz): the guard refuses every step of a ramp at that
    frequency, so the outputs go off at once and the line says why; a generator scanning nothing just goes
    off. (A ramp from an amplitude beyond the limits is taken: test_device_stop_ramps_down_an_overdriven_scan.)"""
    g = simulated("keysight", preset={1: {"vpp": 1.0, "frequency": 5000.0, "high_z": True, "output": True}})
    monkeypatch.setattr("mitsuba_eventfield.device.open_transport", lambda *a, **k: g)
    assert cli.main(["device", "stop", "--simulate", "--dialect", "keysight"]) == 0
    out = capsys.readouterr().out
    assert "channel 1: switched off without a ramp (channel 1: 5000 Hz is outside 0 to 1000 Hz)" in out
    assert not g.state[1]["output"]
    assert "ramped down" not in out
    assert [s[1]["vpp"] for _, s in g.history] == [1.0] * len(g.history)          # no step sent to it
    idle = simulated("keysight")
    monkeypatch.setattr("mitsuba_eventfield.device.open_transport", lambda *a, **k: idle)
    assert cli.main(["device", "stop", "--simulate", "--dialect", "keysight"]) == 0
    assert "outputs off (none was scanning)" in capsys.readouterr().out


def test_a_daq_card_plays_amplitudes_below_a_generators_smallest_sine():
    """A 0.002 deg circle is 0.08 mVpp: below a generator's 1 mVpp at its first ramp step, which was refused for
    the card too (its plan was the generator's). The card checks the envelope only; beyond it still refused."""
    import numpy as np

    from mitsuba_eventfield.device import SafetyError
    from mitsuba_eventfield.device.daq import DAQmxOutput
    volts = DAQmxOutput(rate=50_000).waveform(ef.make_curve("circle", frequency=100.0, amplitude=0.002))
    assert np.abs(volts).max() == pytest.approx(0.002 * GalvoSpec().volts_per_deg, rel=1e-6)
    with pytest.raises(SafetyError, match="below the generators' smallest sine"):
        GalvoController(None, "keysight").plan(ef.make_curve("circle", frequency=100.0, amplitude=0.002))
    with pytest.raises(SafetyError, match="derated"):
        DAQmxOutput(rate=50_000).waveform(ef.make_curve("circle", frequency=900.0, amplitude=5.0,
                                                        max_angle_deg=12.5, galvo_model="ideal"))


def test_a_lissajous_from_the_command_line_is_the_one_python_and_scenes_make(tmp_path):
    """--phase defaulted to 0 for a lissajous's x axis: equal frequencies drove a 45 deg diagonal line where
    ``make_curve`` and the scene plugin (phase_x 90) draw a circle. Both axes read back in the metadata."""
    import json
    meta = tmp_path / "l.json"
    assert cli.main(["device", "scan", "--simulate", "--dialect", "keysight", "--curve", "lissajous", "--freq", "100",
                     "--amplitude-deg", "1", "--duration", "0.05", "--metadata", str(meta)]) == 0
    scan = json.loads(meta.read_text())["scan"]
    python = ef.make_curve("lissajous", freq_x=100, freq_y=100, amplitude_x=1, amplitude_y=1)
    assert scan["phase_x"] == python.phase_x == 90.0 and scan["phase_y"] == python.phase_y == 0.0
    assert cli.main(["device", "scan", "--simulate", "--dialect", "keysight", "--curve", "lissajous", "--freq", "100",
                     "--amplitude-deg", "1", "--phase", "0", "--duration", "0.05", "--metadata", str(meta)]) == 0
    assert json.loads(meta.read_text())["scan"]["phase_x"] == 0.0                 # asked for: taken


@pytest.mark.parametrize("argv, words", [
    (["--curve", "circle", "--axis", "y"], "--axis y: a line scan's axis; a circle scans both axes"),
    (["--curve", "lissajous", "--axis", "y"], "--axis y: a line scan's axis; a lissajous scans both axes"),
    (["--resource", "TCPIP0::192.0.2.7::inst0::INSTR"], "--resource TCPIP0::192.0.2.7::inst0::INSTR and --simulate"),
])
def test_options_the_scan_would_ignore_are_refused(argv, words, capsys):
    assert cli.main(["device", "scan", "--simulate", "--dialect", "keysight", "--freq", "100", "--amplitude-deg",
                     "0.5", "--duration", "0.05", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err, err


@pytest.mark.parametrize("fault", ["timeout", "garbage"])
def test_device_stop_switches_off_when_a_read_back_fails(fault, capsys, monkeypatch):
    """A read-back that timed out (an OSError from the link) escaped before anything was written: both outputs
    stayed on at 9.6 Vpp. One that answered garbage was reported as "none was scanning". Either channel is now
    switched off as it is, and named."""
    def link(cmd):
        return OSError("VI_ERROR_TMO: timeout") if fault == "timeout" and cmd == "SOUR1:PHAS?" else None
    g = simulated("keysight", preset={ch: {"vpp": 9.6, "offset": 3.2, "frequency": 20.0, "high_z": True,
                                           "output": True} for ch in (1, 2)}, raise_on=link)
    if fault == "garbage":
        answer = g.query
        monkeypatch.setattr(g, "query", lambda cmd: "?!" if cmd == "SOUR1:FREQ?" else answer(cmd))
    monkeypatch.setattr("mitsuba_eventfield.device.open_transport", lambda *a, **k: g)
    assert cli.main(["device", "stop", "--simulate", "--dialect", "keysight"]) == 0
    out = capsys.readouterr().out
    assert not g.state[1]["output"] and not g.state[2]["output"]
    assert "channel 2: ramped down" in out and "channel 1: settings unreadable, switched off without a ramp" in out


@pytest.mark.parametrize("dialect", ["keysight", "rigol"])
@pytest.mark.parametrize("unit, value", [("DBM", 13.0), ("DBM", -6.0), ("VRMS", 1.5)])
def test_device_stop_ramps_an_amplitude_set_in_dbm_or_vrms(dialect, unit, value):
    """A generator left in dBm: the ramp scaled the dBm figure (1 dBm -> 0.8, 0.6 ... dBm: switched off at 91 %
    of the amplitude while saying "ramped down"; at 13 dBm the first step was 26 %, at -6 dBm the guard refused
    a negative amplitude). The amplitude is now shown in Vpp first (the output stays) and ramped in Vpp."""
    from mitsuba_eventfield.device.recovery import ramp_off
    from mitsuba_eventfield.device.simulator import amplitude_vpp
    vpp = amplitude_vpp(unit, value)
    g = simulated(dialect, preset={1: {"function": "SIN", "frequency": 20.0, "vpp": value, "unit": unit,
                                       "offset": 0.0, "high_z": True, "output": True}})
    with GalvoController(g, dialect, GalvoSpec(), ramp_steps=5, ramp_time=0) as c:
        assert ramp_off(c, sleep=NO_SLEEP) == "channel 1: ramped down from the read-back amplitude and offset; outputs off"
    assert g.state[1]["unit"] == "VPP" and not g.state[1]["output"]
    levels = _on_levels(g.history, 1, "vpp")
    assert levels == pytest.approx([vpp, 0.8 * vpp, 0.6 * vpp, 0.4 * vpp, 0.2 * vpp], rel=1e-6)


def test_device_stop_ramps_down_an_overdriven_scan():
    """A scan left at 1.3x the galvo's derated amplitude at 500 Hz: every ramp step from it was refused (the
    80 % step is still beyond the limit), so it was cut at full amplitude. Steps that come down from what runs
    are taken; a frequency beyond the galvo's is still never ramped at (the test above)."""
    from mitsuba_eventfield.device.recovery import ramp_off
    spec = GalvoSpec()
    vpp = 1.3 * spec.vpp(spec.max_amplitude_deg(500.0))
    g = simulated("keysight", preset={1: {"function": "SIN", "frequency": 500.0, "vpp": vpp, "offset": 0.0,
                                          "high_z": True, "output": True}})
    with GalvoController(g, "keysight", spec, ramp_steps=5, ramp_time=0) as c:
        assert "channel 1: ramped down" in ramp_off(c, sleep=NO_SLEEP)
    assert _on_levels(g.history, 1, "vpp") == pytest.approx([0.8 * vpp, 0.6 * vpp, 0.4 * vpp, 0.2 * vpp], rel=1e-6)
    assert not g.state[1]["output"]


def test_device_stop_switches_off_a_channel_whose_output_state_is_unreadable(monkeypatch):
    """A channel whose output state reads back as neither on nor off (a garbled answer) is switched off as it
    is, said so; a channel that reads clearly off is left out of the line."""
    from mitsuba_eventfield.device.recovery import ramp_off
    g = simulated("keysight", preset={1: {"function": "SIN", "frequency": 20.0, "vpp": 2.0, "offset": 0.0,
                                          "high_z": True, "output": True}})
    with GalvoController(g, "keysight", GalvoSpec(), ramp_steps=5, ramp_time=0) as c:
        real = c.read_channel
        monkeypatch.setattr(c, "read_channel", lambda ch: dict(real(ch), output="unreadable: '2'") if ch == 1
                            else real(ch))
        assert ramp_off(c, sleep=NO_SLEEP) == "channel 1: settings unreadable, switched off without a ramp; outputs off"
    assert not g.state[1]["output"] and _on_levels(g.history, 1, "vpp") == []


RUNNING = {"function": "SIN", "frequency": 500.0, "vpp": 2.0, "offset": 1.0, "high_z": True, "output": True}


@pytest.mark.parametrize("cmd", ["SOUR1:VOLT 2.2", "SOUR1:VOLT:OFFS 1.2", "SOUR1:VOLT:OFFS -1.2", "SOUR1:FREQ 600"])
def test_the_recovery_exception_lets_only_a_descent_through(cmd):
    """The guard takes a recovery step beyond the galvo's derated amplitude only where it comes down from what
    the channel runs: more amplitude or offset, or another frequency, is checked against the limits as ever,
    and each of these is beyond them."""
    from mitsuba_eventfield.device import SafetyError
    from mitsuba_eventfield.device.recovery import _coming_down
    g = simulated("keysight", preset={1: RUNNING})
    with GalvoController(g, "keysight", GalvoSpec(), ramp_steps=5, ramp_time=0) as c:
        running = {1: dict(RUNNING)}
        c._commanded = {1: {k: RUNNING[k] for k in ("function", "frequency", "vpp", "offset")}, 2: {}}
        c._guard("SOUR1:VOLT 1.6", descent=_coming_down(c, running))        # a step down: taken
        c._guard("SOUR1:VOLT:OFFS -0.8", descent=_coming_down(c, running))  # |offset| down: taken
        with pytest.raises(SafetyError):
            c._guard(cmd, descent=_coming_down(c, running))
        with pytest.raises(SafetyError):
            c._guard("SOUR1:VOLT 1.6")                   # without the exception, the same step is refused
        c.outputs_off()


def test_a_generator_that_refuses_vpp_units_goes_off_without_a_ramp():
    """A channel in dBm whose switch to Vpp the instrument refuses is never ramped in dBm figures: it goes
    off as it is, and the line says so."""
    from mitsuba_eventfield.device.recovery import ramp_off
    g = simulated("keysight", preset={1: {"function": "SIN", "frequency": 20.0, "vpp": 1.0, "unit": "DBM",
                                          "offset": 0.0, "high_z": True, "output": True}},
                  refuse=lambda cmd: cmd.endswith("VOLT:UNIT VPP"))
    with GalvoController(g, "keysight", GalvoSpec(), ramp_steps=5, ramp_time=0) as c:
        said = ramp_off(c, sleep=NO_SLEEP)
    assert said == "channel 1: settings unreadable, switched off without a ramp; outputs off"
    assert not g.state[1]["output"] and _on_levels(g.history, 1, "vpp") == [1.0]
