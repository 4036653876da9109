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

    def failed_checks(self) -> list:
        """One line per self-check of the result that failed (the report marks it FAILED), which the command
        line repeats as a warning on stderr: a check in the middle of a report went unseen."""
        return []


def focus_check_failures(regions, where: str) -> list:
    """The failed entries of a focus check (``focus.refocus``'s regions: each depth's region sharpest where it
    is refocused?), one line each, for ``AppResult.failed_checks``."""
    return [f"{where}: focus check failed at {r['depth']:g}: " + (
        f"its region ({r['pixels']} px) is sharper refocused at another depth" if r["pixels"] else
        "no pixel of the scene lies at that depth") for r in regions if not r["sharpest_at_own_depth"]]


def time_split_line(split: dict, indent: str = "") -> str:
    """The report's line of where an application's time went (``meta["time_split_s"]``: stage -> seconds), in
    one form for every application: "time split: render events 0.8 s, light field 2.2 s"."""
    return indent + "time split: " + ", ".join(f"{k.replace('_', ' ')} {v:.1f} s" for k, v in split.items())
