"""The "scaling" benchmark: exponent fit, memory probe, quick run into a temporary directory."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from morsuite import bench
from morsuite.bench.memory import MemoryProbe
from morsuite.bench.output import json_default, resolve_out_dir, write_json
from morsuite.bench.scaling import bench_scaling, fit_exponent
from morsuite.bench.scaling_case import run_case, run_isolated


def test_fit_exponent_recovers_planted_exponent():
    n = np.array([1e3, 1e4, 1e5, 1e6])
    f = fit_exponent(n, 3.0 * n ** 1.07)
    assert f["exponent"] == pytest.approx(1.07, abs=1e-12)
    assert f["prefactor"] == pytest.approx(3.0, rel=1e-10)
    assert f["local_exponent"] == pytest.approx(1.07, abs=1e-12)
    assert f["points"] == 4
    rng = np.random.default_rng(0)
    noisy = 2e-6 * n ** 0.98 * np.exp(0.02 * rng.standard_normal(n.size))
    assert fit_exponent(n, noisy)["exponent"] == pytest.approx(0.98, abs=0.03)
    # unordered input, a failed point (nan) and a zero are left out
    f = fit_exponent([1e5, 1e3, 1e4, 1e6, 1e7], [1e5 ** 2, 1e3 ** 2, 1e4 ** 2, np.nan, 0.0])
    assert f["points"] == 3 and f["exponent"] == pytest.approx(2.0)
    assert f["local_exponent"] == pytest.approx(2.0)
    assert math.isnan(fit_exponent([10.0], [1.0])["exponent"])
    with pytest.raises(ValueError):
        fit_exponent([1, 2], [1, 2, 3])


def test_memory_probe_sees_an_allocation():
    with MemoryProbe() as probe:
        x = np.ones(4_000_000)  # 30.5 MiB
        x += 1
    del x
    assert probe.traced_peak_mb > 30
    assert probe.rss_peak_mb >= probe.rss_before_mb
    assert set(probe.as_dict()) >= {"tracemalloc_peak_mb", "rss_delta_mb", "rss_peak_mb"}


def test_resolve_out_dir_finds_bench_run_out(tmp_path):
    name = "_test_out_dir_probe"

    def probe(quick):
        return {"out": str(resolve_out_dir())}

    bench.BENCHMARKS[name] = probe
    try:
        res = bench.run([name], out_dir=tmp_path / "o", quick=True, echo=None)
    finally:
        del bench.BENCHMARKS[name]
    assert res[name]["out"] == str(tmp_path / "o")
    assert resolve_out_dir(tmp_path) == tmp_path


def test_run_case_reports_guard_and_isolated_child():
    row = run_case({"model": "dsms", "size": 300, "task": "irka-projected", "r": 4,
                    "options": {"memory_budget_gib": 1e-6}})
    assert row["status"] == "refused by memory guard" and "memory_budget_gib" in row["message"]
    row = run_isolated({"model": "dsms", "size": 200, "task": "freqresp", "r": 4, "nfreq": 20,
                         "nfreq_measured": 10}, timeout_s=120, rss_limit_gib=4)
    assert row["status"] == "ok", row
    assert row["scaled"] and row["nfreq_measured"] == 10
    assert row["time_s"] == pytest.approx(2 * row["time_measured_s"])
    assert row["rss_delta_mb"] >= 0 and np.isfinite(row["tracemalloc_peak_mb"])


@pytest.mark.slow
def test_scaling_quick_writes_finite_results(tmp_path):
    res = bench_scaling(True, tmp_path, echo=None)
    for name in ("scaling.csv", "scaling.md", "scaling_fits.csv", "scaling_fits.md", "scaling.png"):
        assert (tmp_path / name).stat().st_size > 0, name
    assert not (tmp_path / "scaling.partial.json").exists()
    json.dumps(res, default=json_default)  # what bench.run writes
    df = pd.read_csv(tmp_path / "scaling.csv")
    ok = df[df["status"] == "ok"]
    assert set(ok["task"]) >= {"irka", "bt", "freqresp", "irka-projected"}
    for col in ("time_s", "tracemalloc_peak_mb", "rss_delta_mb", "n1"):
        assert np.all(np.isfinite(ok[col].astype(float))), col
    assert (ok["time_s"] > 0).all()
    assert (df["status"] == "refused by memory guard").sum() == 1
    fits = pd.read_csv(tmp_path / "scaling_fits.csv")
    assert np.all(np.isfinite(fits["time_exponent"]))
    md = (tmp_path / "scaling_fits.md").read_text()
    assert "time_exponent" in md and "dsms" in md
    assert all(np.isfinite(r["value"]) for r in res["ratios"].values())
    assert res["code"]["digest"] and all(r.get("code_digest") for r in res["rows"] if r["status"] == "ok")
    from morsuite.bench.scaling import rewrite

    write_json(tmp_path / "scaling.json", res)
    rewrite(tmp_path)
    again = json.loads((tmp_path / "scaling.json").read_text())
    assert again["ratios"].keys() == res["ratios"].keys()


def test_write_readme_summarises_every_json(tmp_path):
    from morsuite.bench.readme import write_readme

    (tmp_path / "irka.json").write_text(json.dumps({
        "benchmark": "irka", "quick": False, "wall_time_s": 3.0, "finished": "now",
        "ratios": {"dsms r=20": {"value": 1.2, "target": 1.5, "what": "w"},
                   "tcom r=30": {"value": 1.6, "target": 1.5, "what": "w"}},
        "rows": [{"model": "dsms", "r": 20, "ratio": 1.2, "time_s": 0.5}]}))
    (tmp_path / "other.json").write_text(json.dumps({"ratios": {"x": {"value": 0.5, "target": None}}}))
    (tmp_path / "broken.json").write_text("{")
    (tmp_path / "scaling.partial.json").write_text("[]")
    text = write_readme(tmp_path).read_text()
    assert "## irka" in text and "ABOVE TARGET" in text and "| dsms | 20 | 0.5 | 1.2 |" in text
    assert "## other" in text and "## broken" in text and "unreadable" in text
    assert "partial" not in text


@pytest.mark.slow
def test_tcom_large_bench_records_times_memory_and_choices():
    """The tcom-1e6 benchmark on a small plan: both cases finish in child processes, with their
    LU counts, phases, peak RSS, the load, and the size-dependent choices resolved as at small n1
    (no compression, no stage stall); one time and one memory ratio per case, against issue 33's targets."""
    from morsuite.bench.tcom_large import TARGETS, bench_tcom_large

    res = bench_tcom_large(True, plan={"nc": 40, "timeout_s": {"irka": 300, "bt": 300}, "rss_limit_gib": 4},
                           echo=None)
    rows = {r["task"]: r for r in res["rows"]}
    assert set(rows) == {"irka", "bt"}
    for task, row in rows.items():
        assert row["status"] == "ok", row
        assert row["n1"] == 121 and row["lu_count"] > 0 and row["time_s"] > 0 and row["time_breakdown"]
        assert 0 < row["peak_rss_gib"] < 4 and len(row["load_before"]) == 3
        t = res["ratios"][f"{task} time / {TARGETS[task]:g} s"]
        assert t["value"] == pytest.approx(row["time_s"] / TARGETS[task]) and t["target"] == 1.0
        assert res["ratios"][f"{task} peak RSS / 24 GiB"]["value"] == pytest.approx(row["peak_rss_gib"] / 24)
    assert rows["bt"]["compress_tol"] == 0.0 and rows["irka"]["stage_stall"] == 0
    assert rows["bt"]["factor_ranks"]["controllability"] > 0
    json.dumps(res, default=json_default)


