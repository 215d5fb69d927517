"""The smallest model within a tolerance (morsuite.analysis.tolerance), its study scene and ``compare --tol``.

References, independent of the code under test:

- the band error of every chosen and next-smaller model recomputed from a dense null-space
  realization of the full model (scipy.linalg.null_space of G, dense solves at each frequency);
- the H2 error recomputed from dense Lyapunov equations of the error system (first-order
  realization on the null space, scipy.linalg.solve_continuous_lyapunov);
- planted budgets and caps whose outcome is known in advance.
"""

from __future__ import annotations

import json
import math
import re
import warnings

import numpy as np
import pytest
import scipy.linalg as sla

import morsuite as ms
from morsuite.analysis.tolerance import OUTCOMES, ToleranceSearch, reach_tolerance
from morsuite.errors import InputError, OptionError

warnings.filterwarnings("ignore", category=ms.MorsuiteWarning)


def _dense(fom):
    """(E, A, B, C) of the first-order realization on the null space of G (dense)."""
    Z = sla.null_space(fom.G.toarray())
    M, D, K = (Z.T @ (X @ Z) for X in (fom.M, fom.D, fom.K))
    n = Z.shape[1]
    E = np.block([[np.eye(n), np.zeros((n, n))], [np.zeros((n, n)), M]])
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-K, -D]])
    B = np.vstack([np.zeros((n, fom.m)), Z.T @ fom.F])
    C = np.hstack([fom.L @ Z, np.zeros((fom.p, n))])
    return E, A, B, C


def _dense_response(fom, omega):
    E, A, B, C = _dense(fom)
    return np.stack([C @ np.linalg.solve(1j * w * E - A, B) for w in omega])


def _sigma(H):
    return np.linalg.svd(H, compute_uv=False)[..., 0]


def _dense_h2(E, A, B, C):
    """||C (sE - A)^-1 B||_H2 from the controllability Gramian (E invertible)."""
    Ai, Bi = np.linalg.solve(E, A), np.linalg.solve(E, B)
    P = sla.solve_continuous_lyapunov(Ai, -Bi @ Bi.T)
    return math.sqrt(max(np.trace(C @ P @ C.T), 0.0))


def _error_h2(fom, rom):
    E, A, B, C = _dense(fom)
    Er, Ar, Br, Cr, Dr = rom._first_order_arrays()
    Z = np.zeros((A.shape[0], Ar.shape[0]))
    return _dense_h2(np.block([[E, Z], [Z.T, Er]]), np.block([[A, Z], [Z.T, Ar]]), np.vstack([B, Br]),
                     np.hstack([C, -Cr]))


@pytest.fixture(scope="module")
def tcom():
    return ms.models.tcom(nc=20)


@pytest.mark.parametrize("method", ["bt", "krylov", "irka", "adaptive", "dominant"])
def test_band_tolerance_met_and_the_next_smaller_misses_against_a_dense_reference(tcom, method):
    omega = np.logspace(np.log10(tcom.band[0]), np.log10(tcom.band[1]), 60)
    H = _dense_response(tcom, omega)
    peak = _sigma(H).max()
    outcomes, search = reach_tolerance(tcom, method, [1e-2, 1e-4], measure="band", omega=omega)
    assert [o.tol for o in outcomes] == [1e-2, 1e-4]
    for o in outcomes:
        assert o.status == "met", o.reason
        ch, sm = o.chosen, o.smaller
        # the dense reference agrees with the values the search judged by, and with its verdict
        e_ch = _sigma(H - ch.rom.freqresp(omega)).max() / peak
        assert e_ch == pytest.approx(ch.value, rel=1e-6)
        assert e_ch <= o.tol
        assert ch.trusted and ch.stable
        if ch.r > 1:
            assert sm is not None and sm.r == ch.r - 1
            assert sm.states == ch.states - search.spo
            assert _sigma(H - sm.rom.freqresp(omega)).max() / peak > o.tol
    # the tighter tolerance needs at least as many states here (both met)
    assert outcomes[1].chosen.states >= outcomes[0].chosen.states
    # the counts: every evaluated order once, the method's LUs and the errors' apart
    cands = sorted(search.candidates.values(), key=lambda c: c.index)
    proxy = 0 if search.proxy is None else search.proxy._cum_lus  # the proxy's LU is the method's too
    assert [c.cum_lus for c in cands] == list(proxy + np.cumsum([c.lus for c in cands]))
    assert all(c.eval_lus == 0 for c in cands)  # a band error costs no LU beyond the reference response
    if method in ("adaptive", "dominant"):  # the first order is the one its own estimate stopped at (the guess):
        # its LUs are paid once, every later order reuses them
        assert cands[0].lus >= 1 and all(c.lus == 0 for c in cands[1:])


