"""so-h2 (structure-preserving H2 descent) and its kernels against independent dense references.

References, built from the model's matrices without morsuite's solvers (``test_norms``): the
hidden-manifold realization through an explicit null(G) basis and the error system's Gramian by
scipy's Lyapunov solver (reliable where the error is not small against the model); for a small
error, scipy's adaptive quadrature of ||T(jw) - Tr(jw)||_F^2 with both responses refined in long
double. Gradients against central differences (fourth order) of the dense reference.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.linalg as sla

import morsuite as ms
from morsuite.errors import InputError, OptionError
from morsuite.linalg.h2 import modal_form, norm_squared
from morsuite.reducers.h2.gradient import (FullTarget, ModalTarget, gauss_newton_diagonal, h2_objective,
                                         second_order_realization)
from morsuite.reducers.h2.lbfgs import Evaluation, lbfgs_descent
from morsuite.reducers.h2 import so_h2 as so_h2_module
from morsuite.reducers.h2.params import General, Passive
from test_norms import error_ss, extended_h2_error, hidden_ss, lyap_h2

MIMO = dict(n1=30, n2=3, m=3, p=3, seed=1, zeta=0.01)


def reduce(fom, method, r, **opts):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return ms.reducers.make(method, fom, **opts).reduce(r)


def dense_J(fom, K, D, F, L):
    """||T - Tr||^2 from the dense error system (independent of morsuite's H2 code)."""
    rom = ms.rom.SecondOrderROM(np.eye(K.shape[0]), D, K, F, L)
    return lyap_h2(*error_ss(fom, rom)) ** 2


def modal_target_of(fom):
    """The model itself as a dense modal target (its hidden-manifold realization in modal form)."""
    A, B, C = hidden_ss(fom)
    md = modal_form(np.eye(A.shape[0]), A, B, C, np.zeros((fom.p, fom.m)))
    return ModalTarget(md.poles, md.B, md.C)


@pytest.fixture(scope="module")
def mimo():
    return ms.models.random_constrained(**MIMO)


@pytest.mark.parametrize("which", ["full", "modal"])
@pytest.mark.parametrize("pname,form", [("general", "vv"), ("passive", "fv")])
def test_gradient_against_finite_differences(mimo, which, pname, form):
    """The chain-ruled Wilson gradient in the parameters against central differences of the dense J."""
    fom = mimo
    rom = reduce(fom, "bt", 4, form=form).rom
    param = {"general": General, "passive": Passive}[pname](rom.order, fom.m, fom.p)
    theta = param.from_rom(rom)
    if which == "full":
        n2, f2, _, _ = norm_squared(fom, {})
        target = FullTarget(fom, n2, f2)
    else:
        target = modal_target_of(fom)
    ev = h2_objective(target, *param.matrices(theta))
    assert ev.stable
    assert ev.value == pytest.approx(dense_J(fom, *param.matrices(theta)), rel=1e-9)
    g = param.gradient(theta, ev.gradient)
    rng = np.random.default_rng(3)
    for _ in range(3):
        d = rng.standard_normal(theta.size)
        d *= 1e-5 * np.linalg.norm(theta) / np.linalg.norm(d)
        f = [dense_J(fom, *param.matrices(theta + c * d)) for c in (-2, -1, 1, 2)]
        fd = (f[0] - 8 * f[1] + 8 * f[2] - f[3]) / 12.0
        # fourth-order differences of a lightly damped model (zeta = 0.01): measured truncation 1e-6
        # relative at steps of 1e-4 of |theta|, 1e-9 at 1e-5, where rounding (eps J / |d|) is 1e-9 too
        assert g @ d == pytest.approx(fd, rel=1e-7)


def test_full_target_lu_count_and_value(mimo):
    """One LU per real pole or conjugate pair; the value is the dense error norm."""
    fom = mimo
    rom = reduce(fom, "bt", 5, form="vv").rom
    n2, f2, _, _ = norm_squared(fom, {})
    target = FullTarget(fom, n2, f2)
    p = General(rom.order, fom.m, fom.p)
    ev = h2_objective(target, *p.matrices(p.from_rom(rom)), gradient=False)
    lam = rom.poles()
    assert ev.lu_count == int(np.sum(lam.imag >= 0))
    assert np.sqrt(ev.value) == pytest.approx(lyap_h2(*error_ss(fom, rom)), rel=1e-9)


def test_cancellation_free_value_where_the_three_terms_cancel():
    """dsms(50) and second-order BT at r = 10: ||E|| / ||T|| about 6e-7, so the three-term form keeps
    about three digits; the residual form agrees with the long-double quadrature to 1e-6."""
    fom = ms.models.dsms(g=50)
    rom = reduce(fom, "bt", 10, form="vv").rom
    ref = extended_h2_error(fom, rom)
    assert ref < 1e-6 * ms.analysis.h2_norm(fom)
    p = General(rom.order, fom.m, fom.p)
    ev = h2_objective(modal_target_of(fom), *p.matrices(p.from_rom(rom)), gradient=False)
    assert ev.details["balanced"]
    assert np.sqrt(ev.value) == pytest.approx(ref, rel=1e-6)
    assert ev.floor < 1e-4 * ev.value < ev.three_term_floor
    assert abs(ev.three_term - ref ** 2) > 1e-4 * ref ** 2  # what the cancellation costs


def test_unstable_model_is_infinite_without_solves(mimo):
    fom = mimo
    n2, f2, _, _ = norm_squared(fom, {})
    target = FullTarget(fom, n2, f2)
    r = 3
    ev = h2_objective(target, -np.eye(r), np.eye(r), np.ones((r, fom.m)), np.ones((fom.p, r)))
    assert not ev.stable and ev.value == np.inf and ev.lu_count == 0 and target.lu_count == 0


def test_gauss_newton_diagonal_against_gramians(mimo):
    r"""For F and L the Gauss-Newton diagonal is exact: 2 ||L R(s) e_j||^2 = 2 (Q_r)_{vv,jj} and
    2 ||e_i^T R(s) F||^2 = 2 (P_r)_{pp,ii}; the trapezoidal quadrature reproduces them to 5% (a
    preconditioner needs no more)."""
    fom = mimo
    rom = reduce(fom, "bt", 4, form="vv").rom
    p = General(rom.order, fom.m, fom.p)
    K, D, F, L = p.matrices(p.from_rom(rom))
    A, B, C = second_order_realization(K, D, F, L)
    P = sla.solve_continuous_lyapunov(A, -B @ B.T)
    Q = sla.solve_continuous_lyapunov(A.T, -C.T @ C)
    r = K.shape[0]
    HK, HD, HF, HL = gauss_newton_diagonal(K, D, F, L)
    np.testing.assert_allclose(HF[:, 0], 2 * np.diag(Q)[r:], rtol=5e-2)
    np.testing.assert_allclose(HL[0], 2 * np.diag(P)[:r], rtol=5e-2)
    assert np.all(HK > 0) and np.all(HD > 0)


def test_passive_parametrisation_is_stable_by_construction(mimo):
    rng = np.random.default_rng(0)
    p = Passive(5, 3, 3)
    for _ in range(20):
        K, D, F, L = p.matrices(rng.standard_normal(p.size))
        assert np.allclose(K, K.T) and np.allclose(D, D.T)
        assert ms.rom.SecondOrderROM(np.eye(5), D, K, F, L).is_stable()
    fv = reduce(mimo, "bt", 4, form="fv").rom
    q = Passive(4, 3, 3)
    back = q.rom(q.from_rom(fv))
    s = 0.3 + 0.7j
    np.testing.assert_allclose(back.transfer(s), fv.transfer(s), rtol=1e-10)
    with pytest.raises(InputError):
        q.from_rom(reduce(mimo, "bt", 4, form="vv").rom)


def test_lbfgs_is_monotone_and_stays_in_the_domain():
    """Rosenbrock's function, infinite outside the disc |x| < 1.6: every accepted iterate is inside,
    the values never increase, and the minimum (1, 1) is found."""
    seen = []

    def fun(x):
        if x @ x >= 1.6 ** 2:
            return Evaluation(np.inf)
        f = (1 - x[0]) ** 2 + 100 * (x[1] - x[0] ** 2) ** 2
        g = np.array([-2 * (1 - x[0]) - 400 * x[0] * (x[1] - x[0] ** 2), 200 * (x[1] - x[0] ** 2)])
        return Evaluation(f, 1e-15, g)

    res = lbfgs_descent(fun, np.array([-1.2, 1.0]), maxit=500, rtol=1e-14,
                        callback=lambda it, x, ev: seen.append((x.copy(), ev.value)))
    assert res.converged
    assert all(x @ x < 1.6 ** 2 for x, _ in seen)
    assert np.all(np.diff(res.history) < 0)
    np.testing.assert_allclose(res.x, [1.0, 1.0], atol=1e-6)
    # an initial inverse Hessian given as a product (here that of Rosenbrock's Hessian at the start)
    H = np.array([[1330.0, 480.0], [480.0, 200.0]])
    res2 = lbfgs_descent(fun, np.array([-1.2, 1.0]), precond=lambda v: np.linalg.solve(H, v), maxit=500, rtol=1e-14)
    assert res2.converged and np.all(np.diff(res2.history) < 0)
    np.testing.assert_allclose(res2.x, [1.0, 1.0], atol=1e-6)


@pytest.fixture(scope="module")
def soh2_run():
    """so-h2 on the MIMO model at r = 4, every accepted iterate recorded (lbfgs_descent wrapped)."""
    fom = ms.models.random_constrained(**MIMO)
    accepted = []
    original = so_h2_module.lbfgs_descent

    def recording(*args, **kwargs):
        kwargs["callback"] = lambda it, x, ev: accepted.append(ev.data)
        return original(*args, **kwargs)

    so_h2_module.lbfgs_descent = recording
    try:
        res = reduce(fom, "so-h2", 4, maxit=400)
    finally:
        so_h2_module.lbfgs_descent = original
    return fom, res, accepted


def test_every_iterate_is_stable_and_the_error_decreases(soh2_run):
    _, res, accepted = soh2_run
    assert len(accepted) > 10
    assert all(ev.stable and ev.details["max_pole_real"] < 0 for ev in accepted)
    h = np.asarray(res.info["history"])
    assert np.all(np.diff(h) <= 0)
    hf = np.asarray(res.info["history_full"])
    assert np.all(np.diff(hf) <= 0)


def test_result_against_dense_and_never_worse_than_start_or_bt(soh2_run):
    fom, res, _ = soh2_run
    info, rom = res.info, res.rom
    assert rom.is_stable() and info["stable"] and rom.order == 4
    ref = lyap_h2(*error_ss(fom, rom))
    assert info["h2_error"] == pytest.approx(ref, rel=1e-8)
    levels = {f: lyap_h2(*error_ss(fom, reduce(fom, "bt", 4, form=f).rom)) for f in ("pp", "pv", "vv", "fv")}
    start = info["start"]
    assert info["start_h2_error"] == pytest.approx(levels.get(start, info["start_h2_error"]), rel=1e-8)
    assert ref <= info["start_h2_error"]
    assert ref <= min(v for v in levels.values() if np.isfinite(v))
    assert info["converged"] and info["iterations"] == info["iterations_surrogate"] + info["iterations_full"]
    assert info["lu_breakdown"]["exact"] > 0 and info["lu_count"] == sum(info["lu_breakdown"].values())
    assert np.isfinite(info["gradient_norm"]) and info["surrogate"]["states"] >= 8


def test_options_are_validated(mimo):
    make = ms.reducers.make
    assert "so-h2" in ms.reducers.available()
    with pytest.raises(OptionError, match="unknown option"):
        make("so-h2", mimo, step=1)
    with pytest.raises(OptionError, match="'parametrization'"):
        make("so-h2", mimo, parametrization="symmetric")
    with pytest.raises(OptionError, match="'levels'"):
        make("so-h2", mimo, levels=("vv", "xx"))
    with pytest.raises(OptionError, match="'levels'"):
        make("so-h2", mimo, levels="vv")
    with pytest.raises(OptionError, match="'surrogate_tol'"):
        make("so-h2", mimo, surrogate_tol=0.0)
    with pytest.raises(OptionError, match="'maxit'"):
        make("so-h2", mimo, maxit=-1)
    with pytest.raises(InputError, match="passive"):
        make("so-h2", mimo, parametrization="passive", start="vv")
    red = make("so-h2", mimo, levels=["vv", "pp"], irka_start=False)
    assert red.get_params()["levels"] == ["vv", "pp"]
