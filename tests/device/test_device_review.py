"""The galvo controller against a reviewer's findings (2026-11-26), on the simulated instruments: a request at
the derated limit, a second scan on one controller, a switch-off the link refuses, a second Ctrl-C during the
switch-off, an instrument that answers neither on nor off, and the DAQ path's rates and buffers. In each the
galvo is never driven outside its envelope, and an output that may still be on is said to be on."""
import signal
from fractions import Fraction

import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.device import GalvoController, GalvoSpec, SafetyError, simulated

DIALECTS = ("keysight", "rigol", "siglent")
NO_SLEEP = lambda s: None  # noqa: E731
SPEC = GalvoSpec()


def _sent_vpp(gen):
    """The largest Vpp either channel held at any moment (the simulated instrument's own state)."""
    return max(state[ch]["vpp"] for _, state in gen.history for ch in (1, 2) if state[ch].get("vpp") is not None)


@pytest.mark.parametrize("dialect", DIALECTS)
@pytest.mark.parametrize("frequency", [40.0, 77.7, 200.0, 456.7, 999.0])
def test_a_scan_at_the_derated_limit_starts_and_stays_within_it(dialect, frequency):
    """Checked exactly and sent with ten digits, an amplitude at the limit rounded up past it: the plan passed
    and the guard refused at the last ramp step, with the outputs on. Now the volts sent are rounded down, and
    the plan checks every command as the dialect formats it."""
    limit = SPEC.max_amplitude_deg(frequency)
    gen = simulated(dialect)
    ctl = GalvoController(gen, dialect)
    ctl.start(ef.make_curve("circle", frequency=frequency, amplitude=limit), sleep=NO_SLEEP)
    assert _sent_vpp(gen) <= 2 * limit * SPEC.volts_per_deg
    ctl.close()
    assert not gen.state[1]["output"] and not gen.state[2]["output"]


def test_a_second_scan_on_one_controller():
    """The guard checked the new scan's settings against the old scan's Vpp, and refused a valid request after
    its first bytes."""
    gen = simulated("keysight")
    with GalvoController(gen, "keysight") as ctl:
        ctl.start(ef.make_curve("circle", frequency=30, amplitude=12.0), sleep=NO_SLEEP)
        ctl.stop(sleep=NO_SLEEP)
        ctl.start(ef.make_curve("circle", frequency=1000, amplitude=0.2), sleep=NO_SLEEP)
        assert gen.state[1]["output"] and gen.state[1]["frequency"] == 1000.0
    assert not gen.state[1]["output"]


def test_an_unconfirmed_switch_off_is_reported_as_such():
    """A refused ramp step whose switch-off the instrument also refused said "(outputs off)" with output 1 on;
    now the error says they could not be confirmed off, and close tries again and says so too."""
    gen = None

    def refuse(cmd):
        return (cmd == "OUTP1 OFF" and gen.state[1]["output"]) or cmd == "SOUR2:VOLT 1.6"
    gen = simulated("keysight", refuse=refuse)
    ctl = GalvoController(gen, "keysight")
    with pytest.raises(SafetyError, match=r"the outputs could not be confirmed off: switch the generator's outputs "
                                          r"off by hand$"):
        ctl.start(ef.make_curve("circle", frequency=100, amplitude=1.0), sleep=NO_SLEEP)
    assert gen.state[1]["output"] and ctl.running
    with pytest.raises(SafetyError, match="closing the connection: the outputs could not be confirmed off"):
        ctl.close()
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL      # the controller's SIGTERM handler is gone


def test_a_refusal_whose_switch_off_worked_says_outputs_off():
    gen = simulated("keysight", refuse=lambda cmd: cmd == "SOUR2:VOLT 1.6")
    ctl = GalvoController(gen, "keysight")
    with pytest.raises(SafetyError, match=r"reported errors at ramp step \d of \d: .* \(outputs off\)$"):
        ctl.start(ef.make_curve("circle", frequency=100, amplitude=1.0), sleep=NO_SLEEP)
    assert not gen.state[1]["output"] and not gen.state[2]["output"] and not ctl.running
    ctl.close()


