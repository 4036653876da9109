"""Regenerate the gallery figures in docs/gallery/ from the bundled scenes (python docs/gallery/make_gallery.py).

One figure per application of the paper's section 6; each prints its scores against the renderer's ground
truth. So far: the HDR light field (scenes/hdr_leds) and slow-motion refocus (scenes/falling).
"""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))


def hdr_figure():
    from mitsuba_eventfield import hdr
    r = hdr.compare(os.path.join(ROOT, "scenes", "hdr_leds", "hdr_leds.xml"), depth=1.45)
    print("[HDR light field]\n" + r.report())
    return hdr.figure(r, os.path.join(HERE, "hdr.png"))


def slomorf_figure():
    from mitsuba_eventfield import slomorf
    r = slomorf.slomorf(slomorf.DEFAULT_SCENE)
    print("[SloMoRF]\n" + r.report())
    return slomorf.figure(r, os.path.join(HERE, "slomorf.png"))


if __name__ == "__main__":
    sys.exit(0 if hdr_figure() and slomorf_figure() else 1)
