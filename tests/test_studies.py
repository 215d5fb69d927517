"""The study runner: validation, planning (only what the scenes need), schedulers,
cache, and the outputs (CSV, PNG, Markdown, pgfplots, manifest).

Small models only (dsms g = 100, tcom nc = 20, r in 2..6, 30-50 frequencies).
Tests that need "bt" or "irka-projected" skip when those reducers are not registered.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import morsuite as ms
from morsuite.errors import SpecError
from morsuite.reducers.outcome import CONVERGED_STATUSES, STATUS
from morsuite.report.tables import read_markdown
from morsuite.studies import load_spec, run
from morsuite.studies import tasks as study_tasks

BASE = """
name = "small"
title = "small study"

[models]
dsms = "dsms:g=100"
tcom = "tcom:nc=20"

[grids]
g40 = { band = [1e-2, 1.0], n = 40 }
g30 = { band = [1e-3, 1.0], n = 30 }

[methods.irka]
label = "IRKA"
options = { tol = 1e-6 }

[[scenes]]
name = "dsms_sigma"
kind = "sigma"
model = "dsms"
grid = "g40"
r = 4
paper_csv = { full = "no/such/dir/paper_full.csv" }

[[scenes]]
name = "dsms_abs"
kind = "error"
model = "dsms"
grid = "g40"
r = 4

[[scenes]]
name = "dsms_time"
kind = "time_vs_r"
model = "dsms"
r = [2, 4]
axis = "states"

[[scenes]]
name = "tcom_err_r"
kind = "error_vs_r"
model = "tcom"
grid = "g30"
r = { from = 2, to = 6, step = 2 }

[[scenes]]
name = "tcom_pareto"
kind = "pareto"
model = "tcom"
grid = "g30"
r = [2, 4, 6]

[[scenes]]
name = "tcom_conv"
kind = "convergence"
model = "tcom"
r = [2, 4]

