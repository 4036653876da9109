"""``eventfield paper``: the paper's figures and tables side by side with what this project measures
(``apps.paper``)."""
from __future__ import annotations


def add_parsers(sub) -> None:
    from ..apps.paper import ENTRIES
    pp = sub.add_parser("paper", help="run every result of the paper and write docs/paper.md: claim, measurement, "
                                      "command, difference")
    pp.add_argument("-o", "--output", default="out/paper", help="outputs of each result (default out/paper)")
    pp.add_argument("--doc", default=None, help="the document to write (default docs/paper.md for a full run, "
                                                "OUTPUT/paper.md for --only or --quick); its figures go to paper/ "
                                                "beside it")
    pp.add_argument("--only", action="append", choices=[e.key for e in ENTRIES], metavar="KEY",
                    help="run only these results (repeatable): " + ", ".join(e.key for e in ENTRIES))
    pp.add_argument("--quick", action="store_true", help="reduced sizes (minutes instead of tens of minutes)")


def run_paper(a) -> int:
    import os

    from ..apps.paper import generate
    # a partial or reduced run writes beside its outputs: over docs/paper.md it replaced every other result's
    # row with nothing (`--only hdr_lightfield` left 7 of its rows) or the default sizes' numbers with reduced ones
    doc = a.doc or ("docs/paper.md" if not (a.only or a.quick) else os.path.join(a.output, "paper.md"))
    rows = generate(a.output, doc, only=a.only, quick=a.quick, progress=True)
    print(f"wrote {doc} ({len(rows)} rows) and the results under {a.output}/")
    return 0


COMMANDS = {"paper": run_paper}
