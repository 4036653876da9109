"""The command line, as a user runs it: the demo job, info, preview, and bad input."""
import os
import subprocess
import sys

import h5py
import pytest
from conftest import DEMO, ROOT

BROKEN_XML = '<scene version="3.0.0"><shape type="sphere"></scene>'
UNKNOWN_PLUGIN = '<scene version="3.0.0"><shape type="hyperboloid_xyz"/></scene>'


def run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "mitsuba_eventfield.cli", *args], capture_output=True, text=True,
                          timeout=600, cwd=cwd)


def test_render_info_preview(tmp_path):
    out, png = tmp_path / "demo.h5", tmp_path / "demo.png"
    r = run("render", DEMO, "-o", str(out), "--preview", str(png), "-D", "width=64", "-D", "height=48",
            "--duration", "0.01", "--steps", "10", "--quiet")
    assert r.returncode == 0, r.stderr
    assert "events" in r.stdout and "ev/s" in r.stdout and "wall" in r.stdout
    with h5py.File(out, "r") as f:
        assert f["events/t"].shape[0] > 100
    assert png.stat().st_size > 0
    info = run("info", str(out))
    assert info.returncode == 0 and "64x48" in info.stdout and "pixel_model" in info.stdout
    p2 = tmp_path / "window.png"
    pv = run("preview", str(out), "-o", str(p2), "--t0", "2", "--t1", "4")
    assert pv.returncode == 0 and p2.stat().st_size > 0
    import cv2          # a small sensor's previews enlarged by a whole factor to about 400 px (64 px: 7x)
    assert cv2.imread(str(png)).shape[:2] == cv2.imread(str(p2)).shape[:2] == (336, 448)
    p3 = tmp_path / "one.png"
    assert run("preview", str(out), "-o", str(p3), "--scale", "1").returncode == 0
    assert cv2.imread(str(p3)).shape[:2] == (48, 64)


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")
BAD = {
    "galvo_amplitude": (lambda d: [GALVO, "-D", "amplitude=20"], "exceeds the galvo's derated limit"),
    "galvo_frequency": (lambda d: [GALVO, "-D", "frequency=0"], "frequency (Hz) = 0.0: allowed range is (0, 1000]"),
    "malformed_xml": (lambda d: [_write(d, "bad.xml", BROKEN_XML)], "bad.xml"),
    "unknown_plugin": (lambda d: [_write(d, "unk.xml", UNKNOWN_PLUGIN)], "hyperboloid_xyz"),
    "missing_motion_id": (lambda d: [DEMO, "--motion", _write(d, "m.motion.toml",
                                                              "[objects.ghost]\nvelocity = [1, 0, 0]\n")],
                          "objects.ghost"),
    "threshold_zero": (lambda d: [DEMO, "--threshold", "0"], "argument --threshold: '0': allowed range is (0, 10]"),
    "negative_duration": (lambda d: [DEMO, "--duration", "-1"], "argument --duration: '-1': allowed range is (0, 3600]"),
    "unwritable_output": (lambda d: [DEMO, "-o", "/nonexistent_dir/x.h5"], "/nonexistent_dir does not exist"),
    "huge_resolution": (lambda d: [DEMO, "-D", "width=200000", "-D", "height=200000"], "200000x200000"),
    "over_memory": (lambda d: [DEMO, "-D", "width=60000", "-D", "height=30000", "--spp", "2"], "GiB of render buffers"),
    "beyond_event_coordinates": (lambda d: [DEMO, "-D", "width=70000", "-D", "height=4"],
                                 "70000x4 pixels: events hold at most 65536 x 32768"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_one_line_error_no_output(tmp_path, case):
    make_args, expected = BAD[case]
    args = make_args(tmp_path)
    out = tmp_path / "out.h5"
    if "-o" not in args:
        args += ["-o", str(out)]
    small = case not in ("huge_resolution", "over_memory", "beyond_event_coordinates") and args[0] in (DEMO, GALVO)
    args += ["-D", "width=32", "-D", "height=24"] if small else []
    before = set(os.listdir(tmp_path))
    r = run("render", *args, "--quiet")
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith("eventfield: error:") and expected in lines[0], lines[0]
    assert set(os.listdir(tmp_path)) == before        # nothing written, not even a temporary


def test_corrupt_event_file_is_a_clear_error(tmp_path):
    bad = tmp_path / "x.h5"
    bad.write_bytes(b"not hdf5")
    r = run("info", str(bad))
    assert r.returncode == 2 and "cannot read as h5" in r.stderr


def test_every_command_prints_its_help():
    """``--help`` of every command and subcommand (argparse formats each help with %: a bare "10 % far" in one
    option's help made ``refocus --help`` and ``depth --help`` exit with a TypeError)."""
    import argparse

    from mitsuba_eventfield.cli.main import build_parser

    def parsers(p, name):
        yield name, p
        for action in p._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub, child in action.choices.items():
                    yield from parsers(child, f"{name} {sub}")
    seen = []
    for name, p in parsers(build_parser(), "eventfield"):
        text = p.format_help()
        assert text.startswith("usage: ") and len(text) > 100, name
        seen.append(name)
    assert {"eventfield refocus", "eventfield depth", "eventfield calibrate galvo"} <= set(seen) and len(seen) > 20


def test_preview_scale_and_scene_defaults_by_rule():
    """``preview.auto_scale``: the whole factor (at most 8) bringing the longer side to about 400 px; and
    ``declared_defaults`` reads ``<default>`` names in either attribute order and quoting (EVENTFIELD_FILM and
    a sweep's names use it)."""
    from mitsuba_eventfield.events.preview import auto_scale
    from mitsuba_eventfield.scene.timed import declared_defaults, settable_parameters
    assert [auto_scale(*s) for s in ((16, 12), (64, 48), (346, 260), (400, 300), (4000, 10))] == [8, 7, 2, 1, 1]
    text = "<default name='a' value='1'/><default value=\"2\" name=\"b\"/><float value=\"$c\"/><x v=\"$a\"/>"
    assert declared_defaults(text) == ["a", "b"] and settable_parameters(text) == ["a", "b", "c"]
