"""``eventfield calibrate depth`` from LED captures, from their events alone, against the galvo the captures were
rendered with. It used to reconstruct the LED with the galvo start-image solver, which relates the views by the
scan at infinity and so measured every LED's scan as if it were far away: README's 173x130 captures fitted an
inverted depth model and were refused, and at 96x72 the x pivot came out at 7.9 cm for 10 cm."""
import math
import os

import numpy as np
import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield import cli
from mitsuba_eventfield.calibration import CalibrationError, fit_led, load_calibration
from mitsuba_eventfield.events.stream import EventStream
from mitsuba_eventfield.optics.galvo import GalvoGeometry

LED = os.path.join(ROOT, "scenes", "led_depth", "led.xml")
DEPTHS = (0.4, 0.8, 1.6)                    # README's calibration depths (m)
UNSEEN = 1.0                                # a depth between them that no capture was made at
PIVOT, SEPARATION = 0.1, 0.01               # led.xml's mirror_distance and mirror_separation (m)
FREQ = 250.0                                # led.xml's scan frequency (Hz): one period is 4 ms
# Tolerances: with the scan phase at 0, 37, 123, 250 and 300 deg and the pivot at 10 and 15 cm, each film
# below (10 set-ups each) gave pivots within 4.8 %, angle gains within 2.2 % and the scan amplitude predicted
# at 0.6 m and 1 m within 1.7 % of the geometry rendered. The centroids carry 0.03-0.08 px of pixel
# quantisation (rms residual of the track), 0.4-1 % of the scale, and the pivot is ~20x as sensitive as the
# scales over 0.4-1.6 m (dS/S = pivot (1/0.4 - 1/1.6) = 19 %); pivot and gain errors are correlated (the
# amplitude inside the calibrated range is the better determined). Bounds: 1.6x the worst measured.
PIVOT_TOL, GAIN_TOL, AMPLITUDE_TOL = 0.08, 0.04, 0.025


@pytest.mark.parametrize("width,height,amplitude,steps,ray", [
    (173, 130, 0.5, 64, (0, 0)),    # README's captures: scan radius 3.1-3.9 px, LED image radius 0.9-3.6 px
    (96, 72, 2.0, 32, (0, 0)),      # a coarser film, a wider scan (radius 6.9-8.6 px), half the time steps
    # the LED off the axis (33 and 20 px from the centre): fitted as if on it, the gains read 6 % and 2 % high
    (96, 72, 2.0, 32, (0.25, 0.15)),
])
def test_depth_calibration_from_led_events_recovers_the_galvo(tmp_path, capsys, width, height, amplitude, steps,
                                                              ray):
    captures = []
    for z in DEPTHS:
        scene = ef.load_scene(LED, width=width, height=height, depth=z, amplitude=amplitude, mirror_distance=PIVOT,
                              led_x=ray[0] * z, led_y=ray[1] * z)
        path = str(tmp_path / f"led_{z}.h5")
        ef.write_events(path, ef.render_events(scene, 1 / FREQ, steps=steps))
        captures.append(f"{path}:{z}")
    out = str(tmp_path / "cal.json")
    code = cli.main(["calibrate", "depth", *captures, "-o", out])
    assert code == 0, capsys.readouterr().err
    depth = load_calibration(out)["depth"]
    rendered = GalvoGeometry.from_optics(depth.optics, width, height)
    assert (rendered.pivot_x, rendered.pivot_y) == pytest.approx((PIVOT, PIVOT + SEPARATION))
    fitted = depth.geometry(rendered)
    a = math.radians(amplitude)
    theta = np.linspace(0, 2 * np.pi, 721)
    radius = [np.ptp(g.image_shift(a * np.cos(theta), a * np.sin(theta), UNSEEN), axis=0) / 2
              for g in (rendered, fitted)]
    with capsys.disabled():
        print(f"\n[LED depth calibration {width}x{height}, {amplitude} deg, LED ray {ray}, events only] pivots "
              f"{fitted.pivot_x * 100:.2f}, {fitted.pivot_y * 100:.2f} cm (rendered {PIVOT * 100:g}, "
              f"{(PIVOT + SEPARATION) * 100:g}); gains {fitted.gain_x:.4f}, {fitted.gain_y:.4f}; scan radius at "
              f"{UNSEEN} m {radius[1][0]:.3f} x {radius[1][1]:.3f} px (exact {radius[0][0]:.3f} x {radius[0][1]:.3f})")
    assert fitted.pivot_x == pytest.approx(PIVOT, rel=PIVOT_TOL)
    assert fitted.pivot_y == pytest.approx(PIVOT + SEPARATION, rel=PIVOT_TOL)
    assert (fitted.gain_x, fitted.gain_y) == pytest.approx((1.0, 1.0), rel=GAIN_TOL)
    assert radius[1] == pytest.approx(radius[0], rel=AMPLITUDE_TOL)


