"""What the fan needs (issue 18, part 4): event count and per-pixel count error at 4 spp for 320 to 20 steps
per 4 ms scan period, rendering every pixel at every step or the static pixels once a period
(``simulate/static_pixels.py``), against a reference converged in samples and in steps, and the wall time per
simulated second of each, in one run.

Scene: scenes/fan (250 Hz circle scan, 480 rpm fan), 346x260 by default. Accuracy window: the second scan
period (4-8 ms), where the split reuses the first period's static pixels. Reference: ``REF_SPP`` spp (128) at
320 steps per period over that window; its own count moves by well under 1 % when its steps are halved
(printed), so it is converged in time, and 128 against 256 spp moved it by 0.6 % at 173x130. Candidates, all
through the event pixel (``events_from_frames``) from the window's first instant: "every pixel": the 4-spp
frames of the same instants, every 2nd, 4th, ... (the frames a 4-spp render makes: fixed seed); "static
reused": the frames the split makes at those instants (its plan made for the speed runs' duration, its first
period rendered to fill the cache). Per-pixel error: sum over pixels of |count - reference count| / reference
events. Speed: ``render_events`` over ``SPEED_PERIODS`` periods per setting and mode after a warm-up render,
wall seconds / simulated seconds (render, events, motion, bookkeeping and, for the split, its masks: a fixed
cost, also given alone and taken out in the steady-state column).

Writes benchmarks/results/fan_steps.json and .md. Usage: ./run bench fan_steps [--quick]
(--quick: 96x72, 32 spp reference: a check of the script, not a result)
"""
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _report import write_results  # noqa: E402

FAN = os.path.join(os.path.dirname(HERE), "scenes", "fan", "fan.xml")
PERIOD = 0.004
FINEST = 320                  # steps per period of the reference and of the finest candidate
STRIDES = (1, 2, 4, 8, 10, 16)    # candidates: 320, 160, 80, 40, 32, 20 steps per period
SPEED_STEPS = (80, 40, 32, 20)    # steps per period timed
SPEED_PERIODS = 25            # the speed runs simulate this many periods (the split forced on there: its default
                              # waits for static_pixels.MIN_PERIODS = 40, the long run's 50 periods use the default)
SPP = 4
TARGET_S_PER_SIM_S = 200.0
MODES = {"every pixel": False, "static reused": True}
LONG_PERIODS = 50             # the long run: 0.2 s
DART = os.path.join(os.path.dirname(HERE), "scenes", "dart", "galvo.xml")


def _counts(ev, width, height):
    return np.bincount(ev.y.astype(np.int64) * width + ev.x, minlength=width * height)


def _split_frames(timed, steps_per_period):
    """The linear frames the static-pixel split makes at the instants of the second period, and its plan."""
    from mitsuba_eventfield.simulate import static_pixels
    from mitsuba_eventfield.simulate.pixel_setup import event_integrator
    from mitsuba_eventfield.simulate.stepping import stepping
    steps = steps_per_period * SPEED_PERIODS
    st = stepping(timed, PERIOD * SPEED_PERIODS, steps, False, 0.5, None, None, SPP, 0, "fixed", 0.0, 1.0)
    integ = event_integrator(timed, None, None, None, None)
    notes = []
    plan = static_pixels.plan(timed, st, integ, notes)
    if plan is None:                 # declined (the note says why): no "static reused" row
        print(f"steps per period {steps_per_period}: {'; '.join(notes) or 'split declined'}")
        return None, None
    frames = []
    for k in range(2 * steps_per_period + 1):
        timed.set_time(k * PERIOD / steps_per_period)
        frames.append(plan.render(timed, integ.inner, 0, k).numpy()[..., 0])
    return np.stack(frames[steps_per_period:]), plan


def accuracy(width, height, ref_spp):
    import mitsuba_eventfield as ef
    timed = ef.load_scene(FAN, width=width, height=height)
    times = PERIOD + np.linspace(0.0, PERIOD, FINEST + 1)          # the second period
    ref_frames = ef.render_frames(timed, times, spp=ref_spp, log=False)
    frames = ef.render_frames(timed, times, spp=SPP, log=False)
    ref = ef.events_from_frames(ref_frames, times, threshold=0.2)
    ref_counts = _counts(ref, width, height)
    ref_half = len(ef.events_from_frames(ref_frames[::2], times[::2], threshold=0.2))
    rows = []
    for stride in STRIDES:
        k = FINEST // stride
        split, plan = _split_frames(timed, k)
        for mode, cand in (("every pixel", frames[::stride]), ("static reused", split)):
            if cand is None:
                continue
            ev = ef.events_from_frames(cand, times[::stride], threshold=0.2)
            rows.append({"steps_per_period": k, "mode": mode, "events": len(ev),
                         "count_error_pct": 100.0 * (len(ev) / len(ref) - 1),
                         "per_pixel_error": float(np.abs(_counts(ev, width, height) - ref_counts).sum() / len(ref)),
                         "dynamic_share": plan.dynamic_share if mode == "static reused" else 1.0})
    return {"reference_events": len(ref), "reference_half_steps_change_pct": 100.0 * (ref_half / len(ref) - 1),
            "rows": rows}


