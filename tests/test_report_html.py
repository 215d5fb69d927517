"""The study's HTML page and the results folder's (issue 28): what they show, checked
against the run's own CSV files, that they are rewritten only when their content changes,
and, in headless Chromium, that they render (every image loads, no console error, a
screenshot that is not blank, no sideways scrolling on a phone)."""

from __future__ import annotations

import io
import math
import shutil
import tomllib
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from browser import Browser, find_chromium
from morsuite.report import html as H
from morsuite.studies import run

SPEC = """
name = "demo"
title = "Three methods on a small DSMS"
description = "A quick comparison."
norms = ["h2", "hinf"]

[models]
dsms = "dsms:g=60"

[methods.irka]
options = { maxit = 2 }          # stopped early: converged = False, flagged on the page

[methods.bt]

[methods.irka_fo]
reducer = "irka-fo"

[[scenes]]
name = "err"
kind = "error"
model = "dsms"
methods = ["irka", "bt"]
r = 4

[[scenes]]
name = "tab"
kind = "table"
model = "dsms"
methods = ["irka", "bt", "irka_fo"]
r = 4
r_by_method = { irka_fo = 8, bt = 8 }
norms = ["h2", "hinf"]
"""

#: planted modes data in the format of docs/design/reports.md ("Modes and poles"): what the page must show
MODES = {
    "rows": [
        {"model": "dsms", "method": "irka", "mode": 1, "full_frequency": 0.123456, "reduced_frequency": 0.123457,
         "rel_frequency_error": 8.1e-6, "damping_error": 2.5e-5, "mac": 0.99998},
        {"model": "dsms", "method": "irka_fo", "mode": 1, "full_frequency": 0.123456,
         "reduced_frequency": 0.1236, "rel_frequency_error": 1.17e-3, "damping_error": 4e-4, "mac": None},
        {"model": "dsms", "method": "bt", "mode": 2, "full_frequency": 0.5, "reduced_frequency": None,
         "rel_frequency_error": None, "damping_error": None, "mac": None},
    ],
    "poles": [{"label": "full", "real": [-0.01, -0.02, -0.05], "imag": [0.12, 0.5, 1.3]},
              {"label": "irka r = 4", "real": [-0.0101, -0.021], "imag": [0.1235, 0.49]},
              {"label": "bt r = 8", "real": [-0.3], "imag": [0.0]}],
    "note": "irka_fo has no lift V q: no MAC.",
}


class Tables(HTMLParser):
    """Every <table> of a page as a list of rows of (text, class) cells; <img> sources; links."""

    def __init__(self):
        super().__init__()
        self.tables, self.classes, self.imgs, self.links, self._cell = [], [], [], [], None
        self.sections = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "table":
            self.tables.append([])
            self.classes.append(a.get("class") or "")
        elif tag == "section":
            self.sections.append(a.get("class") or a.get("id") or "")
        elif tag == "tr":
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self._cell = ["", a.get("class") or ""]
        elif tag == "img":
            self.imgs.append(a["src"])
        elif tag in ("a", "link", "script"):
            self.links.append(a.get("href") or a.get("src") or "")

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self.tables[-1][-1].append(tuple(self._cell))
            self._cell = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell[0] += data


def parse(path) -> Tables:
    p = Tables()
    p.feed(Path(path).read_text(encoding="utf-8"))
    return p


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("page")
    (tmp / "demo.toml").write_text(SPEC)
    res = run(tmp / "demo.toml", out=tmp / "results", quiet=True, formats=("png", "svg"))
    return tmp, res


