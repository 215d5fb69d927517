"""Adaptive interpolation ("adaptive", issue 46 items 1 and 3): the interpolation conditions at every point
the greedy chose against a dense reference (null space of G, dense Taylor moments), the structure of the
one-sided model (SPD, stable), the estimate against the true error on chains, a MIMO model, a finite-element
block and lightly damped models, the LU budget, validation samples, the state kept across reduce(r) calls and
refused input."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import morsuite as ms
from morsuite.linalg.dense import sigma_max
from morsuite.reducers.adaptive.estimate import ReducedResponse, local_maxima
from morsuite.reducers.base import as_complex
from morsuite.utils import blas_threads
from support import assert_sets_close, dense_reduced, eig_tolerance, moments

TOL = 1e-8  # relative error of a matched moment

MODELS = {
    "dsms": lambda: ms.models.dsms(g=60),
    "tcom": lambda: ms.models.tcom(nc=30),
    "mimo": lambda: ms.models.random_constrained(n1=200, n2=4, m=2, p=3, seed=1),
    "fem_block": lambda: ms.models.fem_block(400),
    "light_chain": lambda: ms.models.tcom(nc=60, alpha=1e-4, beta=1e-4, v=0.05),
    "light_fem": lambda: ms.models.fem_block(400, alpha=1e-4, beta=1e-4),
}


@pytest.fixture(scope="module")
def models():
    return {k: f() for k, f in MODELS.items()}


def _reduce(fom, r, method="adaptive", **opts):
    """(reducer, reduction) of ``method`` at order r, its convergence and rank warnings silenced."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ms.errors.ConvergenceWarning)
        warnings.simplefilter("ignore", ms.errors.RankWarning)
        red = ms.reducers.make(method, fom, **opts)
        return red, red.reduce(r)


def dense_transfer(ref, s):
    """T(s) of the dense system on ker G, one dense solve per point: (len(s), p, m)."""
    M, D, K, F, L = ref
    s = np.asarray(s, dtype=complex)
    with blas_threads(1):
        return np.concatenate([L @ np.linalg.solve(z[:, None, None] ** 2 * M + z[:, None, None] * D + K,
                                                   np.broadcast_to(F, (z.size,) + F.shape))
                               for z in np.array_split(s, max(1, s.size // 32))])


def dense_curve(ref, s):
    """T(s) of the dense system on ker G at many points from the eigendecomposition of its companion form
    (numpy's eig: A = [[0, I], [-M^-1 K, -M^-1 D]]), checked against dense solves at 8 of them."""
    M, D, K, F, L = ref
    n = M.shape[0]
    with blas_threads(1):
        A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M, K), -np.linalg.solve(M, D)]])
        lam, X = np.linalg.eig(A)
        B = np.linalg.solve(X, np.vstack([np.zeros_like(F), np.linalg.solve(M, F)]))
        C = np.hstack([L, np.zeros_like(L)]) @ X
        s = np.asarray(s, dtype=complex)
        H = np.einsum("pk,fk,km->fpm", C, 1.0 / (s[:, None] - lam[None, :]), B)
    probe = np.linspace(0, s.size - 1, 8).astype(int)
    want = dense_transfer(ref, s[probe])
    assert np.abs(H[probe] - want).max() <= 1e-9 * np.abs(want).max()
    return H


def true_curve(fom, ref, info, rom):
    """The true error on the estimate's own grid, relative to the peak of sigma_max(T) on the peak grid (the
    definition of the estimate: the 200 log-spaced frequencies of the band by default)."""
    grid = np.asarray(info["estimate_grid"])
    H = dense_curve(ref, 1j * np.concatenate([grid, np.geomspace(*fom.band, info["options"]["peak_grid"])]))
    peak = sigma_max(H[grid.size:]).max()
    Hr = dense_curve((rom.M, rom.D, rom.K, rom.F, rom.L), 1j * grid)  # the reduced model's, the same way
    return grid, sigma_max(H[:grid.size] - Hr) / peak


# -- interpolation conditions at the chosen points ------------------------------------------------------
@pytest.mark.parametrize("name", ["dsms", "tcom", "mimo", "fem_block"])
def test_moments_match_at_every_point_the_greedy_chose(models, name):
    fom = models[name]
    ref = dense_reduced(fom)
    red, res = _reduce(fom, 24, levels=2)
    pts = as_complex(res.info["points"])
    assert len(pts) >= 2 and res.info["status"] == "direct" and res.rom.order == 24
    assert pts[0] == pytest.approx(np.sqrt(fom.band[0] * fom.band[1]), rel=1e-15)  # the real start
    assert np.all(pts[1:].real == 0) and np.all((pts[1:].imag >= fom.band[0]) & (pts[1:].imag <= fom.band[1]))
    # the full basis holds 2 levels of F and of L^T at each point: a symmetric model matches 4 moments there
    V = red._state["basis"].V
    Mr, Dr, Kr = (V.T @ (X @ V) for X in (fom.M, fom.D, fom.K))
    full = (Mr, Dr, Kr, V.T @ fom.F, fom.L @ V)
    for s0 in pts:
        want = moments(*ref, s0, 4)
        got = moments(*full, s0, 4)
        err = max(np.linalg.norm(a - g) / np.linalg.norm(a) for a, g in zip(want, got))
        assert err <= TOL, (s0, err)
    # and the true sample kept at each point is T(s0)
    for pt in red._state["points"]:
        assert np.allclose(pt.T, moments(*ref, pt.s, 1)[0], rtol=1e-10, atol=0)


