"""Exact norms and time-domain errors in studies and on the command line (issues 18 and 20, "Where it shows").

The numbers a study and ``morsuite reduce|simulate --json`` report are checked against
independent dense references (the hidden-manifold realization through an explicit
null(G) basis: the error system's Gramian by scipy's Lyapunov solver, slycot's ab13dd
through ``control.linfnorm``, python-control's exact step response); the rest checks what
is computed (only what is asked, shared, cached), what is recorded, and bad input.

Small models: dsms(g = 40), tcom(nc = 20), r = 2..4.
"""

from __future__ import annotations

import functools
import inspect
import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import control
import numpy as np
import pandas as pd
import pytest

import morsuite as ms
from morsuite.analysis.compare import HINF_ROUTES
from morsuite.cli import main
from morsuite.report.tables import read_markdown
from morsuite.studies import run
from test_norms import error_ss, hidden_ss, lyap_h2

REPO = Path(__file__).resolve().parents[1]

SPEC = """
name = "nt"
title = "norms and time"

[models]
dsms = "dsms:g=40"
tcom = "tcom:nc=20"

[grids]
g = { band = [1e-2, 1.0], n = 30 }

[methods.irka]
label = "IRKA"
options = { tol = 1e-6 }

[methods.bt]
label = "BT"
options = { form = "vv" }

[[scenes]]
name = "h2_vs_r"
kind = "error_vs_r"
model = "tcom"
methods = ["irka", "bt"]
r = [2, 4]
measure = "h2_rel"

[[scenes]]
name = "tab"
kind = "table"
model = "dsms"
grid = "g"
methods = ["irka", "bt"]
r = 4
norms = ["h2", "hinf"]

[[scenes]]
name = "step"
kind = "time"
model = "dsms"
methods = ["irka", "bt"]
r = 4
horizon = 200.0
step = 0.5

[[scenes]]
name = "step_control"
kind = "time"
model = "dsms"
methods = ["bt"]
r = 4
horizon = 200.0
step = 0.5
rom_method = "control"

[[scenes]]
name = "tcom_sine"
kind = "time"
model = "tcom"
methods = ["bt"]
r = 4
input = "multisine:omegas=0.3;0.9"
horizon = 60.0
step = 0.05
"""


def _rom(spec, method, r, **opts):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return ms.reducers.make(method, ms.models.parse(spec), **opts).reduce(r).rom


@functools.lru_cache(maxsize=None)
def dense(spec, method, r, opts=()):
    """Dense references of one reduction: the error system (A, B, C), ||T - T_r||_H2 (Lyapunov),
    ||T||_H2, and, for the DSMS, ||T - T_r||_Hinf and ||T||_Hinf (slycot ab13dd)."""
    fom = ms.models.parse(spec)
    Ae, Be, Ce = error_ss(fom, _rom(spec, method, r, **dict(opts)))
    A, B, C = hidden_ss(fom)
    out = {"ss": (Ae, Be, Ce), "h2": lyap_h2(Ae, Be, Ce), "norm_h2": lyap_h2(A, B, C), "hidden": (A, B, C)}
    if spec.startswith("dsms"):
        out["hinf"] = control.linfnorm(control.ss(Ae, Be, Ce, 0), 1e-12)[0]
        out["norm_hinf"] = control.linfnorm(control.ss(A, B, C, 0), 1e-12)[0]
    return out


IRKA, BT = (("tol", 1e-6),), (("form", "vv"),)


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    from morsuite.studies import tasks

    tasks._model.cache_clear()   # models (and their Gramian factors) of earlier tests in this process
    tmp = tmp_path_factory.mktemp("nt")
    (tmp / "nt.toml").write_text(SPEC)
    res = run(tmp / "nt.toml", out=tmp / "results", quiet=True)
    return tmp, res


def _row(res, model, method, r):
    s = res.summary
    rows = s[(s.model == model) & (s.method == method) & (s.r_requested == r)]
    assert len(rows) == 1
    return rows.iloc[0]


def _arts(res, kind):
    return [a for a in res.manifest["artifacts"] if a["kind"] == kind]


