"""The explicit Pi-projected dense IRKA ("irka-projected"): the projected model is a
realization of the index-3 transfer function, the splitting has the stated
properties, "irka" and "irka-projected" give the same ROMs from the same shifts,
and the memory guard refuses before allocating."""

from __future__ import annotations

import time
import tracemalloc
import warnings

import numpy as np
import pytest
import scipy.sparse.linalg as spla
from threadpoolctl import threadpool_limits

import morsuite as ms
from morsuite.linalg.dense import shift_distance
from morsuite.reducers.irka.projected import form_projector, memory_estimate, split_projector
from support import assert_rounding, rounding_unit


def rel(a, b):
    return np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(np.asarray(b))


def points(fom):
    lo, hi = fom.band
    jw = 1j * np.logspace(np.log10(lo), np.log10(hi), 16)
    return list(jw) + [0.1 + 0.5j, 1.0 + 2.0j, 0.3, 0.05 - 0.2j]


def shifts(info_shifts):
    return np.array([complex(z["re"], z["im"]) for z in info_shifts])


#: how closely the two IRKAs agree on a shift set (relative, optimally matched), and so on the
#: convergence measure (a relative shift change) of each iteration
AGREE = 1e-8


def assert_same_course(a, b):
    """The two runs take the same course: their convergence measures agree to AGREE at every
    common iteration, and they stop at the same iteration, or one apart when the measure
    that decides the stop is within AGREE of tol (then rounding decides, not the method);
    their best iterates agree likewise. Measured: the deciding measures sit 1.3 to 10 times
    below tol and agree to 1e-14 in eight BLAS kernel / thread / SIMD settings."""
    tol = a.info["options"]["tol"]
    ma, mb = (np.asarray(x.info["history"]["measure"]) for x in (a, b))
    k = min(ma.size, mb.size)
    assert np.allclose(ma[:k], mb[:k], rtol=0, atol=AGREE), (ma, mb)
    if ma.size != mb.size:
        assert abs(ma.size - mb.size) == 1 and abs(ma[k - 1] - tol) <= AGREE, (ma, mb, tol)
    ba, bb = a.info["best_iteration"], b.info["best_iteration"]
    if ba != bb:
        assert abs(ma[ba - 1] - mb[bb - 1]) <= AGREE, (ba, bb, ma, mb)


@pytest.mark.parametrize("make_fom", [lambda: ms.models.dsms(g=600), lambda: ms.models.tcom(nc=100)],
                         ids=["dsms600", "tcom100"])
def test_projected_model_realizes_the_index3_transfer_function(make_fom):
    with threadpool_limits(limits=1, user_api="blas"):  # dense n x n work; threads crawl on a loaded box
        _check_projected_transfer_function(make_fom())


def _check_projected_transfer_function(fom):
    pm = ms.reducers.make("irka-projected", fom).projected_model()
    assert pm.order == fom.n1 - fom.n2
    pts = points(fom)
    assert len(pts) == 20
    for s in pts:
        assert rel(pm.transfer(s), fom.transfer(s)) < 1e-10, s
    # symmetric positive definite M, K stay symmetric positive definite
    for X in (pm.M, pm.K):
        assert np.allclose(X, X.T, rtol=0, atol=1e-13 * np.abs(X).max())  # formed symmetric: measured exact
        assert np.linalg.eigvalsh(0.5 * (X + X.T)).min() > 0
    # ||G Psi|| / (||G|| ||Psi||), products over n1 terms: measured <= 2e-16, bounds >= 4e-14
    assert_rounding(pm.split["constraint_residual"], rounding_unit(fom.n1), "constraint residual")


