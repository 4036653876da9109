"""HDR light field: the event field against two 8-bit exposures, scored in the log domain against the render.

The light-field tests (``hdr.lightfield``) run scenes/hdr_depth at 96 x 72 with 24 views, with its realistic
prophesee_gen4 pixel. Each bound has the value measured at that size in a comment.
"""
import json
import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT

from mitsuba_eventfield.apps import hdr
from mitsuba_eventfield.apps.hdr_lightfield import refocus_bilinear
from mitsuba_eventfield.output_folders import MANIFEST

SCENE = os.path.join(ROOT, "scenes", "hdr_leds", "hdr_leds.xml")
LF_SCENE = os.path.join(ROOT, "scenes", "hdr_depth", "hdr_depth.xml")


def test_ldr_model_quantises_and_clips():
    lin = np.array([0.0, 0.001, 0.5, 1.0, 3.0])
    codes = hdr.ldr_codes(lin, exposure=1.0)
    assert codes.tolist() == [0, 0, 128, 255, 255]
    back = hdr.ldr_to_linear(codes, 1.0)
    assert back[0] == 0.5 / 255 and abs(back[2] - 0.5) <= 0.5 / 255 and back[4] == 1.0   # clipped: 3 reads as 1


def test_event_field_keeps_both_ends_of_the_range(capsys):
    r = hdr.compare(SCENE, {"width": 80, "height": 60}, depth=1.45, steps_per_period=48)
    with capsys.disabled():
        print("\n[HDR light field, 80x60]\n" + r.report())
    assert r.dynamic_range >= 1e4                                   # the scene is HDR as the issue asks
    assert r.regions["bright"].sum() > 50 and r.regions["dark"].sum() > 500
    # the regions are the exposures' failures, recomputed from the truth: the long frame's clipped codes, the
    # short frame's codes under a tenth of quantisation error (radiance from the lin-log truth)
    from mitsuba_eventfield.plugins.pixel_model import linlog_inverse_np
    linear = linlog_inverse_np(r.truth_log, r.meta["pixel_model"]["linlog_threshold"])
    exposures = hdr.ldr_exposures(linear)
    assert np.array_equal(r.regions["bright"], hdr.ldr_codes(linear, exposures["long"]) == 255)
    assert np.array_equal(r.regions["dark"], hdr.ldr_codes(linear, exposures["short"]) < hdr.WELL_EXPOSED[0])
    ev, short, long = (r.errors[k] for k in ("events", "ldr_short", "ldr_long"))
    # each exposure fails where it clips or underflows; the events hold both ends to within ~2 thresholds (C = 0.2)
    assert short["dark"] > 0.8 and long["bright"] > 0.8
    assert ev["worst_region"] < 0.4 < 0.5 * min(short["worst_region"], long["worst_region"])
    assert ev["all"] < min(short["all"], long["all"])


def test_hdr_cli_outputs_and_bad_depth(tmp_path):
    env = dict(os.environ)
    cmd = [sys.executable, "-m", "mitsuba_eventfield.cli", "hdr", SCENE, "-o", str(tmp_path / "h"),
           "-D", "width=48", "-D", "height=36", "--steps", "32"]
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
    assert r.returncode == 0, r.stderr
    assert sorted(n for n in os.listdir(tmp_path / "h") if n != MANIFEST) == ["events.exr", "hdr.png", "ldr_long.exr", "ldr_short.exr",
                                                   "metrics.json", "truth.exr"]
    with open(tmp_path / "h" / "metrics.json") as f:
        m = json.load(f)
    row = m["paper"][0]
    assert row["figure"] == "Fig. 7" and f"long exposure {m['errors']['ldr_long']['bright']:.2f}" in row["measured"]
    assert row["command"].startswith("eventfield hdr ") and "-D width=48" in row["command"]
    # the depth the solver was given (the default, from how the scene was built) is said in the row
    assert f"The solver is given the scene's depth ({m['solver_depth']:g} m" in row["differs"]
    bad = subprocess.run(cmd[:-2] + ["--depth", "-1"], capture_output=True, text=True, env=env, timeout=600)
    assert bad.returncode == 2 and "argument --depth: '-1': allowed range is (0, inf)" in bad.stderr