@pytest.mark.parametrize("name", list(MODELS))
def test_one_sided_models_are_spd_and_stable(models, name):
    fom = models[name]
    _, res = _reduce(fom, 24)
    rom = res.rom
    for X in (rom.M, rom.K):
        assert np.array_equal(X, X.T) and np.linalg.eigvalsh(X).min() > 0
    lam = np.linalg.eigvalsh(rom.D)
    assert lam.min() >= -1e-12 * np.abs(lam).max()
    assert rom.is_stable() and res.info["stable"] and res.info["definite"] == {"M_spd": True, "K_spd": True,
                                                                               "D_psd": True}
    assert res.info["symmetric"] is True


# -- the estimate against the true error -------------------------------------------------------------------
@pytest.mark.parametrize("name", list(MODELS))
@pytest.mark.parametrize("tol", [1e-2, 1e-4])
def test_estimate_within_a_factor_10_of_the_true_error(models, name, tol):
    fom = models[name]
    ref = dense_reduced(fom)
    _, res = _reduce(fom, fom.order, tol=tol)
    info = res.info
    assert info["status"] == "converged" and info["estimate_max"] <= tol
    grid, true = true_curve(fom, ref, info, res.rom)
    est = np.asarray(info["estimate"])
    if res.rom.order == fom.order:  # the whole hidden manifold: exact to rounding, and so is the estimate
        assert true.max() < 1e-9 and info["estimate_max"] < 1e-9
        return
    assert true.max() <= 10 * tol  # the target holds on the estimate's grid to the factor the estimate promises
    assert 0.1 <= info["estimate_max"] / true.max() <= 10, (info["estimate_max"], true.max())
    # frequency by frequency, where the true error is within 1/10 of its band max
    big = true >= 0.1 * true.max()
    ratio = est[big] / true[big]
    assert ratio.min() >= 0.1 and ratio.max() <= 10, (ratio.min(), ratio.max())


def test_the_history_holds_the_true_error_where_each_point_went(models):
    fom = models["fem_block"]
    ref = dense_reduced(fom)
    red, res = _reduce(fom, fom.order, tol=1e-3)
    peak = sigma_max(dense_transfer(ref, 1j * np.geomspace(*fom.band, 200))).max()
    rows = [h for h in res.info["history"] if h["kind"] == "point"]
    assert rows
    for h in rows:  # the sample at the new point measures the model before it; the estimate was largest there
        assert h["estimate_at"] == pytest.approx(h["estimate_max_before"], rel=1e-12)
        assert 0.1 <= h["estimate_at"] / h["true_rel_error"] <= 10
    # the point's sample against the dense reference
    pt = red._state["points"][1]
    assert np.allclose(pt.T, dense_transfer(ref, [pt.s])[0], rtol=1e-10, atol=1e-14 * peak)


# -- stopping: tolerance, budget, order, validation -----------------------------------------------------
def test_budget_stops_the_greedy(models):
    fom = models["light_fem"]
    with pytest.warns(ms.errors.ConvergenceWarning, match="max_lus = 3"):
        res = ms.reducers.make("adaptive", fom, tol=1e-6, max_lus=3).reduce(fom.order)
    info = res.info
    assert info["status"] == "budget" and info["converged"] is False
    assert info["lu_count"] == 3 == len(info["points"]) and info["estimate_max"] > 1e-6


def test_validation_samples_are_true_errors_below_tol(models, count_factorizations):
    fom = models["fem_block"]
    ref = dense_reduced(fom)
    red = ms.reducers.make("adaptive", fom, tol=1e-3, validate=3)  # (its rigid-body check may factor: not counted)
    count_factorizations.clear()
    res = red.reduce(fom.order)
    info = res.info
    assert info["status"] == "converged"
    val = info["validated"]
    assert len(val) >= 3
    peak = sigma_max(dense_transfer(ref, 1j * np.geomspace(*fom.band, 200))).max()
    for v in val:
        true = sigma_max(dense_transfer(ref, [1j * v["omega"]]) - res.rom.freqresp([v["omega"]]))[0] / peak
        assert v["true_rel_error"] == pytest.approx(true, rel=1e-6, abs=1e-12)
        assert v["true_rel_error"] <= 1e-3
    # every LU counted: points and validation samples (independently of the solver's counters)
    assert info["lu_count"] == len(count_factorizations) == len(info["points"]) + len(val)