@pytest.fixture(scope="module")
def moded(results, tmp_path_factory):
    """The demo study re-run from the cache with the planted modes data handed to the page (the hook the
    modes analysis plugs into: ``Results.modes``)."""
    from morsuite.studies import runner

    tmp, _ = results
    copy = tmp_path_factory.mktemp("moded")
    shutil.copytree(tmp, copy, dirs_exist_ok=True, copy_function=shutil.copy2)

    class WithModes(runner.Results):
        def __init__(self, *a, **k):
            super().__init__(*a, modes=MODES, **k)
    pages = []

    def keep(data, *a, **k):
        pages.append(data)
        return realize(data, *a, **k)
    realize = runner.realize_page
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(runner, "Results", WithModes)
        mp.setattr(runner, "realize_page", keep)
        res = run(copy / "demo.toml", out=copy / "results", quiet=True, formats=("png", "svg"))
    res.page_data = pages[0]
    return copy, res


def _scoreboard_cells(page, table_index=0):
    """The scoreboard's rows as {method: {heading: (text, class)}}."""
    boards = [t for t, c in zip(page.tables, page.classes) if c == "scoreboard"]
    head = [c[0] for c in boards[table_index][0]]
    return {row[0][0].split()[0]: dict(zip(head, row)) for row in boards[table_index][1:]}, len(boards)


def test_scoreboard_one_row_per_method_values_best_and_ratios_from_the_table(results):
    tmp, res = results
    page = parse(res.outdir / "index.html")
    rows, n = _scoreboard_cells(page)
    assert n == 1                                      # tab compares its three methods at 8 states
    csv = pd.read_csv(res.outdir / "tab.csv")
    at8 = csv[csv.states == 8].set_index("method")
    assert sorted(rows) == sorted(at8.index) == ["bt", "irka", "irka_fo"]
    for heading, col in (("band max", "max_abs_error"), ("H2", "h2_error"), ("H∞", "hinf_error")):
        best = at8[col].min()
        for method, cells in rows.items():
            text, cls = cells[heading]
            value = float(text.replace("≥", "").replace("≈", "").replace("✓", "").split()[0].split("×")[0]
                          .replace("best", ""))
            assert math.isclose(value, at8.loc[method, col], rel_tol=5e-4), (heading, method, text)
            if at8.loc[method, col] == best:
                assert "best" in cls and text.endswith("best")
            else:                                      # the ratio to the best, to the digits shown
                ratio = float(text.rsplit("×", 1)[1])
                assert math.isclose(ratio, at8.loc[method, col] / best, rel_tol=6e-3), (heading, method, text)
    # the planted flag: irka stopped after 2 iterations is marked "nc" beside its name, with its meaning
    assert "nc" in rows["irka"]["method"][0].split() and not at8.loc["irka", "converged"]
    text = (res.outdir / "index.html").read_text()
    assert 'title="not converged: the method' in text and "<details" in text


