"""The step's radiance render as a Dr.Jit frozen function (simulate/frames.py, ``frozen_render``): the same events,
bit for bit, as rendering with ``mi.render`` every step, for every design and stepping the loop has (moving
sphere through a pinhole, moving mesh through the galvo, the kaleidoscope, a period-reusing static galvo scene,
a new seed per step, adaptive steps); and it is recorded a bounded number of times, then replayed."""
import os

import numpy as np
import pytest
from conftest import ROOT

import mitsuba_eventfield as ef
from mitsuba_eventfield.simulate import frames
from mitsuba_eventfield.simulate import render as render_module

SCENES = {
    "demo": ("demo/demo.xml", {"width": 40, "height": 30}, {}),
    "fan": ("fan/fan.xml", {"width": 40, "height": 30}, {}),
    "kaleidoscope": ("moving_grid/kaleidoscope.xml", {"views_px": 30}, {}),
    "galvo_static": ("galvo_static/galvo_static.xml", {"width": 40, "height": 30}, {"duration": 0.008}),
    "demo_new_seeds": ("demo/demo.xml", {"width": 40, "height": 30}, {"seed_mode": "independent"}),
    # textured area emitters: Dr.Jit refuses to record the nested virtual calls; the render falls back to tracing
    "cards_not_frozen": ("offaxis_cards/offaxis_cards.xml", {"width": 40, "height": 30}, {}),
    "demo_adaptive": ("demo/demo.xml", {"width": 40, "height": 30}, {"adaptive": "log-change", "max_step": 4e-4,
                                                                     "steps": None}),
    # the default steps: their noise probe renders the first frame and one with another seed through the
    # loop's frozen render (its two recordings), and the loop replays it from the first step on
    "demo_default_steps": ("demo/demo.xml", {"width": 40, "height": 30}, {"duration": 0.02, "steps": None}),
}


def _render(name, freeze: bool, monkeypatch, recordings: list):
    path, defines, kw = SCENES[name]
    monkeypatch.setenv(frames.FREEZE_ENV, "1" if freeze else "0")
    finish = render_module._Loop.finish

    def counting_finish(loop, *a, **k):
        frozen = loop.renderer.frozen
        recordings.append(frozen.n_recordings if frozen is not None else None)
        return finish(loop, *a, **k)
    monkeypatch.setattr(render_module._Loop, "finish", counting_finish)
    args = dict({"duration": 0.004, "steps": 40}, **kw)
    return ef.render_events(ef.load_scene(os.path.join(ROOT, "scenes", path), **defines), args.pop("duration"),
                            **args)


@pytest.mark.parametrize("name", list(SCENES))
def test_frozen_steps_give_the_same_events(name, monkeypatch):
    recordings = []
    frozen = _render(name, True, monkeypatch, recordings)
    plain = _render(name, False, monkeypatch, recordings)
    assert len(frozen) > 50, "a scene that fires nothing tests nothing"
    for column in "xytp":
        assert np.array_equal(getattr(frozen, column), getattr(plain, column)), column
    fell_back = [n for n in frozen.meta["render"]["notes"] if "could not be frozen" in n]
    if name == "cards_not_frozen":
        # Dr.Jit's refusal differs by backend: LLVM meets the nested virtual calls first; CUDA (H100, 2026-11-26)
        # an emitter's texture upload it cannot place ("Tried to record a memcpy_async operation, but the source
        # pointer ... is unknown"). Either way the render falls back to tracing, with the same events (above)
        import mitsuba as mi
        cause = "memcpy_async" if mi.variant().startswith("cuda") else "virtual function call"
        assert fell_back and cause in fell_back[0] and recordings[0] is None, fell_back
        return
    assert not fell_back
    # recorded twice (the first frame; then once more, as a freshly loaded scene's first render changes the layout
    # of some of its inputs), then replayed, whatever the stepping: the accuracy-limit frame with another seed and
    # the adaptive render's ~1600 frames replay. With the pixel state among the inputs (the integrator's
    # __dict__, before plugins/pixel_state.PixelVariables) its first commit made 3, adaptive stepping 5
    assert recordings[0] == 2 and recordings[1] is None


def test_no_cycle_collection_inside_a_frozen_call():
    """Python's cycle collector is paused while a frozen function records (and replays): a destructor it ran
    there aborted the whole process (docs/design.md, "Frozen frames"). The traced fallback runs with it on."""
    import gc

    import drjit as dr
    import mitsuba as mi

    from mitsuba_eventfield import backend
    seen = []

    def doubled(x):
        seen.append(gc.isenabled())
        return x * 2

    frozen = backend.FrozenOrTraced(doubled)
    assert gc.isenabled()
    out = frozen(mi.Float([1.0, 2.0]))
    assert seen == [False] and gc.isenabled() and out.numpy().tolist() == [2.0, 4.0]
    frozen.refused = "for the test"                                # the traced fallback
    frozen(dr.arange(mi.Float, 3))
    assert seen == [False, True] and gc.isenabled()


def test_an_interrupt_while_recording_stops_instead_of_falling_back():
    """A KeyboardInterrupt (Ctrl-C, or the CLI's SIGTERM) raised inside a recording reaches the caller. Dr.Jit
    hands it back wrapped in a RuntimeError, which FrozenOrTraced took for a refusal to freeze: it traced on, and
    an interrupted CLI render ran to its end (seen under pytest-xdist). The next call records again."""
    import mitsuba as mi

    from mitsuba_eventfield import backend
    calls = []

    def stopped_once(x):
        calls.append(1)
        if len(calls) == 1:
            raise KeyboardInterrupt("SIGINT")
        return x + 1

    frozen = backend.FrozenOrTraced(stopped_once)
    with pytest.raises(KeyboardInterrupt, match="SIGINT"):
        frozen(mi.Float([1.0, 2.0]))
    assert frozen.refused is None and len(calls) == 1              # not traced on after the interrupt
    assert frozen(mi.Float([1.0, 2.0])).numpy().tolist() == [2.0, 3.0] and frozen.refused is None


def test_only_the_main_thread_freezes(monkeypatch):
    """Off the main thread nothing is frozen (a frozen call's traversal of our Python plugins takes the GIL
    under Dr.Jit's lock, which deadlocked a Dask worker against its event-loop thread: plugins/frozen.py): a
    render on another thread traces its frames and its event passes, and its events equal the main thread's."""
    import threading
    from mitsuba_eventfield.plugins import frozen
    monkeypatch.setenv(frames.FREEZE_ENV, "1")
    path, defines, _ = SCENES["fan"]
    seen = {}

    def render(where):
        seen[where] = (frozen.freezing(), frames.frozen_render(None, 4) is None)
        timed = ef.load_scene(os.path.join(ROOT, "scenes", path), **defines)
        seen[where + " events"] = ef.render_events(timed, 0.004, steps=12)
        made = frozen.FrozenCache().made("k", lambda: (lambda: 1))
        seen[where + " cache"] = isinstance(made, frozen.FrozenOrTraced)
    render("main")
    worker = threading.Thread(target=render, args=("thread",))
    worker.start()
    worker.join()
    assert seen["main"] == (True, False) and seen["main cache"]
    assert seen["thread"] == (False, True) and not seen["thread cache"]
    assert len(seen["main events"]) > 1000 and seen["main events"].equals(seen["thread events"])
