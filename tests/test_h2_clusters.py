"""The descent in cluster-polynomial coordinates (morsuite.reducers.h2.clusters).

References independent of the module: the error system's Lyapunov solution (scipy), the pole-residue
variable projection of morsuite.reducers.h2.poles (value, relative gradient and its own descent, where
the poles are well separated), central differences of J for the gradient, and of the gradient for
Kaufman's matrix at a zero residual (where it is the Hessian).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from morsuite.errors import MorsuiteError
from morsuite.linalg.dense import match_sets
from morsuite.reducers.h2.clusters import (Clusters, ModalTM, _fd_hessian, alternating_descent, cluster_descent,
                                         cluster_evaluate)
from morsuite.reducers.h2.gradient import ModalTarget
from morsuite.reducers.h2.poles import Coordinates, ModalValues, optimal_residues
from morsuite.reducers.h2.poles_descent import pole_descent
from support import assert_rounding, rounding_unit, solve_tolerance


def _target(seed=3, n=20, close=1.03):
    """A real block-diagonal SISO model of n/2 lightly damped modes (two of them close) and its modal form."""
    rng = np.random.default_rng(seed)
    w = np.sort(rng.uniform(0.5, 5, n // 2))
    w[1] = w[0] * close
    lam = -0.05 * w + 1j * w
    A = np.zeros((n, n))
    for k, lk in enumerate(lam):
        A[2 * k:2 * k + 2, 2 * k:2 * k + 2] = [[lk.real, -lk.imag], [lk.imag, lk.real]]
    B, C = rng.standard_normal((n, 1)), rng.standard_normal((1, n))
    mu, X = np.linalg.eig(A)
    return (A, B, C), ModalTarget(mu, np.linalg.solve(X, B), C @ X), lam


def _dense_error2(sys_full, sys_red):
    A, B, C = sys_full
    Ar, br, cr = sys_red
    Ae = sla.block_diag(A, Ar)
    Be = np.vstack([B, br[:, None]])
    Ce = np.hstack([C, -cr[None, :]])
    P = sla.solve_continuous_lyapunov(Ae, -Be @ Be.T)
    return float((Ce @ P @ Ce.T)[0, 0])


def _pole_residue(poles):
    """Pole-residue coordinates of three pairs (residues to be optimised), the constraint enforced."""
    co = Coordinates(0, 3)
    x = co.join([], [], poles[:3], np.full(3, 0.1 + 0.1j))
    co.set_pivot(6)
    x[6] -= (co.a @ x) / co.a[6]
    return co, x


def _start(lam, k=3):
    s = lam[:k] * (1 + 0.02j)
    return np.concatenate([s, np.conj(s)])


def test_clusters_group_close_poles_and_give_them_back():
    poles = np.array([-0.03 + 0.011j, -0.0302 + 0.0112j, -0.5 + 2j, -0.7])
    poles = np.concatenate([poles, np.conj(poles[poles.imag != 0])])
    cl = Clusters(poles, ctol=0.5)
    assert sorted(cl.m) == [1, 2, 4]
    back = cl.poles(cl.y)
    perm, dist = match_sets(poles, back, scale=np.abs(poles))
    assert dist.max() < 1e-6     # a double-ish root of a quartic: about sqrt(eps) of the gap
    with pytest.raises(MorsuiteError, match="poles"):
        cluster_descent(np.array([0.1, -1.0]), ModalTM(_target()[1]))
    with pytest.raises(MorsuiteError, match="hessian"):
        cluster_descent(poles, ModalTM(_target()[1]), hessian="newton")


def test_value_and_rho_against_dense_and_pole_residue_references():
    full, tgt, lam = _target()
    poles = _start(lam)
    cl = Clusters(poles)
    ev = cluster_evaluate(cl, cl.y, ModalTM(tgt))
    A, b, c = ev.realization()
    # relative degree 2: c b = 0 up to the rounding of its r terms (measured 3e-17, bound 8e-15)
    assert_rounding(abs(c @ b) / (np.linalg.norm(c) * np.linalg.norm(b)), rounding_unit(b.size), "c b")
    J_dense = _dense_error2(full, (A, b, c))
    assert ev.value == pytest.approx(J_dense, rel=1e-10)
    # the same projection in pole-residue coordinates (poles 0.5 apart here: well conditioned)
    co, x = _pole_residue(poles)
    pr = optimal_residues(co, x, ModalValues(tgt))
    assert ev.value == pytest.approx(pr.value, rel=1e-9)
    assert ev.rho == pytest.approx(pr.rho, rel=1e-6)
    assert 1e-3 < ev.rho < 1.0


def test_gradient_against_central_differences():
    full, tgt, lam = _target()
    cl = Clusters(_start(lam))
    tt = ModalTM(tgt)
    ev = cluster_evaluate(cl, cl.y, tt)
    rng = np.random.default_rng(0)
    h = 1e-4
    for _ in range(4):
        d = rng.standard_normal(ev.y.size)
        jp = [cluster_evaluate(cl, ev.y + k * h * d, tt, derivatives=0).value for k in (-2, -1, 1, 2)]
        fd = (jp[0] - 8 * jp[1] + 8 * jp[2] - jp[3]) / (12 * h)
        assert ev.g @ d == pytest.approx(fd, rel=1e-6, abs=1e-9 * ev.value)


def test_kaufman_matrix_is_the_hessian_at_zero_residual():
    """T itself of degree 6 and relative degree 2: at its own poles J = 0, and the Gauss-Newton matrix is the
    Hessian (differences of the gradient)."""
    full, tgt, lam = _target(n=6)
    A, B, C = full
    C = C - (C @ B) / (B.T @ B) * B.T          # C B = 0: relative degree 2
    mu, X = np.linalg.eig(A)
    tgt = ModalTarget(mu, np.linalg.solve(X, B), C @ X)
    cl = Clusters(mu)
    ev = cluster_evaluate(cl, cl.y, ModalTM(tgt))
    assert abs(ev.value) < 1e-10 * tgt.norm2
    H = _fd_hessian(cl, ev, ModalTM(tgt), h=1e-6)
    np.testing.assert_allclose(H, ev.G, rtol=1e-4, atol=1e-5 * np.abs(ev.G).max())


def test_newton_descent_converges_to_the_pole_residue_optimum():
    full, tgt, lam = _target()
    poles = _start(lam)
    ev, its, reason, hist = cluster_descent(poles, ModalTM(tgt), maxit=200, gtol=1e-9, hessian="fd")
    assert reason == "converged" and ev.rho <= 1e-9
    assert np.all(np.diff(hist) <= 1e-9 * hist[0])
    # the reference: variable projection in pole-residue coordinates from the same poles
    co, x = _pole_residue(poles)
    tv = ModalValues(tgt)
    co, ref, _, why, _, _ = pole_descent(co, optimal_residues(co, x, tv).x, tv, maxit=300, gtol=1e-9)
    assert why == "converged"
    assert ev.value == pytest.approx(ref.value, rel=1e-8)
    perm, dist = match_sets(ev.poles, co.split(ref.x)[0], scale=np.abs(ev.poles))
    assert dist.max() < 1e-6
    assert _dense_error2(full, ev.realization()) == pytest.approx(ev.value, rel=1e-8)


def test_alternating_descent_hands_over_to_the_same_optimum():
    """Cluster Gauss-Newton, then the pole-residue descent from its poles (residues re-optimised): the
    handover keeps the model (no jump in J) and ends at the pole-residue descent's own optimum."""
    full, tgt, lam = _target()
    poles = _start(lam)
    tv = ModalValues(tgt)
    co, x = _pole_residue(poles)
    co_a, ev_a, its, reason, record = alternating_descent(co, x, tv, rounds=2, cluster_maxit=5, gtol=1e-9)
    assert reason == "converged" and ev_a.rho <= 1e-9 and record
    assert record[0]["h2_pole"] <= record[0]["h2_cluster"] * (1 + 1e-12)
    co_r, ref, _, why, _, _ = pole_descent(co, optimal_residues(co, x, tv).x, tv, maxit=300, gtol=1e-9)
    assert why == "converged"
    assert ev_a.value == pytest.approx(ref.value, rel=1e-8)
    assert _dense_error2(full, _real(co_a, ev_a.x)) == pytest.approx(ev_a.value, rel=1e-8)