def test_scoreboard_view_marks_planted_flags_and_ties():
    rows = [
        {"method": "a", "status": "ok", "converged": True, "stable": True, "max_abs_error": 2.0, "h2_error": 1.0,
         "h2_trusted": False, "hinf_error": 3.0, "hinf_certified": True, "time_standalone_s": 1.0, "lu_count": 0},
        {"method": "b", "status": "ok", "converged": False, "stable": False, "max_abs_error": float("inf"),
         "h2_error": float("inf"), "hinf_error": float("inf"), "time_s": 2.0, "lu_count": 4,
         "worse_than_zero": "band,h2,hinf"},
        {"method": "c", "status": "ok", "converged": True, "stable": True, "max_abs_error": 2.0, "h2_error": 4.0,
         "h2_trusted": True, "hinf_error": 6.0, "time_standalone_s": 0.5, "lu_count": 2},
        {"method": "d", "status": "failed"},
    ]
    v = H.scoreboard_view({"title": "t", "where": "r = 2", "rows": rows})
    assert [c["heading"] for c in v["columns"]] == ["band max", "H2", "H∞", "time (s)", "LUs"]
    a, b, c, d = v["rows"]
    cell = {r["method"]: dict(zip([k["key"] for k in v["columns"]], r["cells"])) for r in v["rows"]}
    assert cell["a"]["band"]["best"] and cell["c"]["band"]["best"]          # a tie: both best
    # a's H2 value is untrusted: never ranked, so nothing is best in H2 (c, the one trusted value, has no peer)
    assert [m for m, _ in cell["a"]["h2"]["marks"]] == ["≈"] and cell["a"]["h2"]["ratio"] == ""
    assert not cell["a"]["h2"]["best"] and not cell["c"]["h2"]["best"] and cell["c"]["h2"]["ratio"] == ""
    assert cell["a"]["hinf"]["ratio"] == "best" and cell["c"]["hinf"]["ratio"] == "×2.00"
    assert [m for m, _ in cell["a"]["hinf"]["marks"]] == ["✓"] and [m for m, _ in cell["c"]["hinf"]["marks"]] == ["≥"]
    assert [m for m, _ in b["marks"]] == ["nc", "unst"] and cell["b"]["h2"]["text"] == "∞"
    assert cell["b"]["h2"]["ratio"] == "" and "zero" in [m for m, _ in cell["b"]["band"]["marks"]]
    assert cell["b"]["time"]["text"] == "2" and cell["b"]["time"]["ratio"] == "×4.00"   # time_s when no standalone
    assert cell["a"]["lus"]["best"] and cell["c"]["lus"]["ratio"] == ""       # best 0: no ratio
    assert [m for m, _ in d["marks"]] == ["fail"] and all(x["text"] == "" for x in d["cells"])
    assert all(m in H.MARKS for r in v["rows"] for m, _ in r["marks"])
    # the untrusted H2 value decides nothing: the headline falls to the band maximum, a tie of a and c
    assert H.headline({"where": "r = 2", "rows": rows}) == "r = 2: a has the smallest band max error, tied with c"
    assert H.headline({"where": "r = 2", "rows": rows[1:2]}) == ""


def _planted(method, states, h2, h2_rel, trusted, band, band_rel):
    return {"method": method, "status": "ok", "converged": True, "stable": True, "r_requested": 30, "r": states // 2,
            "states": states, "h2_error": h2, "h2_rel_error": h2_rel, "h2_trusted": trusted, "max_abs_error": band,
            "max_rel_error": band_rel}


