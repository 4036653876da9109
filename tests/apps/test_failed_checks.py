"""A self-check that fails is said on stderr, where it is seen, not only as FAILED in the middle of a report
(``AppResult.failed_checks``; slomorf's and the HDR light field's focus checks)."""
from mitsuba_eventfield.apps.result import AppResult, focus_check_failures
from mitsuba_eventfield.cli.apps import _application

REGIONS = [{"depth": 0.55, "pixels": 310, "sharpest_at_own_depth": True},
           {"depth": 0.8, "pixels": 120, "sharpest_at_own_depth": False},
           {"depth": 1.4, "pixels": 0, "sharpest_at_own_depth": False}]


def test_each_failed_depth_is_one_line():
    assert focus_check_failures(REGIONS, "slomorf") == [
        "slomorf: focus check failed at 0.8: its region (120 px) is sharper refocused at another depth",
        "slomorf: focus check failed at 1.4: no pixel of the scene lies at that depth"]
    assert focus_check_failures(REGIONS[:1], "slomorf") == []


class _Result(AppResult):
    def __init__(self, failed):
        self.failed = failed

    def report(self):
        return "focus check: 0.55: ok, 0.8: FAILED"

    def write(self, out_dir):
        return {}

    def failed_checks(self):
        return focus_check_failures(self.failed, "slomorf")


def test_the_command_says_a_failed_check_on_stderr(capsys):
    assert _application(lambda: _Result(REGIONS), "out", lambda p: "nothing") == 0     # its outputs are written
    out, err = capsys.readouterr()
    assert "FAILED" in out and err.splitlines() == [
        "eventfield: warning: slomorf: focus check failed at 0.8: its region (120 px) is sharper refocused at "
        "another depth", "eventfield: warning: slomorf: focus check failed at 1.4: no pixel of the scene lies at "
        "that depth"]
    _application(lambda: _Result(REGIONS[:1]), "out", lambda p: "nothing")
    assert capsys.readouterr().err == ""