def test_tcom_large_bench_runs_the_cases_asked_for():
    """``tcom-1e6-irka`` / ``tcom-1e6-bt`` are registered and run their one case only, with only its ratios."""
    from morsuite.bench import BENCHMARKS, available
    from morsuite.bench.tcom_large import bench_tcom_large

    assert {"tcom-1e6", "tcom-1e6-irka", "tcom-1e6-bt"} <= set(available())
    res = bench_tcom_large(True, plan={"nc": 20, "timeout_s": {"bt": 300}, "rss_limit_gib": 4}, echo=None,
                           tasks=("bt",))
    assert [r["task"] for r in res["rows"]] == ["bt"] and res["rows"][0]["status"] == "ok"
    assert sorted(res["ratios"]) == ["bt peak RSS / 24 GiB", "bt time / 1200 s"]
    assert BENCHMARKS["tcom-1e6-bt"].__doc__ and BENCHMARKS["tcom-1e6-irka"].__doc__


def test_fem_large_bench_runs_irka_fo_on_a_3d_solid():
    """``fem-1e5-irka-fo`` on a small plan: the case runs in a child process on fem_block, with its LU
    count, time per LU, peak RSS and the time ratio over its limit; the three fem benches are registered."""
    from morsuite.bench import BENCHMARKS, available
    from morsuite.bench.tcom_large import bench_fem_large

    assert {"fem-1e5", "fem-1e5-irka-fo", "fem-1e5-bt"} <= set(available())
    res = bench_fem_large(True, plan={"n1": 600, "timeout_s": {"irka-fo": 300}, "rss_limit_gib": 4}, echo=None,
                          tasks=("irka-fo",))
    (row,) = res["rows"]
    assert row["status"] == "ok" and row["model"] == "fem_block" and 500 < row["n1"] < 700, row
    assert row["lu_count"] > 0 and row["time_per_lu_s"] == pytest.approx(row["time_s"] / row["lu_count"])
    assert sorted(res["ratios"]) == ["irka-fo peak RSS / 24 GiB", "irka-fo time / 300 s"]
    assert res["ratios"]["irka-fo time / 300 s"]["value"] == pytest.approx(row["time_s"] / 300)
    assert BENCHMARKS["fem-1e5-bt"].__doc__ and BENCHMARKS["fem-1e5-irka-fo"].__doc__


def test_bench_run_records_the_code_of_every_benchmark(tmp_path):
    """``bench.run`` adds the code state (git HEAD, digests) before and after to a result that has none."""
    from morsuite import bench
    from morsuite.bench.output import code_state

    bench.BENCHMARKS["_probe"] = lambda quick: {"ratios": {}}
    try:
        res = bench.run(["_probe"], out_dir=tmp_path, quick=True, echo=None)["_probe"]
    finally:
        del bench.BENCHMARKS["_probe"]
    now = code_state(git=False)
    assert res["code"]["digest"] == res["code_start"]["digest"] == now["digest"]
    assert json.loads((tmp_path / "_probe.json").read_text())["code"]["modules"] == now["modules"]
