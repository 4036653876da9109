"""``eventfield frame``'s two files a frame (EXR, and a PNG beside it), from a fault-injection audit
(2026-11-28): the PNG's path was checked only when written, after the EXR had replaced the user's; the PNG's
name replaced every ".exr" in the path; a full disk under OpenEXR read as an "unexpected" error."""
import os

import pytest
from conftest import ROOT

from mitsuba_eventfield.cli.main import main as cli
from mitsuba_eventfield.images import read_exr

GALVO = os.path.join(ROOT, "scenes", "galvo_static", "galvo_static.xml")
SMALL = ["-D", "width=16", "-D", "height=12", "--spp", "1"]


def _run(args, capsys):
    code = cli(["frame", GALVO, *SMALL, *map(str, args)])
    return code, capsys.readouterr()


def test_every_file_of_every_frame_is_checked_before_rendering(tmp_path, capsys):
    (tmp_path / "f.exr").write_text("the user's")
    (tmp_path / "f.png").mkdir()
    code, out = _run(["-o", tmp_path / "f.exr"], capsys)
    assert code == 2 and f"{tmp_path / 'f.png'}: is a directory" in out.err and len(out.err.splitlines()) == 1
    assert (tmp_path / "f.exr").read_text() == "the user's"
    (tmp_path / "g_0001.exr").mkdir()
    code, out = _run(["-o", tmp_path / "g.exr", "--times", "0,1"], capsys)
    assert code == 2 and "g_0001.exr: is a directory" in out.err
    assert sorted(os.listdir(tmp_path)) == ["f.exr", "f.png", "g_0001.exr"]       # nothing written
    code, out = _run(["-o", tmp_path / "h.png"], capsys)
    assert code == 2 and "h.png: frame must be a .exr file" in out.err


def test_the_png_sits_beside_the_exr_as_named(tmp_path, capsys):
    """A folder whose name holds ".exr" stays that folder, and the EXR keeps the name given (upper case too)."""
    folder = tmp_path / "x.exr.d"
    folder.mkdir()
    code, out = _run(["-o", folder / "f.EXR", "--times", "0,2"], capsys)
    assert code == 0, out.err
    assert sorted(os.listdir(folder)) == ["f_0000.EXR", "f_0000.png", "f_0001.EXR", "f_0001.png"]
    channels, meta = read_exr(str(folder / "f_0001.EXR"))
    assert channels["Y"].shape == (12, 16) and meta["time_s"] == pytest.approx(0.002)
    assert f"wrote {folder / 'f_0000.EXR'} and {folder / 'f_0000.png'} (t = 0 ms)" in out.out


def test_a_full_disk_under_openexr_is_one_line_and_leaves_nothing(tmp_path, capsys, monkeypatch):
    """OpenEXR reports a failed write as a RuntimeError ending in the system's words: a full disk is said as
    every other full disk is (exit status 2), and no partial file is left."""
    import OpenEXR
    real = OpenEXR.File

    class Full:
        def __init__(self, *a, **k):
            self.file = real(*a, **k)

        def __enter__(self):
            return self

        def __exit__(self, *a):
            return False

        def write(self, path):
            with open(path, "wb") as f:
                f.write(b"\0" * 100)
            raise RuntimeError(f'Failed to write pixel data to image file "{path}". No space left on device')
    monkeypatch.setattr(OpenEXR, "File", Full)
    code, out = _run(["-o", tmp_path / "f.exr"], capsys)
    assert code == 2 and out.err.strip().startswith(f"eventfield: error: disk full while writing {tmp_path}")
    assert os.listdir(tmp_path) == []
