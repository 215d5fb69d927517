"""The results tables of the docs (docs/_ext/morsuite_results.py) read the study CSVs at build time.

A regenerated ``results/`` whose columns or rows no longer match a page's
``morsuite-results-table`` would only fail the -W docs build; these tests catch it where
the results are regenerated, and check the shown cells against the CSV read by pandas.
"""

import importlib.util
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[1]
DIRECTIVE = re.compile(r"```\{morsuite-results-table\} (?P<path>\S+)\n(?P<opts>(?::\w+:.*\n)*)```")


@pytest.fixture(scope="module")
def ext():
    pytest.importorskip("docutils")
    path = ROOT / "docs" / "_ext" / "morsuite_results.py"
    spec = importlib.util.spec_from_file_location("morsuite_results_for_test", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _directives():
    for page in sorted((ROOT / "docs").rglob("*.md")):
        for m in DIRECTIVE.finditer(page.read_text(encoding="utf-8")):
            opts = dict(re.match(r":(\w+): ?(.*)", line).groups() for line in m["opts"].splitlines())
            yield page, (page.parent / m["path"]).resolve(), opts


def test_every_results_table_of_the_docs_matches_its_csv(ext):
    found = list(_directives())
    assert found, "no morsuite-results-table in docs/*.md"
    for page, csv, opts in found:
        if not csv.exists():
            pytest.skip(f"{csv} not generated here (results/ is written by the main command)")
        header, body, _ = ext.results_table(str(csv), opts.get("where"), opts.get("columns"), opts.get("sort"),
                                            opts.get("labels"))
        frame = pd.read_csv(csv, dtype=str, keep_default_na=False)
        for col, vals in ext._pairs(opts.get("where")):
            frame = frame[frame[col].isin([v.strip() for v in vals.split(",")])]
        assert len(body) == len(frame) > 0, f"{page.name}: {csv.name}"
        assert len(header) == len(body[0])


def test_cells_round_the_csv_values_and_flag_untrusted_h2(ext, tmp_path):
    csv = tmp_path / "summary.csv"
    pd.DataFrame({"method": ["irka", "bt", "so_h2"], "r": [30, 30, 30], "converged": [True, True, False],
                  "h2_error": [1024.2475, 2.880429867e-17, np.nan], "h2_trusted": [True, False, True],
                  "time_standalone_s": [2.32608, 0.0283629, 37.6011]}).to_csv(csv, index=False)
    header, body, flagged = ext.results_table(str(csv), "method=bt,irka,so_h2",
                                              "method=m; converged=conv.; h2_error=H2; time_standalone_s",
                                              "method", "bt=BT (vv)")
    assert header == ["m", "conv.", "H2", "time_standalone_s"]
    assert [row[0] for row in body] == ["BT (vv)", "irka", "so_h2"]  # the order of :where:
    assert body[0][2] == "(2.88e-17)" and flagged  # untrusted: in parentheses
    assert float(body[1][2]) == pytest.approx(1024.2475, rel=5e-3)
    assert body[1][2] == "1.02e3" and body[2][2] == "-" and body[2][1] == "no"
    assert body[1][3] == "2.3" and body[0][3] == "0.028"  # times: two significant digits
    with pytest.raises(ValueError, match="no column"):
        ext.results_table(str(csv), "model=x")
