"""The `eventfield` integrator declared in XML: its thresholds, its nested integrator, its errors."""
import numpy as np
import pytest

import mitsuba_eventfield as ef

SCENE = """<scene version="3.0.0">
  <integrator type="eventfield">
    <float name="threshold_on" value="{on}"/>
    <float name="threshold_off" value="0.3"/>
    <integrator type="direct"/>
  </integrator>
  <sensor type="perspective"><float name="fov" value="40"/>
    <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="16"/></film></sensor>
  <emitter type="constant"><float name="radiance" value="1"/></emitter>
  <shape type="sphere" id="ball"><point name="center" value="0, 0, 4"/><float name="radius" value="0.5"/></shape>
</scene>"""
MOTION = {"objects": {"ball": {"velocity": [100.0, 0.0, 0.0]}}}   # ~8 px in 0.01 s


def test_xml_thresholds_and_nested_integrator(tmp_path):
    path = tmp_path / "s.xml"
    path.write_text(SCENE.format(on=0.35))
    timed = ef.load_scene(str(path), motion=MOTION)
    integ = timed.scene.integrator()
    assert "direct" in str(integ.inner).lower() or "Direct" in type(integ.inner).__name__
    ev = ef.render_events(timed, 0.01, steps=10)
    assert ev.meta["pixel_model"]["threshold_on"] == 0.35 and ev.meta["pixel_model"]["threshold_off"] == 0.3
    # an override applies to one render only; the next render is back to the scene's values
    ev2 = ef.render_events(timed, 0.01, steps=10, threshold=0.1)
    assert ev2.meta["pixel_model"]["threshold_on"] == 0.1 and len(ev2) > len(ev)
    ev3 = ef.render_events(timed, 0.01, steps=10)
    assert ev3.meta["pixel_model"]["threshold_on"] == 0.35
    # the same events but for the renderer's own run-to-run difference on a moving scene (docs/design.md,
    # "Render determinism": once seen here, 2026-11-26): the 0.1 threshold's render differs by hundreds
    assert np.abs(ev3.signed_counts() - ev.signed_counts()).sum() <= 2 < len(ev2) - len(ev)


def test_net_events_follow_log_change(tmp_path):
    """Per pixel, ON minus OFF equals the log-brightness change over C_on/C_off to within one event."""
    import mitsuba as mi
    path = tmp_path / "s.xml"
    path.write_text(SCENE.format(on=0.3))
    timed = ef.load_scene(str(path), motion=MOTION)
    ev = ef.render_events(timed, 0.01, steps=20)
    frames = []
    for t in (0.0, 0.01):
        timed.set_time(t)
        frames.append(np.array(mi.render(timed.scene, spp=4, seed=0))[..., 0])
    dlog = np.log(np.maximum(frames[1], 1e-3)) - np.log(np.maximum(frames[0], 1e-3))
    assert len(ev) > 50
    assert np.all(np.abs(ev.signed_counts() - dlog / 0.3) <= 1.0 + 1e-4)


def test_bad_threshold_in_xml_is_a_clear_error(tmp_path):
    path = tmp_path / "bad.xml"
    path.write_text(SCENE.format(on=-0.2))
    with pytest.raises(ef.EventFieldError, match=r"bad.xml.*threshold_on = -0.2: must be > 0"):
        ef.load_scene(str(path))


def test_pixel_preset_and_overrides_in_xml(tmp_path):
    xml = SCENE.format(on=0.3).replace('<float name="threshold_off" value="0.3"/>',
                                       '<float name="threshold_off" value="0.3"/>\n    <string name="preset" '
                                       'value="davis346"/>\n    <float name="refractory_s" value="0.002"/>')
    path = tmp_path / "p.xml"
    path.write_text(xml)
    timed = ef.load_scene(str(path), motion=MOTION)
    ev = ef.render_events(timed, 0.01, steps=10)
    pm = ev.meta["pixel_model"]
    assert pm["preset"] == "davis346" and pm["refractory_s"] == 0.002 and pm["threshold_on"] == 0.35 - 0.05
    assert pm["shot_noise_hz"] == 1.0                    # from the preset
    bad = tmp_path / "q.xml"
    bad.write_text(xml.replace('name="refractory_s"', 'name="refractory_time"'))
    with pytest.raises(ef.EventFieldError, match="unknown parameter 'refractory_time'"):
        ef.load_scene(str(bad))


def test_render_frames_use_the_scene_linlog_threshold(tmp_path):
    """Frames are in the pixel's own log domain: the XML's linlog_threshold, not the preset's."""
    path = tmp_path / "s.xml"
    path.write_text(SCENE.format(on=0.3).replace('<integrator type="direct"/>',
                                                 '<float name="linlog_threshold" value="5"/><integrator type="direct"/>'))
    timed = ef.load_scene(str(path))
    lin = ef.render_frames(timed, [0.0], log=False)[0]
    log = ef.render_frames(timed, [0.0])[0]
    assert np.allclose(log, ef.plugins.pixel_model.linlog_np(lin, 5.0))
    assert not np.allclose(log, ef.plugins.pixel_model.linlog_np(lin, 1e-3))


def test_the_documented_parameter_table_matches_the_pixel_model():
    """Every pixel-model field is in the integrator's parameter table, with its real default."""
    from dataclasses import fields

    from mitsuba_eventfield.plugins import event_integrator, pixel_model
    rows = {}
    for line in event_integrator.__doc__.splitlines():
        parts = line.split()
        if len(parts) >= 3 and parts[1] in ("float", "integer", "string"):
            rows[parts[0]] = parts[2]
    for f in fields(pixel_model.PixelConfig):
        assert f.name in rows, f.name
        documented = rows[f.name]
        assert (documented == f.default if isinstance(f.default, str) else float(documented) == f.default), f.name
    assert rows["threshold"] == "0.2"
