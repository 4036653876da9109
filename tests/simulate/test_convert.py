"""Frames to events (``ef.events_from_frames``, ``eventfield convert``) against closed-form crossings, through
every input kind, and on bad input."""
import os

import numpy as np
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.cli.main import main as cli
from mitsuba_eventfield.validate import DEFAULT_SPP

C = 0.2


def _ramps(width=24, height=3, frames=40, duration=0.04):
    """Pixel x brightens log-linearly at rate a_x (log units / s): crossing k of it is at k C / a_x exactly,
    and linear interpolation between frames is exact for such a ramp."""
    rates = np.linspace(6.1, 70.3, width)      # no crossing falls on the last frame
    t = np.linspace(0.0, duration, frames)
    stack = np.exp(rates[None, None, :] * t[:, None, None]) * np.ones((frames, height, width))
    return stack.astype(np.float32), t, rates


def _ramp_truth(rates, duration):
    return {x: np.array([k * C / a * 1e6 for k in range(1, int(np.floor(a * duration / C + 1e-9)) + 1)])
            for x, a in enumerate(rates)}


def test_log_ramps_fire_at_the_closed_form_instants():
    stack, t, rates = _ramps()
    ev = ef.events_from_frames(stack, t, threshold=C)
    truth = _ramp_truth(rates, t[-1])
    assert len(ev) == 3 * sum(len(v) for v in truth.values()) and (ev.p == 1).all() and ev.is_sorted
    for x, expected in truth.items():
        got = np.sort(ev.t[(ev.x == x) & (ev.y == 1)])
        assert len(got) == len(expected)
        assert np.abs(got - expected).max() <= 1.0      # microsecond rounding; float32 frames cost < 0.5 us here
    assert ev.meta["optics"]["design"] == "frames (converted)" and ev.meta["width"] == 24


@pytest.mark.parametrize("pixel", [None, {"shot_noise_hz": 200.0, "cutoff_hz": 300.0, "threshold_jitter": 0.02}],
                         ids=["ideal", "reading-the-radiance"])
def test_same_events_as_a_render_fed_the_same_frames(demo_small, pixel):
    """The converter is the renderer's pixel: frames rendered from the demo scene, converted, give the
    render's own events (same integrator, same interpolation, same rounding), batched or a frame at a time;
    also for a pixel model that reads the radiance (shot noise, low-pass), which both take as given, not as
    exp(log) of it."""
    from mitsuba_eventfield.plugins.event_batch import one_frame_a_step
    times = np.linspace(0.0, 0.01, 11)
    radiance = ef.render_frames(demo_small, times, spp=DEFAULT_SPP, log=False)   # the render's
    rendered = ef.render_events(demo_small, 0.01, steps=10, reuse=False, pixel=pixel)
    converted = ef.events_from_frames(radiance, times, pixel=pixel)
    assert len(rendered) > 300 and converted.equals(rendered)
    with one_frame_a_step():
        assert ef.events_from_frames(radiance, times, pixel=pixel).equals(rendered)
    if pixel:
        assert rendered.meta["render"]["noise_events"] > 10


def test_every_input_kind_gives_the_same_events(tmp_path):
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(0)
    frames = [np.clip(rng.normal(120, 40, (20, 30)), 0, 255).astype(np.uint8) for _ in range(6)]
    folder = tmp_path / "imgs"
    folder.mkdir()
    for i, f in enumerate(frames):
        cv2.imwrite(str(folder / f"frame_{i}.png"), f)      # natural order: frame_10 would follow frame_9
    np.savez(tmp_path / "stack.npz", frames=np.stack(frames), times=np.arange(6) / 500.0)
    ref = ef.events_from_frames(np.stack(frames), fps=500.0)
    assert len(ref) > 100
    assert ef.events_from_frames(str(folder), fps=500.0).equals(ref)
    assert ef.events_from_frames(str(tmp_path / "stack.npz")).equals(ref)
    out = str(tmp_path / "ev.h5")
    assert cli(["convert", str(folder), "-o", out, "--fps", "500", "--quiet"]) == 0
    assert ef.read_events(out).equals(ref)


def test_video_through_opencv(tmp_path):
    cv2 = pytest.importorskip("cv2")
    path = str(tmp_path / "bar.avi")
    video = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 200, (40, 30))
    for i in range(12):
        img = np.full((30, 40, 3), 30, np.uint8)
        img[:, 4 + 2 * i:10 + 2 * i] = 230
        video.write(img)
    video.release()
    ev = ef.events_from_frames(path)
    assert ev.meta["source"]["fps"] == pytest.approx(200.0)
    # a bright bar moving right: ON events ahead of it, OFF behind, about 2 px further each frame
    on_x, off_x = ev.x[ev.p > 0].mean(), ev.x[ev.p < 0].mean()
    assert len(ev) > 200 and on_x > off_x + 3
    assert abs(ev.t.max() - 11 / 200 * 1e6) < 5e3


