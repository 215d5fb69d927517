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
r_by_method = { irka_fo = 8 }
norms = ["h2", "hinf"]
"""


class Tables(HTMLParser):
    """Every <table> of a page as a list of rows of (text, class) cells; <img> sources; links."""

    def __init__(self):
        super().__init__()
        self.tables, self.imgs, self.links, self._cell = [], [], [], None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "table":
            self.tables.append([])
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


def test_page_shows_every_figure_and_the_summary_as_its_csv_says(results):
    tmp, res = results
    page = parse(res.outdir / "index.html")
    assert sorted(page.imgs) == ["err.png"] and (res.outdir / "err.png").is_file()
    csv = pd.read_csv(res.outdir / "summary.csv")
    summary = page.tables[1]               # tab, then the summary, then timings
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


@pytest.mark.skipif(CHROMIUM is None, reason="no Chromium found (Debian: apt-get install chromium; or set "
                                             "MORSUITE_CHROMIUM): the page is not checked in a browser")
@pytest.mark.parametrize("width,height,mobile", [(1280, 900, False), (390, 844, True)])
def test_page_renders_in_headless_chromium(results, width, height, mobile):
    from PIL import Image

    tmp, res = results
    with Browser(CHROMIUM) as b:
        for page in (res.outdir / "index.html", tmp / "results" / "index.html"):
            b.open(page.as_uri(), width, height, mobile)
            images = b.evaluate("[...document.images].map(i => [i.getAttribute('src'), i.complete, i.naturalWidth])")
            assert all(done and w > 0 for _, done, w in images), images
            assert b.errors() == []
            # nothing wider than the screen: wide tables scroll inside their box
            assert b.evaluate("document.documentElement.scrollWidth") <= width
            shot = Image.open(io.BytesIO(b.screenshot())).convert("L")
            px = np.asarray(shot, dtype=float)
            assert px.shape[1] == width and px.shape[0] >= height // 2
            assert (px < 200).mean() > 0.01 and px.std() > 10, "the screenshot is blank"
            shot.save(tmp / f"{page.parent.name}_{width}.png")   # to look at by hand