@pytest.fixture(scope="module")
def hdr_lf():
    return hdr.lightfield(LF_SCENE, {"width": 96, "height": 72}, depths=(0.6, 1.5), views=24)


def test_hdr_light_field_beats_each_exposure_where_it_fails(hdr_lf, capsys):
    r = hdr_lf
    with capsys.disabled():
        print("\n[HDR light field, scenes/hdr_depth 96x72, 24 views]\n" + r.report())
    pm = r.meta["pixel_model"]                 # the realistic pixel, its noise and dim-light low-pass on
    assert pm["preset"] == "prophesee_gen4" and pm["cutoff_hz"] > 0 and pm["threshold_sigma"] > 0
    assert pm["shot_noise_hz"] > 0 and pm["leak_rate_hz"] > 0 and pm["refractory_s"] > 0
    assert r.meta["noise_events"] > 50                             # measured 118
    assert r.dynamic_range > 5e4                                   # measured 7.1e4:1
    assert "long exposure" in r.meta["extra_information"] and "extra information:" in r.report()
    for i, z in enumerate(r.depths):
        ev, short, long = (r.errors[k][i] for k in ("events", "ldr_short", "ldr_long"))
        assert r.regions["bright"][i].sum() > 200 and r.regions["dark"][i].sum() > 5000   # measured 315, ~6680
        # bright (the LEDs): the long exposure clips. Measured at 0.6 / 1.5 m: events 0.53 / 0.57, long 3.37 / 3.47
        assert long["bright"] > 3.0 and ev["bright"] < 0.75 and ev["bright"] < 0.25 * long["bright"], (z, ev, long)
        # dark (card, wall, text): the short exposure reads code 0. Events 0.30 / 0.34, short 1.09 / 1.26
        assert short["dark"] > 1.0 and ev["dark"] < 0.45 and ev["dark"] < 0.45 * short["dark"], (z, ev, short)
        # each exposure's worst region against the events': measured ratio 0.48 / 0.46
        assert ev["worst_region"] < 0.6 * min(short["worst_region"], long["worst_region"])


def test_refocus_at_each_depth_is_sharpest_on_what_is_there(hdr_lf):
    """Pixels whose Mitsuba depth is the card's (0.6 m) or the wall's (1.5 m) are sharpest, in the log image
    refocused from the events, at their own depth (measured Tenengrad ratios 2.53 and 1.34)."""
    fc = hdr_lf.focus
    card, wall = fc["regions"]
    assert fc["all_sharpest_at_own_depth"] and (card["depth"], wall["depth"]) == (0.6, 1.5)
    assert card["pixels"] > 1000 and wall["pixels"] > 4000            # measured 1553, 5359
    assert card["ratio_to_next_best"] > 1.8 and wall["ratio_to_next_best"] > 1.15
    assert hdr_lf.failed_checks() == []
    wall["sharpest_at_own_depth"] = False                              # as a failed check reads
    try:
        assert hdr_lf.failed_checks() == [f"HDR light field: focus check failed at 1.5: its region "
                                          f"({wall['pixels']} px) is sharper refocused at another depth"]
    finally:
        wall["sharpest_at_own_depth"] = True