def speed(width, height):
    import mitsuba_eventfield as ef
    timed = ef.load_scene(FAN, width=width, height=height)
    ef.render_events(timed, PERIOD / 4, steps=10)                 # compile and record the frozen frame
    out = {}
    sim = PERIOD * SPEED_PERIODS
    for per_period in SPEED_STEPS:
        for mode, reuse in MODES.items():
            steps = per_period * SPEED_PERIODS
            t0 = time.perf_counter()
            ev = ef.render_events(timed, sim, steps=steps, reuse=reuse)
            wall = time.perf_counter() - t0
            r = ev.meta["render"]
            plan_s = (r["static_pixels"] or {}).get("plan_s", 0.0)
            out[(per_period, mode)] = {"wall_s": wall, "s_per_simulated_s": wall / sim, "plan_s": plan_s,
                                       "steady_s_per_simulated_s": (wall - plan_s) / sim,
                                       "render_ms_per_step": 1e3 * r["render_s"] / steps,
                                       "static_pixels": r["static_pixels"], "timing_limit": r.get("timing_limit")}
    return out


def long_run(width, height, per_period=32, periods=LONG_PERIODS):
    """Both modes over a longer render: the split's fixed cost (its masks) amortised as in real use."""
    import mitsuba_eventfield as ef
    timed = ef.load_scene(FAN, width=width, height=height)
    out = {}
    for mode, reuse in MODES.items():
        t0 = time.perf_counter()
        ev = ef.render_events(timed, PERIOD * periods, steps=per_period * periods, reuse=reuse)
        wall = time.perf_counter() - t0
        out[mode] = {"events": len(ev), "s_per_simulated_s": wall / (PERIOD * periods),
                     "static_pixels": ev.meta["render"]["static_pixels"]}
    return {"steps_per_period": per_period, "periods": periods, "modes": out}