def test_splitting_properties_on_a_general_model(make_random_model):
    fom = make_random_model(n1=14, n2=3, m=2, p=2, seed=3)
    Pi = form_projector(fom)
    M, G = fom.M.toarray(), fom.G.toarray()
    # Pi = I - M^-1 G^T (G M^-1 G^T)^-1 G in double: rounding eps ||Pi|| kappa(M) kappa(G M^-1 G^T) (1e3: margin)
    tol = 1e3 * np.finfo(float).eps * np.linalg.norm(Pi, 2) * np.linalg.cond(M) * \
        np.linalg.cond(G @ np.linalg.solve(M, G.T))
    nM, nG = np.linalg.norm(M, 2), np.linalg.norm(G, 2)
    assert np.allclose(Pi @ Pi, Pi, rtol=0, atol=tol)
    assert np.allclose(Pi @ G.T, 0, atol=tol * nG)
    assert np.allclose(Pi @ M, M @ Pi.T, rtol=0, atol=tol * nM)
    Psi_l, Psi_r = split_projector(Pi, fom.n2)
    k = fom.n1 - fom.n2
    assert Psi_l.shape == Psi_r.shape == (fom.n1, k)
    assert np.allclose(Psi_l @ Psi_r.T, Pi, rtol=0, atol=tol)
    assert np.allclose(Psi_l.T @ Psi_r, np.eye(k), rtol=0, atol=tol)
    assert np.allclose(Psi_r.T @ Psi_r, np.eye(k), rtol=0, atol=tol)
    assert np.allclose(G @ Psi_r, 0, atol=tol * nG)  # range(Psi_r) = null(G), the hidden manifold


def test_general_model_transfer_function_and_the_wrong_splitting(make_random_model):
    """A dense M (not mapping null(G) into itself) and a nonsymmetric D: the projected
    model still realizes T(s); using range(Pi) = M null(G) as state space would not."""
    fom = make_random_model(n1=14, n2=3, m=2, p=2, seed=3)
    pm = ms.reducers.make("irka-projected", fom).projected_model()
    Psi_l, _ = split_projector(form_projector(fom), fom.n2)
    Q = np.linalg.qr(Psi_l)[0]  # orthonormal basis of range(Pi)
    M, D, K = (X.toarray() for X in (fom.M, fom.D, fom.K))
    for s in (0.3j, 1.0 + 2.0j, 0.7):
        T = fom.transfer(s)
        assert rel(pm.transfer(s), T) < 1e-10
        wrong = fom.L @ Q @ np.linalg.solve(Q.T @ (s * s * M + s * D + K) @ Q, Q.T @ fom.F)
        assert rel(wrong, T) > 1e-6


@pytest.mark.parametrize("make_fom", [lambda: ms.models.dsms(g=100), lambda: ms.models.tcom(nc=20)],
                         ids=["dsms100", "tcom20"])
def test_same_roms_as_irka_from_the_same_shifts(make_fom):
    fom = make_fom()
    r = 6
    lo, hi = fom.band
    init = dict(init="given", init_shifts=np.logspace(np.log10(lo), np.log10(hi), r),
                init_b=np.ones((r, fom.m)), init_c=np.linspace(1.0, 2.0, r * fom.p).reshape(r, fom.p))
    pts = np.array(points(fom))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ms.ConvergenceWarning)
        for maxit in (1, 2, 3):
            a = ms.reducers.make("irka", fom, **init, maxit=maxit).reduce(r)
            b = ms.reducers.make("irka-projected", fom, **init, maxit=maxit).reduce(r)
            assert a.info["iterations"] == maxit or a.info["converged"]
            assert_same_course(a, b)
            assert rel(b.rom.transfer_many(pts), a.rom.transfer_many(pts)) < AGREE
            for sa, sb in zip(a.info["history"]["shifts"], b.info["history"]["shifts"]):
                assert shift_distance(shifts(sb), shifts(sa)) < AGREE  # optimally matched
    a = ms.reducers.make("irka", fom).reduce(r)
    b = ms.reducers.make("irka-projected", fom).reduce(r)
    assert a.info["converged"] and b.info["converged"]
    assert_same_course(a, b)
    assert shift_distance(shifts(b.info["shifts"]), shifts(a.info["shifts"])) < AGREE
    # one LU per real shift or conjugate pair per iteration, in both; equal counts on the same course;
    # the projected baseline's fresh call also paid the two LUs of forming Pi (shared across r)
    assert not b.info["setup_reused"] and b.info["lu_count_shared"] == 2 and a.info["lu_count_shared"] == 0
    for x in (a, b):
        assert x.info["lu_count"] - x.info["lu_count_shared"] == sum(
            int(np.sum(shifts(h).imag >= 0)) for h in x.info["history"]["shifts"])
    if a.info["iterations"] == b.info["iterations"]:
        assert b.info["lu_count"] == a.info["lu_count"] + 2


