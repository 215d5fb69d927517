"""LR-ADI for the projected Lyapunov equations of index-3 systems (morsuite.linalg.lradi).

The iteration works on the index-3 data through saddle-point solves; these tests
check it against an independent dense computation on the projected model
(orthonormal null-space basis Theta of G, the first-order realization of
Theta^T M Theta, ..., scipy's Lyapunov solver), on models with a nonsymmetric D
(so that transposed solves differ from plain ones), a non-scalar M (TCOM, where
the projector Pi is oblique) and the DSMS.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

import morsuite as ms
from morsuite.linalg.adi_shifts import penzl_shifts, projection_shifts, select_shifts
from morsuite.linalg.lradi import LRADIResult, lradi, lradi_pair
from support import assert_rounding, assert_sets_close, orthonormality_error, rounding_unit, solve_tolerance


def projected_system(fom):
    """Dense first-order realization (E, A, B, C) of the model on ker G, and Theta."""
    M, D, K, G = (X.toarray() for X in (fom.M, fom.D, fom.K, fom.G))
    Th = sla.null_space(G)
    k = Th.shape[1]
    I, Z = np.eye(k), np.zeros((k, k))
    E = np.block([[I, Z], [Z, Th.T @ M @ Th]])
    A = np.block([[Z, I], [-Th.T @ K @ Th, -Th.T @ D @ Th]])
    B = np.vstack([np.zeros((k, fom.m)), Th.T @ fom.F])
    C = np.hstack([fom.L @ Th, np.zeros((fom.p, k))])
    return E, A, B, C, Th


def to_coordinates(res, Th):
    """Factor rows in null-space coordinates: Theta^T Z (exact for the ker G blocks; for the
    observability position block, a covector, Theta^T is its action on ker G)."""
    return np.vstack([Th.T @ res.position, Th.T @ res.velocity])


def dense_controllability_gramian(fom):
    """The dense controllability Gramian on ker G (null-space coordinates) and Theta."""
    E, A, B, C, Th = projected_system(fom)
    As, Bs = np.linalg.solve(E, A), np.linalg.solve(E, B)
    return sla.solve_continuous_lyapunov(As, -Bs @ Bs.T), Th


def assert_converged_to(res, P, Th, rtol=1e-9):
    """A converged controllability run whose ZZ^T on ker G is within rtol (2-norm) of P."""
    assert res.converged
    Zq = to_coordinates(res, Th)
    assert np.linalg.norm(Zq @ Zq.T - P, 2) / np.linalg.norm(P, 2) < rtol


def dense_residuals(fom, c, o):
    """Relative 2-norm residuals of both Lyapunov equations, computed densely on ker G."""
    E, A, B, C, Th = projected_system(fom)
    Zq, Yq = to_coordinates(c, Th), to_coordinates(o, Th)
    P, Q = Zq @ Zq.T, Yq @ Yq.T
    rp = np.linalg.norm(A @ P @ E.T + E @ P @ A.T + B @ B.T, 2) / np.linalg.norm(B @ B.T, 2)
    rq = np.linalg.norm(A.T @ Q @ E + E.T @ Q @ A + C.T @ C, 2) / np.linalg.norm(C.T @ C, 2)
    return rp, rq


MODELS = {  # name -> model, given the conftest factory of random models
    "random": lambda make: make(n1=14, n2=2, m=2, p=3, seed=1),
    "tcom": lambda make: ms.models.tcom(nc=10),
    "dsms": lambda make: ms.models.dsms(g=60),
}


@pytest.mark.parametrize("name", sorted(MODELS))
def test_residual_matches_independent_dense_residual(name, make_random_model):
    fom = MODELS[name](make_random_model)
    c, o = lradi_pair(fom, tol=1e-12)
    assert c.converged and o.converged
    rp, rq = dense_residuals(fom, c, o)
    # small on the hidden manifold, computed without the iteration's own bookkeeping
    assert rp < 1e-11 and rq < 1e-11
    # ... and what the iteration reports (its norm is that of the Pi-representative,
    # equal to the null-space one up to the obliqueness of Pi)
    assert rp <= 2 * c.residual + 1e-13 and rq <= 2 * o.residual + 1e-13
    G = fom.G.toarray()
    Minv_GT = np.linalg.solve(fom.M.toarray(), G.T)
    scale = max(np.abs(c.position).max(), np.abs(o.velocity).max())
    # controllability blocks and the observability velocity block lie in ker G
    # residuals of the constraint rows of backward-stable solves, relative to ||G||_inf max|X|; 10 for the
    # recurrence's combinations of solves: measured <= 5e-16, bound 10 rounding_unit(N) >= 9e-14
    N = fom.n1 + fom.n2
    for X in (c.position, c.velocity, o.velocity):
        assert_rounding(np.abs(G @ X).max() / (np.abs(G).sum(axis=1).max() * np.abs(X).max()),
                        10 * rounding_unit(N), "G X")
    # the observability position block is projected: it lies in range(Pi) = {b : G M^-1 b = 0};
    # measured <= 7e-17, the same bound
    P = Minv_GT.T
    assert_rounding(np.abs(P @ o.position).max() / (np.abs(P).sum(axis=1).max() * np.abs(o.position).max()),
                    10 * rounding_unit(N), "G M^-1 Y")


def test_gramians_match_dense_lyapunov_solution(make_random_model):
    fom = make_random_model(n1=14, n2=2, m=2, p=3, seed=2)
    E, A, B, C, Th = projected_system(fom)
    As, Bs = np.linalg.solve(E, A), np.linalg.solve(E, B)
    P = sla.solve_continuous_lyapunov(As, -Bs @ Bs.T)  # = the generalized one for this E
    Qs = sla.solve_continuous_lyapunov(As.T, -C.T @ C)  # = E^T Q E
    c, o = lradi_pair(fom, tol=1e-14)
    Zq, Yq = to_coordinates(c, Th), to_coordinates(o, Th)
    assert np.linalg.norm(Zq @ Zq.T - P) / np.linalg.norm(P) < 1e-10
    EtY = E.T @ Yq
    assert np.linalg.norm(EtY @ EtY.T - Qs) / np.linalg.norm(Qs) < 1e-10
    # the six leading Hankel singular values of the model (down to 0.1 of the largest: rounding
    # leaves them about 1e-14 relative; 1e-9 is the documented tolerance of the Gramians above)
    hsv = np.sqrt(np.abs(np.linalg.eigvals(P @ Qs)))
    s = np.linalg.svd(o.position.T @ c.position + o.velocity.T @ (fom.M @ c.velocity), compute_uv=False)
    assert_sets_close(s[:6], hsv[np.argsort(hsv)[::-1][:6]], rtol=1e-9, what="HSVs")


def test_shifted_solve_signs_dense(make_random_model):
    """One step by hand: (A + mu E) v = w through the saddle-point matrix equals the dense
    solve on ker G, and so does the transposed one."""
    fom = make_random_model(n1=10, n2=2, m=1, p=1, seed=3)
    E, A, B, C, Th = projected_system(fom)
    mu = -0.3 + 0.7j
    lu = fom.new_solver(cache_size=0).factor(-mu)
    rng = np.random.default_rng(0)
    w1, w2 = Th @ rng.standard_normal(Th.shape[1]), rng.standard_normal(fom.n1)
    M, D = fom.M.toarray(), fom.D.toarray()
    v1 = lu.solve((mu * M - D) @ w1 - w2)
    v2 = w1 - mu * v1
    ref = np.linalg.solve(A + mu * E, np.concatenate([Th.T @ w1, Th.T @ w2]))
    tol = solve_tolerance(A + mu * E)  # measured <= 3e-16, bound 3e-13 (and for the transpose)
    assert_rounding(np.linalg.norm(np.concatenate([Th.T @ v1, Th.T @ v2]) - ref) / np.linalg.norm(ref), tol, "solve")
    u2 = lu.solve(mu * w2 - w1, trans=True)
    u1 = w2 - (mu * M.T - D.T) @ u2
    ref = np.linalg.solve((A + mu * E).T, np.concatenate([Th.T @ w1, Th.T @ w2]))
    assert_rounding(np.linalg.norm(np.concatenate([Th.T @ u1, Th.T @ u2]) - ref) / np.linalg.norm(ref), tol,
                    "transposed solve")


def test_inputs_not_mutated(make_random_model):
    fom = make_random_model(n1=14, n2=2, m=2, p=3, seed=4)
    before = {k: getattr(fom, k).copy() for k in ("M", "D", "K", "G", "F", "L")}
    lradi(fom, "controllability")
    lradi(fom, "observability", shifts="penzl")
    lradi_pair(fom, selection="gain")
    for form in ("first-order", "vv", "pp"):
        ms.reducers.make("bt", fom, form=form).reduce(4)
    for k, X in before.items():
        Y = getattr(fom, k)
        same = (abs(X - Y).max() == 0) if k in ("M", "D", "K", "G") else np.array_equal(X, Y)
        assert same, f"{k} was modified"


def test_pair_shares_lus_and_agrees_with_single_runs():
    fom = ms.models.dsms(g=60)
    c, o = lradi_pair(fom, tol=1e-12)
    c1 = lradi(fom, "controllability", tol=1e-12)
    o1 = lradi(fom, "observability", tol=1e-12)
    assert c.lu_count == o.lu_count
    assert c.lu_count < c1.lu_count + o1.lu_count
    for a, b in ((c, c1), (o, o1)):
        Pa, Pb = a.Z @ a.Z.T, b.Z @ b.Z.T
        assert np.linalg.norm(Pa - Pb) / np.linalg.norm(Pb) < 1e-9
    # every shift used lies in the open left half-plane, pairs complete
    for res in (c, o):
        s = res.shifts
        assert np.all(s.real < 0)
        # pairs are formed as (mu, conj(mu)): exact (measured 0)
        assert_sets_close(s[s.imag > 0], np.conj(s[s.imag < 0]), rtol=1e-14, what="conjugate shifts")
        assert res.iterations == s.size and res.columns == res.iterations * (fom.m if res is c else fom.p)
        assert res.rank <= res.columns
        assert len(res.residuals) == 1 + np.sum(s.imag >= 0)


def test_given_shifts_reproduce_a_run():
    fom = ms.models.dsms(g=60)
    c = lradi(fom, "controllability", tol=1e-12)
    again = lradi(fom, "controllability", tol=1e-12, shifts=c.shifts)
    assert again.strategy == "given" and again.iterations == c.iterations
    assert np.allclose(again.Z, c.Z, rtol=0, atol=1e-13 * np.abs(c.Z).max())  # the same operations: measured 0


@pytest.mark.parametrize("strategy,selection", [("projection", "residual"), ("projection", "gain"),
                                                ("penzl", "residual")])
def test_strategies_converge(strategy, selection, make_random_model):
    fom = make_random_model(n1=20, n2=3, m=1, p=2, seed=5)
    c, o = lradi_pair(fom, shifts=strategy, selection=selection)
    assert c.converged and o.converged
    assert c.strategy == strategy and c.residual <= 1e-10 and o.residual <= 1e-10
    rp, rq = dense_residuals(fom, c, o)
    assert rp < 1e-9 and rq < 1e-9


def test_select_shifts_greedy_and_deterministic():
    cand = np.array([-1.0, -0.1 + 1j, -0.1 - 1j, -5.0, -0.5 + 3j, -0.5 - 3j])
    a = select_shifts(cand, 2)
    b = select_shifts(cand[::-1], 2)
    assert_sets_close(a, b, rtol=1e-15, what="selected shifts")  # elements of cand: the same set
    assert np.all(a.imag >= 0) and a.size == 2
    # with history: the candidate where the rational function of the used shifts is largest
    nxt = select_shifts(cand, 1, used=[-1.0, -5.0, -0.5 + 3j])
    assert np.allclose(nxt, [-0.1 + 1j])
    assert select_shifts(cand, 10).size == 4  # pairs counted once


def test_projection_shifts_are_stable_ritz_values():
    fom = ms.models.dsms(g=60)
    c = lradi(fom, "controllability", tol=1e-6)
    X = np.hstack([c.position, c.velocity])
    s = projection_shifts(fom, X, 8, selection="gain")
    assert 0 < s.size <= 8 and np.all(s.real < 0) and np.all(s.imag >= 0)
    s2 = projection_shifts(fom, X, 8, residuals=[("controllability", c.position[:, :1], c.velocity[:, :1])])
    assert 0 < s2.size <= 8 and np.all(s2.real < 0)
    # Ritz values of the DSMS lie in the hull of its spectrum
    E, A, _, _, _ = projected_system(fom)
    lam = sla.eigvals(A, E)
    for x in np.concatenate([s, s2]):
        assert lam.real.min() * 1.01 <= x.real <= lam.real.max() * 0.99 and abs(x.imag) <= lam.imag.max() * 1.01
    sp = penzl_shifts(fom, fom.new_solver(cache_size=0), 6)
    assert 0 < sp.size <= 6 and np.all(sp.real < 0)


def test_unstable_ritz_values_are_mirrored():
    base = ms.models.dsms(g=30)
    fom = ms.models.Index3Model(base.M, -0.1 * base.K, base.K, base.G, base.F, base.L)  # negative damping
    X = sla.null_space(base.G.toarray())[:, :6]
    Mk, Dk, Kk = (X.T @ (Y @ X) for Y in (fom.M, fom.D, fom.K))
    I, Z = np.eye(6), np.zeros((6, 6))
    ritz = sla.eigvals(np.block([[Z, I], [-Kk, -Dk]]), np.block([[I, Z], [Z, Mk]]))
    assert np.all(ritz.real > 0)
    s = projection_shifts(fom, X, 6, selection="gain")
    expected = -ritz.real + 1j * np.abs(ritz.imag)
    assert s.size == 6 and np.all(s.real < 0)
    assert all(np.min(np.abs(expected - x)) < 1e-10 * abs(x) for x in s)


def test_maxiter_warns_and_returns_last_iterate():
    fom = ms.models.dsms(g=60)
    with pytest.warns(ms.ConvergenceWarning, match="maxiter = 3"):
        res = lradi(fom, "controllability", maxiter=3)
    assert not res.converged and res.iterations <= 3
    assert res.residual > res.tol and isinstance(res, LRADIResult)
    assert res.summary()["converged"] is False


@pytest.mark.parametrize("kwargs,match", [
    ({"equation": "both"}, "equation"),
    ({"tol": 0.0}, "tol"),
    ({"tol": 1.5}, "tol"),
    ({"maxiter": 0}, "maxiter"),
    ({"maxiter": 2.5}, "maxiter"),
    ({"num_shifts": 0}, "num_shifts"),
    ({"shifts": "wachspress"}, "shifts"),
    ({"shifts": [0.5, -1.0]}, "left half-plane"),
    ({"shifts": [-1 + 1j]}, "conjugation"),
    ({"shifts": []}, "shifts"),
    ({"selection": "best"}, "selection"),
])
def test_bad_arguments_raise_input_error(kwargs, match):
    fom = ms.models.dsms(g=20)
    with pytest.raises(ms.InputError, match=match):
        lradi(fom, **kwargs)


def test_not_a_model_and_zero_rhs():
    with pytest.raises(ms.InputError, match="fom"):
        lradi(np.eye(3))
    fom = ms.models.dsms(g=20)
    F = np.zeros((20, 1))
    F[0, 0], F[-1, 0] = 1.0, -1.0  # F = G^T: no force on the hidden manifold
    with pytest.raises(ms.InputError, match="F vanishes"):
        lradi(fom.with_io(F=F), "controllability")


def test_any_constrained_system_is_accepted(make_random_model):
    """lradi takes any object with M, D, K, G, F, L, n1, n2, m, p (linalg.system.ConstrainedSystem),
    not only an Index3Model; without new_solver it builds its own solver. Checked against the
    dense residual on ker G."""
    from types import SimpleNamespace

    from morsuite.linalg import ConstrainedSystem

    fom = make_random_model(n1=14, n2=2, m=2, p=3, seed=5)
    plain = SimpleNamespace(**{a: getattr(fom, a) for a in ("M", "D", "K", "G", "F", "L", "n1", "n2", "m", "p")})
    assert isinstance(plain, ConstrainedSystem) and not hasattr(plain, "new_solver")
    c, o = lradi_pair(plain, tol=1e-12)
    assert c.converged and o.converged
    rp, rq = dense_residuals(fom, c, o)
    assert rp < 1e-11 and rq < 1e-11


def test_incomplete_system_names_the_argument_and_attribute():
    from types import SimpleNamespace

    fom = ms.models.dsms(g=20)
    attrs = {a: getattr(fom, a) for a in ("M", "D", "K", "G", "F", "L", "n1", "n2", "m", "p")}
    with pytest.raises(ms.InputError, match=r"fom must provide the attributes .*SimpleNamespace lacks F, L"):
        lradi(SimpleNamespace(**{k: v for k, v in attrs.items() if k not in "FL"}))
    with pytest.raises(ms.ShapeError, match=r"fom\.F has shape \(19, 1\); expected \(20, 1\)"):
        lradi(SimpleNamespace(**{**attrs, "F": attrs["F"][1:]}))
    with pytest.raises(ms.InputError, match=r"fom\.M must be a scipy\.sparse matrix"):
        lradi(SimpleNamespace(**{**attrs, "M": attrs["M"].toarray()}))
    with pytest.raises(ms.InputError, match=r"fom\.n2 must be a non-negative integer"):
        lradi(SimpleNamespace(**{**attrs, "n2": 1.5}))


def test_unconstrained_model():
    fom = ms.models.tcom(nc=10, constrained=False)
    c, o = lradi_pair(fom)
    assert c.converged and o.converged
    rp, rq = dense_residuals(fom, c, o)
    assert rp < 1e-9 and rq < 1e-9


def test_standard_eigenproblem_shifts_equal_qz_shifts():
    """Projection shifts from geev on E^-1 A (the default for a well-conditioned X^T M X)
    are those of QZ on the pencil (standard_rcond=0), for both selections."""
    fom = ms.models.tcom(nc=10)
    c, o = lradi_pair(fom, tol=1e-6)
    X = np.hstack([c.position, c.velocity])
    res = [("controllability", c.position[:, :1], c.velocity[:, :1]),
           ("observability", o.position[:, :1], o.velocity[:, :1])]
    for kw in ({"selection": "gain"}, {"residuals": res}):
        a = projection_shifts(fom, X, 6, **kw)
        b = projection_shifts(fom, X, 6, standard_rcond=0, **kw)
        assert a.size == b.size > 0
        assert_sets_close(a, b, atol=1e-9 * np.abs(b).max(), what="projection shifts (geev against QZ)")
    assert c.summary()["ritz_standard_rcond"] == 1e-8


def test_range_space_projection_equals_dense_projector(make_random_model):
    """ManifoldProjector.project (b - G^T X^T b) against Pi = I - G^T (G M^-1 G^T)^-1 G M^-1,
    formed densely; above RANGE_FORM_MAX_N2 constraints it falls back to the solve."""
    from morsuite.linalg.manifold import ManifoldProjector

    fom = make_random_model(n1=14, n2=3, m=2, p=2, seed=4)
    M, G = fom.M.toarray(), fom.G.toarray()
    Mi = np.linalg.inv(M)
    Pi = np.eye(fom.n1) - G.T @ np.linalg.solve(G @ Mi @ G.T, G @ Mi)
    b = np.random.default_rng(0).standard_normal((fom.n1, 4)) + 1j
    proj = ManifoldProjector(fom, fom.new_solver(cache_size=0))
    assert proj._X is not None
    # Pi's rounding carries the conditioning of M and G M^-1 G^T and its obliqueness ||Pi||:
    # measured <= 6e-16, bound 4e-14
    tol = rounding_unit(fom.n1) * np.linalg.cond(M) * np.linalg.cond(G @ Mi @ G.T) * np.linalg.norm(Pi, 2)
    assert_rounding(np.abs(proj.project(b) - Pi @ b).max() / np.abs(Pi @ b).max(), tol, "range form")
    assert_rounding(np.abs(proj.project(b) - proj(b)[0]).max() / np.abs(b).max(), tol, "range form against solve")
    try:
        ManifoldProjector.RANGE_FORM_MAX_N2 = 2
        proj2 = ManifoldProjector(fom, fom.new_solver(cache_size=0))
        assert proj2._X is None
        assert_rounding(np.abs(proj2.project(b) - Pi @ b).max() / np.abs(Pi @ b).max(), tol, "solve form")
    finally:
        ManifoldProjector.RANGE_FORM_MAX_N2 = 64


# -- kept LUs (shift_reuse) and column compression (compress_tol) -------------------------
def test_shift_reuse_saves_lus_and_keeps_the_dense_gramians(make_random_model):
    """Reused LUs change the shift sequence, not the answer: both runs match the dense Lyapunov
    solutions on ker G to the ADI tolerance, and reuse pays fewer LUs than steps."""
    fom = ms.models.tcom(nc=30)
    P, Th = dense_controllability_gramian(fom)
    fresh = lradi(fom, "controllability", tol=1e-12, shift_reuse=0.0, lu_pool_mib=0.0)
    kept = lradi(fom, "controllability", tol=1e-12, shift_reuse=0.5)
    assert fresh.lu_reused == 0 and kept.lu_reused > 0
    assert kept.lu_count < fresh.lu_count
    # every step is served by a new LU or a kept one (plus the projector's LU)
    steps = int(np.sum(kept.shifts.imag >= 0))
    assert kept.lu_count - 1 + kept.lu_reused == steps
    for res in (fresh, kept):
        assert_converged_to(res, P, Th)


def test_given_shifts_are_factored_once_each():
    fom = ms.models.dsms(g=60)
    shifts = [-0.05 + 0.2j, -0.05 - 0.2j, -0.3, -1.0]
    res = lradi(fom, "controllability", tol=1e-8, shifts=shifts, compress_tol=0.0)
    assert res.converged and res.iterations > 2 * len(shifts)  # cycled several times
    assert res.lu_count == 1 + 3  # the projector's LU and one per distinct shift (a pair counted once)
    # kept LUs change nothing: the same run without them
    again = lradi(fom, "controllability", tol=1e-8, shifts=shifts, compress_tol=0.0, lu_pool_mib=0.0)
    assert again.lu_count > res.lu_count and again.iterations == res.iterations
    assert np.allclose(again.Z, res.Z, rtol=0, atol=1e-13 * np.abs(res.Z).max())  # the same LUs: measured 0


def test_factor_store_compression_matches_truncated_svd():
    """Planted answer: columns spanning 12 directions with singular values down to 1e-9, plus
    noise at 1e-14; compression at 1e-11 keeps exactly the 12, and the Gramian to the bound."""
    from morsuite.linalg.factor_store import FactorStore
    rng = np.random.default_rng(5)
    n1 = 300
    U = np.linalg.qr(rng.standard_normal((2 * n1, 12)))[0]
    s = np.logspace(0, -9, 12)
    cols = U @ (s[:, None] * rng.standard_normal((12, 200))) + 1e-14 * rng.standard_normal((2 * n1, 200))
    plain, comp = FactorStore(n1, 0.0), FactorStore(n1, 1e-11, chunk=16)
    # plain for the first 60 columns (plain_bytes), then compressed; and a budget that all 200 columns fit
    late, fits = FactorStore(n1, 1e-11, chunk=16, plain_bytes=60 * 16 * n1), FactorStore(n1, 1e-11, plain_bytes=1e9)
    for j in range(0, 200, 5):
        for st in (plain, comp, late, fits):
            st.append(2.0, cols[:n1, j:j + 5], cols[n1:, j:j + 5])
        # compressed, the blocks grow by an eighth (at least a chunk), not by doubling; plain up to the
        # switch, by doubling but not beyond the switch and a chunk
        assert comp.Z1.shape[1] <= comp.k_peak + max(comp.chunk, comp.k_peak // 8)
        assert late.Z1.shape[1] <= max(late.k_peak + max(late.chunk, late.k_peak // 8), 60 + late.chunk)
        assert late.compressions == 0 if j + 5 <= 60 else late.compressions >= 1
    for st in (plain, comp, late, fits):
        st.finish()
    Zp, Zc, Zl, Zf = (np.vstack(st.blocks()) for st in (plain, comp, late, fits))
    assert Zp.shape[1] == 200 and comp.columns == 200 and Zc.shape[1] == 12 and Zl.shape[1] == 12
    assert fits.compressions == 0 and Zf.shape[1] == 200 and np.array_equal(Zf, Zp)  # stored as appended
    # finish trims the blocks to the columns in use (the store is kept for the factor's life)
    assert plain.Z1.shape[1] == plain.Z2.shape[1] == 200 and comp.Z1.shape[1] == comp.Z2.shape[1] == 12
    P = Zp @ Zp.T
    # each truncation at most tol^2 ||P||, each absorption 20 sqrt(b) eps ||P||: 40 of b = 5 (comp), the
    # late store's first of b = 65 (the 60 plain columns and 5 more) and 28 of 5
    for Z, bound in ((Zc, comp.compressions * 1e-22 + 40 * 20 * np.sqrt(5) * 2.2e-16),
                     (Zl, late.compressions * 1e-22 + (20 * np.sqrt(65) + 28 * 20 * np.sqrt(5)) * 2.2e-16)):
        assert np.linalg.norm(P - Z @ Z.T, 2) <= bound * np.linalg.norm(P, 2)
        assert_sets_close(np.linalg.svd(Z, compute_uv=False), np.linalg.svd(Zp, compute_uv=False)[:12],
                          rtol=1e-6, what="kept singular values")


def test_householder_fallback_by_row_blocks_is_a_qr_of_the_stacked_blocks():
    """The fallback's tall-skinny QR (FactorStore._tsqr, row blocks of TSQR_BYTES, here 64 rows and a last
    block of 6 rows, fewer than the 16 columns) is a QR of the stacked [X1; X2]: Q orthonormal to rounding,
    QR = X to rounding of ||X||, and R's singular values those of X (dense SVD); a rank-deficient block
    normalised by it keeps its numerical rank."""
    from morsuite.linalg.factor_store import FactorStore
    rng = np.random.default_rng(11)
    n1, b = 70, 16
    X = rng.standard_normal((2 * n1, 10)) @ rng.standard_normal((10, b))  # rank 10
    st = FactorStore(n1, 1e-8)
    st.TSQR_BYTES = 8 * b  # rows per block: max(4 b, TSQR_BYTES / (8 b)) = 64
    X1, X2 = np.asfortranarray(X[:n1]), np.asfortranarray(X[n1:])
    parts, Qr, R = st._tsqr(X1, X2)
    assert len(parts) == 4 and min(j - i for _, i, j, _, _ in parts) == 6
    Q = np.zeros((2 * n1, Qr.shape[1]))
    for (Xb, i, j, q, at) in parts:
        Q[(0 if Xb is X1 else n1) + i:(0 if Xb is X1 else n1) + j] = q @ Qr[at:at + q.shape[1]]
    assert_rounding(*orthonormality_error(Q), "orthonormality of Q")
    assert np.linalg.norm(Q @ R - X) <= 10 * rounding_unit(2 * n1) * np.linalg.norm(X)
    assert_sets_close(np.linalg.svd(R, compute_uv=False)[:10], np.linalg.svd(X, compute_uv=False)[:10],
                      rtol=1e-12, what="singular values")
    st.Z1, st.Z2 = np.asfortranarray(X[:n1].copy()), np.asfortranarray(X[n1:].copy())
    Rn, t = st._normalise(0, b, 1e-10 * np.linalg.norm(X, 2))  # Gram condition ~1e32: Householder
    assert st.householder == 1 and t == 10
    Qn = np.vstack([st.Z1[:, :t], st.Z2[:, :t]])
    assert_rounding(*orthonormality_error(Qn), "orthonormality of the normalised block")
    assert np.linalg.norm(Qn @ Rn - X) <= 1e-10 * np.linalg.norm(X)


def test_compressed_store_keeps_the_plain_gramian_on_both_normalisations():
    """A model's own ADI columns (tcom(30), in the iteration's order) with a nearly repeated
    pair inserted: the compressed store's ZZ^T is within the documented bound of the plain
    store's fed the same columns; the well-conditioned blocks take Cholesky-QR, the block
    with the pair (Gram condition about 1e20) the Householder fallback; Q stays orthonormal."""
    from morsuite.linalg.factor_store import FactorStore
    fom = ms.models.tcom(nc=30)
    n1 = fom.n1
    Z = lradi(fom, "controllability", tol=1e-12, compress_tol=0.0).Z
    x = Z[:, 40]
    pair = np.column_stack([x, x + 1e-10 * np.linalg.norm(x) * np.roll(x, 1) / np.linalg.norm(x)])
    cols = np.hstack([Z[:, :41], pair, Z[:, 41:]])
    tol, chunk = 1e-6, 16
    plain, comp = FactorStore(n1, 0.0), FactorStore(n1, tol, chunk=chunk)
    fallback = None  # Householder normalisations in the absorption of the block with the pair
    for j in range(0, cols.shape[1], 2):
        before = comp.householder
        for st in (plain, comp):
            st.append(1.0, cols[:n1, j:j + 2], cols[n1:, j:j + 2])
        if comp.k and comp.nb == 0:  # just absorbed: Q orthonormal to rounding
            Q = np.vstack([comp.Z1[:, :comp.k], comp.Z2[:, :comp.k]])
            assert_rounding(*orthonormality_error(Q), "orthonormality of Q")  # measured <= 8e-15, bound 3e-13
            if fallback is None and j + 2 > 42:
                fallback = comp.householder - before
    for st in (plain, comp):
        st.finish()
    assert fallback >= 1 and comp.householder < 2 * comp.compressions and comp.compressions >= 2
    P, Pc = (np.vstack(st.blocks()) for st in (plain, comp))
    P, Pc = P @ P.T, Pc @ Pc.T
    assert comp.k < plain.k == cols.shape[1]
    # each absorption with its truncation at most (tol^2 + 20 sqrt(b) eps) ||P||
    bound = comp.compressions * (tol ** 2 + 20 * np.sqrt(chunk) * 2.2e-16) * np.linalg.norm(P, 2)
    assert np.linalg.norm(P - Pc, 2) <= bound


def test_compressed_factors_keep_the_hankel_singular_values():
    """The compressed factors' Gramians are within the compression bound of the uncompressed
    ones, and both give the dense model's Hankel singular values."""
    fom = ms.models.tcom(nc=30)
    E, A, B, C, Th = projected_system(fom)
    As, Bs = np.linalg.solve(E, A), np.linalg.solve(E, B)
    P = sla.solve_continuous_lyapunov(As, -Bs @ Bs.T)
    Qs = sla.solve_continuous_lyapunov(As.T, -C.T @ C)
    hsv = np.sqrt(np.abs(np.linalg.eigvals(P @ Qs)))
    full = lradi_pair(fom, tol=1e-12, compress_tol=0.0)
    tau = 1e-7
    comp = lradi_pair(fom, tol=1e-12, compress_tol=tau, compress_from_mib=0.0)
    kept = lradi_pair(fom, tol=1e-12, compress_tol=tau)  # these factors fit compress_from_mib: kept plain
    for a, b in zip(full, kept):
        assert b.compressions == 0 and b.rank == b.columns == a.columns
        assert np.linalg.norm(a.Z - b.Z) <= 1e-13 * np.linalg.norm(a.Z)  # the same run: the same columns
    for a, b in zip(full, comp):
        assert a.rank == a.columns and b.columns == a.columns and b.rank < a.rank
        Pa, Pb = a.Z @ a.Z.T, b.Z @ b.Z.T
        absorbed = -(-b.columns // 64)  # at most: an absorption takes 64 waiting columns or more
        bound = (b.compressions * tau ** 2 + absorbed * 20 * 8 * 2.2e-16) * np.linalg.norm(Pa, 2)
        assert np.linalg.norm(Pa - Pb, 2) <= bound
    for c, o in (full, comp):
        s = np.linalg.svd(o.position.T @ c.position + o.velocity.T @ (fom.M @ c.velocity), compute_uv=False)
        # each of the factors' 8 leading values matches a dense one (by distance, not by sorted position)
        assert all(np.min(np.abs(hsv - x)) <= 1e-6 * x for x in s[:8]), "HSVs"


@pytest.mark.parametrize("kwargs,match", [
    ({"shift_reuse": 1.0}, "shift_reuse"),
    ({"shift_reuse": -0.1}, "shift_reuse"),
    ({"compress_tol": 1.0}, "compress_tol"),
    ({"compress_from_mib": -1.0}, "compress_from_mib"),
    ({"pool_full_reuse": 1.0}, "pool_full_reuse"),
    ({"pool_full_reuse": -0.2}, "pool_full_reuse"),
    ({"lu_pool_mib": -1.0}, "lu_pool_mib"),
    ({"lu_pool_mib": float("inf")}, "lu_pool_mib"),
])
def test_bad_reuse_and_compression_options(kwargs, match):
    with pytest.raises(ms.InputError, match=match):
        lradi(ms.models.dsms(g=20), **kwargs)


def test_full_pool_rule_saves_lus_and_keeps_the_dense_gramian():
    """A pool too small for the run (about 4 of fem_block(200)'s LUs): the full-pool rule
    (pool_full_reuse, default) pays fewer LUs than the plain one (0: least recently used
    dropped, radius shift_reuse) and both match the dense Lyapunov solution on ker G to the
    ADI tolerance; a pool that never fills gives the same bits with either rule."""
    fom = ms.models.fem_block(n1=200)
    P, Th = dense_controllability_gramian(fom)
    plain = lradi(fom, "controllability", tol=1e-12, lu_pool_mib=2.2, pool_full_reuse=0.0)
    full = lradi(fom, "controllability", tol=1e-12, lu_pool_mib=2.2)
    assert full.pool_full_reuse == 0.8 and full.summary()["pool_full_reuse"] == 0.8
    assert plain.lu_dropped > 0 and full.lu_dropped > 0
    assert full.lu_count < 0.9 * plain.lu_count
    for res in (plain, full):
        assert_converged_to(res, P, Th)
    roomy = [lradi(fom, "controllability", tol=1e-12, pool_full_reuse=f) for f in (0.0, 0.8)]
    assert roomy[0].lu_dropped == 0 and roomy[0].lu_count == roomy[1].lu_count
    assert np.array_equal(roomy[0].Z, roomy[1].Z)