def small_object(width, height):
    """The split where a moving object is small: the dart (scenes/dart/galvo.xml, 20 m/s, hard shadow). Its
    flight lasts six periods, fewer than the split waits for (its masks do not pay there): forced on, to show
    the per-step gain and the check."""
    import mitsuba_eventfield as ef
    from mitsuba_eventfield.simulate import static_pixels
    static_pixels.MIN_PERIODS = 2
    timed = ef.load_scene(DART, width=width, height=height)
    duration = timed.motion.duration
    steps = int(round(duration / PERIOD)) * 40
    ef.render_events(timed, duration / 6, steps=steps // 6, reuse=False)
    out = {}
    for mode, reuse in MODES.items():
        t0 = time.perf_counter()
        ev = ef.render_events(timed, duration, steps=steps, reuse=reuse)
        r = ev.meta["render"]
        out[mode] = {"events": len(ev), "wall_s": time.perf_counter() - t0,
                     "render_ms_per_step": 1e3 * r["render_s"] / steps, "static_pixels": r["static_pixels"]}
    return {"duration_s": duration, "steps": steps, "modes": out}


def main(quick=False):
    import mitsuba_eventfield as ef
    ef.set_variant(os.environ.get("EVENTFIELD_VARIANT") or None)
    width, height, ref_spp = (96, 72, 32) if quick else (346, 260, 128)
    from mitsuba_eventfield.simulate import static_pixels
    default_min_periods = static_pixels.MIN_PERIODS
    static_pixels.MIN_PERIODS = min(default_min_periods, SPEED_PERIODS)     # the 25-period rows: forced on
    acc = accuracy(width, height, ref_spp)
    spd = speed(width, height)
    static_pixels.MIN_PERIODS = default_min_periods if not quick else 2
    long = long_run(width, height, periods=5 if quick else LONG_PERIODS)
    dart = small_object(width, height)
    for row in acc["rows"]:
        s = spd.get((row["steps_per_period"], row["mode"]))
        row["s_per_simulated_s"] = s["s_per_simulated_s"] if s else None
        row["steady_s_per_simulated_s"] = s["steady_s_per_simulated_s"] if s else None
    ok = [r for r in acc["rows"] if abs(r["count_error_pct"]) <= 5 and r["s_per_simulated_s"]
          and r["s_per_simulated_s"] <= TARGET_S_PER_SIM_S]
    import platform
    res = {"film": f"{width}x{height}", "spp": SPP, "reference_spp": ref_spp, "cpu": platform.processor() or "CPU",
           "threads": os.cpu_count(), "accuracy": acc, "long_run": long, "dart": dart,
           "speed": {f"{k[0]} {k[1]}": v for k, v in spd.items()},
           "targets": {f"a setting within 5 % of the reference at <= {TARGET_S_PER_SIM_S:.0f} s per simulated "
                       f"second": bool(ok)}}
    md = [f"# What the fan needs: steps per scan period at {SPP} spp ({width}x{height}; accuracy over the second "
          f"4 ms period, speed over {SPEED_PERIODS})", "",
          f"Reference: {ref_spp} spp at {FINEST} steps per period, {acc['reference_events']} events (at half its "
          f"steps: {acc['reference_half_steps_change_pct']:+.2f} %). CPU, {os.cpu_count()} threads, one run. "
          "\"static reused\": the pixels no moving object can change rendered once per scan period "
          f"(simulate/static_pixels.py; forced on for these {SPEED_PERIODS}-period rows, by default it waits for "
          f"{default_min_periods}); \"s per simulated s\" includes its masks, \"steady\" leaves them out "
          "(a fixed cost per render, given in the last column).", "",
          "| steps per period | mode | events | count vs reference | per-pixel error | s per simulated s | steady | "
          "render ms per step | masks s | timing limit |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    for row in acc["rows"]:
        s = spd.get((row["steps_per_period"], row["mode"]), {})
        lim = s.get("timing_limit") or {}
        limit = f"{lim.get('limit', '-')}: noise {lim.get('noise_us', 0):.0f} us, step {lim.get('steps_us', 0):.1f} us" \
            if lim else "-"
        cell = (lambda k, f: f.format(s[k]) if s else "-")
        md.append(f"| {row['steps_per_period']} | {row['mode']} | {row['events']} | {row['count_error_pct']:+.1f} % | "
                  f"{row['per_pixel_error']:.3f} | {cell('s_per_simulated_s', '{:.0f}')} | "
                  f"{cell('steady_s_per_simulated_s', '{:.0f}')} | {cell('render_ms_per_step', '{:.1f}')} | "
                  f"{cell('plan_s', '{:.2f}')} | {limit} |")
    split = next((r["dynamic_share"] for r in acc["rows"] if r["mode"] == "static reused"), None)
    md += ["", f"The split renders {100 * split:.0f} % of the pixels at every step (the fan's blades sweep most of "
           "the frame; the dynamic mask is bounded by the blades' poses under the scan, the shadows are probed, and "
           "the render checks the rest). At 4 spp every step adds Monte-Carlo noise events (the frozen sampler's "
           "noise changes as the image moves under it), so beyond the steps the motion needs, more steps raise "
           "the count and the per-pixel error instead of lowering them; the timing error is set by that noise, "
           "not by the step.", ""]
    lm = long["modes"]
    md += [f"Over {long['periods']} periods ({long['periods'] * PERIOD:g} s) at {long['steps_per_period']} steps per "
           f"period: every pixel {lm['every pixel']['s_per_simulated_s']:.0f} s per simulated second "
           f"({lm['every pixel']['events']} events), static reused "
           f"{lm['static reused']['s_per_simulated_s']:.0f} s, masks included "
           f"({lm['static reused']['events']} events).",
           ""]
    dm = dart["modes"]
    sp = dm["static reused"]["static_pixels"] or {}
    md += [f"A small moving object (scenes/dart/galvo.xml, {width}x{height}, {dart['duration_s'] * 1e3:g} ms, "
           f"{dart['steps']} steps; the dart and its hard shadow; the split forced on for these six periods): "
           "it renders "
           f"{100 * sp.get('dynamic_share', 1):.0f} % of the pixels at every step, "
           f"{dm['static reused']['render_ms_per_step']:.2f} against {dm['every pixel']['render_ms_per_step']:.2f} ms "
           f"of render a step, wall {dm['static reused']['wall_s']:.1f} against {dm['every pixel']['wall_s']:.1f} s "
           f"(masks {sp.get('plan_s', 0):.2f} s), events {dm['static reused']['events']} against "
           f"{dm['every pixel']['events']}; its check: largest log change {sp.get('check_max_log_change')}, "
           f"share beyond C/2 {sp.get('check_changed_share')}.", ""]
    write_results("fan_steps", res, md)


if __name__ == "__main__":
    main(quick="--quick" in sys.argv)
