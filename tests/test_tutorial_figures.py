"""Every executed tutorial draws at least one figure (issue 47, item 8): a tutorial page with a
notebook kernel (MyST-NB executes it at build time, docs/conf.py) has a code cell that plots
(matplotlib) or shows a figure file (IPython's ``Image``). Parsed, not executed: the docs build
runs the cells."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

TUTORIALS = sorted((Path(__file__).resolve().parents[1] / "docs" / "tutorials").glob("*.md"))
CELL = re.compile(r"^```\{code-cell\}[^\n]*\n(.*?)^```", re.S | re.M)
#: a call that draws or shows a figure in a cell's output
DRAWS = re.compile(r"\bplt\.\w+\(|\.(plot|loglog|semilogx|semilogy|scatter|imshow|bar|fill_between|stem)\(|"
                   r"\bImage\(")


def _executed(text: str) -> bool:
    return bool(re.match(r"---\n.*?^kernelspec:", text, re.S | re.M))


def test_the_parser_sees_the_tutorials():
    """The pattern finds the cells of a known tutorial, and a page without a kernel is not executed."""
    pages = {p.name: p.read_text() for p in TUTORIALS}
    assert _executed(pages["08_engineering_baselines.md"]) and not _executed(pages["index.md"])
    assert len(CELL.findall(pages["08_engineering_baselines.md"])) >= 5
    assert not DRAWS.search("x = ms.analysis.errors(fom, rom, omega)\nprint(rows)")


@pytest.mark.parametrize("path", [p for p in TUTORIALS if _executed(p.read_text())], ids=lambda p: p.stem)
def test_every_executed_tutorial_draws_a_figure(path):
    cells = CELL.findall(path.read_text())
    assert cells, f"{path.name}: no code cell"
    assert any(DRAWS.search(c) for c in cells), f"{path.name}: no code cell draws a figure"