def test_noise_and_unequal_states_never_rank():
    """The committed pages' cases (issue 45, item 3): results/paper_dsms's untrusted 2.5e-16 of IRKA at 48 states
    against Krylov at 60 ('199710x below krylov'), results/sweep's untrusted 9.9e-17 at 48 states against BT at
    42 ('15.1x below bt'): no ranking headline, no best mark, no ranked verdict; two values at the rounding level
    at equal states are said as a tie; a clean board (equal states, trusted) is ranked."""
    from morsuite.report.ranking import rank, standing

    irka = _planted("irka", 48, 2.495e-16, 5.16e-15, False, 2.175e-15, 1.65e-14)
    krylov = _planted("krylov", 60, 4.98e-11, 1.03e-9, True, 4.22e-10, 2.43e-9)
    assert standing(irka, "h2_error") == "rounding" and standing(irka, "max_abs_error") == "rounding"
    assert standing(krylov, "h2_error") == "ok" and standing(krylov, "max_abs_error") == "ok"
    board = {"title": "t", "where": "r = 30", "rows": [irka, krylov]}
    assert H.headline(board) == ""
    view = H.scoreboard_view(board)
    cells = [c for r in view["rows"] for c in r["cells"]]
    assert not any(c["best"] for c in cells[:4]) and not any(c["ratio"] for c in cells)
    assert all("≠" in [m for m, _ in c["marks"]] for c in cells)      # each alone at its number of states
    # the sweep's case, and two rounding-level values at equal states: a tie, said as one, never ranked
    bt = _planted("bt", 42, 3.1e-14, 1.5e-15, True, 4.5e-14, 4.5e-14)
    assert H.headline({"title": "t", "where": "r = 40", "rows": [irka, bt]}) == ""
    projected = _planted("projected", 48, 9.9e-17, 2.0e-15, False, 4.8e-15, 4.8e-15)
    tie = {"title": "t", "where": "r = 40", "rows": [irka, projected]}
    assert H.headline(tie) == "r = 40, H2 error: tie at the rounding level: irka, projected"
    assert "smallest" not in H.headline(tie) and "below" not in H.headline(tie)
    tie_view = H.scoreboard_view(tie)
    assert all("tie" in [m for m, _ in c["marks"]] and not c["best"] and not c["ratio"]
               for r in tie_view["rows"] for c in r["cells"])
    # a noise value at equal states keeps the trusted ones from a 'best' (it may be the smallest)
    g = rank([irka, _planted("so_h2", 48, 1e-9, 2e-8, True, 1e-9, 2e-8),
              _planted("bt", 48, 3e-9, 6e-8, True, 3e-9, 6e-8)], "h2_error")
    assert len(g) == 1 and g[0]["best"] is None and g[0]["rounding"] == ["irka"]
    assert [n for _, n in g[0]["ranked"]] == ["so_h2", "bt"]
    # a clean board: equal states, trusted values above their floors
    clean = {"title": "t", "where": "r = 30", "rows": [
        _planted("irka", 60, 2.0e-9, 4e-8, True, 8e-9, 1e-7), krylov,
        _planted("modal", 60, 2.2e-2, 0.46, True, 0.11, 0.61)]}
    assert H.headline(clean) == "r = 30: krylov has the smallest H2 error, 40.2x below irka"
    cv = {r["method"]: r["cells"] for r in H.scoreboard_view(clean)["rows"]}
    assert cv["krylov"][1]["best"] and cv["irka"][1]["ratio"] == "×40.2"
    # mixed states with a clean group: ranked there, the other row named as not compared
    mixed = {"title": "t", "where": "r = 30", "rows": [irka, krylov, clean["rows"][2]]}
    assert H.headline(mixed) == ("r = 30, 60 states: krylov has the smallest H2 error, 4.4e+08x below modal; "
                                 "not compared, at other states: irka (48 states)")


def test_modes_section_shows_the_planted_modes_and_poles(moded):
    tmp, res = moded
    page = parse(res.outdir / "index.html")
    text = (res.outdir / "index.html").read_text()
    assert "modes" in page.sections
    modes = [t for t, c in zip(page.tables, page.classes) if c == "modes"]
    assert len(modes) == 1
    head = [c[0] for c in modes[0][0]]
    assert head == list(H.MODES_COLUMNS)
    body = [dict(zip(head, [c[0] for c in row])) for row in modes[0][1:]]
    assert [r["method"] for r in body] == [r["method"] for r in MODES["rows"]]
    for got, want in zip(body, MODES["rows"]):
        for col in ("full_frequency", "reduced_frequency", "mac"):
            if want[col] is not None:
                assert math.isclose(float(got[col]), want[col], rel_tol=5e-4)
    assert body[1]["mac"] == "no lift" and body[2]["reduced_frequency"] == "missing"
    # the pole figure: one cross per full-model pole, one ring per reduced-model pole
    svg = text[text.index('<svg class="poles"'):text.index("</svg>")]
    assert svg.count("<path") == len(MODES["poles"][0]["real"])
    assert svg.count("<circle") == sum(len(p["real"]) for p in MODES["poles"][1:])
    assert MODES["note"] in text and "irka r = 4" in text


