"""A render's steps committed in batches (``simulate/step_batch.py``) give the events of committing each step:
bit for bit, on a moving scene under a periodic scan (batches end at every scan period: the timestamp base
changes there), on steps placed by the image motion, through the accuracy-limit estimate, with every effect of
the pixel model (random draws, refractory period, low-pass on the render's radiance, readout cap); and the
renders whose steps are not known in advance or whose events are kept per step are not batched."""
import pytest

import mitsuba_eventfield as ef
from mitsuba_eventfield.plugins import event_batch

from conftest import DEMO, ROOT

FAN = f"{ROOT}/scenes/fan/fan.xml"


@pytest.fixture
def batches(monkeypatch):
    """Every batch committed: its number of steps."""
    sizes, real = [], event_batch.commit_frames

    def counted(integ, frames, times, base_us=0, intensity=False):
        sizes.append(len(times) - 1)
        return real(integ, frames, times, base_us, intensity)
    monkeypatch.setattr(event_batch, "commit_frames", counted)
    return sizes


def _batches_of(monkeypatch, frames, n_pix):
    """At most ``frames`` steps a batch, on either backend."""
    for backend in ("llvm", "cuda"):
        monkeypatch.setitem(event_batch.LANE_STEPS, backend, frames * n_pix)
    monkeypatch.setattr(event_batch, "MIN_FRAMES_PER_KERNEL", 2)


def _pair(timed, **kw):
    batched = ef.render_events(timed, **kw)
    with event_batch.one_frame_a_step():
        single = ef.render_events(timed, **kw)
    return batched, single


def _same(a, b):
    """Same events and the same summary but for how long things took."""
    def steady(render):
        timings = ("events_s", "write_s", "render_s", "motion_s", "wall_s", "writer_busy_s", "writer_wait_s",
                   "writer_tail_s", "writer_copy_s", "plan_s")
        return {k: steady(v) if isinstance(v, dict) else v for k, v in render.items() if k not in timings}
    return a.equals(b) and steady(a.meta["render"]) == steady(b.meta["render"])


def test_fan_batches_end_at_every_scan_period_and_equal_single_steps(batches, monkeypatch):
    """The fan (250 Hz circle, spinning blades): 3 periods of 12 steps on the phase grid, at most 5 steps a
    batch: batches of 5, 5, 2 in each period."""
    _batches_of(monkeypatch, 5, 48 * 36)
    timed = ef.load_scene(FAN, width=48, height=36)
    batched, single = _pair(timed, duration=0.012, steps=36, reuse=False)
    assert batches == [5, 5, 2] * 3
    assert len(batched) > 10_000 and _same(batched, single)


def test_steps_placed_by_the_image_motion_batch_alike(batches):
    """The demo's default steps (no scan: placed by the cards' motion, of unequal lengths); the accuracy-limit
    estimate, which reads the first two steps' frames, comes out the same."""
    timed = ef.load_scene(DEMO, width=48, height=36)
    batched, single = _pair(timed, duration=0.05)
    assert batched.meta["stepping"]["mode"] == "adaptive" and batches and max(batches) > 1
    assert batched.meta["render"]["timing_limit"] is not None
    assert len(batched) > 1000 and _same(batched, single)


@pytest.mark.parametrize("model", [
    dict(pixel={"cutoff_hz": 300.0}),                      # the low-pass takes the render's linear radiance
    dict(pixel={"threshold_jitter": 0.02, "seed": 3}),     # random draws every step
    # every effect: mismatch, jitter, refractory, leak, shot noise, low-pass, clock and readout cap (lowered
    # to 1.5 Mev/s at the native 346x260, 20 kev/s at this film, so that it drops events)
    dict(preset="davis346", pixel={"readout_cap": 1.5e6}),
], ids=["low-pass", "jitter", "davis346"])
def test_every_pixel_model_batches_alike(batches, monkeypatch, model):
    """The demo's moving cards through 24 uniform steps, batches of at most 5 (so that the realistic pixel's
    readout cap meets batches whose bins span several steps; the film's cap is scaled to its pixels). Under a
    low-pass too every step is held: the accuracy limit blends the first two held frames as the batch will, and
    its estimate in the summary (compared by ``_same``) equals that of the render committing a step at a time
    (until 2026-11-27 those two steps were committed singly for it: batches of 5, 5, 5, 5, 2)."""
    _batches_of(monkeypatch, 5, 40 * 30)
    timed = ef.load_scene(DEMO, width=40, height=30)
    batched, single = _pair(timed, duration=0.04, steps=24, **model)
    assert batches == [5] * 4 + [4]
    r = batched.meta["render"]
    assert len(batched) > (500 if "preset" in model else 1000) and _same(batched, single)
    if "preset" in model:
        assert r["dropped_refractory"] > 100 and r["dropped_readout"] > 100 and r["noise_events"] > 0, r
        # the note counts the events still on the device when the render ends (it once counted only those
        # already on the host: 60 of 705 here)
        assert f"dropped {r['dropped_readout']} of {len(batched) + r['dropped_readout']} events" in str(r["notes"])


def test_steps_sized_from_the_last_change_commit_each_step(batches):
    timed = ef.load_scene(DEMO, width=32, height=24)
    ev = ef.render_events(timed, 0.01, adaptive="log-change", min_step=2e-4)
    assert batches == [] and len(ev) > 0


def test_a_periodic_views_kept_events_are_not_batched(batches):
    """A static scene under a scan with reuse: the first periods' events are kept per step for copying."""
    timed = ef.load_scene(f"{ROOT}/scenes/galvo_static/galvo_static.xml", width=48, height=36)
    ev = ef.render_events(timed, 0.016, steps=128)          # 4 periods: the state repeats after the second
    assert batches == [] and ev.meta["render"]["copied_steps"] > 0


def test_static_pixels_rendered_once_a_period_batch_alike(batches, monkeypatch):
    """The fan with the static-pixel split (the pixels no blade can reach rendered once a scan period: the
    frames the batch holds are composed from a cache and a partial render)."""
    from mitsuba_eventfield.simulate import static_pixels
    monkeypatch.setattr(static_pixels, "MIN_PERIODS", 2)
    timed = ef.load_scene(FAN, width=48, height=36)
    batched, single = _pair(timed, duration=0.012, steps=36)
    assert batched.meta["render"]["static_pixels"] is not None and batches
    assert len(batched) > 10_000 and _same(batched, single)