# -- the numbers, against dense references ------------------------------------------------
def test_norm_columns_against_dense_references(study):
    _, res = study
    for spec, name, method, r, opts in [("dsms:g=40", "dsms(g=40)", "irka", 4, IRKA),
                                        ("dsms:g=40", "dsms(g=40)", "bt", 4, BT),
                                        ("tcom:nc=20", "tcom(nc=20)", "irka", 2, IRKA),
                                        ("tcom:nc=20", "tcom(nc=20)", "bt", 4, BT)]:
        ref = dense(spec, method, r, opts)
        row = _row(res, name, method, r)
        # errors of 1e-3..1e-1 of ||T||: the dense Lyapunov reference keeps 10 digits there
        assert row.h2_error == pytest.approx(ref["h2"], rel=1e-7)
        assert row.h2_rel_error == pytest.approx(ref["h2"] / ref["norm_h2"], rel=1e-7)
        assert bool(row.h2_trusted)
        if name.startswith("dsms"):
            assert row.hinf_error == pytest.approx(ref["hinf"], rel=1e-6)
            assert row.hinf_rel_error == pytest.approx(ref["hinf"] / ref["norm_hinf"], rel=1e-6)
        else:
            assert np.isnan(row.hinf_error)   # no scene asked for the Hinf error of the TCOM
    curve = pd.read_csv(res.outdir / "h2_vs_r__bt.csv")
    assert list(curve.columns[:2]) == ["r", "value"] and curve.trusted.all()
    assert curve.value.iloc[-1] == pytest.approx(_row(res, "tcom(nc=20)", "bt", 4).h2_rel_error, rel=1e-14)


def test_time_errors_against_the_exact_step_response(study):
    """The summary's output errors (both models on the trapezoidal rule) against the exact error
    (python-control's step response of the dense error system): second order in the step."""
    _, res = study
    t = np.arange(401) * 0.5
    for method, opts in (("irka", IRKA), ("bt", BT)):
        ref = dense("dsms:g=40", method, 4, opts)
        e = control.forced_response(control.ss(*ref["ss"], 0), T=t, U=np.ones(t.size)).outputs.T
        en = np.linalg.norm(e, axis=1)
        row = _row(res, "dsms(g=40)", method, 4)
        assert row.time_scene == "step" and not row.growth
        assert row.max_output_error == pytest.approx(en.max(), rel=1e-2)
        l2 = np.sqrt(np.trapezoid(en ** 2, t))
        assert row.l2_output_error == pytest.approx(l2, rel=1e-2)
        y = control.forced_response(control.ss(*ref["hidden"], 0), T=t, U=np.ones(t.size)).outputs.T
        assert row.max_output_rel_error == pytest.approx(en.max() / np.linalg.norm(y, axis=1).max(), rel=1e-2)


def test_verdict_and_markdown(study):
    _, res = study
    md = (res.outdir / "tab.md").read_text()
    a, b = _row(res, "dsms(g=40)", "irka", 4), _row(res, "dsms(g=40)", "bt", 4)
    winner = "BT" if b.h2_error < a.h2_error else "IRKA"
    assert f"r = 4, h2_error: {winner} (" in md and "hinf_error:" in md and "max_output_error:" in md
    table = read_markdown(res.outdir / "tab.md")
    assert {"h2_error", "h2_rel_error", "h2_trusted", "hinf_error", "hinf_rel_error", "max_output_error",
            "l2_output_rel_error", "growth"} <= set(table.columns)


