"""Device layer: exact bytes per dialect, the start sequence against simulated instruments (in memory for every
dialect, pyvisa-sim for the PyVISA path), faults mid-sequence. The adversarial property test is in
test_device_safety.py."""
import math

import pytest
from conftest import needs

import mitsuba_eventfield as ef
from mitsuba_eventfield.device import GalvoController, GalvoSpec, SafetyError, simulated, simulated_visa
from mitsuba_eventfield.optics.scan import curve_to_dict

CIRCLE = ef.make_curve("circle", frequency=250.0, amplitude=0.5)     # x: phase 90, y: phase 0
NO_SLEEP = lambda s: None  # noqa: E731


def _writes(gen, start=0):
    return [cmd for cmd, _ in gen.history[start:]]


def _run(dialect):
    g = simulated(dialect)
    c = GalvoController(g, dialect, ramp_steps=2, ramp_time=0)
    c.start(CIRCLE, sleep=NO_SLEEP)
    started = _writes(g)
    c.stop(sleep=NO_SLEEP)
    return started, _writes(g, len(started))


# 0.5 deg at 0.8 V/deg: 0.8 Vpp in full, 0.4 Vpp at the first of two ramp steps. Outputs off first (whatever the
# generator held stays dark), settings read back and confirmed (queries, not listed) before the outputs go on.
EXPECTED = {
    "keysight": (["OUTP1 OFF", "OUTP2 OFF", "*CLS", "OUTP1:LOAD INF", "OUTP2:LOAD INF",
                  "SOUR1:FUNC SIN", "SOUR1:VOLT:UNIT VPP", "SOUR1:FREQ 250.0", "SOUR1:VOLT 0.4", "SOUR1:VOLT:OFFS 0.0",
                  "SOUR1:PHAS 90.0",
                  "SOUR2:FUNC SIN", "SOUR2:VOLT:UNIT VPP", "SOUR2:FREQ 250.0", "SOUR2:VOLT 0.4", "SOUR2:VOLT:OFFS 0.0",
                  "SOUR2:PHAS 0.0",
                  "SOUR1:PHAS:SYNC", "OUTP1 ON", "OUTP2 ON", "SOUR1:VOLT 0.8", "SOUR2:VOLT 0.8"],
                 ["SOUR1:VOLT 0.4", "SOUR2:VOLT 0.4", "OUTP1 OFF", "OUTP2 OFF"]),
    "rigol": ([":OUTP1 OFF", ":OUTP2 OFF", "*CLS", ":OUTP1:LOAD INF", ":OUTP2:LOAD INF",
               ":SOUR1:FUNC SIN", ":SOUR1:VOLT:UNIT VPP", ":SOUR1:FREQ 250.0", ":SOUR1:VOLT 0.4",
               ":SOUR1:VOLT:OFFS 0.0", ":SOUR1:PHAS 90.0",
               ":SOUR2:FUNC SIN", ":SOUR2:VOLT:UNIT VPP", ":SOUR2:FREQ 250.0", ":SOUR2:VOLT 0.4",
               ":SOUR2:VOLT:OFFS 0.0", ":SOUR2:PHAS 0.0",
               ":SOUR1:PHAS:INIT", ":OUTP1 ON", ":OUTP2 ON", ":SOUR1:VOLT 0.8", ":SOUR2:VOLT 0.8"],
              [":SOUR1:VOLT 0.4", ":SOUR2:VOLT 0.4", ":OUTP1 OFF", ":OUTP2 OFF"]),
    "siglent": (["C1:OUTP OFF", "C2:OUTP OFF", "*CLS", "C1:OUTP LOAD,HZ", "C2:OUTP LOAD,HZ",
                 "C1:BSWV WVTP,SINE,FRQ,250.0,AMP,0.4,OFST,0.0,PHSE,90.0",
                 "C2:BSWV WVTP,SINE,FRQ,250.0,AMP,0.4,OFST,0.0,PHSE,0.0",
                 "MODE PHASE-LOCKED", "C1:OUTP ON", "C2:OUTP ON", "C1:BSWV AMP,0.8", "C2:BSWV AMP,0.8"],
                ["C1:BSWV AMP,0.4", "C2:BSWV AMP,0.4", "C1:OUTP OFF", "C2:OUTP OFF"]),
}


@pytest.mark.parametrize("dialect", sorted(EXPECTED))
def test_exact_bytes_per_dialect(dialect):
    started, stopped = _run(dialect)
    assert started == EXPECTED[dialect][0]
    assert stopped == EXPECTED[dialect][1]