def _real(co, x):
    from morsuite.reducers.h2.poles import _real_modal
    return _real_modal(co, x)


def test_product_form_of_the_target_values_against_triangular_solves():
    """ModalTM.tm_values by the all-pass product form against one triangular solve per target pole
    (h2_orthonormal.modal_tm_values) and the triangular Sylvester solve, for a sequence with repeats and
    poles 1e-6 apart."""
    from morsuite.reducers.h2.orthonormal import modal_tm_values, tm_realization
    _, tgt, lam = _target()
    tt = ModalTM(tgt)
    seq = np.repeat(np.array([-0.03 + 0.5j, -0.03 - 0.5j, -0.03 * (1 + 1e-6) + 0.5j, -0.2, -1.0 + 3j]), 2)
    A, b = tm_realization(seq)
    ref = modal_tm_values(A, b, tt.mu, tt.psi)
    # the rounding of solves with A (kappa 63 here): measured <= 3e-15 entrywise relative, bound 4e-13
    tol = solve_tolerance(A)
    np.testing.assert_allclose(tt.tm_values(A, b, seq), ref, rtol=tol, atol=tol * np.abs(ref).max())
    np.testing.assert_allclose(tt.tm_values(A, b), ref, rtol=tol, atol=tol * np.abs(ref).max())