[[scenes]]
name = "tcom_table"
kind = "table"
model = "tcom"
grid = "g30"
r = [2, 4, 6]
"""


def _write(tmp_path, text, name="small.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _drop_scene(text, scene):
    """The spec text without the [[scenes]] block named ``scene``."""
    blocks = text.split("[[scenes]]")
    kept = [b for b in blocks[1:] if f'name = "{scene}"' not in b]
    assert len(kept) == len(blocks) - 2
    return "[[scenes]]".join([blocks[0]] + kept)


COMPUTED = ("fom_response", "reduction", "metrics")   # the other artifacts are figures and tables


def _artifact_ids(manifest, kind=None):
    return {(a["kind"], a["model"], a.get("reducer"), a.get("r_requested"), tuple(a.get("grid") or ()))
            for a in manifest["artifacts"] if (kind is None and a["kind"] in COMPUTED) or a["kind"] == kind}


@pytest.fixture(scope="module")
def base_run(tmp_path_factory):
    """One synchronous run of the base study (fresh cache) shared by the output tests."""
    tmp = tmp_path_factory.mktemp("base")
    res = run(_write(tmp, BASE), out=tmp / "results", quiet=True)
    return tmp, res


# -- validation ------------------------------------------------------------
@pytest.mark.parametrize("old,new,named", [
    ('title = "small study"', 'titel = "x"', "titel"),                       # top-level key
    ('grid = "g40"\nr = 4\npaper', 'gird = "g40"\nr = 4\npaper', "gird"),    # scene key
    ('options = { tol = 1e-6 }', 'options = { tol = 1e-6, maxiter = 5 }', "maxiter"),   # reducer option
    ('options = { tol = 1e-6 }', 'options = { tol = 7.0 }', "tol"),           # option value
    ('[methods.irka]', '[methods.irka]\nreducer = "irkaa"', "irkaa"),         # reducer
    ('dsms = "dsms:g=100"', 'dsms = "dsmss:g=100"', "dsmss"),                 # model
    ('dsms = "dsms:g=100"', 'dsms = "dsms:gg=100"', "gg"),                    # model parameter
    ('kind = "pareto"', 'kind = "paretto"', "paretto"),                       # scene kind
    ('model = "tcom"\nr = [2, 4]', 'model = "tcom"\nr = [2, 400]', "400"),    # r above n1 - n2
    ('grid = "g30"\nr = [2, 4, 6]', 'grid = "g31"\nr = [2, 4, 6]', "g31"),    # grid
    ('axis = "states"', 'axis = "sates"', "sates"),                          # scene option value
])
def test_typo_fails_before_any_computation(tmp_path, monkeypatch, old, new, named):
    assert old in BASE
    text = BASE.replace(old, new, 1)

    def boom(*a, **k):
        raise AssertionError("computation started although the spec is invalid")
    for fn in ("fom_response", "reduce_sweep", "metrics"):
        monkeypatch.setattr(study_tasks, fn, boom)
    with pytest.raises(SpecError) as exc:
        run(_write(tmp_path, text), out=tmp_path / "results", quiet=True)
    msg = str(exc.value)
    assert named in msg
    assert msg.startswith("study spec ")
    assert not (tmp_path / "results").exists()


def test_unknown_key_lists_valid_choices(tmp_path):
    text = BASE.replace('grid = "g40"\nr = 4\npaper', 'gird = "g40"\nr = 4\npaper', 1)
    with pytest.raises(SpecError, match=r"unknown key 'gird'.*did you mean 'grid'.*valid keys: .*grid"):
        load_spec(_write(tmp_path, text))
    with pytest.raises(SpecError, match=r"valid choices: sigma, error"):
        load_spec(_write(tmp_path, BASE.replace('kind = "pareto"', 'kind = "x"')))


# -- planning: only what the scenes need -------------------------------------
def test_removed_scene_computes_nothing_of_its_own(tmp_path):
    full = run(_write(tmp_path, BASE), out=tmp_path / "a", use_cache=False, quiet=True, formats=()).manifest
    # dsms_time alone needs the dsms reduction at r = 2 (r = 4 is shared with the sigma scene)
    text = _drop_scene(BASE, "dsms_time")
    less = run(_write(tmp_path, text, "less.toml"), out=tmp_path / "b", use_cache=False, quiet=True, formats=()).manifest
    a, b = _artifact_ids(full), _artifact_ids(less)
    assert b < a
    assert a - b == {("reduction", "dsms(g=100)", "irka", 2, ())}
    # without every tcom scene, nothing about tcom is computed: no response, no reduction
    text = BASE
    for s in ("tcom_err_r", "tcom_pareto", "tcom_conv", "tcom_table"):
        text = _drop_scene(text, s)
    dsms_only = run(_write(tmp_path, text, "dsms.toml"), out=tmp_path / "c", use_cache=False,
                    quiet=True, formats=()).manifest
    assert not [x for x in dsms_only["artifacts"] if "tcom" in (x["model"] or "")]
    assert len([x for x in dsms_only["artifacts"] if x["kind"] == "fom_response"]) == 1
    # a scene without a grid (time, convergence) needs no full-order response at all
    only_time = "\n".join(BASE.split("[[scenes]]")[:1]) + "[[scenes]]" + \
        [b for b in BASE.split("[[scenes]]") if 'name = "dsms_time"' in b][0]
    m = run(_write(tmp_path, only_time, "t.toml"), out=tmp_path / "d", use_cache=False, quiet=True, formats=()).manifest
    assert {x["kind"] for x in m["artifacts"] if x["kind"] in COMPUTED} == {"reduction"}


def test_irka_only_study_never_forms_projector_or_gramians(tmp_path, monkeypatch):
    mod = pytest.importorskip("morsuite.reducers.irka.projected") if "irka-projected" in \
        ms.reducers.available() else None
    if mod is not None:
        def boom(*a, **k):
            raise AssertionError("the projector was formed in an IRKA-only study")
        monkeypatch.setattr(mod, "form_projector", boom)
    m = run(_write(tmp_path, BASE), out=tmp_path / "r", use_cache=False, quiet=True, formats=()).manifest
    reducers = {a["reducer"] for a in m["artifacts"] if a["kind"] == "reduction"}
    assert reducers == {"irka"}
    assert set(m["methods"]) == {"irka"}


def test_one_full_response_and_one_reducer_group_shared(base_run):
    _, res = base_run
    arts = res.manifest["artifacts"]
    foms = [a for a in arts if a["kind"] == "fom_response"]
    assert sorted((a["model"], a["grid"][2]) for a in foms) == [("dsms(g=100)", 40), ("tcom(nc=20)", 30)]
    groups = {}
    for a in arts:
        if a["kind"] == "reduction":
            groups.setdefault((a["model"], a["reducer"]), []).append((a["call_index"], a["r_requested"]))
    # one reducer instance per (model, method, options), r in increasing order
    assert groups[("dsms(g=100)", "irka")] == [(0, 2), (1, 4)]
    assert groups[("tcom(nc=20)", "irka")] == [(0, 2), (1, 4), (2, 6)]


# -- outputs ---------------------------------------------------------------
def test_outputs_read_back(base_run):
    import matplotlib.image as mpimg

    _, res = base_run
    out = res.outdir
    files = set(res.manifest["files"])
    for f in files:
        assert (out / f).is_file(), f
    for csv in out.glob("*.csv"):
        df = pd.read_csv(csv)
        assert len(df) > 0, csv
    # one CSV per curve, omega,value for frequency scenes
    for name in ("dsms_sigma__full.csv", "dsms_sigma__irka.csv", "dsms_abs.csv"):
        df = pd.read_csv(out / name)
        assert list(df.columns) == ["omega", "value"] and len(df) == 40
    df = pd.read_csv(out / "dsms_time.csv")
    assert list(df.columns[:2]) == ["states", "value"] and list(df["states"]) == [4, 8]
    df = pd.read_csv(out / "tcom_err_r.csv")
    assert list(df.columns[:2]) == ["r", "value"] and list(df["r"]) == [2, 4, 6]
    for png in out.glob("*.png"):
        img = mpimg.imread(png)
        assert img.ndim == 3 and img.shape[0] > 100
    stems = {p.stem for p in out.glob("*.png")}
    assert stems == {"dsms_sigma", "dsms_abs", "dsms_time", "tcom_err_r", "tcom_pareto", "tcom_conv"}
    for stem in stems:
        assert (out / f"{stem}.pdf").stat().st_size > 1000
        tex = (out / f"{stem}.tex").read_text()
        assert r"\begin{axis}" in tex and "col sep=comma" in tex
        for ref in __import__("re").findall(r"\\morsuitedir (\S+?\.csv)", tex):
            assert (out / ref).is_file()
    # the missing paper curve was skipped with a note, not an error
    assert any("paper_full.csv" in n and "skipped" in n for n in res.notes)


def _same_cell(md, csv):
    if isinstance(csv, float) and math.isnan(csv):
        return md == ""
    if isinstance(csv, (bool, np.bool_)):
        return md == str(bool(csv))
    if isinstance(csv, (int, np.integer, float, np.floating)):
        return math.isclose(float(md), float(csv), rel_tol=1e-5, abs_tol=0)
    return md == str(csv)


@pytest.mark.parametrize("stem", ["summary", "tcom_table"])
def test_markdown_matches_csv(base_run, stem):
    _, res = base_run
    csv = pd.read_csv(res.outdir / f"{stem}.csv")
    md = read_markdown(res.outdir / f"{stem}.md")
    assert list(md.columns) == list(csv.columns)
    assert len(md) == len(csv) > 0
    for i in range(len(csv)):
        for col in csv.columns:
            assert _same_cell(md.iloc[i][col], csv.iloc[i][col]), (stem, i, col, md.iloc[i][col], csv.iloc[i][col])


def test_summary_and_manifest_content(base_run):
    _, res = base_run
    s = res.summary
    assert {"model", "method", "r", "states", "converged", "iterations", "stable", "time_s", "lu_count",
            "max_abs_error", "max_rel_error", "cached"} <= set(s.columns)
    # no scene asked for exact norms or a simulation: no such columns (tests/test_studies_norms_time.py)
    assert not {"h2_error", "hinf_error", "max_output_error", "h2_error_grid"} & set(s.columns)
    # every reduction of the run has a row, with errors where a scene asked for them
    assert sorted(zip(s.model, s.r_requested)) == [("dsms(g=100)", 2), ("dsms(g=100)", 4), ("tcom(nc=20)", 2),
                                                   ("tcom(nc=20)", 4), ("tcom(nc=20)", 6)]
    assert s[(s.model == "dsms(g=100)") & (s.r_requested == 2)].max_abs_error.isna().all()
    ok = s[s.status == "ok"]
    assert (ok.states == 2 * ok.r).all()          # second-order ROMs: 2r first-order states
    # how each run ended, consistent with converged; no ROM here is worse than T_r = 0 in the band
    assert set(ok.reducer_status) <= set(STATUS)
    assert (ok.converged == ok.reducer_status.isin(CONVERGED_STATUSES)).all()
    # lu_count_shared: the r-independent LUs a result relies on, whoever paid them (reducers.outcome),
    # so it does not depend on what ran before on the model: IRKA's shortlist scores rely on the model's
    # Gramian factors when a run does not converge (dsms r = 2), nothing else here shares work
    assert (ok.lu_count_standalone >= ok.lu_count).all()
    # (whether a non-converged run found a stable iterate to score depends on the BLAS: 0 or the factors)
    for spec, model in (("dsms:g=100", "dsms(g=100)"), ("tcom:nc=20", "tcom(nc=20)")):
        gram = ms.linalg.gramians.gramian_factors(ms.models.parse(spec), use_cache=False).lu_count
        rows = ok[ok.model == model]
        assert rows.lu_count_shared.isin([0, gram]).all(), (model, gram, list(rows.lu_count_shared))
        assert (rows.lu_count_shared[rows.converged] == 0).all()
    assert (ok.lu_count_standalone >= ok.lu_count_shared).all()
    assert "worse_than_zero" in s.columns and (ok.worse_than_zero.fillna("") == "").all()
    tcom = ok[ok.model == "tcom(nc=20)"]
    assert tcom.max_abs_error.notna().all() and tcom.max_rel_error.notna().all()
    m = res.manifest
    for key in ("versions", "blas", "host", "threads", "config_hash", "seeds", "scheduler", "artifacts",
                "methods", "timing"):
        assert key in m
    assert m["scheduler"]["name"] == "synchronous"
    assert m["methods"]["irka"]["options"]["tol"] == 1e-6
    assert set(m["methods"]["irka"]["options"]) == set(ms.reducers.get_class("irka").OPTIONS)
    assert "band_errors" in m["definitions"] and not any(a["kind"] in ("model_norm", "norm_error", "simulation")
                                                           for a in m["artifacts"])
    json.dumps(m)  # plain data


def test_error_values_match_direct_analysis(base_run):
    """The runner's numbers are those of analysis.errors on the same ROM."""
    _, res = base_run
    fom = ms.models.parse("tcom:nc=20")
    red = ms.reducers.make("irka", fom, tol=1e-6)
    omega = ms.analysis.freq_grid((1e-3, 1.0), 30)
    for r in (2, 4, 6):
        df = ms.analysis.errors(fom, red.reduce(r).rom, omega)
        row = res.summary[(res.summary.model == "tcom(nc=20)") & (res.summary.r_requested == r)].iloc[0]
        assert row.max_abs_error == pytest.approx(df.abs_error.max(), rel=1e-8)
    curve = pd.read_csv(res.outdir / "tcom_err_r.csv")
    assert curve.value.iloc[-1] == pytest.approx(row.max_abs_error, rel=1e-12)