def test_led_track_at_64x48_and_its_refusals():
    scene = ef.load_scene(LED, width=64, height=48, depth=1.0, amplitude=2.0)
    events = ef.render_events(scene, 1 / FREQ, steps=32)
    # measured within 1.1 % at scan phases 0, 90 and 200 deg (LED image radius 0.5 px, scan radius 5.5 px)
    assert fit_led(events).scale_px_per_rad == pytest.approx(rendered_scales(events, 1.0), rel=0.03)
    with pytest.raises(CalibrationError, match="no LED in the scan period"):
        fit_led(EventStream.empty(64, 48, events.meta))
    with pytest.raises(CalibrationError, match="scan period 1 is not in the stream"):
        fit_led(events, period_index=1)
    with pytest.raises(CalibrationError, match="at least 5"):
        fit_led(events, samples=4)
    # a scene, not an LED (a new user's galvo_static among LED captures: the fit blamed the depth labels)
    scene = ef.load_scene(os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml"), width=64, height=48)
    with pytest.raises(CalibrationError, match=r"no single LED in the scan period: [0-9]+% of the film changes"):
        fit_led(ef.render_events(scene, scene.scan_period))


def rendered_scales(events, depth):
    """Exact curve scales (px per mechanical radian, x and y) of the on-axis LED at ``depth`` through the galvo
    the events were rendered with: the span of its image over a scan, per radian of amplitude."""
    g = GalvoGeometry.from_optics(events.meta["optics"], events.width, events.height)
    a = math.radians(events.meta["optics"]["scan"]["amplitude"])
    theta = np.linspace(0, 2 * np.pi, 721)
    return tuple(np.ptp(g.image_shift(a * np.cos(theta), a * np.sin(theta), depth), axis=0) / 2 / a)


def test_depth_calibration_of_camera_recordings_from_nominal_optics(tmp_path, capsys):
    """Camera recordings carry no optics and no thresholds: ``calibrate depth`` refused them, so the documented
    workflow (calibrate the set-up, then refocus its recordings with that calibration) could not start. With
    the set-up's nominal optics (``--optics``) and ``--contrast`` the LED captures written as Prophesee RAW give
    the pivots of the same captures as rendered files."""
    import json
    pytest.importorskip("faery")
    optics, h5, raw = None, [], []
    for z in DEPTHS:
        scene = ef.load_scene(LED, width=96, height=72, depth=z, amplitude=2.0, mirror_distance=PIVOT)
        ev = ef.render_events(scene, 1 / FREQ, steps=32)
        optics = ev.meta["optics"]
        ef.write_events(str(tmp_path / f"led_{z}.h5"), ev)
        ef.write_events(str(tmp_path / f"led_{z}.raw"), ev)
        h5.append(f"{tmp_path / f'led_{z}.h5'}:{z}")
        raw.append(f"{tmp_path / f'led_{z}.raw'}:{z}")
    nominal = str(tmp_path / "optics.json")
    json.dump({k: optics[k] for k in ("design", "fov_x_deg", "mirror_distance", "mirror_separation", "scan")},
              open(nominal, "w"))
    assert cli.main(["calibrate", "depth", *raw, "-o", str(tmp_path / "x.json")]) == 2
    assert "the recording carries no optics (no light-field metadata): pass --optics FILE.json (the set-up's " \
        "nominal galvo optics)" in capsys.readouterr().err
    assert cli.main(["calibrate", "depth", *h5, "-o", str(tmp_path / "from_h5.json")]) == 0
    assert cli.main(["calibrate", "depth", *raw, "--optics", nominal, "--contrast", "0.2",
                     "-o", str(tmp_path / "from_raw.json")]) == 0, capsys.readouterr().err
    a, b = (load_calibration(str(tmp_path / n))["depth"] for n in ("from_h5.json", "from_raw.json"))
    rendered = GalvoGeometry.from_optics(a.optics, 96, 72)
    ga, gb = a.geometry(rendered), b.geometry(rendered)
    assert (gb.pivot_x, gb.pivot_y) == pytest.approx((ga.pivot_x, ga.pivot_y), rel=0.02)
    assert gb.pivot_x == pytest.approx(PIVOT, rel=PIVOT_TOL)
    # the optics file's fields are the sensor's own record's (a misspelt optional one was left out silently),
    # and --optics beside a file that carries optics is refused (it was ignored)
    from mitsuba_eventfield.optics.galvo import OPTICS_RECORD_KEYS
    assert tuple(sorted(optics)) == tuple(sorted(OPTICS_RECORD_KEYS))
    json.dump(dict(json.load(open(nominal)), fov_x_dge=40), open(str(tmp_path / "typo.json"), "w"))
    assert cli.main(["calibrate", "depth", *raw, "--optics", str(tmp_path / "typo.json"), "--contrast", "0.2",
                     "-o", str(tmp_path / "y.json")]) == 2
    assert "typo.json: fov_x_dge: not a field of galvo optics (allowed: design, scan" in capsys.readouterr().err
    assert cli.main(["calibrate", "depth", *h5, "--optics", nominal, "-o", str(tmp_path / "y.json")]) == 2
    assert "carries its own (galvo) optics; --optics is for a camera recording" in capsys.readouterr().err
    assert not (tmp_path / "y.json").exists()