def test_a_second_interrupt_waits_for_the_switch_off():
    """Ctrl-C, then SIGTERM while the outputs are being switched off: the second interrupt left both outputs on.
    Now the signals wait (held) until the outputs are confirmed off."""
    gen = simulated("rigol")

    class Link:                      # the simulated instrument, with a second interrupt at the first "off"
        sent = False

        def write(self, cmd):
            if cmd == ":OUTP1 OFF" and gen.state[1]["output"] and not Link.sent:
                Link.sent = True
                signal.raise_signal(signal.SIGTERM)
            gen.write(cmd)

        def query(self, cmd):
            return gen.query(cmd)

        def close(self):
            gen.close()

    def on_term(signum, frame):
        raise KeyboardInterrupt("SIGTERM")

    def first_ctrl_c(_):
        raise KeyboardInterrupt
    previous = signal.signal(signal.SIGTERM, on_term)
    try:
        ctl = GalvoController(Link(), "rigol", ramp_steps=4, ramp_time=0.1)
        with pytest.raises(KeyboardInterrupt):
            ctl.start(ef.make_curve("circle", frequency=100, amplitude=1.0), sleep=first_ctrl_c)
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert Link.sent and not gen.state[1]["output"] and not gen.state[2]["output"]


@pytest.mark.parametrize("dialect, answer", [("keysight", "+2.0000000000E+02"), ("rigol", ""), ("siglent", "")])
def test_an_output_state_that_is_neither_on_nor_off_counts_as_on(dialect, answer):
    """A desynchronised link answering the output query with a stale number read as "off", so a dropped OFF
    passed as confirmed."""
    gen = simulated(dialect)

    class Stale:
        def write(self, cmd):
            if "OFF" not in cmd:
                gen.write(cmd)

        def query(self, cmd):
            return answer if "OUTP" in cmd and "LOAD" not in cmd else gen.query(cmd)

        def close(self):
            pass
    with pytest.raises(SafetyError, match="still reports output 1, 2 on"):
        GalvoController(Stale(), dialect).outputs_off()


@pytest.mark.parametrize("tolerance", [float("inf"), float("nan"), 0.0, 0.5, "0.001", None])
def test_readback_tolerance_is_checked(tolerance):
    with pytest.raises(SafetyError, match="readback_tolerance"):
        GalvoController(None, "keysight", readback_tolerance=tolerance)


def test_a_fraction_is_a_number_to_the_dialects():
    gen = simulated("keysight")
    with GalvoController(gen, "keysight") as ctl:
        ctl.start(ef.make_curve("lissajous", freq_x=Fraction(100), freq_y=150.0, amplitude_x=0.5, amplitude_y=0.5),
                  sleep=NO_SLEEP)
        assert gen.state[1]["frequency"] == 100.0


def test_daq_rates_channels_and_buffers_are_checked():
    from mitsuba_eventfield.device.daq import DAQmxOutput
    for rate in (float("nan"), float("inf"), "abc", 1e12, 0.0):
        with pytest.raises(SafetyError, match="rate"):
            DAQmxOutput(rate=rate)
    with pytest.raises(SafetyError, match=r"channels = 'ao0': expected two channel names"):
        DAQmxOutput(channels="ao0")
    with pytest.raises(SafetyError, match=r"needs 1e\+09 samples a channel: at most 10,000,000"):
        DAQmxOutput(rate=1_000_000).waveform(ef.make_curve("circle", frequency=1e-3, amplitude=1.0))
    out = DAQmxOutput(rate=50_000)
    out.task = object()                                     # a scan already playing
    with pytest.raises(SafetyError, match="already playing a scan"):
        out.start(ef.make_curve("circle", frequency=250, amplitude=0.5))
