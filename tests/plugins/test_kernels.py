"""Motion updates and event generation reuse compiled kernels: no recompilation between time steps."""
import drjit as dr
from conftest import steady_state_kernels

import mitsuba_eventfield as ef


def _misses(history):
    """Kernels not found in this process's in-memory cache. A disk-cache load (cache_disk) counts as a miss:
    it means the kernel was new to this process, only compiled in an earlier one."""
    jit = [k for k in history if k.get("type") == dr.KernelType.JIT]
    return jit, [k for k in jit if not k.get("cache_hit") or k.get("cache_disk")]


def _steady_render(timed, steps=12):
    """(events, steady-state JIT kernels, those compiled late) of a 12-step render after a warm-up render
    that compiles every kernel once, with Dr.Jit's kernel history on. The warm-up is the same render at other
    instants: the same step batches and chunk spans (a batch's time sort takes one kernel variant per bit
    count of its span: a shorter warm-up left the measured render's last two-pass sort to compile late, and
    the test passed only after another test had compiled it), while a time baked into a kernel as a literal
    would still compile anew at every step of the measured render."""
    ef.render_events(timed, 0.001 * steps, steps=steps, t_start=0.05)
    dr.kernel_history()                                     # clear
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        ev = ef.render_events(timed, 0.001 * steps, steps=steps)
        history = dr.kernel_history()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    return (ev, *steady_state_kernels(history, steps))


def test_no_recompilation_in_steady_state(demo_small):
    """After the first steps, every kernel comes from the in-memory cache. (Within the first steps Dr.Jit can
    meet a variant of a kernel keyed on a buffer's runtime memory alignment, an unaligned load: once per
    process, not per step.)"""
    ev, steady, late_misses = _steady_render(demo_small)
    assert len(ev) > 0
    assert len(steady) >= 8                                 # kernels did run (the check is not vacuous)
    assert late_misses == []


def test_kernel_history_sees_a_real_recompilation(demo_small):
    # the detector works: a new literal in an expression is compiled afresh
    dr.kernel_history()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        import random

        import mitsuba as mi
        x = dr.arange(mi.Float, 1000)
        dr.eval(x * (1.0 + random.random()))   # a literal never seen before, not even in the disk cache
        _, misses = _misses(dr.kernel_history())
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert misses


def test_no_recompilation_with_moving_instances(monkeypatch):
    """The same with the demo's moving shapes loaded as instances (CUDA's default, forced here): an instance's
    new ``to_world`` each step, built from host scalars, compiles nothing new once the steps run."""
    from conftest import DEMO

    from mitsuba_eventfield.scene import instancing
    monkeypatch.setenv(instancing.ENV, "1")
    timed = ef.load_scene(DEMO, width=48, height=36)
    assert timed.instanced == ["ball", "cube"]
    ev, steady, late_misses = _steady_render(timed)
    assert len(ev) > 0 and len(steady) >= 8 and late_misses == []