def test_rom_from_projected_bases_equals_irka_rom_from_lifted_bases(tcom20):
    fom = tcom20
    proj = ms.reducers.make("irka-projected", fom)
    irka = ms.reducers.make("irka", fom)
    proj._setup()
    alpha = np.array([0.05, 0.2 + 0.4j, 0.2 - 0.4j, 1.0], dtype=complex)
    b = np.ones((4, fom.m), dtype=complex)
    c = np.ones((4, fom.p), dtype=complex)
    Vt, Wt = proj._bases(alpha, b, c, True)
    rom_t = proj._project(Vt, Wt)
    V, W = proj.lift(Vt), proj.lift(Wt)
    rom = irka._project(V, W)
    # the products' rounding over n1 terms, relative to the norms of their factors (not to the result);
    # measured <= 1.2e-16, bound 1.7e-14
    nv, nw = np.linalg.norm(V, 2), np.linalg.norm(W, 2)
    scale = {"M": nw * spla.norm(fom.M, 1) * nv, "D": nw * spla.norm(fom.D, 1) * nv, "K": nw * spla.norm(fom.K, 1) * nv,
             "F": nw * np.linalg.norm(fom.F, 2), "L": np.linalg.norm(fom.L, 2) * nv}
    for name in ("M", "D", "K", "F", "L"):
        X, Y = getattr(rom_t, name), getattr(rom, name)
        assert_rounding(np.abs(X - Y).max() / scale[name], rounding_unit(fom.n1), name)


def test_info_cost_accounting_and_setup_reuse(dsms50):
    red = ms.reducers.make("irka-projected", dsms50, maxit=2, init="given", init_shifts=[0.01, 0.1, 1.0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ms.ConvergenceWarning)
        first = red.reduce(3).info
        model = red.projected_model()
        second = red.reduce(2).info
    assert red.projected_model() is model
    tb = first["time_breakdown"]
    for key in ("setup", "form_pi", "split", "project_model", "dense_lu", "dense_solves", "projection",
                "shift_update"):
        assert tb[key] >= 0
    assert len(tb["dense_lu_per_iteration"]) == first["iterations"] == 2
    assert first["lu_count"] >= 3 and not first["setup_reused"]
    assert second["setup_reused"] and second["time_breakdown"]["form_pi"] == 0.0
    assert second["setup_cost"] == first["setup_cost"]
    assert first["memory"]["peak_bytes"] == memory_estimate(50, 1)["peak_bytes"]
    assert first["memory"]["budget_gib"] == 4.0
    assert first["projected_order"] == 49


def test_memory_guard_refuses_large_model_without_allocating():
    fom = ms.models.dsms(g=60000)
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(ms.MemoryBudgetError, match=r"memory_budget_gib") as exc:
            ms.reducers.make("irka-projected", fom)
        elapsed = time.perf_counter() - t0
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert "161 GiB" in str(exc.value)
    assert isinstance(exc.value, ms.MorsuiteError)
    assert peak < 64 * 2**20  # nothing n1 x n1 (or even n1 x k) was allocated
    assert elapsed < 5.0  # loose: it is milliseconds


def test_memory_guard_respects_the_option(dsms50):
    with pytest.raises(ms.MemoryBudgetError, match=r"memory_budget_gib = 1e-06"):
        ms.reducers.make("irka-projected", dsms50, memory_budget_gib=1e-6)
    with pytest.raises(ms.OptionError):
        ms.reducers.make("irka-projected", dsms50, memory_budget_gib=0)
    red = ms.reducers.make("irka-projected", dsms50, memory_budget_gib=0.01, maxit=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ms.ConvergenceWarning)
        assert red.reduce(2).rom.order == 2