# -- cache -----------------------------------------------------------------
def test_cache_second_run_is_fast_and_marked(tmp_path):
    spec = _write(tmp_path, _drop_scene(_drop_scene(BASE, "dsms_sigma"), "dsms_abs"))
    first = run(spec, out=tmp_path / "results", quiet=True, formats=())
    second = run(spec, out=tmp_path / "results", quiet=True, formats=())
    assert not first.summary.cached.any()
    assert second.summary.cached.all()
    # every computed artifact, the metrics too, comes from the cache (figures and tables: test_studies_reuse.py)
    assert all(a["cached"] and a["reused"] for a in second.manifest["artifacts"] if a["kind"] in COMPUTED)
    # the compute phase (reports are written either way) is much shorter
    assert second.manifest["timing"]["compute_s"] < 0.5 * first.manifest["timing"]["compute_s"]
    # a cached artifact keeps the timing of the run that made it
    t1 = {a["id"]: a["time_s"] for a in first.manifest["artifacts"] if a["kind"] == "reduction"}
    t2 = {a["id"]: a["time_s"] for a in second.manifest["artifacts"] if a["kind"] == "reduction"}
    assert t1 == t2
    md = read_markdown(second.outdir / "summary.md")
    assert set(md.cached) == {"True"}
    pd.testing.assert_series_equal(first.summary.max_abs_error, second.summary.max_abs_error)
    # only npz and JSON in the cache
    assert {p.suffix for p in (tmp_path / "results" / ".cache").rglob("*") if p.is_file()} <= {".npz", ".json"}
    # --no-cache recomputes
    third = run(spec, out=tmp_path / "results", use_cache=False, quiet=True, formats=())
    assert not third.summary.cached.any()


