"""The shared pieces of morsuite.bench: the floor's LU, the shifts of a run, run and floor
back to back, tables with a Markdown subset, the package's command line."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

import morsuite as ms
from morsuite import bench
from morsuite.bench.floor import (FloorRun, adi_lu_shifts, bare_lu_floor, bare_splu, irka_lu_shifts, lu_floor,
                                  median_run, run_against_floor, upper_half)
from morsuite.bench.output import write_table
from morsuite.report.tables import read_markdown


def _dense_saddle(fom, s):
    M, D, K, G = (x.toarray() for x in (fom.M, fom.D, fom.K, fom.G))
    return np.block([[s * s * M + s * D + K, G.T], [G, np.zeros((fom.n2, fom.n2))]])


def test_floor_lu_is_an_lu_of_the_saddle_matrix():
    fom = ms.models.dsms(g=40)
    solver = fom.new_solver(cache_size=0)
    s = 0.3 + 0.7j
    S = _dense_saddle(fom, s)
    lu = bare_splu(solver, solver.matrix(s))
    b = np.vstack([fom.F, np.zeros((fom.n2, fom.m))]).astype(complex)
    kappa = np.linalg.cond(S)
    for x, ref in ((lu.solve(b), np.linalg.solve(S, b)), (lu.solve(b, trans="T"), np.linalg.solve(S.T, b))):
        assert np.linalg.norm(x - ref) <= 1e-13 * kappa * np.linalg.norm(ref)


def test_shifts_of_a_run_one_per_real_shift_or_conjugate_pair():
    plain = [{"re": -1.0, "im": 2.0}, {"re": -1.0, "im": -2.0}, -3.0]  # the plain-data form in info
    assert set(upper_half(plain)) == {-1 + 2j, -3 + 0j}
    info = {"adi": {"controllability": {"shifts": plain}},
            "history": {"shifts": [plain, [-5.0, -6.0]]}}
    assert set(adi_lu_shifts(info)) == {1 - 2j, 3 + 0j}  # LR-ADI factorizes S(-p)
    assert sorted(irka_lu_shifts(info), key=lambda z: (z.real, z.imag)) == [-6, -5, -3, -1 + 2j]


def test_run_against_floor_and_median():
    fom = ms.models.dsms(g=60)
    shifts = [0.1 + 0.5j, 0.2]
    info = {"lu_count": 4, "shifts": shifts}
    fr = run_against_floor(fom, lambda: (1.0, info), lambda i: i["shifts"])
    assert fr.info is info and fr.time_s == 1.0 and 0 < fr.floor_s < 1.0
    assert fr.ratio == pytest.approx(1.0 / fr.floor_s)
    assert bare_lu_floor(fom, [], 3) == 0.0
    runs = [FloorRun(3.0, 1.0, {}), FloorRun(1.0, 1.0, {}), FloorRun(4.0, 2.0, {})]
    assert median_run(runs).time_s == 4.0  # ratios 3, 1, 2: the median is 2
    with pytest.raises(ms.MorsuiteError, match="shifts"):
        lu_floor(fom, [])


def test_write_table_markdown_shows_a_subset(tmp_path):
    df = pd.DataFrame({"a": [1, 2], "b": [0.5, 0.25], "c": ["x", "y"]})
    files = write_table(df, tmp_path / "t", title="T", note="n", md_columns=["c", "a", "missing"])
    assert [p.name for p in files] == ["t.csv", "t.md"]
    pd.testing.assert_frame_equal(pd.read_csv(files[0]), df)
    md = files[1].read_text()
    assert md.startswith("## T\n\nn\n\n")
    back = read_markdown(md[md.index("|"):])
    assert list(back.columns) == ["c", "a"] and list(back["a"]) == ["1", "2"]


def test_package_command_line_writes_readme(tmp_path, capsys):
    from morsuite.bench.__main__ import main

    bench.run(["irka"], out_dir=tmp_path, quick=True, echo=None)
    assert main(["--readme", str(tmp_path)]) == 0
    text = (tmp_path / "README.md").read_text()
    assert "## irka" in text and "python -m morsuite.bench --readme DIR" in text
    data = json.loads((tmp_path / "irka.json").read_text())
    assert {row["model"] for row in data["rows"]} == {"dsms:g=600", "tcom:nc=200"}
    assert all(np.isfinite(r["value"]) and r["value"] > 0 for r in data["ratios"].values())


def test_profile_categories_and_key_modules_name_existing_code():
    """The profiler's categories and the code-state digest name morsuite files by path: after a
    module is split or renamed they must follow, or time lands silently in "Python overhead"."""
    import ast
    from pathlib import Path

    import morsuite
    from morsuite.bench import output, profiler

    pkg = Path(morsuite.__file__).resolve().parent
    for rel in output._KEY_MODULES:
        assert (pkg / rel).is_file(), f"_KEY_MODULES names a missing file {rel}"
    for _group, category, matchers in profiler.CATEGORIES:
        for where, func in matchers:
            if where == "builtin" or not where.endswith(".py") or not where.startswith(("linalg/", "reducers/",
                                                                                       "models/", "analysis/")):
                continue
            path = pkg / where
            assert path.is_file(), f"category {category!r} names a missing file {where}"
            if func != "*":
                names = {n.name for n in ast.walk(ast.parse(path.read_text()))
                         if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}
                assert func in names, f"category {category!r}: {where} has no function {func}"
