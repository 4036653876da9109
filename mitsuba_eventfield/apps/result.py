"""What every application returns: one result type, so the command line, the gallery and a user's script
handle them alike. ``report()`` is the text summary, ``write(out_dir)`` writes every output (images, EXRs,
metrics.json, the figure) and returns their paths, ``figure(path)`` draws the summary figure alone."""
from __future__ import annotations


class AppResult:
    """Base of the applications' result dataclasses (``demo.DemoResult``, ``highspeed.PlaneRefocus``, ``highspeed.FocusTrack``,
    ``scanrate.ScanRateDepth``, ``slomorf.SloMoRFResult``, ``hdr.HDRComparison``)."""

    def report(self) -> str:
        raise NotImplementedError

    def write(self, out_dir: str) -> dict:
        raise NotImplementedError

    def figure(self, path: str) -> str:
        raise NotImplementedError


def time_split_line(split: dict, indent: str = "") -> str:
    """The report's line of where an application's time went (``meta["time_split_s"]``: stage -> seconds), in
    one form for every application: "time split: render events 0.8 s, light field 2.2 s"."""
    return indent + "time split: " + ", ".join(f"{k.replace('_', ' ')} {v:.1f} s" for k, v in split.items())