def test_interrupted_sweep_resumes(tmp_path, monkeypatch):
    """Entries are stored per r as they finish: a run that dies after r = 2 keeps r = 2."""
    spec = _write(tmp_path, BASE.split("[[scenes]]")[0] + "[[scenes]]" +
                  [b for b in BASE.split("[[scenes]]") if 'name = "dsms_time"' in b][0])
    real = ms.reducers.get_class("irka").reduce

    def dying(self, r):
        if r == 4:
            raise KeyboardInterrupt
        return real(self, r)
    monkeypatch.setattr(ms.reducers.get_class("irka"), "reduce", dying)
    with pytest.raises(KeyboardInterrupt):
        run(spec, out=tmp_path / "results", quiet=True, formats=())
    monkeypatch.setattr(ms.reducers.get_class("irka"), "reduce", real)
    res = run(spec, out=tmp_path / "results", quiet=True, formats=())
    cached = dict(zip(res.summary.r_requested, res.summary.cached))
    assert cached == {2: True, 4: False}


# -- schedulers ------------------------------------------------------------
def test_distributed_local_cluster_matches_synchronous(tmp_path, base_run):
    distributed = pytest.importorskip("distributed")
    _, sync = base_run
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        res = run(_write(tmp_path, BASE), out=tmp_path / "results", scheduler=cluster.scheduler_address,
                  quiet=True, formats=())
    assert res.manifest["scheduler"]["name"] == "distributed"
    assert res.manifest["scheduler"]["address"] == cluster.scheduler_address
    assert not res.summary.cached.any()
    cols = ["model", "method", "r_requested", "r", "states", "converged", "iterations", "max_abs_error",
            "max_rel_error"]
    pd.testing.assert_frame_equal(res.summary[cols], sync.summary[cols], rtol=1e-10)
    for name in ("dsms_abs.csv", "tcom_err_r.csv"):
        np.testing.assert_allclose(pd.read_csv(res.outdir / name).value, pd.read_csv(sync.outdir / name).value,
                                   rtol=1e-10)
    # the workers could not be assumed to share the disk: the driver filled the cache
    assert any((tmp_path / "results" / ".cache" / "reduction").rglob("*.npz"))


