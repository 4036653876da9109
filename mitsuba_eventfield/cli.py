"""Command line: a thin layer over the Python API. Errors print as one line and exit with status 2."""
from __future__ import annotations

import argparse
import json
import sys


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="eventfield", description="Render and inspect event fields.")
    sub = ap.add_subparsers(dest="command", required=True)

    r = sub.add_parser("render", help="render the event stream of a Mitsuba scene")
    r.add_argument("scene", help="Mitsuba scene XML (motion from <scene>.motion.toml if present)")
    r.add_argument("-o", "--output", required=True, help="event file: .h5 (DSEC layout, streamed), .npz, .txt, .aedat4")
    r.add_argument("--motion", help="motion TOML (default: <scene>.motion.toml if it exists)")
    r.add_argument("--no-motion", action="store_true", help="ignore any motion file (static scene)")
    r.add_argument("--duration", type=float, help="simulated seconds (default: `duration` of the motion file)")
    g = r.add_mutually_exclusive_group()
    g.add_argument("--steps", type=int, help="uniform time steps over the duration (default 100)")
    g.add_argument("--adaptive", action="store_true", help="adaptive steps bounded by --max-log-change")
    r.add_argument("--max-log-change", type=float, default=0.5,
                   help="adaptive: largest per-pixel log change per step, as a fraction of C (default 0.5)")
    r.add_argument("--min-step", type=float, help="adaptive: shortest step in seconds (default 1e-6)")
    r.add_argument("--max-step", type=float, help="adaptive: longest step in seconds (default duration/20)")
    r.add_argument("--spp", type=int, default=4, help="samples per pixel per step (default 4)")
    r.add_argument("--seed", type=int, default=0, help="sampler seed (default 0)")
    r.add_argument("--independent-seeds", action="store_true",
                   help="new seed every step (Monte-Carlo noise then fires events; for comparisons only)")
    r.add_argument("--threshold", type=float, help="contrast threshold C for ON and OFF (default: scene's or 0.2)")
    r.add_argument("--threshold-on", type=float, help="ON threshold (overrides --threshold)")
    r.add_argument("--threshold-off", type=float, help="OFF threshold (overrides --threshold)")
    r.add_argument("--linlog-threshold", type=float, help="radiance below which the response is linear (1e-3)")
    r.add_argument("--variant", help="Mitsuba variant or backend: cuda, llvm, llvm_ad_mono, ... (default: auto)")
    r.add_argument("--color", action="store_true", help="render in colour (rgb variant); events use luminance")
    r.add_argument("-D", "--define", action="append", default=[], metavar="NAME=VALUE",
                   help="value of an XML <default name=...> parameter, e.g. -D width=64 (repeatable)")
    r.add_argument("--preview", help="also write an event-frame PNG of the last --preview-window ms")
    r.add_argument("--preview-window", type=float, default=10.0, help="preview window in ms (default 10)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")

    i = sub.add_parser("info", help="resolution, duration, counts and metadata of an event file")
    i.add_argument("file")
    i.add_argument("--json", action="store_true", help="print everything as JSON")

    p = sub.add_parser("preview", help="event frame PNG (ON red, OFF blue) over a time window")
    p.add_argument("file")
    p.add_argument("-o", "--output", required=True, help="PNG path")
    p.add_argument("--t0", type=float, help="window start, ms (default: first event)")
    p.add_argument("--t1", type=float, help="window end, ms (default: last event)")
    p.add_argument("--scale", type=int, default=1, help="integer upscaling of the image")
    return ap


def _render(a) -> int:
    import os

    import mitsuba_eventfield as ef
    from .atomic import check_writable
    check_writable(a.output, "event file")          # fail before the (slow) Mitsuba import and render
    if a.preview:
        check_writable(a.preview, "preview")
    ef.set_variant(a.variant, a.color)
    motion = None if a.no_motion else (a.motion or "auto")
    defines = {}
    for item in a.define:
        name, eq, value = item.partition("=")
        if not eq or not name:
            raise ef.EventFieldError(f"-D {item!r}: expected NAME=VALUE")
        defines[name] = value
    scene = ef.load_scene(a.scene, motion=motion, **defines)
    fmt_ext = os.path.splitext(a.output)[1].lower()
    summary = ef.render_events(
        scene, a.duration, steps=a.steps, adaptive=a.adaptive, max_log_change=a.max_log_change,
        min_step=a.min_step, max_step=a.max_step, spp=a.spp, seed=a.seed,
        seed_mode="independent" if a.independent_seeds else "fixed", threshold=a.threshold,
        threshold_on=a.threshold_on, threshold_off=a.threshold_off, linlog_threshold=a.linlog_threshold,
        output=a.output, progress=not a.quiet)
    print(summary.format())
    if a.preview:
        ev = ef.read_events(a.output) if fmt_ext != ".txt" else None
        if ev is not None:
            end = int(ev.meta.get("t_start_us", 0)) + ev.duration_us
            t0 = max(int(ev.meta.get("t_start_us", 0)), end - int(round(a.preview_window * 1e3)))
            ef.write_preview(a.preview, ev, t0, end + 1, scale=2 if max(ev.width, ev.height) < 400 else 1)
            print(f"wrote {os.path.abspath(a.preview)} (events of {(end - t0) / 1e3:g} ms up to the end)")
    return 0


def _info(a) -> int:
    import mitsuba_eventfield as ef
    ev = ef.read_events(a.file)
    s = ev.summary()
    if a.json:
        print(json.dumps({"summary": s, "meta": ev.meta}, indent=2, default=str))
        return 0
    m = ev.meta
    print(f"{a.file}: {s['width']}x{s['height']}, {s['events']} events ({s['on']} ON, {s['off']} OFF), "
          f"duration {s['duration_s'] * 1e3:.3f} ms, {s['rate_ev_per_s']:.4g} ev/s")
    if len(ev):
        print(f"timestamps {ev.t[0]} .. {ev.t[-1]} us")
    for key in ("optics", "pixel_model", "spp", "seed", "seed_mode", "stepping", "variant", "package_version"):
        if key in m:
            print(f"  {key}: {json.dumps(m[key], default=str)}")
    if "scene" in m:
        print(f"  scene: {m['scene'].get('scene_path')}")
    return 0


def _preview(a) -> int:
    import mitsuba_eventfield as ef
    from .atomic import check_writable
    check_writable(a.output, "preview")
    ev = ef.read_events(a.file)
    t0 = None if a.t0 is None else int(round(a.t0 * 1e3))
    t1 = None if a.t1 is None else int(round(a.t1 * 1e3))
    ef.write_preview(a.output, ev, t0, t1, scale=a.scale)
    win = ev.time_window(t0, t1)
    print(f"wrote {a.output}: {len(win)} events in the window")
    return 0


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    from .errors import EventFieldError
    try:
        return {"render": _render, "info": _info, "preview": _preview}[args.command](args)
    except EventFieldError as e:
        print(f"eventfield: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("eventfield: interrupted (no partial output kept)", file=sys.stderr)
        return 130
    except BrokenPipeError:          # e.g. `eventfield info f.h5 | head`: the reader left; not an error of ours
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    sys.exit(main())
