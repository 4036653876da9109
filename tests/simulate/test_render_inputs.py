"""Render inputs a reviewer found unchecked (2026-11-26): a film or scene a render cannot use, motion numbers
too large to compute with, and options that contradict each other (a resume with another -D value:
test_checkpoint.py). Each is one line before anything is rendered or written."""
import os

import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.cli.main import main as cli

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DEMO = os.path.join(ROOT, "scenes", "demo", "demo.xml")


def test_a_scene_a_render_cannot_use(tmp_path, capsys):
    """No camera (an IndexError) and a film with a 0-pixel side (a ZeroDivisionError sizing the event
    batches): exit 2, one line naming the scene, nothing written."""
    path = tmp_path / "s.xml"
    path.write_text('<scene version="3.0.0"><shape type="sphere"/></scene>')
    for scene, defines, message in ((str(path), [], "the scene has no <sensor>: events need a camera"),
                                    (DEMO, ["-D", "width=0", "-D", "height=24"],
                                     "film 0x24: each side must be at least 1 pixel")):
        code = cli(["render", scene, *defines, "-o", str(tmp_path / "o.h5"), "--duration", "0.001", "--steps", "2",
                    "--quiet"])
        err = capsys.readouterr().err.strip()
        assert code == 2 and err == f"eventfield: error: {scene}: {message}", err
    assert os.listdir(tmp_path) == ["s.xml"]


@pytest.mark.parametrize("motion, key", [
    ({"spin": {"rpm": 1e300}}, r"objects\.ball\.spin\.rpm = 1e\+300: allowed range is \[-1e\+09, 1e\+09\]"),
    ({"spin": {"rpm": 100, "axis": [1e300, 1e300, 0]}}, r"objects\.ball\.spin\.axis\[0\] = 1e\+300"),
    ({"velocity": [1e30, 0, 0]}, r"objects\.ball\.velocity\[0\] = 1e\+30"),
    ({"keyframes": [{"t": 0, "translate": [1e300, 0, 0]}, {"t": 0.01}]}, r"keyframes\[0\]\.translate\[0\]"),
])
def test_motion_numbers_too_large_to_compute_with(motion, key):
    with pytest.raises(ef.ConfigError, match=key):
        ef.parse_motion({"objects": {"ball": motion}})
    ef.parse_motion({"objects": {"ball": {"spin": {"rpm": 1e9}, "velocity": [1e9, 0, 0]}}})   # the bound itself


def test_contradicting_options_are_one_line(tmp_path, capsys):
    timed = ef.load_scene(DEMO, width=16, height=12)
    with pytest.raises(ef.EventFieldError, match=r"^steps = 5 and adaptive = True: give one"):
        ef.render_events(timed, 0.004, steps=5, adaptive=True)
    with pytest.raises(ef.EventFieldError, match=r"^on_device = 'yes': must be True or False"):
        ef.render_events(timed, 0.004, steps=5, on_device="yes")
    with pytest.raises(ef.EventFieldError, match=r"x\.h5: format 'npz' does not match the extension"):
        ef.render_events(timed, 0.004, steps=5, output=str(tmp_path / "x.h5"), fmt="npz")
    code = cli(["render", DEMO, "-D", "width=16", "-D", "height=12", "--duration", "0.002", "--steps", "2",
                "-o", str(tmp_path / "e.h5"), "--preview", str(tmp_path / "p.jpg"), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.endswith("p.jpg: preview must be a .png file") and os.listdir(tmp_path) == []
    code = cli(["render", DEMO, "--motion", "nope.toml", "--no-motion", "-o", str(tmp_path / "e.h5"), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.endswith("--motion nope.toml and --no-motion: give one") and not os.listdir(tmp_path)


def test_a_scene_renders_in_its_own_variant_after_a_colour_scene_was_loaded():
    """load_scene(color=True) switches the process's variant, and a mono scene loaded before it then failed to
    render on a bare AssertionError inside Mitsuba; each scene now renders in the variant it was loaded in, and
    the same events as before the colour load."""
    import mitsuba as mi
    from conftest import TEST_VARIANT
    fan = os.path.join(ROOT, "scenes", "fan", "fan.xml")
    mono = ef.load_scene(fan, width=32, height=24)
    first = ef.render_events(mono, 0.002, steps=4)
    colour = ef.load_scene(os.path.join(ROOT, "scenes", "demo", "demo.xml"), width=32, height=24, color=True)
    assert mi.variant() != mono.variant
    try:
        again = ef.render_events(mono, 0.002, steps=4)
        assert mi.variant() == mono.variant and len(first) > 1000 and again.equals(first)
        assert ef.render_frames(colour, [0.0], log=False, rgb=True).shape[-1] == 3 and mi.variant() == colour.variant
    finally:
        ef.set_variant(TEST_VARIANT)