# -- the other reducers (skipped until registered) ---------------------------
def test_projected_irka_reuses_one_projector(tmp_path):
    if "irka-projected" not in ms.reducers.available():
        pytest.skip("irka-projected is not registered")
    text = BASE.split("[[scenes]]")[0] + """
[methods.proj]
reducer = "irka-projected"
label = "IRKA, projected"

[[scenes]]
name = "proj_time"
kind = "time_vs_r"
model = "dsms"
methods = ["irka", "proj"]
r = [2, 4]
"""
    m = run(_write(tmp_path, text), out=tmp_path / "results", use_cache=False, quiet=True, formats=()).manifest
    proj = sorted((a for a in m["artifacts"] if a["reducer"] == "irka-projected"), key=lambda a: a["r_requested"])
    assert [a["call_index"] for a in proj] == [0, 1]
    bd = [a["time_breakdown"] for a in proj]
    assert bd[0]["form_pi"] > 0 and bd[1]["form_pi"] == 0    # formed once, reused for r = 4
    assert proj[1]["time_standalone_s"] > proj[1]["time_s"]


def test_bt_hsv_and_compare(tmp_path):
    if "bt" not in ms.reducers.available():
        pytest.skip("bt is not registered")
    text = BASE.split("[[scenes]]")[0] + """
[methods.bt]
label = "BT"

[[scenes]]
name = "bt_vs_irka"
kind = "compare"
model = "tcom"
grid = "g30"
methods = ["bt", "irka"]
r = 4
error = "rel"

[[scenes]]
name = "bt_hsv"
kind = "hsv"
model = "tcom"
methods = ["bt"]
r = 4

[[scenes]]
name = "bt_time"
kind = "time_vs_r"
model = "tcom"
methods = ["bt"]
r = [2, 4, 6]
"""
    res = run(_write(tmp_path, text), out=tmp_path / "results", use_cache=False, quiet=True, formats=("png",))
    assert (res.outdir / "bt_hsv.png").is_file() and (res.outdir / "bt_vs_irka__bt.csv").is_file()
    bt = [a for a in res.manifest["artifacts"] if a["kind"] == "reduction" and a["reducer"] == "bt"]
    assert sorted(a["r_requested"] for a in bt) == [2, 4, 6]
    assert len({a["group"] for a in bt}) == 1                 # one instance: one pair of Gramians