# -- what is computed: only what is asked, each thing once ------------------------------------
def test_only_the_asked_norms_and_one_shared_simulation(study):
    _, res = study
    errs = {(a["model"], a["reducer"], a["norm"], a["r_requested"]) for a in _arts(res, "norm_error")}
    assert errs == {("dsms(g=40)", m, k, 4) for m in ("irka", "bt") for k in ("h2", "hinf")} | \
        {("tcom(nc=20)", m, "h2", r) for m in ("irka", "bt") for r in (2, 4)}
    assert sorted((a["model"], a["norm"]) for a in _arts(res, "model_norm")) == \
        [("dsms(g=40)", "h2"), ("dsms(g=40)", "hinf"), ("tcom(nc=20)", "h2")]
    # a norm measure needs no grid: no full-order response of the TCOM
    assert [a["model"] for a in _arts(res, "fom_response")] == ["dsms(g=40)"]
    # the two dsms scenes simulate the full model once; the reduced model per rom_method
    sims = _arts(res, "simulation")
    assert sorted((a["model"], tuple(a["scenes"])) for a in sims) == \
        [("dsms(g=40)", ("step", "step_control")), ("tcom(nc=20)", ("tcom_sine",))]
    assert all(a["lu_count"] == 1 for a in sims)
    assert sorted(a["rom_method"] for a in _arts(res, "sim_error") if a["model"] == "dsms(g=40)" and
                  a["reducer"] == "bt") == ["control", "scheme"]


def test_manifest_records_how_each_number_was_computed(study):
    _, res = study
    for a in _arts(res, "norm_error"):
        assert a["route"] in ("error-gramian", "pole-residue", "quadrature") + HINF_ROUTES
        assert a["trusted"] is True and a["options"] and a["warnings"] == []
        # the error system's Gramian route can certify an H2 error without any LU of its own
        assert a["lu_count"] > 0 or (a["norm"] == "h2" and a["route"] == "error-gramian")
        if a["norm"] == "h2":
            assert a["rel_floor"] < 1e-6 and a["floor"] > 0
        else:  # dsms(40): small enough for the level-set certificate
            assert a["peak_frequency"] > 0 and a["certified"] and a["lower_bound"] == a["value"]
            assert a["value"] < a["upper_bound"] <= a["value"] * (1 + 1e-3)
    h2 = [a for a in _arts(res, "model_norm") if a["norm"] == "h2"]
    assert all(a["route"] == "gramian" and a["trusted"] for a in h2)
    # bt ran before the norms of its model: it paid (and reports) its own LR-ADI
    bt = [a for a in res.manifest["artifacts"] if a["kind"] == "reduction" and a["reducer"] == "bt"
          and a["call_index"] == 0]
    assert bt and all(a["lu_count"] > 0 for a in bt)
    assert res.manifest["models"]["dsms"]["m"] == 1 and res.manifest["models"]["dsms"]["p"] == 3
    sine = next(a for a in _arts(res, "simulation") if a["model"] == "tcom(nc=20)")
    assert sine["steps"] == 1200 and sine["solves"] >= 1200 and sine["settings"]["horizon"] == 60.0


def test_time_figures_and_curves(study):
    _, res = study
    out = res.outdir
    for name in ("step", "step_error", "tcom_sine", "tcom_sine_error"):
        assert (out / f"{name}.png").is_file() and (out / f"{name}.tex").is_file()
    full = pd.read_csv(out / "step__full.csv")
    assert list(full.columns) == ["t", "value", "y1", "y2", "y3"] and len(full) == 401
    sine = pd.read_csv(out / "tcom_sine__bt.csv")
    assert list(sine.columns) == ["t", "value"] and len(sine) == 1201


def test_thinning_keeps_peaks():
    from morsuite.studies.time_figures import thin

    rng = np.random.default_rng(0)
    v = rng.standard_normal(100_000)
    v[54_321] = 50.0
    idx = thin(v, 4000)
    assert idx.size <= 4000 and idx[0] == 0 and idx[-1] == v.size - 1 and np.all(np.diff(idx) > 0)
    assert 54_321 in idx and v[idx].min() == v.min()
    assert thin(v[:100], 4000).tolist() == list(range(100))


def _python(*args):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, env=env, timeout=300)