@pytest.mark.parametrize("args, message", [
    (["{d}/nothing.mp4"], "no such file"),
    (["{d}/imgs"], "frame rate"),
    (["{d}/x.txt"], "unknown input type"),
    (["{d}/bad.npz"], "no 'frames' array"),
    (["{d}/back.npz"], "strictly increasing"),
    (["{d}/imgs", "--fps", "-5"], "--fps"),
    (["{d}/imgs", "--fps", "10", "--preset", "bogus"], "unknown preset 'bogus'"),
    (["{d}/imgs", "--fps", "10", "--pixel", "refractory_s=-1"], "refractory_s = -1.0: must be >= 0"),
])
def test_bad_input_one_line_no_output(tmp_path, capsys, args, message):
    cv2 = pytest.importorskip("cv2")
    (tmp_path / "imgs").mkdir()
    for i in range(3):
        cv2.imwrite(str(tmp_path / "imgs" / f"{i}.png"), np.zeros((4, 4), np.uint8))
    (tmp_path / "x.txt").write_text("hello")
    np.savez(tmp_path / "bad.npz", images=np.zeros((3, 4, 4)))
    np.savez(tmp_path / "back.npz", frames=np.ones((3, 4, 4)), times=[0.0, 0.2, 0.1])
    out = tmp_path / "out.h5"
    try:
        code = cli(["convert"] + [a.format(d=tmp_path) for a in args] + ["-o", str(out), "--quiet"])
    except SystemExit as e:             # argparse refuses out-of-range options itself
        code = e.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and message in err and len(err.splitlines()) == 1 and not out.exists()


def test_api_refuses_bad_arrays():
    with pytest.raises(ef.EventFieldError, match="T >= 2"):
        ef.events_from_frames(np.ones((1, 4, 4)), [0.0])
    with pytest.raises(ef.EventFieldError, match="finite and >= 0"):
        ef.events_from_frames(-np.ones((2, 4, 4)), [0.0, 1.0])
    with pytest.raises(ef.EventFieldError, match="3 values for 2 frames"):
        ef.events_from_frames(np.ones((2, 4, 4)), [0.0, 1.0, 2.0])


def test_progress_and_long_inputs_stream(tmp_path):
    """A generator-backed source is read one frame at a time: memory does not hold the whole input."""
    from mitsuba_eventfield.simulate.frame_sources import FrameSource
    seen = []

    def frames():
        for i in range(50):
            seen.append(i)
            yield i * 1e-3, np.full((8, 8), 0.1 + 0.01 * i, np.float32)
    src = FrameSource("generated", 8, 8, 50, frames, {"kind": "generator"})
    out = str(tmp_path / "g.h5")
    summary = ef.events_from_frames(src, output=out, progress=True, event_buffer_mb=1e-6)
    assert seen == list(range(50)) and summary.events == len(ef.read_events(out)) > 0
    assert os.listdir(tmp_path) == ["g.h5"]


def test_a_pixel_dict_may_name_its_preset(demo_small):
    """A pixel model given as a dict that names its preset (``PixelConfig.as_dict()``, a render's metadata) is
    taken as that preset and its values: the converter and a render make the events of ``preset=`` with the
    same values, and two different preset names are one line. (The readout cap is off: scaled to these tiny
    films, davis346's would pass almost nothing.)"""
    from mitsuba_eventfield.plugins.pixel_model import pixel_config
    values = {"shot_noise_hz": 50.0, "readout_cap": 0.0}
    described = pixel_config("davis346", **values).as_dict()
    assert described["preset"] == "davis346"
    stack, t, _ = _ramps(frames=12, duration=0.012)
    by_name = ef.events_from_frames(stack, t, preset="davis346", pixel=values)
    assert len(by_name) > 50 and ef.events_from_frames(stack, t, pixel=described).equals(by_name)
    assert not ef.events_from_frames(stack, t, pixel=values).equals(by_name)        # the ideal pixel + noise
    rendered = ef.render_events(demo_small, 0.004, steps=4, reuse=False, preset="davis346", pixel=values)
    assert len(rendered) > 50 and ef.render_events(demo_small, 0.004, steps=4, reuse=False,
                                                   pixel=described).equals(rendered)
    for call in (lambda: ef.events_from_frames(stack, t, preset="ideal", pixel=described),
                 lambda: ef.render_events(demo_small, 0.004, steps=4, preset="prophesee_gen4", pixel=described)):
        with pytest.raises(ef.ConfigError, match=r"^pixel model: pixel\['preset'\] = 'davis346' and preset = "):
            call()


def test_the_pixel_models_drops_and_noise_are_counted(tmp_path):
    """A conversion records what the pixel model dropped and added, as a render does (it recorded 0 for each):
    on one random-walk stack the readout cap's and the refractory period's drops plus the events kept are the
    ideal pixel's events exactly, and shot noise adds exactly the noise events it reports (also in a file)."""
    rng = np.random.default_rng(0)
    frames = np.exp(np.cumsum(rng.normal(0, 0.15, (80, 24, 32)), 0) + np.log(0.2)).astype(np.float32)
    times = np.arange(80) / 1000

    def counts(pixel):
        r = ef.events_from_frames(frames, times, pixel=pixel).meta["render"]
        return r["events"], r["dropped_readout"], r["dropped_refractory"], r["noise_events"], r["notes"]
    ideal = counts(None)[0]
    assert ideal > 10000
    kept, dropped, _, _, notes = counts({"readout_cap": 3e6, "readout_cap_native_pixels": 89960})
    assert dropped > 0.5 * ideal and kept + dropped == ideal
    assert any(f"readout cap dropped {dropped} of {ideal} events" in n for n in notes)
    kept, _, dropped, _, _ = counts({"refractory_s": 5e-4})
    assert dropped > 0 and kept + dropped == ideal
    kept, _, _, noise, _ = counts({"shot_noise_hz": 200.0})
    assert noise > 0.2 * ideal and kept == ideal + noise
    summary = ef.events_from_frames(frames, times, pixel={"refractory_s": 5e-4}, output=str(tmp_path / "r.h5"))
    assert ef.read_events(str(tmp_path / "r.h5")).meta["render"]["dropped_refractory"] == summary.dropped_refractory > 0
