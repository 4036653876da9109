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