def test_hdr_refocus_does_not_ring_next_to_an_led(hdr_lf):
    """An LED 1000 times its surround, in views that the refocus warps by sub-pixel homographies. Plain Lanczos
    rings far below the surround (the test's own warps: the oracle that there is something to catch); the
    refocus keeps each sample within its neighbours' values (up to ``RING_MARGIN``), and refocus_bilinear
    averages with non-negative weights: it stays within [1, 1000]."""
    import cv2
    from mitsuba_eventfield.focus.refocus import RING_MARGIN, refocus
    from mitsuba_eventfield.lightfield.model import from_galvo, galvo_view_times
    optics = hdr_lf.meta["optics"]
    views = np.ones((8, 72, 96))
    views[:, 30:33, 40:43] = 1000.0
    lf = from_galvo(np.log(views), galvo_view_times(optics, 0.0, 8), optics)
    bilinear, lanczos = refocus_bilinear(lf, 0.9), refocus(lf, 0.9)
    # measured: bilinear 0.99996 (float32 warp weights) .. 125.9
    assert bilinear.min() > 1 - 1e-3 and bilinear.max() < 1000 + 1e-3 and bilinear.max() > 100
    assert lanczos.min() > 1 / RING_MARGIN - 1e-3 and lanczos.max() < 1000 * RING_MARGIN and lanczos.max() > 100
    plain = [cv2.warpPerspective(v.astype(np.float32), m, (96, 72), flags=cv2.INTER_LANCZOS4 | cv2.WARP_INVERSE_MAP,
                                 borderMode=cv2.BORDER_REFLECT_101) for v, m in zip(lf.views, lf.alignments(0.9))]
    assert min(float(p.min()) for p in plain) < 0                      # Lanczos alone rings below the surround


@pytest.mark.parametrize("kw, words", [({"depths": (0.6, -1.0)}, ["depths = -1.0", "(0, inf)"]),
                                       ({"views": 1}, ["views = 1", "[2, 4096]"]),
                                       ({"solver_depth": 0.0}, ["solver_depth = 0.0", "(0, inf)"])])
def test_hdr_lightfield_refuses_bad_input_before_rendering(kw, words):
    with pytest.raises(ValueError) as err:
        hdr.lightfield(LF_SCENE, **kw)
    assert all(w in str(err.value) for w in words), str(err.value)


def test_hdr_lightfield_cli_outputs_and_paper_row(tmp_path):
    out = tmp_path / "l"
    cmd = [sys.executable, "-m", "mitsuba_eventfield.cli", "hdr", "--lightfield", "-o", str(out),
           "-D", "width=64", "-D", "height=48", "--views", "12"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert "extra information:" in r.stdout and "focus check" in r.stdout
    names = sorted(n for n in os.listdir(out) if n != MANIFEST)
    assert names == sorted([f"{k}_{z}m.exr" for k in ("truth", "events", "ldr_short", "ldr_long")
                            for z in ("0.6", "1.5")] + ["hdr_lightfield.png", "metrics.json"])
    with open(out / "metrics.json") as f:
        m = json.load(f)
    row = m["paper"][0]
    assert set(row) == {"figure", "claim", "measured", "command", "differs"} and row["figure"] == "Fig. 7"
    assert f"events {m['errors']['events'][1]['bright']:.2f} vs long" in row["measured"]
    # and over all pixels against both exposures, where one of them may be the closer (per region it is not)
    assert (f"over all pixels events {m['errors']['events'][1]['all']:.2f} vs long "
            f"{m['errors']['ldr_long'][1]['all']:.2f} and short {m['errors']['ldr_short'][1]['all']:.2f}"
            in row["measured"])
    assert row["command"] == ("eventfield hdr --lightfield -D width=64 -D height=48 --depths 0.6,1.5 --views 12 "
                              f"--steps {m['steps']}")
    assert "long exposure" in m["extra_information"] and m["pixel_model"]["preset"] == "prophesee_gen4"
    cmd[cmd.index(str(out))] = str(tmp_path / "bad")
    bad = subprocess.run(cmd + ["--depths", "0.6,0"], capture_output=True, text=True, timeout=600)
    assert bad.returncode == 2 and bad.stderr.strip() == \
        "eventfield: error: --depths = '0': allowed range is (0, inf)", bad.stderr
