"""Pixel noise on a uniform, static emitter (every pixel sees one radiance; no real brightness change), its
rate read from the events against the model's law:

* leak: the reference sinks by leak_rate x C_on a second, so a pixel fires ON events at leak_rate whatever its
  OFF threshold (ON 0.2, OFF 0.4: measured 5.000 Hz a pixel at 5 Hz, all ON; drifting by C_off would fire
  10 Hz);
* shot noise: the rate falls linearly from shot_noise_hz in the dark to shot_noise_bright_factor x it at the
  bright intensity, and stays there above it (radiance 2 at bright_intensity 1: 0.25 x 8 = 2 Hz; measured
  1.965 Hz over 1024 pixels, whose Poisson spread is 2.2 %; a law extrapolated past the bright intensity would
  give 8 (1 - 0.75 x 2) < 0, no events)."""
import numpy as np

import mitsuba_eventfield as ef

SIZE, DURATION = 32, 1.0


def _uniform_scene(radiance):
    """A static emitter filling a SIZE x SIZE view: every pixel sees ``radiance``."""
    import mitsuba as mi
    wall = mi.ScalarTransform4f().translate([0, 0, 1]).rotate([0, 1, 0], 180).scale(2)
    return ef.load_scene(mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": {"type": "perspective", "fov": 30,
                   "film": {"type": "hdrfilm", "width": SIZE, "height": SIZE, "rfilter": {"type": "box"},
                            "pixel_format": "luminance"}},
        "wall": {"type": "rectangle", "to_world": wall, "emitter": {"type": "area", "radiance": radiance}}}),
        motion=None)


def _rate(ev):
    return len(ev) / (SIZE * SIZE * DURATION)


def test_the_leak_fires_on_events_at_its_rate_with_asymmetric_thresholds():
    pixel = {"leak_rate_hz": 5.0, "threshold_on": 0.2, "threshold_off": 0.4, "seed": 5}
    ev = ef.render_events(_uniform_scene(0.5), DURATION, steps=400, pixel=pixel)
    print(f"leak: {_rate(ev):.3f} Hz a pixel ({len(ev)} events, {np.count_nonzero(ev.p < 0)} OFF)")
    assert abs(_rate(ev) - 5.0) / 5.0 < 0.05
    assert np.all(ev.p > 0)


def test_shot_noise_above_the_bright_intensity_stays_at_the_bright_rate():
    pixel = {"shot_noise_hz": 8.0, "bright_intensity": 1.0, "seed": 5}
    ev = ef.render_events(_uniform_scene(2.0), DURATION, steps=400, pixel=pixel)
    expected = 8.0 * 0.25                                   # shot_noise_bright_factor's default
    print(f"shot noise at twice the bright intensity: {_rate(ev):.3f} Hz a pixel (law {expected} Hz)")
    assert abs(_rate(ev) - expected) / expected < 0.05
    assert abs(np.count_nonzero(ev.p > 0) / len(ev) - 0.5) < 0.05