def test_a_table_of_many_sizes_shows_its_largest_and_folds_the_others(moded):
    from morsuite.studies import pages

    rows = [{"method": m, "r_requested": r, "r": r, "states": r, "status": "ok", "h2_error": float(r * (i + 1))}
            for r in (2, 4, 6, 8, 10) for i, m in enumerate(("bt", "irka"))]
    study = moded[1].study
    boards = pages.scoreboards(study, [{"name": "t", "title": "T", "rows": rows}])
    assert [b["where"] for b in boards] == [f"r = {r}" for r in (2, 4, 6, 8, 10)]
    assert [b["folded"] for b in boards] == [True] * 4 + [False]     # more than _OPEN_SIZES sizes
    assert [b["folded"] for b in pages.scoreboards(study, [{"name": "t", "title": "T", "rows": rows[:6]}])] == \
        [False] * 3
    html = H.render_study({**moded[1].page_data, "scoreboards": boards})
    p = Tables()
    p.feed(html)
    assert p.classes.count("scoreboard") == 5
    fold = html[html.index('<details class="sizes">'):]
    assert fold.index("4 more sizes of this table (r = 2, r = 4, r = 6, r = 8)") < fold.index("r = 2")
    assert html.index("· r = 10") < html.index('<details class="sizes">')   # the largest open, before the fold


def test_no_modes_data_no_modes_section(results):
    tmp, res = results
    page = parse(res.outdir / "index.html")
    assert "modes" not in page.sections and "modes" not in page.classes and "<svg" not in \
        (res.outdir / "index.html").read_text()
    assert H.modes_view(None) is None and H.modes_view({"rows": []}) is None and H.pole_svg([]) is None


def test_results_index_has_thumbnail_headline_and_folded_description(results):
    tmp, res = results
    path = tmp / "results" / "index.html"
    page = parse(path)
    text = path.read_text()
    assert page.imgs == ["demo/err.png"] and (tmp / "results" / "demo" / "err.png").is_file()
    assert "8 states: " in text and "has the smallest H2 error" in text
    assert "<details><summary>description</summary><p>A quick comparison.</p></details>" in text


def test_page_shows_every_figure_and_the_summary_as_its_csv_says(results):
    tmp, res = results
    page = parse(res.outdir / "index.html")
    assert sorted(page.imgs) == ["err.png"] and (res.outdir / "err.png").is_file()
    csv = pd.read_csv(res.outdir / "summary.csv")
    plain_tables = [t for t, c in zip(page.tables, page.classes) if not c]
    summary = plain_tables[1]              # tab, then the summary, then timings
    head = [c[0] for c in summary[0]]
    assert head == list(csv.columns)
    assert len(summary) - 1 == len(csv) > 0  # one HTML row per CSV row (zip below would hide a missing one)
    for (_, row), cells in zip(csv.iterrows(), summary[1:], strict=True):
        got = dict(zip(head, cells))
        assert got["method"][0] == row.method
        h2 = got["h2_error"][0].lstrip("≈")
        assert math.isclose(float(h2), row.h2_error, rel_tol=5e-4)          # 4 significant digits
        # a lower bound (the peak found) is marked so; a certified value carries the certified mark
        cell = got["hinf_error"][0]
        assert cell.endswith("✓") if str(row.get("hinf_certified")) == "True" else cell.startswith("≥")
        # the relative Hinf error is a ratio of two peaks found: no mark, whatever hinf_certified says
        assert math.isclose(float(got["hinf_rel_error"][0]), row.hinf_rel_error, rel_tol=5e-4)
        assert got["converged"] == (("yes", "ok") if row.converged else ("no", "bad"))
    assert not csv[csv.method == "irka"].converged.iloc[0]                  # the planted flag is there


def test_page_states_the_verdict_the_flags_and_the_run_facts(results):
    tmp, res = results
    text = (res.outdir / "index.html").read_text()
    tab = (res.outdir / "tab.md").read_text()
    verdict = next(line for line in tab.splitlines() if "Smallest error per measure" in line)
    assert verdict.replace("'", "&#39;") in text
    assert "1 reduction(s) did not converge (best iterate shown): irka r = 4" in text
    m = res.manifest
    for fact in (m["versions"]["numpy"], m["versions"]["scipy"], m["host"]["platform"], "maxit = 2",
                 "taken from the cache"):
        assert str(fact) in text
    assert '<meta name="viewport"' in text