def test_cached_rerun_computes_nothing_and_imports_no_numerics(study, tmp_path):
    import shutil

    src, _ = study
    shutil.copytree(src, tmp_path / "s")
    spec, out = tmp_path / "s" / "nt.toml", tmp_path / "s" / "results"
    second = run(spec, out=out, quiet=True)   # figures, tables and the page with a "cached" column settle here
    assert [a["id"] for a in second.manifest["artifacts"] if a["kind"] not in ("figure", "table", "page")
            and not a["cached"]] == []
    pd.testing.assert_frame_equal(second.summary.drop(columns="cached"), study[1].summary.drop(columns="cached"))
    heavy = ("matplotlib", "pandas", "control", "dask", "scipy.sparse", "morsuite.models", "morsuite.reducers",
             "morsuite.analysis")
    code = ("import sys\nfrom morsuite.cli import main\n"
            f"rc = main(['run', {str(spec)!r}, '--out', {str(out)!r}, '--quiet'])\n"
            f"print(rc, [m for m in {heavy!r} if m in sys.modules])")
    proc = _python("-c", code)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "0 []"
    m = json.loads((out / "nt" / "manifest.json").read_text())
    assert m["computed"] == []


# -- an unstable reduced model: infinite norms and growth, with warnings and flags -------------
@pytest.fixture
def unstable_reducer(monkeypatch):
    """A registered reducer whose models have negative damping (poles in the right half-plane)."""
    from morsuite.reducers import registry
    from morsuite.reducers.irka.second_order import IRKA

    class Unstable(IRKA):
        name = "unstable"

        def _reduce(self, r):
            rom, info = super()._reduce(r)
            rom = ms.rom.SecondOrderROM(rom.M, -0.05 * rom.M, rom.K, rom.F, rom.L)
            return rom, {**info, "stable": False}

    monkeypatch.setitem(registry._REGISTRY, "unstable", Unstable)
    return Unstable


def test_unstable_rom_in_a_study(tmp_path, unstable_reducer):
    text = SPEC.split("[[scenes]]")[0].replace('[methods.bt]\nlabel = "BT"\noptions = { form = "vv" }',
                                               '[methods.bad]\nreducer = "unstable"') + """
[[scenes]]
name = "tab"
kind = "table"
model = "dsms"
grid = "g"
methods = ["bad"]
r = 2
norms = ["h2", "hinf"]

[[scenes]]
name = "step"
kind = "time"
model = "dsms"
methods = ["bad"]
r = 2
horizon = 100.0
step = 0.5
"""
    (tmp_path / "u.toml").write_text(text)
    res = run(tmp_path / "u.toml", out=tmp_path / "r", quiet=True)
    row = _row(res, "dsms(g=40)", "bad", 2)
    assert row.h2_error == np.inf and row.hinf_error == np.inf and row.h2_rel_error == np.inf
    assert bool(row.growth) and row.max_output_rel_error > 1   # the reduced output outgrows the full one
    assert any("infinite" in n and "unstable" in n for n in res.notes)
    assert any("unstable" in n and "grows" in n for n in res.notes)
    errs = _arts(res, "norm_error")
    assert errs and all(a["value"] == np.inf and "StabilityWarning" in a["warnings"][0] for a in errs)
    sim = _arts(res, "sim_error")[0]
    assert sim["growth"] is True and sim["unstable_poles"] == 4 and "StabilityWarning" in sim["warnings"][0]
    assert "grows" in (res.outdir / "step.tex").read_text()   # the curve's legend says so


# -- the command line --------------------------------------------------------------------------
def _json(capsys, argv):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_reduce_json_prints_the_exact_norms(capsys):
    out = _json(capsys, ["reduce", "--model", "dsms:g=40", "--method", "bt", "--r", "4", "--option", "form=vv",
                         "--json"])
    ref = dense("dsms:g=40", "bt", 4, BT)
    assert out["h2_error"] == pytest.approx(ref["h2"], rel=1e-7)
    assert out["h2_rel_error"] == pytest.approx(ref["h2"] / ref["norm_h2"], rel=1e-7)
    assert out["hinf_error"] == pytest.approx(ref["hinf"], rel=1e-6)
    assert out["hinf_rel_error"] == pytest.approx(ref["hinf"] / ref["norm_hinf"], rel=1e-6)
    assert out["h2_route"] in ("error-gramian", "pole-residue") and out["h2_trusted"] is True and out["hinf_lu_count"] > 0
    # hinf_error is the peak found (lower bound); ab13dd's value lies below the certified upper bound
    assert out["hinf_certified"] is True and out["hinf_error"] < out["hinf_upper_bound"]
    assert ref["hinf"] <= out["hinf_upper_bound"] * (1 + 1e-9)
    none = _json(capsys, ["reduce", "--model", "dsms:g=40", "--method", "bt", "--r", "4", "--json", "--no-norms"])
    assert all(none[k] is None for k in ("h2_error", "h2_rel_error", "hinf_error", "hinf_rel_error", "h2_route",
                                         "hinf_upper_bound", "hinf_certified"))
    assert none["max_abs_error"] > 0