@pytest.mark.parametrize("dialect", ["keysight", "rigol"])
def test_pyvisa_sim_start_readback_stop(dialect):
    needs("pyvisa_sim", "device")     # simulated_visa: pyvisa with the pyvisa-sim backend
    t = simulated_visa(dialect)
    c = GalvoController(t, dialect, ramp_steps=3, ramp_time=0)
    report = c.start(CIRCLE, sleep=NO_SLEEP)
    assert report["mismatches"] == [] and report["errors"] == []
    assert report["channels"][1]["vpp"] == pytest.approx(0.8) and report["channels"][2]["phase"] == 0.0
    meta = c.metadata(CIRCLE)
    assert meta["scan"] == curve_to_dict(CIRCLE)             # the capture describes the scan as the simulation does
    assert meta["instrument"].startswith(("Keysight", "Rigol"))
    t.write(c.d.readback(1)["frequency"][0][:-1] + " 300.0")   # someone turns a knob
    assert any("channel 1 frequency: requested 250" in m for m in c.read_back()["mismatches"])
    c.stop(sleep=NO_SLEEP)
    assert all(not c.read_back()["channels"][ch]["output"] for ch in (1, 2))
    c.close()


@pytest.mark.parametrize("dialect", ["keysight", "rigol"])
def test_refused_setting_never_reaches_an_output_pyvisa_sim(dialect, monkeypatch):
    """The instrument refuses what our envelope (widened here on purpose) lets through: the read-back before
    "output on" catches it and the outputs stay off."""
    needs("pyvisa_sim", "device")     # simulated_visa: pyvisa with the pyvisa-sim backend
    t = simulated_visa(dialect)
    # a galvo model widened for the test (a rig's spec may only narrow its model's limits) lets 200 kHz through
    # our check ...
    from dataclasses import replace

    from mitsuba_eventfield.optics import envelope
    monkeypatch.setitem(envelope.GALVO_MODELS, "gvs01x", replace(envelope.GALVO_MODELS["gvs01x"],
                                                                 derating=((35.0, 12.5), (1e6, 0.2))))
    wide = GalvoSpec(envelope=((35.0, 12.5), (1e6, 0.2)))
    c = GalvoController(t, dialect, spec=wide, ramp_steps=1, ramp_time=0)
    fast = ef.make_curve("circle", frequency=2e5, amplitude=0.1, max_angle_deg=12.5, galvo_model="ideal")
    with pytest.raises(SafetyError, match="did not confirm.*frequency"):  # ... the instrument refuses it
        c.start(fast, sleep=NO_SLEEP)
    out = c.d.readback(1)["output"][0]
    assert t.query(out).strip() in ("0", "OFF") and t.query(out.replace("1", "2")).strip() in ("0", "OFF")
    t.write("NONSENSE:COMMAND")
    assert c.errors() == [(-113, "Undefined header")] and c.errors() == []   # the queue drains
    c.close()


@pytest.mark.parametrize("fail_on, error", [("SOUR1:PHAS:SYNC", TimeoutError("VISA timeout")),
                                            ("OUTP2 ON", OSError("connection lost")),
                                            ("SOUR2:VOLT 0.8", TimeoutError("VISA timeout"))])
def test_fault_mid_start_leaves_outputs_off(fail_on, error):
    g = simulated("keysight", raise_on=lambda cmd: error if cmd == fail_on else None)
    c = GalvoController(g, "keysight", ramp_steps=2, ramp_time=0)
    with pytest.raises(type(error)):
        c.start(CIRCLE, sleep=NO_SLEEP)
    assert _writes(g)[-2:] == ["OUTP1 OFF", "OUTP2 OFF"] and not c.running
    assert not g.state[1]["output"] and not g.state[2]["output"]


def test_ctrl_c_during_ramp_leaves_outputs_off():
    g = simulated("rigol")
    c = GalvoController(g, "rigol", ramp_steps=4, ramp_time=0.1)

    def interrupted(_):
        raise KeyboardInterrupt
    with pytest.raises(KeyboardInterrupt):
        c.start(CIRCLE, sleep=interrupted)
    assert _writes(g)[-2:] == [":OUTP1 OFF", ":OUTP2 OFF"] and not g.state[1]["output"]


SPEC = GalvoSpec()


def test_envelope_derates_with_frequency():
    assert SPEC.max_amplitude_deg(20) == 12.5 and SPEC.max_amplitude_deg(130) == pytest.approx(6.25)
    assert SPEC.max_amplitude_deg(35) > SPEC.max_amplitude_deg(250) > SPEC.max_amplitude_deg(1000) == pytest.approx(0.2)
    assert SPEC.max_amplitude_deg(1001) == 0.0
    assert math.isclose(SPEC.max_amplitude_deg(math.sqrt(35 * 130)), math.sqrt(12.5 * 6.25))   # log-log


