"""The orthonormal (Takenaka-Malmquist) form of the relative gradient (morsuite.reducers.h2.orthonormal).

References independent of the module: scipy's Lyapunov solver for the basis' Gram matrix, adaptive
quadrature on the imaginary axis for the inner products, and the pole-residue relative gradient of
morsuite.reducers.h2.poles where its Gram matrix is well conditioned (the dense reference of the
derivative systems against the index-3 model is in test_so_h2_certified.py).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.integrate as sint
import scipy.linalg as sla

from morsuite.reducers.h2.gradient import ModalTarget
from morsuite.reducers.h2.orthonormal import (modal_tm_values, realization_tm_values, tm_realization,
                                            tm_rho)
from morsuite.reducers.h2.poles import Coordinates, ModalValues, optimal_residues
from support import solve_tolerance

CLUSTER = np.array([-0.03 + 0.011j, -0.03 * (1 + 1e-7) + 0.011j * (1 + 1e-7), -0.5 + 0j])


def _conj_closed(lam):
    return np.concatenate([lam, np.conj(lam[lam.imag != 0])])


def test_basis_is_orthonormal_with_clustered_repeated_poles():
    seq = np.repeat(_conj_closed(CLUSTER), 2)       # gaps of 3e-9 and exact repeats
    A, beta = tm_realization(seq)
    gram = sla.solve_continuous_lyapunov(A, -np.outer(beta, beta).astype(complex))
    np.testing.assert_allclose(gram, np.eye(seq.size), atol=1e-9)


def test_inner_products_against_quadrature():
    """conj(v_k) = <x_k, T> = (1/2 pi) int conj(x_k(jw)) T(jw) dw, for a modal T and a realization of it."""
    lam = _conj_closed(np.array([-0.2 + 1.0j, -0.7 + 0j]))
    A, beta = tm_realization(np.repeat(lam, 2))
    mu = np.array([-0.3 + 0.8j, -0.3 - 0.8j, -1.5 + 0j])
    psi = np.array([0.4 - 0.2j, 0.4 + 0.2j, 1.1 + 0j])
    v = modal_tm_values(A, beta, mu, psi)
    # the same T as a real realization
    Ar = np.array([[-0.3, -0.8, 0.0], [0.8, -0.3, 0.0], [0.0, 0.0, -1.5]])
    br, cr = np.array([1.0, 0.0, 1.0]), np.array([0.8, 0.4, 1.1])
    # solves with A (kappa 13): measured 1.4e-15 entrywise relative, bound 7e-14
    tol = solve_tolerance(A)
    np.testing.assert_allclose(realization_tm_values(A, beta, Ar, br, cr), v, rtol=tol, atol=tol * np.abs(v).max())
    n = A.shape[0]
    for k in range(n):
        def integrand(w, part):
            s = 1j * w
            xk = np.linalg.solve(s * np.eye(n) - A, beta.astype(complex))[k]
            t = np.sum(psi / (s - mu))
            z = np.conj(xk) * t / (2 * np.pi)
            return z.real if part == 0 else z.imag
        ref = complex(sint.quad(integrand, -np.inf, np.inf, args=(0,), limit=400, epsabs=1e-12)[0],
                      sint.quad(integrand, -np.inf, np.inf, args=(1,), limit=400, epsabs=1e-12)[0])
        assert np.conj(v[k]) == pytest.approx(ref, abs=1e-8)


@pytest.mark.parametrize("iterations", [0, 3])
def test_rho_equals_the_pole_residue_form_where_that_is_well_conditioned(iterations):
    """A modal target of 12 lightly damped modes, a reduced model of 4 poles (2 pairs): both forms of
    rho agree (the pole-residue one inverts a Gram matrix of condition about 1e3 here)."""
    mu = np.array([-0.02 * k + 1j * k for k in range(1, 7)])
    mu = np.concatenate([mu, np.conj(mu)])
    psi = np.concatenate([1.0 / np.arange(1, 7), 1.0 / np.arange(1, 7)]).astype(complex)
    tgt = ModalTarget(mu, psi[:, None], np.ones((1, mu.size)))
    tv = ModalValues(tgt)
    co = Coordinates(0, 2)
    x = co.join([], [], np.array([-0.05 + 1.1j, -0.05 + 2.9j]), np.array([0.5 + 0j, -0.5 + 0j]))
    ev = optimal_residues(co, x, tv)
    if iterations:
        from morsuite.reducers.h2.poles_descent import varpro_descent
        ev = varpro_descent(co, ev.x, tv, maxit=iterations, gtol=1e-12)[0]
    lam, phi = co.split(ev.x)
    A, beta = tm_realization(np.repeat(lam, 2))
    J = tv.precise(co, ev.x)[0]
    v = modal_tm_values(A, beta, tv.mu, tv.psi) - modal_tm_values(A, beta, lam, phi)
    rho = tm_rho(v, beta, J)
    assert 1e-4 < ev.rho < 1.0
    assert rho == pytest.approx(ev.rho, rel=1e-6)


def test_rho_bad_input():
    assert tm_rho(np.ones(2), np.ones(2), 0.0) == np.inf


def test_full_model_rho_in_the_orthonormal_form_against_the_dense_reference(monkeypatch):
    """The index-3 recursion (saddle-point solves, TMRecursion) against the dense reference of
    test_so_h2_certified (derivative systems in (K, D, F, L), one Lyapunov/Sylvester solve), at
    second-order BT on tcom(20), r = 3; the orthonormal form forced."""
    import warnings

    import morsuite as ms
    from morsuite.reducers.h2 import stationarity as h2_stationarity
    from morsuite.linalg.h2 import norm_squared
    from morsuite.reducers.h2.gradient import FullTarget, second_order_realization
    from test_so_h2_certified import dense_rho

    fom = ms.models.tcom(nc=20)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rom = ms.reducers.make("bt", fom, form="vv").reduce(3).rom
    Mi = np.linalg.inv(rom.M)
    K, D, F, L = Mi @ rom.K, Mi @ rom.D, Mi @ rom.F, rom.L
    rho_ref, J_ref = dense_rho(fom, K, D, F, L)
    n2, f2, _, _ = norm_squared(fom, {})
    monkeypatch.setattr(h2_stationarity, "TM_CONDITION", 1.0)
    st = h2_stationarity.full_stationarity(FullTarget(fom, n2, f2), *second_order_realization(K, D, F, L))
    assert st["rho_form"] == "orthonormal"
    assert 0.01 < rho_ref < 1.0
    assert st["rho"] == pytest.approx(rho_ref, rel=1e-5)
    assert st["rho_pole_residue"] == pytest.approx(rho_ref, rel=1e-5)
    assert st["value"] == pytest.approx(J_ref, rel=1e-8)