def test_reduce_json_unstable_rom_is_inf_with_warnings(capsys, unstable_reducer):
    out = _json(capsys, ["reduce", "--model", "dsms:g=40", "--method", "unstable", "--r", "2", "--json"])
    assert out["h2_error"] == "inf" and out["hinf_error"] == "inf" and out["h2_rel_error"] == "inf"
    assert sum("StabilityWarning" in w for w in out["warnings"]) >= 2


def test_simulate_json_and_csv(capsys, tmp_path):
    csv = tmp_path / "y.csv"
    out = _json(capsys, ["simulate", "--model", "dsms:g=40", "--method", "bt", "--r", "4", "--option", "form=vv",
                         "--horizon", "200", "--step", "0.5", "--csv", str(csv), "--json"])
    for key in ("model", "method", "r", "input", "horizon", "step", "steps", "max_output_error", "l2_output_error",
                "max_output_rel_error", "l2_output_rel_error", "growth", "lu_count", "times", "warnings"):
        assert key in out
    assert out["steps"] == 400 and out["lu_count"] == 1 and out["growth"] is False and out["input"] == "step"
    curves = pd.read_csv(csv)
    assert list(curves.columns) == ["t", "y1", "y2", "y3", "y_r1", "y_r2", "y_r3"] and len(curves) == 401
    e = np.linalg.norm(curves[["y1", "y2", "y3"]].to_numpy() - curves[["y_r1", "y_r2", "y_r3"]].to_numpy(), axis=1)
    assert out["max_output_error"] == pytest.approx(e.max(), rel=1e-12)
    # the defaults: step 0.3 / band_hi, horizon 2 pi / band_lo
    d = _json(capsys, ["simulate", "--model", "dsms:g=40", "--method", "irka", "--r", "2", "--json"])
    assert d["step"] == pytest.approx(0.3) and d["horizon"] == pytest.approx(2 * np.pi / 1e-2)


def test_simulate_unstable_rom_grows_with_a_warning(capsys, unstable_reducer):
    out = _json(capsys, ["simulate", "--model", "dsms:g=40", "--method", "unstable", "--r", "2", "--horizon", "300",
                         "--json"])
    assert out["growth"] is True and out["unstable_poles"] == 4 and out["growth_factor"] > 10
    assert any("StabilityWarning" in w and "right half-plane" in w for w in out["warnings"])


@pytest.mark.parametrize("extra,csv,match", [
    (["--horizon", "1", "--step", "2"], None, "larger than the horizon"),
    ([], "t,u\n0,1\n1,nan\n2,1\n", "non-finite entry in row 2"),
    ([], "t,u1,u2\n0,1,1\n1,1,1\n", "has 2 input columns; the model has m = 1"),
    (["--direction", "1,2"], None, "direction must have m = 1 entries"),
])
def test_simulate_bad_input_exits_2_naming_the_problem(capsys, tmp_path, extra, csv, match):
    argv = ["simulate", "--model", "dsms:g=40", "--method", "irka", "--r", "2", "--json"] + extra
    if csv is not None:
        (tmp_path / "u.csv").write_text(csv)
        argv += ["--input", f"csv:{tmp_path / 'u.csv'}"]
    assert main(argv) == 2
    assert match in capsys.readouterr().err