def test_projection_value_against_the_error_systems_lyapunov_solution():
    """The cancellation-free value of the projection (h2_orthonormal.projection_value, ModalValues.projected)
    against the error system's Lyapunov solution (scipy) for the optimal model of the poles, and against the
    residual form of h2_value at the pole-residue optimum."""
    full, tgt, lam = _target()
    tv = ModalValues(tgt)
    for k in (3, 4):
        poles = _start(lam, k)
        cl = Clusters(poles)
        ev = cluster_evaluate(cl, cl.y, ModalTM(tgt))
        J_dense = _dense_error2(full, ev.realization())
        co = Coordinates(0, k)
        x = co.join([], [], poles[:k], np.full(k, 0.1 + 0.1j))
        co.set_pivot(2 * k)
        x[2 * k] -= (co.a @ x) / co.a[2 * k]
        pr = optimal_residues(co, x, tv)
        J, floor = tv.projected(co, pr.x)
        assert J == pytest.approx(J_dense, rel=1e-12)
        assert 0 < floor < 1e-10 * J
        assert J == pytest.approx(tv.precise(co, pr.x)[0], rel=1e-9)


def test_polish_moves_a_coarse_optimum_to_the_closer_targets_stationary_point():
    """so_h2_siso._polish: the optimum against a coarse target (the model without its two weakest modes) moved
    to the full target: stationary there (the orthonormal relative gradient of h2_clusters, an independent
    form), its J the error system's Lyapunov value, and the same point as the pole descent against the full
    target from the same start."""
    from morsuite.reducers.h2.siso import _polish
    full, tgt, lam = _target()
    weight = np.abs(tgt.C[0] * tgt.B[:, 0]) / np.abs(tgt.poles.real)
    # the two weakest conjugate pairs dropped: a cut between the 4th and 5th smallest weights, clear of
    # rounding (conjugates have equal weights), not an order of the eigensolver's output
    w = np.partition(weight, [3, 4])[3:5]
    assert w[1] > 1.01 * w[0]
    keep = np.flatnonzero(weight > 0.5 * (w[0] + w[1]))
    assert keep.size == weight.size - 4
    coarse = ModalValues(ModalTarget(tgt.poles[keep], tgt.B[keep], tgt.C[:, keep]))
    co, x = _pole_residue(_start(lam))
    co, ev_c, _, why, _, _ = pole_descent(co, optimal_residues(co, x, coarse).x, coarse, maxit=300, gtol=1e-9)
    assert why == "converged"
    tv = ModalValues(tgt)
    assert optimal_residues(co, ev_c.x, tv).rho > 1e-4     # not stationary for the full target
    co_p, ev_p, its, reason, rec = _polish(co, ev_c, lambda: tgt, gtol=1e-9, maxit=100)
    assert reason == "converged" and its > 0 and rec["states"] == tgt.order
    poles = co_p.split(ev_p.x)[0]
    cl = Clusters(poles)
    assert cluster_evaluate(cl, cl.y, ModalTM(tgt), derivatives=1).rho < 1e-7
    assert _dense_error2(full, _real(co_p, ev_p.x)) == pytest.approx(ev_p.value, rel=1e-8)
    _, ref, _, _, _, _ = pole_descent(co, optimal_residues(co, ev_c.x, tv).x, tv, maxit=300, gtol=1e-9)
    perm, dist = match_sets(poles, co.split(ref.x)[0], scale=np.abs(poles))
    assert dist.max() < 1e-6
