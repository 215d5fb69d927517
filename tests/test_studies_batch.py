"""Several studies computed together on pinned worker processes (morsuite.studies.batch).

The reference is the sequential run (``--jobs 1``: one study after the other on Dask's
synchronous scheduler): the same numbers, the same files, and the artifacts two studies
share computed once and recorded as computed by the first study only.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest

from morsuite.cli import main
from morsuite.studies import tasks as T
from morsuite.studies.batch import Shared, _chunks, split_claims

A = """
name = "sa"
title = "small a"
norms = ["h2"]
[models]
tcom = "tcom:nc=20"
[grids]
g = { band = [1e-3, 1.0], n = 30 }
[methods.irka]
reducer = "irka"
[methods.bt]
reducer = "bt"
options = { form = "vv" }
[[scenes]]
name = "a_err"
kind = "error_vs_r"
model = "tcom"
grid = "g"
methods = ["irka", "bt"]
r = [2, 4, 6]
"""

B = """
name = "sb"
title = "small b"
[models]
tcom = "tcom:nc=20"
[grids]
g = { band = [1e-3, 1.0], n = 30 }
[methods.irka]
reducer = "irka"
[methods.bt]
reducer = "bt"
options = { form = "vv" }
[[scenes]]
name = "b_h2"
kind = "error_vs_r"
model = "tcom"
methods = ["irka", "bt"]
r = [4, 6, 8]
measure = "h2"
[[scenes]]
name = "b_band"
kind = "error_vs_r"
model = "tcom"
grid = "g"
methods = ["irka"]
r = [4, 8]
"""

NUMBERS = ["max_abs_error", "max_rel_error", "h2_error", "h2_rel_error"]


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("batch")
    a, b = d / "a.toml", d / "b.toml"
    a.write_text(A)
    b.write_text(B)
    assert main(["run", str(a), str(b), "--out", str(d / "seq"), "--jobs", "1", "--quiet"]) == 0
    assert main(["run", str(a), str(b), "--out", str(d / "par"), "--jobs", "2", "--quiet"]) == 0
    return d


def _manifest(root, name):
    return json.loads((root / name / "manifest.json").read_text())


@pytest.mark.slow
def test_shared_run_gives_the_sequential_numbers(two_runs):
    """Summaries of the shared (2 pinned workers) and the sequential run agree to 1e-12."""
    for name in ("sa", "sb"):
        seq = pd.read_csv(two_runs / "seq" / name / "summary.csv")
        par = pd.read_csv(two_runs / "par" / name / "summary.csv")
        keys = ["method", "r_requested"]
        seq, par = seq.sort_values(keys).reset_index(drop=True), par.sort_values(keys).reset_index(drop=True)
        assert list(seq.method) == list(par.method) and list(seq.r_requested) == list(par.r_requested)
        for col in [c for c in NUMBERS if c in seq]:
            # the same computations on pinned workers (measured equal): a determinism check
            np.testing.assert_allclose(par[col].to_numpy(float), seq[col].to_numpy(float), rtol=1e-12, atol=0,
                                       err_msg=f"{name}: {col}")
        assert sorted(p.name for p in (two_runs / "par" / name).iterdir()) == \
            sorted(p.name for p in (two_runs / "seq" / name).iterdir())


@pytest.mark.slow
def test_shared_artifacts_are_computed_once_and_claimed_by_the_first_study(two_runs):
    """irka r = 4, 6 and bt r = 4, 6 are in both studies: computed in sa, reused in sb, as in
    the sequential run; each unit ran on one core; the record is in both manifests."""
    for root in ("seq", "par"):
        red = {}
        for name in ("sa", "sb"):
            for a in _manifest(two_runs / root, name)["artifacts"]:
                if a["kind"] == "reduction":
                    red.setdefault((a["reducer"], a["r_requested"]), []).append((name, a["cached"]))
        assert red[("irka", 4)] == [("sa", False), ("sb", True)], root
        assert red[("bt", 6)] == [("sa", False), ("sb", True)], root
        assert red[("irka", 8)] == [("sb", False)], root
    m = _manifest(two_runs / "par", "sb")
    rec = m["shared_compute"]
    assert rec["jobs"] == 2 and rec["units"] >= 4 and rec["pinned"] and 0 < m["timing"]["shared_compute_s"]
    assert all(a["scheduler"] == "processes (shared)" for a in m["artifacts"] if a["kind"] == "reduction")
    assert "shared_compute" not in _manifest(two_runs / "seq", "sb")


@pytest.mark.slow
def test_the_shared_run_writes_its_record(two_runs):
    """OUT/run.json: the studies in command-line order, the wall and busy time, and one log entry per
    unit (the same count as the manifests' record); the sequential run writes none."""
    rec = json.loads((two_runs / "par" / "run.json").read_text())
    assert rec["studies"] == ["sa", "sb"] and rec["jobs"] == 2 and rec["wall_s"] > 0 and rec["busy_s"] > 0
    assert len([e for e in rec["log"] if e["kind"] != "study"]) == _manifest(two_runs / "par", "sa")["shared_compute"]["units"]
    assert not (two_runs / "seq" / "run.json").exists()


@pytest.mark.slow
def test_a_cached_shared_run_computes_nothing(two_runs, tmp_path):
    """The same command again: no unit of work, every computed artifact taken from the cache. Into a
    copy of the shared run's folder: the module's other tests read its manifests as the first run wrote
    them, in whatever order they run."""
    shutil.copytree(two_runs / "par", tmp_path / "par")
    assert main(["run", str(two_runs / "a.toml"), str(two_runs / "b.toml"), "--out", str(tmp_path / "par"),
                 "--jobs", "2", "--quiet"]) == 0
    m = _manifest(tmp_path / "par", "sa")
    assert "shared_compute" not in m  # nothing to share: the studies ran in this process
    computed = [a for a in m["artifacts"] if a["kind"] not in ("figure", "table", "page")]
    assert computed and all(a["reused"] and a["cached"] for a in computed)


@pytest.mark.slow
def test_default_workers_give_the_numbers_of_two(two_runs, tmp_path, monkeypatch):
    """Without --jobs: as many workers as usable cores (three here, however many the machine has, with the
    usable cores stubbed; the workers are pinned round-robin to the real ones) when the memory holds them; the
    study's summary agrees with the two-worker run's to 1e-12, and run.json records the rule."""
    from morsuite.studies import workers
    monkeypatch.setattr(workers, "usable_cores", lambda: [0, 1, 2])
    rule = workers.default_jobs(61, available=2 ** 40)  # tcom:nc=20: n1 = 61
    assert rule["jobs"] == 3 and rule["by_memory"] > 3
    b = two_runs / "b.toml"
    if workers.available_memory() is not None and workers.available_memory() < 3 * rule["worker_mib"] * 2 ** 20:
        pytest.skip("less available memory than three workers' estimate")
    assert main(["run", str(b), "--out", str(tmp_path / "auto"), "--quiet"]) == 0
    rec = json.loads((tmp_path / "auto" / "run.json").read_text())
    assert rec["jobs"] == 3 and rec["jobs_rule"]["jobs"] == 3 and rec["jobs_rule"]["cores"] == 3
    keys = ["method", "r_requested"]
    par = pd.read_csv(two_runs / "par" / "sb" / "summary.csv").sort_values(keys).reset_index(drop=True)
    auto = pd.read_csv(tmp_path / "auto" / "sb" / "summary.csv").sort_values(keys).reset_index(drop=True)
    assert list(auto.method) == list(par.method) and list(auto.r_requested) == list(par.r_requested)
    for col in [c for c in NUMBERS if c in par]:
        np.testing.assert_allclose(auto[col].to_numpy(float), par[col].to_numpy(float), rtol=1e-12, atol=0,
                                   err_msg=col)
    assert json.loads((two_runs / "par" / "run.json").read_text())["jobs_rule"] == "given"


def test_default_jobs_rule(monkeypatch):
    """default_jobs: min(cores, available / (256 MiB + 64 KiB n1)), at least 1, with the numbers worked by hand:
    16 cores and 64 GiB at n1 = 2e4 (1506 MiB a worker: 43 fit) give 16; 16 GiB give 10 (16384 / 1506 =
    10.9); 4 GiB at n1 = 1e5 (6506 MiB) give 1 (none fits: still one); no memory figure: the cores."""
    from morsuite.studies import workers
    from morsuite.studies.workers import default_jobs
    cores = list(range(16))
    assert default_jobs(20_000, cores, 64 * 2 ** 30)["jobs"] == 16
    r = default_jobs(20_000, cores, 16 * 2 ** 30)
    assert r["jobs"] == 10 and r["worker_mib"] == 1506.0 and r["by_memory"] == 10
    assert default_jobs(100_000, cores, 4 * 2 ** 30)["jobs"] == 1
    assert default_jobs(100_000, [0, 1], 0)["jobs"] == 1
    monkeypatch.setattr(workers, "available_memory", lambda: None)
    r = default_jobs(10 ** 6, cores[:4])
    assert r["jobs"] == 4 and r["by_memory"] is None and r["available_mib"] is None


def test_split_orders_give_the_same_reduced_models():
    """irka has no r-independent work: r = 6 on its own instance is the ROM of a sweep 2, 4, 6."""
    T._model.cache_clear()
    keys = {r: f"k{r}" for r in (2, 4, 6)}
    sweep = T.reduce_sweep("tcom:nc=20", "irka", {}, [2, 4, 6], keys)
    alone = T.reduce_sweep("tcom:nc=20", "irka", {}, [6], keys)
    for name, x in sweep[6]["rom"]["arrays"].items():
        np.testing.assert_allclose(alone[6]["rom"]["arrays"][name], x, rtol=1e-13, atol=0)  # measured equal
    assert alone[6]["info"]["iterations"] == sweep[6]["info"]["iterations"]


def test_chunks_are_consecutive_and_balanced():
    rs = [2, 4, 6, 8, 10, 12]
    est = dict(zip(rs, [1.0, 1.0, 1.0, 1.0, 4.0, 4.0]))
    parts = _chunks(rs, est, 3)
    assert [r for p in parts for r in p] == rs and len(parts) == 3
    assert parts[-1] == [12] and parts[-2] == [10]
    assert _chunks(rs, {r: None for r in rs}, 2) == [[2, 4, 6], [8, 10, 12]]
    assert _chunks([4], {4: 1.0}, 3) == [[4]]


def test_claims_go_to_the_first_study_that_reads_them(tmp_path):
    from morsuite.studies import load_spec

    (tmp_path / "a.toml").write_text(A)
    (tmp_path / "b.toml").write_text(B)
    sa, sb = load_spec(tmp_path / "a.toml"), load_spec(tmp_path / "b.toml")
    from morsuite.studies.plan import build_plan
    pa, pb = build_plan(sa), build_plan(sb)
    ga = next(g for g in pa.reduces.values() if g.method.reducer == "irka")
    gb = next(g for g in pb.reduces.values() if g.method.reducer == "irka")
    fresh = {("reduction", ga.keys[4]), ("reduction", gb.keys[8]), ("reduction", "not-read")}
    one, two = split_claims([sa, sb], Shared(2, fresh))
    assert one.fresh == {("reduction", ga.keys[4])} and two.fresh == {("reduction", gb.keys[8])}
    assert one.claim("reduction", ga.keys[4]) and not one.claim("reduction", ga.keys[4])


def test_each_unit_runs_on_one_pinned_core(tmp_path):
    """shared_compute alone: every unit's worker had one core (its own, in turn), IRKA's
    automatic solver threads resolved to 1 there, and the results are in the cache."""
    from morsuite.studies import load_spec
    from morsuite.studies.batch import shared_compute, usable_cores
    from morsuite.studies.cache import Cache
    from morsuite.studies.plan import build_plan

    (tmp_path / "a.toml").write_text(A)
    study = load_spec(tmp_path / "a.toml")
    cache = Cache(tmp_path / "cache")
    shared = shared_compute([study], cache, jobs=2)
    log = shared.record["log"]
    assert log and all(len(e["cores"]) == 1 for e in log)
    if len(usable_cores()) >= 2:
        assert {e["cores"][0] for e in log} <= set(usable_cores()) and len({e["pid"] for e in log}) <= 2
    g = next(g for g in build_plan(study).reduces.values() if g.method.reducer == "irka")
    for r in g.rs:
        arrays, meta = cache.get("reduction", g.keys[r])
        assert meta["info"]["solver_threads"] == 1 and ("reduction", g.keys[r]) in shared.fresh


def test_a_study_waits_for_what_another_study_claims(tmp_path):
    """Each study's own run depends on every unit computing something it reads, also on those whose
    entries an earlier study claims (sb reads irka r = 4, which sa claims): otherwise it may start
    first and compute them itself (the race CI met when the workers' start was slow)."""
    from morsuite.studies.batch import _add_study_units, _units
    from morsuite.studies.cache import Cache
    from morsuite.studies.plan import build_plan
    from morsuite.studies.spec import load_spec

    (tmp_path / "a.toml").write_text(A)
    (tmp_path / "b.toml").write_text(B)
    studies = [load_spec(tmp_path / "a.toml"), load_spec(tmp_path / "b.toml")]
    plans = [build_plan(s) for s in studies]
    units = _units(plans, Cache(tmp_path / "cache"), {})
    owners = _add_study_units(units, studies, plans, {"out": str(tmp_path / "out")})
    computing = {u.id: {(u.kind, k) for k in u.keys.values()} for u in units.values() if u.kind != "study"}
    for study, plan in zip(studies, plans):
        reads = {("reduction", g.keys[r]) for g in plan.reduces.values() for r in g.rs}
        needed = {uid for uid, keys in computing.items() if keys & reads}
        assert needed and needed <= units[f"study-{study.name}"].deps, study.name
    irka4 = next(("reduction", g.keys[4]) for g in plans[1].reduces.values() if g.method.reducer == "irka")
    assert irka4 in owners["study-sa"] and irka4 not in owners["study-sb"]