def test_order_r_without_tol_and_the_state_kept_across_calls(models, count_factorizations):
    fom = models["tcom"]
    red = ms.reducers.make("adaptive", fom, levels=2)
    count_factorizations.clear()
    small = red.reduce(10)
    n_small = len(count_factorizations)
    assert small.rom.order == 10 and small.info["lu_count"] == n_small
    big = red.reduce(30)
    assert big.rom.order == 30
    # the second call paid only its new points; the first points are the same
    assert big.info["lu_count"] == len(count_factorizations) - n_small
    assert big.info["setup_reused"] is True
    assert as_complex(big.info["points"])[:len(small.info["points"])].tolist() == \
        as_complex(small.info["points"]).tolist()
    again = red.reduce(10)  # nested: the leading block of the larger basis, no LU
    assert again.info["lu_count"] == 0 and np.allclose(again.rom.M, big.rom.M[:10, :10], rtol=0, atol=1e-13)
    # standalone LUs of the small model: the LUs the greedy had made when it reached 10 columns
    assert ms.reducers.outcome.standalone_lu_count(again.info) == n_small


def test_info_carries_the_interface_keys(models):
    fom = models["dsms"]
    _, res = _reduce(fom, fom.order, tol=1e-6)
    info = res.info
    for key in ("lu_count", "points", "estimate_max", "estimate_grid", "estimate", "validated", "status", "history"):
        assert key in info, key
    assert isinstance(info["estimate"], list) and len(info["estimate"]) == len(info["estimate_grid"])
    assert info["estimate_max"] == max(info["estimate"])
    assert info["status"] in ms.reducers.outcome.STATUS


# -- the reduced responses and the curve's peaks ------------------------------------------------------------
def test_reduced_response_pole_residue_form_agrees_with_solves():
    rng = np.random.default_rng(4)
    r = 30
    A = rng.standard_normal((r, r))
    K = A @ A.T + r * np.eye(r)
    M = np.eye(r) + 0.1 * np.diag(rng.random(r))
    D = 1e-3 * K + 1e-2 * M
    F, L = rng.standard_normal((r, 2)), rng.standard_normal((3, r))
    resp = ReducedResponse(M, D, K, F, L, check=1j * np.array([0.1, 1.0, 10.0]))
    assert resp.method == "modal"
    s = 1j * np.geomspace(0.01, 100, 50)
    want = L @ np.linalg.solve(s[:, None, None] ** 2 * M + s[:, None, None] * D + K, np.broadcast_to(F, (50, r, 2)))
    assert np.abs(resp(s) - want).max() <= 1e-10 * np.abs(want).max()
    # the poles matched one to one (never sorted: a conjugate pair's order is rounding), each within the
    # first-order rounding bound of the pencil's eigenvalue (its condition number), both computations counted
    lam, tol = eig_tolerance(np.block([[np.zeros((r, r)), np.eye(r)], [-K, -D]]),
                             np.block([[np.eye(r), np.zeros((r, r))], [np.zeros((r, r)), M]]), factor=100.0)
    assert_sets_close(resp.poles, lam, atol=tol, what="poles")


def test_local_maxima_by_decreasing_value():
    assert local_maxima([3.0, 1.0, 2.0, 0.5, 5.0]).tolist() == [4, 0, 2]
    assert local_maxima([1.0]).tolist() == [0]


# -- refused input ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("opts, word", [({"start": "middle"}, "start"), ({"start": -1.0}, "start"),
                                        ({"band": [2.0, 1.0]}, "band"), ({"tol": 0.0}, "tol"),
                                        ({"max_lus": 0}, "max_lus"), ({"levels": 0}, "levels")])
def test_bad_options_are_refused(models, opts, word):
    with pytest.raises(ms.errors.OptionError, match=word):
        ms.reducers.make("adaptive", models["dsms"], **opts)


# -- compress: the greedy's model as a surrogate, reduced by an H2 method without LUs of the full model ---------
def test_compressed_to_r_states_matches_irka_fo_on_the_full_model(models):
    fom = models["tcom"]
    ref = dense_reduced(fom)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        full = ms.reducers.make("irka-fo", fom).reduce(6)
        res = ms.reducers.make("adaptive", fom, compress="irka-fo").reduce(6)
    info = res.info
    assert res.rom.kind == "first-order" and res.rom.states == 6 and info["status"] == "converged"
    c = info["compress"]
    assert c["surrogate_estimate_max"] <= 0.1 * c["surrogate_gap_max"]  # the surrogate is 10x closer to T
    h2_full = ms.analysis.h2_error(fom, full.rom)
    h2 = ms.analysis.h2_error(fom, res.rom)
    assert h2 <= 2 * h2_full, (h2, h2_full)
    # the returned model's estimate against its true band error (dense reference on the estimate's grid)
    grid = np.asarray(info["estimate_grid"])
    H = dense_curve(ref, 1j * np.concatenate([grid, np.geomspace(*fom.band, 200)]))
    true = sigma_max(H[:grid.size] - res.rom.freqresp(grid)) / sigma_max(H[grid.size:]).max()
    assert 0.1 <= info["estimate_max"] / true.max() <= 10