def test_pages_load_nothing_from_the_network(results):
    tmp, res = results
    for path in (res.outdir / "index.html", tmp / "results" / "index.html"):
        page = parse(path)
        text = path.read_text()
        assert "<script" not in text and "<link" not in text and "@import" not in text and "url(" not in text
        assert not [u for u in page.links + page.imgs if "://" in u], path


def test_results_index_links_the_study(results):
    tmp, res = results
    page = parse(tmp / "results" / "index.html")
    assert "demo/index.html" in page.links
    assert "Three methods on a small DSMS" in (tmp / "results" / "index.html").read_text()


def test_unchanged_rerun_renders_no_page(results, tmp_path, monkeypatch):
    tmp, _ = results
    shutil.copytree(tmp, tmp_path / "s", copy_function=shutil.copy2)
    out = tmp_path / "s" / "results"
    run(tmp_path / "s" / "demo.toml", out=out, quiet=True, formats=("png", "svg"))   # rows become "cached"
    files = [out / "demo" / "index.html", out / "index.html"]
    before = [(p.read_bytes(), p.stat().st_mtime_ns) for p in files]

    def boom(*a, **k):
        raise AssertionError("a page was rendered although nothing changed")
    monkeypatch.setattr(H, "render_study", boom)
    monkeypatch.setattr(H, "render_index", boom)
    res = run(tmp_path / "s" / "demo.toml", out=out, quiet=True, formats=("png", "svg"))
    assert [(p.read_bytes(), p.stat().st_mtime_ns) for p in files] == before
    assert "page/index" in res.manifest["reused"]


def test_cell_marks_planted_flags():
    row = {"h2_error": 1.23456e-3, "h2_trusted": False, "hinf_error": 2.0, "hinf_certified": True}
    assert H.cell("h2_error", row["h2_error"], row) == {"text": "≈0.001235", "cls": "num untrusted",
                                                        "title": "not accurate to four digits (h2_trusted = False)"}
    assert H.cell("hinf_error", 2.0, row)["text"] == "2 ✓"
    assert H.cell("hinf_error", 2.0, {})["text"] == "≥2"
    # a mark only on the quantity it was established for: hinf_rel_error, a ratio of two peaks found,
    # is neither a lower bound nor certified (certified or not); h2_trusted covers the relative error too
    for r in (row, {"hinf_error": 2.0, "hinf_certified": False}):
        assert H.cell("hinf_rel_error", 0.5, r) == {"text": "0.5", "cls": "num", "title": ""}
    assert H.cell("h2_rel_error", 0.25, row)["text"] == "≈0.25"
    assert H.cell("h2_error", float("nan"), {})["cls"] == "na"
    assert H.cell("stable", False, {})["cls"] == "bad" and H.cell("growth", True, {})["cls"] == "bad"
    assert H.cell("status", "failed", {})["cls"] == "bad"


def test_templates_are_package_data():
    """A non-editable install ships the templates: pyproject's package-data covers each one."""
    root = Path(__file__).resolve().parents[1]
    data = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    patterns = data["morsuite.report"]
    pkg = root / "morsuite" / "report"
    covered = {p for pat in patterns for p in pkg.glob(pat)}
    assert set(H.TEMPLATES.glob("*")) <= covered and len(covered) >= 3
    assert "jinja2" in " ".join(tomllib.loads((root / "pyproject.toml").read_text())["project"]["dependencies"])


# -- a real browser ----------------------------------------------------------------------
CHROMIUM = find_chromium()


@pytest.fixture(scope="module")
def browser():
    """One headless Chromium for the three screen sizes (each page opened in a fresh tab)."""
    with Browser(CHROMIUM) as b:
        yield b


@pytest.mark.skipif(CHROMIUM is None, reason="no Chromium found (Debian: apt-get install chromium; or set "
                                             "MORSUITE_CHROMIUM): the page is not checked in a browser")