def test_captured_events_carry_the_same_scan_description(tmp_path):
    needs("pyvisa_sim", "device")     # simulated_visa: pyvisa with the pyvisa-sim backend
    import numpy as np

    from mitsuba_eventfield.device import tag_events
    c = GalvoController(simulated_visa("keysight"), "keysight", ramp_steps=1, ramp_time=0)
    c.start(CIRCLE, sleep=NO_SLEEP)
    captured = ef.EventStream([1, 2], [3, 4], [1000, 2500], [1, -1], 8, 8)      # e.g. read from the camera
    tag_events(captured, c.metadata(CIRCLE), fov_x_deg=40.0, mirror_distance=0.1, mirror_separation=0.01)
    c.stop(sleep=NO_SLEEP)
    path = str(tmp_path / "cap.h5")
    ef.write_events(path, captured)
    back = ef.read_events(path)
    ax, ay = back.scan_angles()
    assert np.allclose(ax, CIRCLE.angles(back.t * 1e-6)[0]) and back.meta["device"]["dialect"] == "keysight"


def test_daqmx_output_calls_with_a_stand_in_module(monkeypatch):
    """The optional NI-DAQmx path: checked waveform, channel set-up, continuous timing, zero on stop."""
    import sys
    import types

    import numpy as np

    from mitsuba_eventfield.device.daq import DAQmxOutput
    calls = []

    class Task:
        def __init__(self):
            self.ao_channels = types.SimpleNamespace(add_ao_voltage_chan=lambda name, **kw: calls.append(("chan", name)))
            self.timing = types.SimpleNamespace(
                cfg_samp_clk_timing=lambda rate, **kw: calls.append(("rate", rate, kw.get("sample_mode"))))
            self.out_stream = types.SimpleNamespace(total_samp_per_chan_generated=1037)   # stopped mid-period

        def write(self, data, auto_start=False):
            calls.append(("write", np.asarray(data)))

        def start(self):
            calls.append(("start",))

        def wait_until_done(self, timeout):
            calls.append(("done",))

        def stop(self):
            calls.append(("stop",))

        def close(self):
            calls.append(("close",))

        def __enter__(self):
            return self

        def __exit__(self, *a):
            self.close()

    fake = types.ModuleType("nidaqmx")
    fake.Task = Task
    fake.constants = types.SimpleNamespace(AcquisitionType=types.SimpleNamespace(CONTINUOUS="continuous",
                                                                                  FINITE="finite"))
    fake.constants.__path__ = []
    monkeypatch.setitem(sys.modules, "nidaqmx", fake)
    monkeypatch.setitem(sys.modules, "nidaqmx.constants", fake.constants)
    out = DAQmxOutput(rate=50_000)
    out.start(CIRCLE)
    fade_in, volts = [c[1] for c in calls if c[0] == "write"]
    assert volts.shape == (2, 200) and np.isclose(np.abs(volts).max(), 0.5 * 0.8, rtol=1e-3)   # 0.5 deg x 0.8 V/deg
    assert ("chan", "Dev1/ao0") in calls and ("rate", 50_000.0, "continuous") in calls and calls[-1] == ("start",)
    # faded in from rest over whole periods (0.5 s: 125 of them), played once before the regenerated period, and
    # ending on the sample before the period's first (no step at the hand-over)
    assert fade_in.shape == (2, 125 * 200) and np.abs(fade_in[:, 0]).max() < 1e-4 and ("rate", 50_000.0, "finite") in calls
    assert np.allclose(fade_in[:, -1], volts[:, -1]) and np.abs(np.diff(fade_in, axis=1)).max() < 0.02
    out.stop()
    fade_out = [c[1] for c in calls if c[0] == "write"][-1]
    # from the sample after the last one played (1037 generated: 1037 % 200 = 37), down to 0 V
    assert np.allclose(fade_out[:, 0], volts[:, 37], rtol=1e-4) and fade_out[:, -1].tolist() == [0.0, 0.0]
    with pytest.raises(SafetyError):
        DAQmxOutput().waveform(ef.make_curve("raster", frequency=100, lines=4))


def test_daq_refuses_a_rate_that_splits_the_period():
    """A regenerated buffer holding 199.6 samples of a period would jump at every wrap."""
    from mitsuba_eventfield.device.daq import DAQmxOutput
    with pytest.raises(SafetyError, match=r"199.6 samples per 4 ms period: must be a whole number"):
        DAQmxOutput(rate=49_900).waveform(CIRCLE)
    assert DAQmxOutput(rate=50_000).waveform(CIRCLE).shape == (2, 200)