def test_progress_bar_counts_tasks():
    import io

    from dask import delayed

    from morsuite.studies.execute import choose, compute, progress_enabled

    def slow_square(i):
        time.sleep(0.25)  # longer than the bar's refresh interval
        return i * i

    graph = {f"t{i}": delayed(slow_square, pure=False)(i, dask_key_name=f"t{i}") for i in range(3)}
    buf = io.StringIO()
    out = compute(graph, choose(), progress=True, desc="demo", file=buf)
    assert out == {"t0": 0, "t1": 1, "t2": 4}
    assert "1/3" in buf.getvalue() and "2/3" in buf.getvalue()
    assert progress_enabled(quiet=True) is False


def test_local_processes_match_synchronous(tmp_path, base_run):
    """--jobs 2: Dask's multiprocessing scheduler gives the same numbers."""
    _, sync = base_run
    text = BASE.split("[[scenes]]")[0] + "[[scenes]]" + \
        [b for b in BASE.split("[[scenes]]") if 'name = "tcom_err_r"' in b][0]
    res = run(_write(tmp_path, text), out=tmp_path / "results", jobs=2, quiet=True, formats=())
    assert res.manifest["scheduler"] == {**res.manifest["scheduler"], "name": "processes", "workers": 2}
    a = res.summary.set_index("r_requested").max_abs_error
    b = sync.summary[sync.summary.model == "tcom(nc=20)"].set_index("r_requested").max_abs_error
    np.testing.assert_allclose(a.sort_index(), b.sort_index(), rtol=1e-10)


def test_scheduler_arguments_validated(tmp_path):
    from morsuite.errors import OptionError

    spec = _write(tmp_path, BASE)
    with pytest.raises(OptionError, match="jobs"):
        run(spec, out=tmp_path / "r", jobs=0, quiet=True)
    with pytest.raises(OptionError, match="scheduler"):
        run(spec, out=tmp_path / "r", scheduler="localhost", quiet=True)
    with pytest.raises(OptionError, match="formats"):
        run(spec, out=tmp_path / "r", formats=("jpeg",), quiet=True)
    assert not (tmp_path / "r").exists()


# -- command line and the repository's specs ---------------------------------
@pytest.mark.slow
def test_cli_run(tmp_path, capsys):
    from morsuite.cli import main

    text = BASE.split("[[scenes]]")[0] + "[[scenes]]" + \
        [b for b in BASE.split("[[scenes]]") if 'name = "dsms_abs"' in b][0]
    spec = _write(tmp_path, text)
    assert main(["run", str(spec), "--dry-run"]) == 0
    assert "reducer run" in capsys.readouterr().out
    assert not (tmp_path / "results").exists()
    assert main(["run", str(spec), "--out", str(tmp_path / "results"), "--quiet"]) == 0
    assert (tmp_path / "results" / "small" / "dsms_abs.png").is_file()
    bad = _write(tmp_path, text.replace("error", "eror"), "bad.toml")
    assert main(["run", str(spec), str(bad), "--out", str(tmp_path / "r2"), "--quiet"]) == 2
    assert "eror" in capsys.readouterr().err
    assert not (tmp_path / "r2").exists()   # the good spec did not run either


REPO_STUDIES = sorted((Path(__file__).resolve().parents[1] / "studies").glob("*.toml"))


