"""``eventfield paper`` (issue 17): the paper side by side. Every number in the document comes from the run of
the command its row names: rerunning that command reproduces the numbers."""
import json
import os
import re
import shlex

from mitsuba_eventfield.apps import paper
from mitsuba_eventfield.cli.main import main as cli


def test_every_paper_figure_has_a_row_and_numbers_come_from_the_named_command(tmp_path, capsys):
    doc = tmp_path / "docs" / "paper.md"
    rc = cli(["paper", "-o", str(tmp_path / "out"), "--doc", str(doc), "--only", "demo", "--quick"])
    assert rc == 0
    text = doc.read_text()
    rows = [line for line in text.splitlines() if line.startswith("| Fig") or line.startswith("| Table")]
    labels = {re.match(r"\| (Fig\. \d+|Table \d+)", r).group(1) for r in rows}
    assert {"Fig. 1", "Fig. 2", "Fig. 3", "Fig. 4", "Fig. 13", "Fig. 14", "Fig. 15"} <= labels
    demo_row = next(r for r in rows if r.startswith("| Fig. 14"))
    assert "](paper/demo.png)" in demo_row and (doc.parent / "paper" / "demo.png").stat().st_size > 1000
    # the row's command, run again, writes the same card depths the row states
    command = re.search(r"`(eventfield [^`]+)`", demo_row).group(1)
    again = tmp_path / "again"
    assert cli(shlex.split(command)[1:] + ["-o", str(again)]) == 0
    cards = json.loads((again / "metrics.json").read_text())["cards"]
    for name, card in cards.items():
        assert f"{name} {card['true_m']:.3f} m -> {card['measured_m']:.3f} m" in demo_row
    assert "reduced sizes" in text


def test_a_partial_run_leaves_the_full_document_alone(tmp_path, monkeypatch):
    """`eventfield paper --only KEY` wrote docs/paper.md with that result's row and none of the others'."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "paper.md").write_text("the full document\n")
    assert cli(["paper", "--only", "demo", "--quick", "-o", "out"]) == 0
    assert (tmp_path / "docs" / "paper.md").read_text() == "the full document\n"
    assert "| Fig. 14" in (tmp_path / "out" / "paper.md").read_text()


def test_unknown_result_is_one_line(tmp_path):
    import pytest

    from mitsuba_eventfield.errors import ConfigError
    with pytest.raises(ConfigError, match="unknown result"):
        paper.generate(str(tmp_path / "o"), str(tmp_path / "p.md"), only=["nonsense"])
    assert not (tmp_path / "p.md").exists()
    assert os.listdir(tmp_path) == []


def test_fig_8_runs_at_the_papers_factor(monkeypatch):
    """The paper's Fig. 8 is 6x (720 fps from 120 fps); the app's default 8x is its Fig. 9's dart."""
    from mitsuba_eventfield.apps import slomorf
    asked = {}
    monkeypatch.setattr(slomorf, "slomorf", lambda *a, **k: asked.update(k))
    for quick in (True, False):
        next(e for e in paper.ENTRIES if e.key == "slomorf").run(quick)
        assert asked["factor"] == 6
        asked.clear()
        next(e for e in paper.ENTRIES if e.key == "slomorf_dart").run(quick)
        assert asked["factor"] == 8