def test_h2_tolerance_against_dense_lyapunov(tcom):
    outcomes, search = reach_tolerance(tcom, "bt", 1e-3, measure="h2")
    o = outcomes[0]
    assert o.status == "met", o.reason
    norm = _dense_h2(*_dense(tcom))
    assert search.scale == pytest.approx(norm, rel=1e-6)
    assert _error_h2(tcom, o.chosen.rom) / norm <= 1e-3
    assert _error_h2(tcom, o.chosen.rom) / norm == pytest.approx(o.chosen.value, rel=1e-5)
    assert _error_h2(tcom, o.smaller.rom) / norm > 1e-3


@pytest.mark.parametrize("method", ["bt", "irka-fo"])
def test_bt_guess_comes_from_its_hankel_singular_values_and_the_gramians_are_counted_once(tcom, method):
    s = ToleranceSearch(tcom, method, measure="band")
    s.run([1e-3])
    # the first order tried is the Hankel singular values' guess (the Gramian factors computed for it)
    cands = sorted(s.candidates.values(), key=lambda c: c.index)
    bt = ms.reducers.make("bt", ms.models.tcom(nc=20)).reduce(2).info  # a fresh model: its own LR-ADI
    hsv = np.asarray(bt["hsv"])
    assert cands[0].r == int(np.flatnonzero(hsv > 1e-3 * s.scale)[-1]) + 1
    # the Gramian factors' LUs are the search's once, at the first order (reused by the later ones)
    assert cands[0].lus >= bt["lu_count"] > 0
    assert all(c.info["setup_reused"] for c in cands)


def test_budget_stops_with_the_best_model(tcom):
    outcomes, search = reach_tolerance(tcom, "irka", 1e-8, measure="band", budget_lus=12)
    o = outcomes[0]
    assert o.status == "budget" and "budget of 12" in o.reason
    assert o.lus >= 12
    best = min((c for c in search.candidates.values() if c.error is None and c.stable), key=lambda c: c.value)
    assert o.chosen is best


@pytest.mark.parametrize("method", ["irka", "irka-fo"])
def test_a_deadline_stops_an_iterating_reduction_with_its_best_iterate(tcom, method):
    """Reducer.deadline (a time budget inside a run): past it, the IRKA family stops after the iteration in
    progress with status "budget", converged=False and a warning, where the same reduction without it
    iterates on (r = 3: three iterations for both here)."""
    import time

    fresh = ms.reducers.make(method, tcom).reduce(3)
    assert fresh.info["iterations"] > 1
    red = ms.reducers.make(method, tcom)
    red.deadline = time.perf_counter()
    res = red.reduce(3)
    assert res.info["status"] == "budget" and not res.info["converged"] and res.info["iterations"] == 1
    assert any("the time budget ran out (deadline)" in w for w in res.info["warnings"])


def test_a_time_budget_binds_inside_the_searchs_first_run(tcom):
    """The search sets the deadline from budget_s for each reduction and clears it after: with the budget
    spent before the first run, that run stops on its first iteration and the search on its budget."""
    outcomes, search = reach_tolerance(tcom, "irka", 1e-8, measure="band", budget_s=1e-9, proxy=None)
    first = min(search.candidates.values(), key=lambda c: c.index)
    assert first.status == "budget" and first.info["iterations"] == 1
    assert outcomes[0].status == "budget" and "budget of 1e-09 s" in outcomes[0].reason
    assert search.red.deadline is None


def test_cap_and_untrusted_say_so(tcom):
    outcomes, _ = reach_tolerance(tcom, "krylov", 1e-9, measure="band", max_states=8)
    assert outcomes[0].status == "cap" and "8 states" in outcomes[0].reason
    assert set(OUTCOMES) >= {"met", "budget", "cap", "untrusted", "failed"}


