"""Regenerate the gallery figures in docs/gallery/ from the bundled scenes (python docs/gallery/make_gallery.py).

One figure per application of the paper's section 6, each at its documented default size; each prints its
scores against the renderer's ground truth: the HDR light field (scenes/hdr_leds), slow-motion refocus
(scenes/falling), high-speed refocus (scenes/fan) and focus tracking (scenes/dart) with the galvo, and depth at
the scan rate (scenes/runner). Pass names to make only some: python docs/gallery/make_gallery.py highspeed
"""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))


def hdr_figure():
    from mitsuba_eventfield.apps import hdr
    r = hdr.compare(os.path.join(ROOT, "scenes", "hdr_leds", "hdr_leds.xml"), depth=1.45)
    print("[HDR light field]\n" + r.report())
    return hdr.figure(r, os.path.join(HERE, "hdr.png"))


def slomorf_figure():
    from mitsuba_eventfield.apps import slomorf
    r = slomorf.slomorf(slomorf.DEFAULT_SCENE)
    print("[SloMoRF]\n" + r.report())
    return slomorf.figure(r, os.path.join(HERE, "slomorf.png"))


def highspeed_figure():
    from mitsuba_eventfield.apps import highspeed
    from mitsuba_eventfield.apps.highspeed import FAN_DEFAULTS
    defines = dict(item.split("=") for item in FAN_DEFAULTS["define"])
    r = highspeed.refocus_planes(os.path.join(ROOT, "scenes", "fan", "fan.xml"), {"fan": 0.6, "wall": 1.5}, defines)
    print("[high-speed refocus, fan]\n" + r.report())
    return highspeed.planes_figure(r, os.path.join(HERE, "highspeed_fan.png"))


def track_figure():
    from mitsuba_eventfield.apps import highspeed
    r = highspeed.track_focus_depth(os.path.join(ROOT, "scenes", "dart", "galvo.xml"), (0.58, 0.44, 0.78, 0.56),
                                    0.6, 1.5, 1.6, background_depth=1.8)
    print("[focus tracking, dart]\n" + r.report())
    return highspeed.track_figure(r, os.path.join(HERE, "track_dart.png"))


def scanrate_figure():
    from mitsuba_eventfield.apps import scanrate
    r = scanrate.run(os.path.join(ROOT, "scenes", "runner", "runner.xml"))
    print("[depth at the scan rate, runner]\n" + r.report())
    return scanrate.figure(r, os.path.join(HERE, "scanrate_runner.png"))


FIGURES = {"hdr": hdr_figure, "slomorf": slomorf_figure, "highspeed": highspeed_figure, "track": track_figure,
           "scanrate": scanrate_figure}

if __name__ == "__main__":
    wanted = sys.argv[1:] or list(FIGURES)
    unknown = [w for w in wanted if w not in FIGURES]
    if unknown:
        sys.exit(f"unknown figure(s) {unknown}; choose from {', '.join(FIGURES)}")
    sys.exit(0 if all(FIGURES[w]() for w in wanted) else 1)