@pytest.mark.parametrize("path", REPO_STUDIES, ids=lambda p: p.stem)
def test_repository_specs_validate(path):
    import tomllib

    wanted = {t.get("reducer", a) for a, t in tomllib.loads(path.read_text())["methods"].items()}
    missing = wanted - set(ms.reducers.available())
    if missing:
        pytest.skip(f"reducer(s) {sorted(missing)} not registered yet")
    study = load_spec(path)
    plan = ms.studies.build_plan(study)
    assert plan.reduces or plan.tolerances


@pytest.fixture
def fake_bt(monkeypatch):
    """A stand-in "bt" with BT's conventions: r-independent work done once per instance
    (reported as setup_cost/setup_reused), Hankel singular values and an error bound."""
    from morsuite.reducers import base, registry
    from morsuite.reducers.irka.second_order import IRKA

    class FakeBT(IRKA):
        name = "fake-bt"
        OPTIONS = {**IRKA.OPTIONS, "form": base.Option("vv", "choice", "level", choices=("pv", "vv"))}
        setups = 0

        def _reduce(self, r):
            reused = getattr(self, "_gram", None) is not None
            if not reused:
                time.sleep(1.0)  # "the Gramians"
                self._gram = np.logspace(0, -12, 13)
                FakeBT.setups += 1
            opts = dict(self.options)
            self.options = {k: v for k, v in opts.items() if k != "form"}
            try:
                rom, info = super()._reduce(r)
            finally:
                self.options = opts
            info.update(hsv=self._gram.tolist(), error_bound=float(2 * self._gram[r:].sum()),
                        setup_reused=reused, setup_cost={"gramians": 1.0}, lu_count_shared=5,
                        lu_count=info["lu_count"] + (0 if reused else 5))  # "the Gramians' 5 LUs"
            return rom, info

    monkeypatch.setitem(registry._REGISTRY, "fake-bt", FakeBT)
    return FakeBT


def test_bt_like_reducer_one_setup_hsv_and_standalone_time(tmp_path, fake_bt):
    text = BASE.split("[[scenes]]")[0] + """
[methods.bt]
reducer = "fake-bt"
options = { form = "vv" }
label = "BT"

[[scenes]]
name = "cmp"
kind = "compare"
model = "tcom"
grid = "g30"
methods = ["bt", "irka"]
r = 4

[[scenes]]
name = "hsv"
kind = "hsv"
model = "tcom"
methods = ["bt"]
r = 2
count = 8

[[scenes]]
name = "time"
kind = "time_vs_r"
model = "tcom"
methods = ["bt"]
r = [2, 4, 6]
"""
    res = run(_write(tmp_path, text), out=tmp_path / "results", use_cache=False, quiet=True, formats=())
    assert fake_bt.setups == 1                       # one instance for r = 2, 4, 6
    hsv = pd.read_csv(res.outdir / "hsv.csv")
    assert list(hsv.columns) == ["index", "value"] and len(hsv) == 8
    bt = res.summary[res.summary.method == "bt"].set_index("r_requested")
    assert bt.error_bound.notna().all()
    assert bt.loc[2, "time_s"] >= 1.0                # the first call did the setup (slept 1 s)
    # the reused calls: their standalone time adds the declared setup cost (1 s) to their own time,
    # bookkeeping checked exactly (no bound on the own time: that would be a timed assertion)
    assert bt.loc[4, "time_standalone_s"] == pytest.approx(bt.loc[4, "time_s"] + 1.0, rel=1e-9)
    assert bt.loc[2, "time_standalone_s"] == pytest.approx(bt.loc[2, "time_s"], rel=1e-9)
    # the shared LUs: paid (and counted) by the first call only, added back to the others' standalone count
    assert (bt.lu_count_shared == 5).all() and bt.loc[2, "lu_count_standalone"] == bt.loc[2, "lu_count"]
    assert bt.loc[4, "lu_count_standalone"] == bt.loc[4, "lu_count"] + 5
    t = pd.read_csv(res.outdir / "time.csv")         # standalone by default
    assert (t.value >= 1.0).all()
    assert (res.outdir / "cmp__bt.csv").is_file() and (res.outdir / "cmp__irka.csv").is_file()