def test_irka_is_steered_by_its_proxy_and_continues_from_the_nearest_model(tcom):
    outcomes, search = reach_tolerance(tcom, "irka", 1e-3, measure="band")
    assert search.proxy_method == "krylov" and search.proxy is not None
    proxy_met = search.proxy.candidates[next(c.r for c in search.proxy.candidates.values()
                                             if c.meets(1e-3) and c.r - 1 in search.proxy.candidates)]
    cands = sorted(search.candidates.values(), key=lambda c: c.index)
    # the first order is the proxy's (or a quarter of it, to calibrate), started from the proxy's model
    assert cands[0].states in (proxy_met.states, max(2, proxy_met.states // 4 // 2 * 2))
    assert cands[0].info["continued_from"] is not None
    assert all(c.info.get("continued_from") is not None for c in cands[1:] if c.error is None)
    # the proxy's LU is the method's too
    assert outcomes[0].lus == search.proxy._cum_lus + sum(c.lus for c in cands)
    assert reach_tolerance(tcom, "irka", 1e-3, measure="band", proxy=None)[1].proxy is None


def test_bad_arguments_are_named(tcom):
    with pytest.raises(InputError, match="tol must be numbers in"):
        reach_tolerance(tcom, "bt", 1.5)
    with pytest.raises(OptionError, match="measure must be one of"):
        ToleranceSearch(tcom, "bt", measure="l2")
    with pytest.raises(InputError, match="budget_lus must be a positive integer"):
        ToleranceSearch(tcom, "bt", budget_lus=-3)
    with pytest.raises(InputError, match="H_full has shape"):
        ToleranceSearch(tcom, "bt", omega=[0.1, 1.0], H_full=np.zeros((3, 1, 1)))


# -- the study scene, the page and ``morsuite compare --tol`` ---------------------------------------------
SPEC = """
name = "reach"
[models]
model = "tcom:nc=20"
[grids]
band = { n = 60 }
[methods.bt]
reducer = "bt"
[methods.krylov]
reducer = "krylov"
[[scenes]]
name = "to_reach"
kind = "tolerance"
model = "model"
grid = "band"
methods = ["bt", "krylov"]
tol = [1e-4, 1e-2]
"""


@pytest.fixture(scope="module")
def reached(tmp_path_factory):
    from morsuite.studies import run

    d = tmp_path_factory.mktemp("reach")
    (d / "reach.toml").write_text(SPEC)
    return run(d / "reach.toml", out=d / "out", quiet=True), d


@pytest.mark.slow
def test_scene_table_is_the_search_and_the_dense_reference_agrees(reached):
    import pandas as pd

    res, d = reached
    df = pd.read_csv(res.outdir / "to_reach.csv")
    assert list(df["tol"]) == [1e-2, 1e-2, 1e-4, 1e-4]  # loosest first, methods in scene order
    assert list(df["method"]) == ["bt", "krylov"] * 2
    assert set(df["status"]) == {"met"}
    fom = ms.models.tcom(nc=20)
    omega = np.logspace(np.log10(fom.band[0]), np.log10(fom.band[1]), 60)
    H = _dense_response(fom, omega)
    peak = _sigma(H).max()
    for _, row in df.iterrows():
        s = ToleranceSearch(fom, row["method"], omega=omega, H_full=H)  # the same route, run again
        o = s.run([row["tol"]])[0]
        assert o.chosen.states == row["states"] and o.smaller.states == row["smaller_states"]
        assert _sigma(H - o.chosen.rom.freqresp(omega)).max() / peak == pytest.approx(row["error"], rel=1e-6)
    # the headline names only models that met the tolerance
    note = (res.outdir / "to_reach.md").read_text()
    best = df[df.tol == 1e-2].sort_values("time_s").iloc[0]
    assert f"Within 1% (band max error / band peak): cheapest" in note
    for name in ("to_reach_states.png", "to_reach_time.png", "to_reach_bode.png"):
        assert (res.outdir / name).is_file()
    page = (res.outdir / "index.html").read_text()
    assert page.index('id="to-reach"') < page.index('id="figures"')  # the page leads with it
    assert best["method"] in page


@pytest.mark.slow
def test_scene_rerun_is_served_from_the_cache(reached):
    from morsuite.studies import run

    res, d = reached
    again = run(d / "reach.toml", out=d / "out", quiet=True)
    arts = [a for a in again.manifest["artifacts"] if a["kind"] == "tolerance"]
    assert len(arts) == 2 and all(a["cached"] for a in arts)
    assert [o["status"] for a in arts for o in a["outcomes"]] == ["met"] * 4


@pytest.mark.parametrize("edit, named", [
    ("tol = [1e-4, 1e-2]", "missing key 'tol'"),
    ("tol = [1e-4, 1e-2]\nr = 4", "unknown key 'r'"),
    ("tol = [1e-4, 1.5]", "in (0, 1)"),
    ("tol = [1e-4, 1e-2]\nerror = \"l2\"", "error"),
    ("tol = [1e-4, 1e-2]\nbudget_lus = -1", "budget_lus"),
])
def test_spec_refuses_a_bad_tolerance_scene(tmp_path, edit, named):
    from morsuite.errors import SpecError
    from morsuite.studies import load_spec

    text = SPEC.replace("tol = [1e-4, 1e-2]", "" if named.startswith("missing") else edit)
    (tmp_path / "bad.toml").write_text(text)
    with pytest.raises(SpecError, match=re.escape(named)):
        load_spec(tmp_path / "bad.toml")


def test_headline_ranks_only_models_that_met_the_tolerance():
    from morsuite.studies.tolerance_scene import headline

    row = dict(tol=0.01, error_measure="band", states=None, lu_count=None, time_s=None)
    rows = [{**row, "method": "a", "status": "budget", "states": 4, "lu_count": 1, "time_s": 0.01},
            {**row, "method": "b", "status": "met", "states": 40, "lu_count": 1, "time_s": 1.0},
            {**row, "method": "c", "status": "met", "states": 12, "lu_count": 90, "time_s": 30.0}]
    text = headline(rows)
    assert text.startswith("Within 1% (band max error / band peak): cheapest b (40 states, 1 LU, 1 s); "
                           "smallest c (12 states, 90 LUs, 30 s); not reached by a (budget).")
    assert "no method reached it" in headline([rows[0]])


def test_compare_tol_prints_the_table_and_writes_the_study(tmp_path, capsys):
    from morsuite.cli import main

    rc = main(["compare", "tcom:nc=20", "--tol", "1e-2", "--error", "h2", "--methods", "bt", "irka-fo",
               "--out", str(tmp_path), "--quiet", "--jobs", "1"])
    out = capsys.readouterr().out
    assert rc == 0
    assert "smallest model within 0.01 (h2 error)" in out and "Within 1% (H2 error / ||T||_H2)" in out
    toml = (tmp_path / "compare_tcom_nc20" / "compare_tcom_nc20.toml").read_text()
    assert 'kind = "tolerance"' in toml and 'error = "h2"' in toml
    assert main(["compare", "tcom:nc=20", "--out", str(tmp_path / "x"), "--quiet"]) == 2
    assert "--tol" in capsys.readouterr().err


def test_saved_models_load_bit_identical_and_verify_reproduces_their_errors(tmp_path, capsys):
    from morsuite.cli import main
    from morsuite.studies.tolerance import entry_from_cache

    assert main(["compare", "tcom:nc=20", "--tol", "1e-2", "--error", "h2", "--methods", "bt", "--out", str(tmp_path),
                 "--quiet", "--jobs", "1", "--save-roms"]) == 0
    out = capsys.readouterr().out
    stem = tmp_path / "compare_tcom_nc20" / "roms" / "to_reach_bt_tol0p01"
    assert str(stem) + ".npz" in out
    # the saved model is the search's, to the bit (its arrays in the study's cache)
    from morsuite.studies.cache import Cache
    arts = json.loads((tmp_path / "compare_tcom_nc20" / "manifest.json").read_text())["artifacts"]
    key = next(a["key"] for a in arts if a["kind"] == "tolerance")
    entry = entry_from_cache(*Cache(tmp_path / ".cache").get("tolerance", key))
    chosen = entry["search"]["outcomes"][0]["chosen"]
    for ext in ("npz", "mat"):
        rom = ms.load_rom(f"{stem}.{ext}")
        for f, arr in entry["roms"][chosen]["arrays"].items():
            if f != "basis":
                assert np.array_equal(getattr(rom, f), arr)
        assert rom.provenance["provenance"]["tolerance"]["status"] == "met"
    assert main(["verify", "tcom:nc=20", f"{stem}.mat"]) == 0
    assert "verified: every recorded value agrees" in capsys.readouterr().out