@pytest.mark.parametrize("width,height,mobile", [(1280, 900, False), (400, 800, True), (390, 844, True)])
def test_page_renders_in_headless_chromium(results, moded, browser, width, height, mobile):
    from PIL import Image

    tmp, res = results
    b = browser
    for page in (res.outdir / "index.html", tmp / "results" / "index.html", moded[1].outdir / "index.html"):
        b.open(page.as_uri(), width, height, mobile)
        images = b.evaluate("[...document.images].map(i => [i.getAttribute('src'), i.complete, i.naturalWidth])")
        assert all(done and w > 0 for _, done, w in images), images
        assert b.errors() == []
        # nothing wider than the screen: wide tables scroll inside their box
        assert b.evaluate("document.documentElement.scrollWidth") <= width
        # nothing but what a scroll box holds reaches past the viewport (the box itself does not)
        wide = b.evaluate("[...document.querySelectorAll('body *')].filter(e => "
                          "e.getBoundingClientRect().right > window.innerWidth + 0.5 && "
                          "!(e.parentElement && e.parentElement.closest('.scroll')))"
                          ".map(e => e.tagName + '.' + e.className)")
        assert wide == [], wide
        modes = b.evaluate("[document.querySelectorAll('section.modes table.modes tbody tr').length, "
                           "document.querySelectorAll('section.modes svg.poles').length]")
        assert modes == ([len(MODES["rows"]), 1] if moded[0] in page.parents else [0, 0])
        if page.parent.name == "demo":
            n = b.evaluate("[...document.querySelectorAll('table.scoreboard')].map(t => t.tBodies[0].rows.length)")
            assert n == [3]
            if width >= 1280:  # the scoreboard shows whole, without a sideways scroll of its own
                assert b.evaluate("[...document.querySelectorAll('table.scoreboard')].every(t => "
                                  "t.parentElement.scrollWidth <= t.parentElement.clientWidth)")
        shot = Image.open(io.BytesIO(b.screenshot())).convert("L")
        px = np.asarray(shot, dtype=float)
        assert px.shape[1] == width and px.shape[0] >= height // 2
        assert (px < 200).mean() > 0.01 and px.std() > 10, "the screenshot is blank"
        shot.save(page.parent / f"shot_{width}.png")   # to look at by hand


def test_table_verdict_ranks_only_equal_states_above_the_floors():
    """The table scenes' verdict on the planted rows of results/paper_dsms (r = 30: IRKA returned 48 states, an
    untrusted H2 value at rounding; Krylov and modal 60): IRKA is named as not compared, Krylov ranked against
    modal; a tie at the rounding level is said as a tie and never ranked."""
    from types import SimpleNamespace

    from morsuite.studies.scenes import _verdict

    study = SimpleNamespace(methods={m: SimpleNamespace(label=m.upper()) for m in ("irka", "krylov", "modal", "bt")})
    irka = _planted("irka", 48, 2.495e-16, 5.16e-15, False, 2.175e-15, 1.65e-14)
    krylov = _planted("krylov", 60, 4.98e-11, 1.03e-9, True, 4.22e-10, 2.43e-9)
    modal = _planted("modal", 60, 2.2e-2, 0.46, True, 0.11, 0.61)
    text = _verdict([irka, krylov, modal], study)
    assert "IRKA (" not in text and "smaller than the next" in text
    assert "r = 30, 60 states, h2_error: KRYLOV (4.98e-11; 4.42e+08x smaller than the next)" in text
    assert "Not compared (no other method at their number of states): IRKA at r = 30 (48 states)." in text
    bt = _planted("bt", 48, 1.0e-16, 2.0e-15, False, 1.0e-15, 1.0e-14)
    tie = _verdict([irka, bt], study)
    assert "smaller than the next" not in tie
    assert "r = 30, h2_error: tie at the rounding level: IRKA, BT" in tie
    assert "r = 30, max_abs_error: tie at the rounding level: IRKA, BT" in tie
