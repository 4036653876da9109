"""A rendered start frame must be the pixels' own first image: the render's spp and seed. Events are changes
from that image; a frame with other Monte-Carlo noise differs from it by whole log units in places, a fixed
pattern in every reconstructed view. `eventfield frame --spp 4` (the render's default) is that image, and a
start frame rendered otherwise gets a one-line warning naming the command that makes the right one."""
import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.cli.main import main as cli
from mitsuba_eventfield.scene.bundled import bundled_scene

DEMO = bundled_scene("demo/demo.xml")
SIZE = ["-D", "width=48", "-D", "height=36"]


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    folder = tmp_path_factory.mktemp("start")
    out = str(folder / "ev.h5")
    assert cli(["render", DEMO, "-o", out, *SIZE, "--duration", "0.004", "--steps", "8", "--quiet"]) == 0
    return folder, out


def test_the_renders_spp_reconstructs_the_end_frame_within_one_threshold(rendered):
    """Direct integration from the start frame ends within C of the image the pixel saw last (ideal pixel,
    C = 0.2) only from the render's own first image: from a 16-spp frame 23 % of the pixels miss by more
    (up to 5.4 log units)."""
    _, out = rendered
    ev = ef.read_events(out)
    scene = ef.load_scene(DEMO, width=48, height=36)
    end = ef.render_frames(scene, [0.004], spp=4)[0]
    misses = {}
    for spp in (4, 16):
        start = ef.render_frames(scene, [0.0], spp=spp)[0]
        final = ef.reconstruct.reconstruct(ev, [0.004], "direct", log_start=start, t_start=0.0)[0]
        misses[spp] = float(np.mean(np.abs(final - end) > 0.2 + 1e-4))
    assert misses[4] == 0.0 and misses[16] > 0.1, misses


def test_a_start_frame_of_other_samples_is_named(rendered, capsys):
    folder, out = rendered
    for spp in (16, 4):
        frame = str(folder / f"start{spp}.exr")
        assert cli(["frame", DEMO, "-o", frame, *SIZE, "--spp", str(spp)]) == 0
        capsys.readouterr()
        assert cli(["reconstruct", out, "-o", str(folder / f"rec{spp}"), "--fps", "1000", "--start-frame",
                    frame]) == 0
        err = capsys.readouterr().err
        warned = "rendered at 16 spp, seed 0, multijitter sampler; the events at 4 spp, seed 0" in err
        assert warned == (spp == 16) and ("eventfield frame --spp 4 --seed 0" in err) == warned, err


def test_the_light_field_commands_say_it_after_their_own_checks(tmp_path, capsys):
    """refocus holds the warning with the solver's: said once the light field is made (a refused command says
    one line: tests/cli/test_lightfield_cli.py's bad inputs)."""
    galvo = bundled_scene("galvo_static/galvo_static.xml")
    out, frame = str(tmp_path / "gs.h5"), str(tmp_path / "f16.exr")
    assert cli(["render", galvo, "-o", out, *SIZE, "--duration", "0.004", "--steps", "16", "--quiet"]) == 0
    assert cli(["frame", galvo, "-o", frame, *SIZE]) == 0                          # the default: 16 spp
    capsys.readouterr()
    assert cli(["refocus", out, "-o", str(tmp_path / "rf.png"), "--depth", "0.5", "--start-frame", frame]) == 0
    err = capsys.readouterr().err
    assert err.count("rendered at 16 spp, seed 0, multijitter sampler; the events at 4 spp") == 1, err


def _frame_against(tmp_path, capsys, render_args, frame_args, command=("reconstruct",)):
    """stderr of a command reading a frame rendered with ``frame_args`` against events rendered with
    ``render_args`` (galvo_static, 48x36)."""
    galvo = bundled_scene("galvo_static/galvo_static.xml")
    out, frame = str(tmp_path / "gs.h5"), str(tmp_path / "f.exr")
    assert cli(["render", galvo, "-o", out, *SIZE, "--duration", "0.004", "--steps", "16", "--quiet",
                *render_args]) == 0
    assert cli(["frame", galvo, "-o", frame, *SIZE, *frame_args]) == 0
    capsys.readouterr()
    tail = ["-o", str(tmp_path / "rec"), "--fps", "1000"] if command[0] == "reconstruct" else []
    code = cli([*command, out, *tail, "--start-frame", frame])
    return code, capsys.readouterr().err


@pytest.mark.parametrize("render_args, frame_args, said", [
    (["--spp-changing", "16"], ["--spp", "4"], "samples where they matter (--spp-changing): no frame of one spp"),
    (["--independent-seeds", "--seed", "3"], ["--spp", "4", "--seed", "3"], None),   # the first image's own seed
    (["--spp", "4"], ["--spp", "4", "--sampler", "independent"], "--sampler multijitter`"),
    (["--spp", "4"], ["--spp", "4"], ""),
])
def test_what_no_frame_of_one_spp_and_seed_can_match_is_said(tmp_path, capsys, render_args, frame_args, said):
    """A render with samples where they matter has no single-spp first image; under independent seeds the first
    image's seed is step_seed(seed, 0), which the hint names; a frame of another sampler is named with the option
    that fixes it."""
    from mitsuba_eventfield.simulate.stepping import step_seed
    code, err = _frame_against(tmp_path, capsys, render_args, frame_args)
    assert code == 0
    if said is None:
        assert f"`eventfield frame --spp 4 --seed {step_seed(3, 0)}`" in err, err
    else:
        assert (said in err) if said else ("warning" not in err), err


def test_a_refused_calibration_says_one_line(tmp_path, capsys):
    """calibrate galvo read the frame (and warned) before refusing its patches: now one line."""
    code, err = _frame_against(tmp_path, capsys, [], ["--spp", "16"],
                               ("calibrate", "galvo", "--patch", "10,10", "--patch", "30,20", "-o",
                                str(tmp_path / "cal.json")))
    assert code == 2 and err.count("\n") == 1 and "error" in err, err


def test_a_render_that_split_off_static_pixels_has_no_frame_to_match():
    """(A moving scene under a scan renders its static pixels once per period from 40 periods on: its first
    image is no single frame; a 4-spp frame of the fan differed from it by up to 5.2 log units, unsaid.)"""
    from mitsuba_eventfield.cli.inputs import _other_samples
    stream = {"spp": 4, "seed": 0, "seed_mode": "fixed", "sampler": {"type": "MultijitterSampler"},
              "render": {"static_pixels": {"reused_share": 0.168}}}
    frame = {"spp": 4, "seed": 0, "sampler": "multijitter"}
    assert "render the events with --no-reuse" in _other_samples("f.exr", frame, stream)
    assert _other_samples("f.exr", frame, dict(stream, render={"static_pixels": None})) is None
    assert _other_samples("f.exr", {"spp": 4}, dict(stream, render={})) is None      # an older frame: seed 0
