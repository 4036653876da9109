"""``eventfield paper`` keeps the results that ran when one fails, as its refusal says (a review, 2026-11-28:
the output folder's failure path, which puts a failed run's folder back, removed them too)."""
import os

from mitsuba_eventfield.apps import paper
from mitsuba_eventfield.atomic import write_json
from mitsuba_eventfield.cli.main import main
from mitsuba_eventfield.errors import EventFieldError


class _Written:
    def write(self, out_dir):
        os.makedirs(out_dir, exist_ok=True)
        return {"metrics": write_json(os.path.join(out_dir, "metrics.json"), {"paper": []}), "figure": None}


def _fails(quick):
    raise EventFieldError("this result failed")


def test_a_failed_result_keeps_the_others_outputs(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(paper, "ENTRIES", [paper.Entry("good", lambda q: _Written(), lambda r: []),
                                           paper.Entry("bad", _fails, lambda r: [])])
    out = tmp_path / "paper_out"
    code = main(["paper", "-o", str(out), "--doc", str(tmp_path / "doc" / "paper.md")])
    err = capsys.readouterr().err
    assert code == 2 and "1 result(s) failed" in err and f"their outputs are in {out}" in err
    assert (out / "good" / "metrics.json").is_file() and not (tmp_path / "doc" / "paper.md").exists()