# -- the declared option tables agree with the functions they describe -------------------------
def test_option_tables_match_the_analysis_functions():
    import importlib

    from morsuite.analysis import compare
    from morsuite.analysis.timestep import SCHEMES
    from morsuite.linalg.gramians import ADI_DEFAULTS
    from morsuite.studies import norms, timedomain

    for kind in norms.NORM_KINDS:
        assert {k: v[0] for k, v in norms.NORM_OPTIONS[kind].items()} == compare.norm_options(kind)
    assert set(norms.ADI_KEYS) == set(ADI_DEFAULTS)
    assert timedomain.SCHEMES == tuple(SCHEMES)
    assert timedomain.ROM_METHODS == importlib.import_module("morsuite.analysis.simulate").OPTIONS["rom_method"][1]
    assert set(timedomain.INPUT_KINDS) <= set(inspect.getsource(ms.analysis.signals.make).split('"'))


def test_untrusted_value_is_flagged_in_summary_figure_and_notes(tmp_path):
    """The pole-residue formula forced on a tiny error (dsms, BT at r = 12: ||E|| ~ 1e-9 ||T||)
    cancels: the value is kept, flagged, ringed in the figure, never shown as exact."""
    text = SPEC.split("[[scenes]]")[0].replace('[models]', 'norm_options = { h2 = { method = "pole-residue" } }\n\n'
                                               '[models]') + """
[[scenes]]
name = "h2"
kind = "error_vs_r"
model = "dsms"
methods = ["bt"]
r = [2, 12]
measure = "h2"
"""
    (tmp_path / "f.toml").write_text(text)
    res = run(tmp_path / "f.toml", out=tmp_path / "r", quiet=True, formats=("png",))
    assert [bool(_row(res, "dsms(g=40)", "bt", r).h2_trusted) for r in (2, 12)] == [True, False]
    ringed = pd.read_csv(res.outdir / "h2__flagged_bt.csv")
    assert ringed.r.tolist() == [12]
    assert ringed.value.iloc[0] == _row(res, "dsms(g=40)", "bt", 12).h2_error
    assert any("not accurate to four digits" in n and "r = 12" in n for n in res.notes)
    tex = (res.outdir / "h2.tex").read_text()
    assert "only marks, mark=o" in tex and "not accurate to 4 digits" in tex


@pytest.mark.parametrize("csv,scene,match", [
    ("t,u\n0,1\n100,nan\n200,1\n", {}, "non-finite entry in row 2"),
    ("t,u1,u2\n0,1,1\n200,1,1\n", {}, "has 2 input columns; the model has m = 1"),
    ("t,u\n0,1\n100,1\n", {}, "ends at t = 100, before the horizon 200"),
    ("t,u\n0,1\n200,1\n", {"step": 500.0}, "step 500.0 is larger than the horizon 200.0"),
    ("t,u\n0,1\n200,1\n", {"direction": [1.0]}, "direction does not apply to a CSV input"),
    ("t,u\n0,1\n200,1\n", {"channel": 4}, "channel 4 does not exist: model 'dsms' has p = 3 outputs"),
])
def test_time_scene_bad_input_is_refused_before_anything_runs(tmp_path, monkeypatch, csv, scene, match):
    from morsuite.errors import SpecError
    from morsuite.studies import tasks, timedomain

    def boom(*a, **k):
        raise AssertionError("computation started although the spec is invalid")
    for mod, fn in ((tasks, "reduce_sweep"), (timedomain, "full_simulation")):
        monkeypatch.setattr(mod, fn, boom)
    (tmp_path / "u.csv").write_text(csv)
    extra = "".join(f"{k} = {json.dumps(v)}\n" for k, v in scene.items())
    text = SPEC.split("[[scenes]]")[0] + f"""
[[scenes]]
name = "measured"
kind = "time"
model = "dsms"
methods = ["irka"]
r = 2
input = "csv:u.csv"
horizon = 200.0
{extra}"""
    (tmp_path / "m.toml").write_text(text)
    with pytest.raises(SpecError, match=r"scenes\[0\] \('measured'\)") as exc:
        run(tmp_path / "m.toml", out=tmp_path / "r", quiet=True)
    assert match in str(exc.value)
    assert not (tmp_path / "r").exists()
