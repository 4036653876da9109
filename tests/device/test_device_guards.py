"""The device layer's defences that a normal start never reaches, each forced on its own (a mutation audit
found each could be removed without a test noticing): a generator that stays at 50 ohm, a SIGTERM during a scan,
the guard's refusal of an output with unknown settings."""
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.device import GalvoController, GalvoSpec, SafetyError, simulated

NO_SLEEP = lambda s: None  # noqa: E731


@pytest.mark.parametrize("dialect", ["keysight", "rigol", "siglent"])
def test_a_generator_left_at_50_ohm_never_switches_on(dialect):
    """A generator that refuses the high-Z load command stays at 50 ohm, where its output into the galvo's
    high-Z input is twice the voltage set: the read-back refuses the start before any output goes on."""
    g = simulated(dialect, refuse=lambda cmd: "LOAD" in cmd)
    with GalvoController(g, dialect, GalvoSpec(), ramp_steps=3, ramp_time=0) as c:
        with pytest.raises(SafetyError, match="high_z"):
            c.start(ef.make_curve("circle", frequency=20.0, amplitude=2.0), sleep=NO_SLEEP)
    assert not any(state[ch]["output"] for _, state in g.history for ch in (1, 2))


def test_a_load_read_back_of_50_ohm_is_not_high_z():
    from mitsuba_eventfield.device.dialects import _high_z
    assert _high_z("+9.9E+37") and _high_z("INF")
    assert not _high_z("+5.0E+01") and not _high_z("50")


def test_a_sigterm_during_a_scan_ramps_down_before_switching_off():
    """SystemExit (SIGTERM's, in the command line) inside a scan ramps the amplitude down as Ctrl-C does: the
    last level with the outputs on is the first ramp step's, not the full amplitude."""
    g = simulated("keysight")
    with pytest.raises(SystemExit):
        with GalvoController(g, "keysight", GalvoSpec(), ramp_steps=4, ramp_time=0) as c:
            c.start(ef.make_curve("circle", frequency=20.0, amplitude=6.0), sleep=NO_SLEEP)
            raise SystemExit(143)
    levels = [state[1]["vpp"] for _, state in g.history if state[1]["output"]]
    assert levels[-1] == pytest.approx(levels[0]) and max(levels) > 3 * levels[0]
    assert not g.state[1]["output"] and not g.state[2]["output"]


def test_the_guard_refuses_an_output_whose_settings_are_not_all_known():
    """The per-command guard alone (start always sets every channel first): armed, with channel 1's frequency
    and amplitude never commanded, switching it on is refused before the byte is sent."""
    g = simulated("keysight")
    c = GalvoController(g, "keysight", GalvoSpec(), ramp_steps=2, ramp_time=0)
    c._armed, c._commanded = True, {1: {"function": "SIN", "offset": 0.0}, 2: {}}
    sent = len(g.history)
    with pytest.raises(SafetyError, match="not all known"):
        c._send(["OUTP1 ON"])
    assert len(g.history) == sent and not g.state[1]["output"]
    c._armed = False
    c.close()
