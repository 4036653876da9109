"""Every subcommand against every kind of bad input file it can be given: missing, empty, garbage, truncated,
and of the wrong kind. Each must answer with exit status 2 and one line naming the file, no traceback, and no
output. The table of commands is checked against the parser, so a new subcommand cannot skip the sweep."""
import argparse
import os

import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.cli.main import build_parser
from mitsuba_eventfield.cli.main import main as cli

# how each command is called; {E} an event file, {S} a scene, {X} an EXR frame, {F} frames to convert
COMMANDS = {
    "info": ["info", "{E}"],
    "preview": ["preview", "{E}", "-o", "{O}/p.png"],
    "reconstruct": ["reconstruct", "{E}", "-o", "{O}/rec"],
    "refocus": ["refocus", "{E}", "-o", "{O}/r.png", "--depth", "1"],
    "depth": ["depth", "{E}", "-o", "{O}/d.png", "--near", "0.3", "--far", "2"],
    "calibrate galvo": ["calibrate", "galvo", "{E}", "--patch", "3,3", "-o", "{O}/c.json"],
    "calibrate depth": ["calibrate", "depth", "{E}:0.5", "{E}:1", "{E}:2", "-o", "{O}/c.json"],
    "calibrate kaleidoscope": ["calibrate", "kaleidoscope", "{X}", "-o", "{O}/k.json"],
    "render": ["render", "{S}", "-o", "{O}/e.h5", "--quiet"],
    "frame": ["frame", "{S}", "-o", "{O}/f.exr"],
    "convert": ["convert", "{F}", "-o", "{O}/c.h5", "--fps", "100", "--quiet"],
    "bench": ["bench", "{S}", "-o", "{O}/bench"],
    "hdr": ["hdr", "{S}", "-o", "{O}/hdr"],
    "hdr lightfield": ["hdr", "--lightfield", "{S}", "-o", "{O}/hl"],
    "highspeed": ["highspeed", "{S}", "-o", "{O}/hs", "--plane", "fan=0.5"],
    "track-focus": ["track-focus", "{S}", "-o", "{O}/tf"],
    "scanrate-depth": ["scanrate-depth", "{S}", "-o", "{O}/sd"],
    "slomorf": ["slomorf", "{S}", "-o", "{O}/sm"],
    "scan-frequency": ["scan-frequency", "{S}", "-o", "{O}/sf", "--plane", "fan=0.6"],
    "compare-designs": ["compare-designs", "--galvo", "{S}", "-o", "{O}/cd"],
    "grid-experiment": ["grid-experiment", "--galvo", "{S}", "-o", "{O}/ge"],
}
# commands that take no input file
NO_INPUT = {"regression", "demo", "device", "paper"}


def test_the_table_covers_every_subcommand():
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    covered = {name.split()[0] for name in COMMANDS} | NO_INPUT
    assert set(sub.choices) == covered


def _bad_files(folder):
    """Bad inputs of each kind, by placeholder."""
    os.makedirs(folder, exist_ok=True)

    def put(name, data):
        path = os.path.join(folder, name)
        with open(path, "wb") as f:
            f.write(data)
        return path
    rng = np.random.default_rng(0)
    good = os.path.join(folder, "good.h5")
    ef.write_events(good, ef.EventStream(rng.integers(0, 8, 500), rng.integers(0, 6, 500),
                                         np.sort(rng.integers(0, 10_000, 500)), rng.choice([-1, 1], 500), 8, 6))
    data = open(good, "rb").read()
    os.remove(good)
    return {
        "E": {"missing": os.path.join(folder, "none.h5"), "empty": put("empty.h5", b""),
              "garbage": put("garbage.h5", rng.bytes(2000)), "truncated": put("cut.h5", data[: len(data) // 2]),
              "text": put("words.npz", b"not a zip")},
        "S": {"missing": os.path.join(folder, "none.xml"), "empty": put("empty.xml", b""),
              "garbage": put("garbage.xml", b"<scene version='3.0.0'><shape type="),
              "not a scene": put("other.xml", b"<html><body>hello</body></html>")},
        "X": {"missing": os.path.join(folder, "none.exr"), "empty": put("empty.exr", b""),
              "garbage": put("garbage.exr", rng.bytes(3000))},
        "F": {"missing": os.path.join(folder, "none.mp4"), "empty npz": put("empty.npz", b""),
              "garbage npz": put("garbage.npz", rng.bytes(1000)), "empty video": put("empty.mp4", b"")},
    }


CASES = [(command, kind, bad) for command, argv in COMMANDS.items()
         for kind in ("E", "S", "X", "F") if any("{" + kind + "}" in a for a in argv)
         for bad in {"E": ("missing", "empty", "garbage", "truncated", "text"),
                     "S": ("missing", "empty", "garbage", "not a scene"),
                     "X": ("missing", "empty", "garbage"),
                     "F": ("missing", "empty npz", "garbage npz", "empty video")}[kind]]


@pytest.mark.parametrize("command, kind, bad", CASES, ids=[f"{c}-{b}" for c, _, b in CASES])
def test_bad_input_file_is_one_line_and_leaves_nothing(tmp_path, capsys, command, kind, bad):
    files = _bad_files(str(tmp_path / "in"))
    out = tmp_path / "out"
    out.mkdir()
    path = files[kind][bad]
    argv = [a.replace("{" + kind + "}", path).replace("{O}", str(out)) for a in COMMANDS[command]]
    code = cli(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1 and err.startswith("eventfield: error: ") and "Traceback" not in err, err
    assert os.path.basename(path) in err, err
    assert list(out.iterdir()) == []
