"""The dense kernels of one IRKA iteration against independent dense references.

References: scipy's triangular solve, numpy's SVD and QR of the column-scaled matrix, the
orthogonal projector onto null(G) formed densely, and a fresh refinement operator.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

import morsuite as ms
from morsuite.linalg.dense import orth, right_solve
from support import assert_rounding, rounding_unit, solve_tolerance


@pytest.mark.parametrize("dtype", [float, complex])
@pytest.mark.parametrize("order", ["C", "F"])
def test_right_solve_against_solve_triangular(dtype, order):
    rng = np.random.default_rng(0)
    X = np.array(rng.standard_normal((300, 7)) + (1j * rng.standard_normal((300, 7)) if dtype is complex else 0),
                 order=order)
    R = np.triu(rng.standard_normal((7, 7))) + 4 * np.eye(7)
    R[np.tril_indices(7, -1)] = np.nan  # the strictly lower part is not read
    X0 = X.copy()
    Y = right_solve(X, R)
    ref = sla.solve_triangular(np.triu(np.nan_to_num(R)), X.T, trans="T").T
    assert np.array_equal(X, X0) and Y.flags.f_contiguous
    # triangular solves with R: measured 2e-16, bound 2e-14
    assert_rounding(np.max(np.abs(Y - ref)) / np.max(np.abs(ref)), solve_tolerance(np.triu(np.nan_to_num(R))), "X R^-1")


def test_orth_ill_tol_skips_the_basis_exactly_when_the_svd_says_ill_conditioned():
    """ill_tol: Q is None iff the smallest kept singular value of the scaled X (numpy's SVD) is
    below ill_tol * s[0]; otherwise the same basis as without ill_tol. Both the Cholesky-QR
    (cond 1e2) and the Householder path (cond 1e7, 1e10) are taken."""
    rng = np.random.default_rng(5)
    for cond in (1e2, 1e7, 1e10):
        U0, _ = np.linalg.qr(rng.standard_normal((2000, 8)))
        X = U0 @ np.diag(np.logspace(0, -np.log10(cond), 8)) @ np.linalg.qr(rng.standard_normal((8, 8)))[0]
        s_ref = np.linalg.svd(X / np.linalg.norm(X, axis=0), compute_uv=False)
        k = int(np.sum(s_ref > 1e-14 * s_ref[0]))
        Q, s = orth(X, 1e-14, ill_tol=1e-8)
        # rounding-level tolerances (tests/test_irka.py::test_cholesky_qr_orth_matches_svd_and_falls_back):
        # Cholesky QR below kappa 1e6 has its small singular values to eps kappa s[0], Householder to eps s[0]
        unit = rounding_unit(X.shape[0])
        assert np.allclose(s, s_ref, rtol=1e-6, atol=unit * (cond if cond < 1e6 else 1.0) * s_ref[0])
        assert (Q is None) == (s_ref[k - 1] < 1e-8 * s_ref[0]) == (cond > 1e9)
        if Q is not None:
            Q0, _ = orth(X, 1e-14)
            assert Q.shape == Q0.shape and np.allclose(Q, Q0, atol=1e-9)
            assert np.allclose(Q.T @ Q, np.eye(Q.shape[1]), atol=unit)


def _in_order_basis(Y, keep):
    """Orthonormal basis of Y's columns ``keep`` in their order (QR with a positive diagonal)."""
    Q, R = np.linalg.qr(Y[:, keep])
    return Q * np.sign(np.diag(R))


def test_kernel_projection_on_the_rows_of_g_against_the_dense_projector(monkeypatch):
    """_restrict changes only the rows G touches; its result is the in-order orthonormal basis of
    (I - P) X, P the dense orthogonal projector onto range(G^T): the one-pass path (small
    removed part), and the fallback that drops a column almost wholly in range(G^T)."""
    fom = ms.models.tcom(nc=30)
    red = ms.reducers.make("irka", fom)
    red._setup()
    import morsuite.reducers.irka.second_order as irka_mod
    fallbacks = []
    gs = irka_mod.gram_schmidt
    monkeypatch.setattr(irka_mod, "gram_schmidt", lambda *a, **k: fallbacks.append(1) or gs(*a, **k))
    G = fom.G.toarray()
    P = G.T @ np.linalg.solve(G @ G.T, G)
    N = np.linalg.svd(G)[2][G.shape[0]:].T  # orthonormal basis of null(G)
    rng = np.random.default_rng(2)
    X = np.linalg.qr(N @ rng.standard_normal((N.shape[1], 5)) + 1e-3 * G.T @ rng.standard_normal((G.shape[0], 5)))[0]
    Z = red._restrict(X)
    ref = _in_order_basis(X - P @ X, slice(None))
    unit = rounding_unit(fom.n1)  # tcom's G: condition number 1, entries of order 1
    assert np.max(np.abs(Z - ref)) < unit
    assert np.max(np.abs(G @ Z)) < unit and np.allclose(Z.T @ Z, np.eye(5), atol=unit)
    assert not fallbacks  # the one-pass path
    # column 1 almost wholly in range(G^T) (0.1 of it left), column 3 wholly (1e-5 left: dropped)
    g = G.T @ rng.standard_normal(G.shape[0])
    n = N @ rng.standard_normal(N.shape[1])
    X2 = X.copy()
    X2[:, 1] = 0.1 * n / np.linalg.norm(n) + g / np.linalg.norm(g)
    X2[:, 3] = 1e-5 * n / np.linalg.norm(n) + g / np.linalg.norm(g)
    X2 = np.linalg.qr(X2)[0]
    Z2 = red._restrict(X2)
    Y = X2 - P @ X2
    assert Z2.shape[1] == 4 and fallbacks == [1]  # Gram-Schmidt dropped column 3
    assert np.max(np.abs(Z2 - _in_order_basis(Y, [0, 1, 2, 4]))) < 1e-10
    assert np.max(np.abs(G @ Z2)) < unit and np.allclose(Z2.T @ Z2, np.eye(4), atol=unit)


def test_refinement_operator_reused_across_shifts_bit_for_bit():
    """One operator over real -> complex -> real -> complex shifts gives the bits of a fresh
    operator at each shift, in both orientations; a product made at one shift stays that shift's
    after the operator moved on (nothing is overwritten in place)."""
    from morsuite.linalg.refine import SaddleOperator

    fom = ms.models.dsms(g=300)
    solver = fom.new_solver(cache_size=0)
    rng = np.random.default_rng(1)
    n = fom.n1 + fom.n2
    xr, xi = (rng.standard_normal(n).astype(np.longdouble) for _ in range(2))
    op = SaddleOperator(solver.pattern)
    for a in (0.05, 0.3 + 0.7j, 0.2, 1.5 + 0.1j):
        for trans in (True, False):
            got = op.at(a, trans, True)(xr, xi)
            ref = SaddleOperator(solver.pattern).at(a, trans, True)(xr, xi)
            assert all(np.array_equal(u, v) for u, v in zip(got, ref))
            got1 = op.at(a, trans, True)(xr)
            ref1 = SaddleOperator(solver.pattern).at(a, trans, True)(xr)
            assert np.array_equal(got1[0], ref1[0]) and (got1[1] is None) == (ref1[1] is None)
    first = op.at(0.3 + 0.7j, True, True)
    op.at(1.5 + 0.1j, True, True)
    ref = SaddleOperator(solver.pattern).at(0.3 + 0.7j, True, True)(xr, xi)
    assert all(np.array_equal(u, v) for u, v in zip(first(xr, xi), ref))


def test_bases_made_orthonormal_on_two_threads_give_the_same_rom(monkeypatch):
    """The right and left bases orthonormalised concurrently (threshold lowered so that a small
    model takes that path) give the bits of the serial run, with refined solves and the
    kernel projection in play (DSMS)."""
    from morsuite.reducers.irka.second_order import IRKA

    fom = ms.models.dsms(g=400)
    opts = dict(maxit=4, tol=1e-300, safeguard="off", refine_when="always")
    monkeypatch.setattr(IRKA, "PARALLEL_BASES_MIN", 0)
    calls = []
    import morsuite.reducers.irka.second_order as irka_mod
    mt = irka_mod.map_threads
    monkeypatch.setattr(irka_mod, "map_threads", lambda fn, jobs, t: calls.append((len(jobs), t)) or mt(fn, jobs, t))
    with pytest.warns(ms.errors.ConvergenceWarning):
        one = ms.reducers.make("irka", fom, solver_threads=1, **opts).reduce(6)
    with pytest.warns(ms.errors.ConvergenceWarning):
        two = ms.reducers.make("irka", fom, solver_threads=2, **opts).reduce(6)
    assert (2, 2) in calls  # the two bases went to two threads
    for k in ("M", "D", "K", "F", "L"):
        assert np.array_equal(getattr(one.rom, k), getattr(two.rom, k)), k
