"""The "pareto" benchmark: quick run through ``morsuite.bench.run``; the stack profiler."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from morsuite import bench
from morsuite.bench.pareto import _compare
from morsuite.bench.profiler import REST, StackProfiler
from morsuite.linalg.dense import orth


def test_stack_profiler_charges_by_call_stack():
    n = 20000
    A = sp.diags([-np.ones(n - 1), 4 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csc")
    X = np.random.default_rng(0).standard_normal((n, 40))

    def work():
        lu = spla.splu(A)
        lu.solve(X[:, :5])
        orth(X)
        sum([i * i for i in range(20000)])  # pure Python

    prof = StackProfiler()
    prof.run(work)
    s = prof.summary()
    cats = s["categories_s"]
    assert cats["sparse LU (SuperLU gstrf)"] > 0
    assert cats["sparse triangular solves (SuperLU)"] > 0
    assert cats["orthogonalisation (QR/SVD of n1 x k bases)"] > 0
    assert cats[REST] > 0
    assert s["total_s"] == sum(cats.values())
    assert s["groups_s"]["floor"] > 0


def test_compare_counts_wins_at_equal_states():
    rows = [{"method": "irka", "status": "ok", "states_nominal": 4, "r_requested": 2, "max_abs_error": 1e-3,
             "time_standalone_s": 1.0, "converged": True, "stable": True},
            {"method": "bt", "status": "ok", "states_nominal": 4, "r_requested": 4, "max_abs_error": 1e-4,
             "time_standalone_s": 2.0, "converged": True, "stable": True},
            {"method": "irka", "status": "ok", "states_nominal": 8, "r_requested": 4, "max_abs_error": 1e-6,
             "time_standalone_s": 1.0, "converged": True, "stable": True},
            {"method": "bt", "status": "ok", "states_nominal": 8, "r_requested": 8, "max_abs_error": 1e-5,
             "time_standalone_s": 0.5, "converged": True, "stable": True}]
    pairs, s = _compare(rows, "m", "bt", noise=1e-14)
    assert [p["more_accurate"] for p in pairs] == ["bt", "irka"]
    assert [p["faster"] for p in pairs] == ["irka", "bt"]
    assert s["claim_holds"] == 0 and s["pairs"] == 2 and "refuted" in s["verdict"]


def test_pareto_quick_through_bench_run(tmp_path):
    res = bench.run(["pareto"], out_dir=tmp_path, quick=True, echo=None)["pareto"]
    data = json.loads((tmp_path / "pareto.json").read_text())
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert "pareto" in manifest["benchmarks"] and manifest["machine"]["cpu_count"] >= 1
    for name in ("pareto.csv", "pareto.md", "pareto_verdict.csv", "pareto_verdict.md", "pareto_pairs.csv",
                 "pareto_floor.csv", "pareto_floor.md", "pareto_floor.png", "pareto_dsms_g200.png",
                 "pareto_tcom_nc20.png"):
        assert (tmp_path / name).stat().st_size > 0, name
    df = pd.read_csv(tmp_path / "pareto.csv")
    ok = df[df["status"] == "ok"]
    assert set(ok["method"]) == {"irka", "bt", "bt-vv", "irka-projected", "irka-fo", "so-h2"}
    soh2 = pd.read_csv(tmp_path / "pareto_soh2.csv")
    assert list(soh2["r"]) == [2, 4] and (soh2["so_h2_lus"] >= soh2["bt_vv_lus"]).all()
    assert (ok[ok["method"] == "so-h2"]["lu_count_standalone"] > 0).all()
    for col in ("time_s", "time_standalone_s", "max_abs_error", "max_rel_error"):
        assert np.all(np.isfinite(ok[col])), col
    assert (ok["time_standalone_s"] >= ok["time_s"] - 1e-12).all()
    from morsuite.reducers.outcome import CONVERGED_STATUSES, STATUS
    assert set(ok["reducer_status"]) <= set(STATUS) and "worse_than_zero" in df
    assert (ok["converged"] == ok["reducer_status"].isin(CONVERGED_STATUSES)).all()
    assert (ok["lu_count_standalone"] >= ok["lu_count"]).all()
    floor = pd.read_csv(tmp_path / "pareto_floor.csv")
    assert np.all(np.isfinite(floor["ratio"])) and (floor["ratio"] > 0).all()
    for x in data["floor"]:
        total = x["profile"]["total_s"]
        assert total > 0 and abs(sum(x["profile"]["categories_s"].values()) - total) < 1e-9 * max(total, 1)
    verdict = (tmp_path / "pareto_verdict.md").read_text()
    assert "claim" in verdict
    assert all(np.isfinite(r["value"]) for r in res["ratios"].values())
    assert {v["matched_on"] for v in data["verdicts"]} == {"states", "r"}
    # derived tables can be recomputed from the JSON without measuring again
    from morsuite.bench.pareto import rewrite

    rewrite(tmp_path)
    again = json.loads((tmp_path / "pareto.json").read_text())
    assert again["rows"] == data["rows"] and len(again["pairs"]) == len(data["pairs"])
