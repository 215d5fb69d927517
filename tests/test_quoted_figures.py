"""Figures quoted in README.md and docs/ agree with the results files they name (issue 36).

Each quoted figure carries its source (``morsuite.report.quoted``); a regenerated
``results/`` that no longer says what the prose says fails here, on every CI run.
"""

from pathlib import Path

import pytest

from morsuite.errors import InputError
from morsuite.report.quoted import check_text, evaluate, find_quotes

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md"] + sorted(p for p in (ROOT / "docs").rglob("*.md") if "_build" not in p.parts)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_quoted_figure_matches_its_source(page):
    bad = [q for q in check_text(page.read_text(encoding="utf-8"), ROOT) if not q.ok]
    assert not bad, "\n".join(f"{page.name}:{q.line}: {q.text} <- {q.expr}: "
                              f"{q.error or f'value {q.value:.6g} outside [{q.low:.6g}, {q.high:.6g}]'}"
                              for q in bad)


def test_the_readme_headline_figures_are_quoted_with_their_source():
    quotes = find_quotes((ROOT / "README.md").read_text(encoding="utf-8"))
    assert len(quotes) >= 10


def _csv(tmp_path):
    (tmp_path / "r.csv").write_text("model,method,r,h2_error\ntcom,irka,30,1024.2475\ntcom,bt,30,92.83\n"
                                    "tcom,bt,20,92.83\n")
    (tmp_path / "b.json").write_text('{"rows": [{"t": 0.25}, {"t": 0.05}]}')
    return tmp_path


def test_a_quote_is_judged_at_the_digits_it_shows(tmp_path):
    root = _csv(tmp_path)
    src = 'csv("r.csv", "h2_error", method="irka", r=30)'
    ok = check_text(f"IRKA 1024<!-- = {src} --> and 1024.2<!-- = {src} -->, 1.02e3<!-- = {src} -->", root)
    assert [q.ok for q in ok] == [True, True, True]
    bad = check_text(f"IRKA 1025<!-- = {src} -->, 1024.3<!-- = {src} -->", root)
    assert [q.ok for q in bad] == [False, False]
    ratio = 'csv("r.csv", "h2_error", method="irka", r=30) / csv("r.csv", "h2_error", method="bt", r=30)'
    assert [q.ok for q in check_text(f"11x<!-- = {ratio} --> 12x<!-- = {ratio} -->", root)] == [True, False]
    loose = check_text(f"about 10<!-- = {ratio} | rel=0.15 -->", root)
    assert loose[0].ok and loose[0].value == pytest.approx(1024.2475 / 92.83)
    assert check_text('1/20<!-- = 1 / json("b.json", "rows", 1, "t") -->', root)[0].ok


def test_a_source_that_selects_no_row_or_several_is_an_error_not_a_guess(tmp_path):
    root = _csv(tmp_path)
    many = check_text('92.8<!-- = csv("r.csv", "h2_error", method="bt") -->', root)
    none = check_text('92.8<!-- = csv("r.csv", "h2_error", method="so_h2") -->', root)
    missing = check_text('92.8<!-- = csv("nope.csv", "h2_error") -->', root)
    assert all(not q[0].ok and q[0].error for q in (many, none, missing))
    assert "2 rows" in many[0].error and "0 rows" in none[0].error


def test_the_expression_language_refuses_anything_else(tmp_path):
    for expr in ('__import__("os").getcwd()', 'csv.__class__', 'open("r.csv")'):
        with pytest.raises(InputError):
            evaluate(expr, _csv(tmp_path))


@pytest.mark.parametrize("page,least", [("docs/design/backends.md", 40), ("docs/benchmarks.md", 15)])
def test_the_measurement_pages_quote_their_headline_figures_with_sources(page, least):
    """The pages of measured figures mark what they take from results/ (checked above), not only the README."""
    assert len(find_quotes((ROOT / page).read_text(encoding="utf-8"))) >= least


_EXAMPLE_LINE = (r"^(?P<method>[\w-]+)\s+(?P<status>\w+): (?P<states>\d+) states, band error (?P<error>\S+), "
                 r"(?P<lus>\d+) sparse LUs; (?P<smaller>\d+) states miss it$")


def _example_rows(text):
    import re

    rows = [re.match(_EXAMPLE_LINE, ln.strip()) for ln in text.splitlines() if ln.strip()]
    assert rows and all(rows), text
    return [r.groupdict() for r in rows]


def test_the_readme_python_example_prints_what_the_readme_says(tmp_path):
    """The README's Python example, run as a user would (in an empty folder), prints the lines the README
    shows: the same status, states, next smaller states and LUs per method, band errors to the two digits
    shown (a 10% band: another BLAS moves the last digit), and it writes the model files it names. The
    dense-reference check of the search itself is tests/test_tolerance.py."""
    import os
    import subprocess
    import sys

    text = (ROOT / "README.md").read_text(encoding="utf-8")
    code = text.split("```python\n", 1)[1].split("```", 1)[0]
    shown = text.split("prints (a test runs it and compares)\n", 1)[1].lstrip("\n").split("\n\n", 1)[0]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, env=env,
                         timeout=600)
    assert out.returncode == 0, out.stderr
    got, want = _example_rows(out.stdout), _example_rows(shown)
    assert [r["method"] for r in got] == [r["method"] for r in want]
    for g, w in zip(got, want):
        assert (g["status"], g["states"], g["smaller"], g["lus"]) == (w["status"], w["states"], w["smaller"],
                                                                      w["lus"]), (g, w)
        assert float(g["error"]) == pytest.approx(float(w["error"]), rel=0.1), (g, w)
        assert g["status"] != "met" or float(g["error"]) <= 1e-3
    assert {p.suffix for p in tmp_path.glob("dsms_irka.*")} >= {".npz", ".mat", ".json"}


def test_the_committed_fe_study_is_the_committed_spec():
    """results/fem (not part of the main job: run by hand, docs/results.md quotes it) was made from
    studies/fem.toml as committed: its manifest's spec hash is the file's, and every method of the
    spec has its row per tolerance in the "to reach" table, with a status from the search's vocabulary."""
    import hashlib
    import json

    import pandas as pd
    import tomllib

    spec = (ROOT / "studies" / "fem.toml").read_text(encoding="utf-8")
    manifest = json.loads((ROOT / "results" / "fem" / "manifest.json").read_text(encoding="utf-8"))
    assert manifest["spec_sha256"] == hashlib.sha256(spec.encode()).hexdigest()
    from morsuite.analysis.tolerance import OUTCOMES

    parsed = tomllib.loads(spec)
    scene = next(sc for sc in parsed["scenes"] if sc["kind"] == "tolerance")
    df = pd.read_csv(ROOT / "results" / "fem" / f"{scene['name']}.csv")
    assert set(df["method"]) == set(scene["methods"]) == set(parsed["methods"])
    assert sorted(set(df["tol"])) == sorted(scene["tol"])
    assert set(df["status"]) <= set(OUTCOMES)
