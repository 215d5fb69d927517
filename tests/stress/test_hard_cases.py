"""Named hard cases: what the suite must do at the edges (issue "numerical stability under stress").

Each test states the documented outcome: a result that passes its invariants,
a MorsuiteError naming the problem, or converged=False with a warning. Never a
NaN and never silence.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

import morsuite as ms
from morsuite import stress as S
from morsuite.reducers.base import as_complex

pytestmark = pytest.mark.stress

IRKAS = ["irka", "irka-projected"]


def _reduce(method, fom, r, **options):
    with warnings.catch_warnings(record=True) as W:
        warnings.simplefilter("always")
        res = ms.reducers.make(method, fom, **options).reduce(r)
    return res, W


def _cats(W):
    return {w.category for w in W}


def _max_rel_error(fom, rom, n=80):
    omega = np.logspace(np.log10(fom.band[0]), np.log10(fom.band[1]), n)
    H, _ = S.reference_response(fom, omega)
    Hr = rom.freqresp(omega)
    assert np.all(np.isfinite(Hr))
    return float(np.max(S.sigma(H - Hr)) / np.max(S.sigma(H)))


# -- r above the numerical order of the model -------------------------------------------
def low_order_model(n1=30):
    """A 5-mass chain with one tie (4 DOF, 8 first-order states) plus n1 - 5 masses that F and L never see."""
    k = np.ones(n1)
    K = sp.lil_matrix((n1, n1))
    for i in range(4):
        K[i, i] += 2.0
        K[i + 1, i + 1] += 2.0
        K[i, i + 1] = K[i + 1, i] = -2.0
    for i in range(n1):
        K[i, i] += 0.5 + 0.1 * i  # ground springs, distinct frequencies
    M = sp.diags(k)
    K = sp.csr_matrix(K)
    D = 0.05 * M + 0.02 * K
    G = sp.csr_matrix(([1.0, -1.0], ([0, 0], [0, 4])), shape=(1, n1))
    F = np.zeros((n1, 1))
    F[1, 0] = 1.0
    L = np.zeros((1, n1))
    L[0, 2] = 1.0
    return ms.models.Index3Model(M, D, K, G, F, L, name="low-order", band=(1e-2, 1e1))


@pytest.mark.parametrize("method", IRKAS)
def test_r_above_numerical_order_is_capped_with_rank_warning(method):
    fom = low_order_model()
    res, W = _reduce(method, fom, 8)  # asks for 16 states; the input-output map has at most 8
    info = res.info
    assert ms.RankWarning in _cats(W)
    assert info["rank_capped"] is True and info["r"] < info["r_requested"] == 8
    assert info["r"] == res.rom.order <= 4
    assert any(w.startswith("RankWarning") for w in info["warnings"])
    assert res.rom.is_stable() and info["stable"]
    assert _max_rel_error(fom, res.rom) < 1e-8


# -- r = n1 - n2 and r > n1 - n2 -------------------------------------------------------------
@pytest.mark.parametrize("method", IRKAS)
def test_r_equal_to_manifold_dimension_reproduces_the_model(method):
    fom = ms.models.random_constrained(n1=12, n2=2, m=2, p=2, seed=3, zeta=0.05)
    res, W = _reduce(method, fom, fom.order, maxit=20)
    # exact reproduction (up to conditioning), possibly with a documented rank cap
    assert _max_rel_error(fom, res.rom) < 1e-8
    if res.info["r"] < fom.order:
        assert res.info["rank_capped"] and ms.RankWarning in _cats(W)


@pytest.mark.parametrize("method", IRKAS)
def test_r_above_manifold_dimension_is_refused(method):
    fom = ms.models.random_constrained(n1=12, n2=2, m=2, p=2, seed=3)
    red = ms.reducers.make(method, fom)
    with pytest.raises(ms.InputError, match=r"r = 11 exceeds the order of the full model on its hidden "
                       r"manifold \(n1 - n2 = 10\)"):
        red.reduce(11)


# -- shifts at or next to poles of the full model -----------------------------------------------
def model_with_pole_at_one(n1=10):
    """Coordinate 0 has mass 1, no damping and stiffness -1: T(s) contains 1/(s^2 - 1), a pole at s = +1.

    The rest is a damped chain tied by one constraint; F and L see both parts.
    """
    K = sp.diags([-np.ones(n1 - 2), 2.5 * np.ones(n1 - 1), -np.ones(n1 - 2)], [-1, 0, 1]).tolil()
    K = sp.block_diag([sp.csr_matrix([[-1.0]]), K]).tocsr()
    M = sp.identity(n1, format="csr")
    D = sp.diags(np.r_[0.0, 0.1 * np.ones(n1 - 1)], format="csr")
    G = sp.csr_matrix(([1.0, -1.0], ([0, 0], [1, n1 - 1])), shape=(1, n1))
    F = np.zeros((n1, 1))
    F[[0, 2], 0] = 1.0
    L = np.zeros((1, n1))
    L[0, [0, 3]] = 1.0
    return ms.models.Index3Model(M, D, K, G, F, L, name="pole-at-1", band=(1e-2, 1e1))


def test_saddle_solver_reports_a_shift_exactly_at_a_pole():
    fom = model_with_pole_at_one()
    with pytest.raises(ms.SingularShiftError, match="exactly singular"):
        fom.new_solver().factor(1.0)
    with pytest.raises(ms.SingularShiftError):
        fom.transfer(1.0)


def test_saddle_solver_flags_a_shift_next_to_a_pole_when_asked():
    fom = model_with_pole_at_one()
    with pytest.raises(ms.SingularShiftError, match="reciprocal condition"):
        fom.new_solver(rcond_tol=1e-10).factor(1.0 + 1e-13)


def test_next_to_a_pole_the_default_solver_returns_the_true_large_value():
    """Without the optional check the solve is still right: T ~ 1/(s^2 - 1) + bounded part."""
    fom = model_with_pole_at_one()
    for eps in (1e-6, 1e-9):
        s = 1.0 + eps
        T = fom.transfer(s)[0, 0]
        assert np.isfinite(T)
        singular_part = 1.0 / (s * s - 1.0)
        assert abs(T - singular_part) < 1e-6 * abs(singular_part) + 10.0


def test_irka_perturbs_a_given_shift_at_a_pole_and_records_it():
    fom = model_with_pole_at_one()
    with warnings.catch_warnings(record=True) as W:
        warnings.simplefilter("always")
        try:
            res = ms.reducers.make("irka", fom, init="given", init_shifts=[1.0, 3.0], maxit=3).reduce(2)
        except ms.MorsuiteError:  # a documented refusal would also do; it is not what happens today
            pytest.fail("IRKA refused instead of perturbing the shift")
    assert res.info["perturbed_shifts"] >= 1
    msgs = [str(w.message) for w in W]
    assert any("hit a pole" in m for m in msgs)
    assert any("hit a pole" in m for m in res.info["warnings"])
    # the shift used in the first iteration is the perturbed one, not 1.0 itself
    first = as_complex(res.info["history"]["shifts"][0])
    assert not np.any(first == 1.0) and np.any(np.isclose(first, 1.0, rtol=1e-5))
    assert np.all(np.isfinite(res.rom.freqresp(np.logspace(-2, 1, 20))))


# -- IRKA that cycles ---------------------------------------------------------------------
def _check_cycle_outcome(res, W):
    info = res.info
    assert info["cycle_detected"] is True and info["converged"] is False
    assert any(w.category is ms.ConvergenceWarning and "cycle" in str(w.message) for w in W)
    assert any(w.startswith("ConvergenceWarning") for w in info["warnings"])
    assert 1 <= info["best_iteration"] <= info["iterations"] < info["options"]["maxit"]
    # the best iterate: smallest measure among the stable iterates (all iterates if none is stable)
    hist = info["history"]
    pool = [m for m, st in zip(hist["measure"], hist["stable"]) if st] or hist["measure"]
    assert hist["measure"][info["best_iteration"] - 1] == min(pool)
    assert np.all(np.isfinite(res.rom.freqresp(np.logspace(-3, 0, 20))))


def test_a_forced_two_cycle_is_detected_and_the_best_iterate_returned(monkeypatch):
    """Roundoff-independent: the shift update alternates between two sets, so IRKA must stop on a cycle."""
    from morsuite.reducers.irka import engine as irka_engine

    fom = ms.models.dsms(100)
    sets = [np.array([0.02, 0.3 - 0.2j, 0.3 + 0.2j], dtype=complex),
            np.array([0.05, 0.1 - 0.1j, 0.1 + 0.1j], dtype=complex)]
    calls = []

    def alternate(self, rom, k, how, current=None):
        alpha = sets[len(calls) % 2]
        calls.append(how)
        ones = np.ones((3, 1), dtype=complex)
        return alpha, ones, np.ones((3, 3), dtype=complex), {"update": how, "mirrored": 0, "hsv": None}

    monkeypatch.setattr(irka_engine.IRKABase, "_update", alternate)
    res, W = _reduce("irka", fom, 3, init="given", init_shifts=sets[1], update="bt", maxit=50)
    _check_cycle_outcome(res, W)
    assert res.info["iterations"] <= 4


def test_cycling_irka_on_tcom_is_detected():
    """update="bt" on tcom(nc=200) cycles at some r (which one depends on roundoff in the LU)."""
    fom = ms.models.tcom(nc=200)
    seen = []
    for r in (15, 20, 16, 18, 12):
        res, W = _reduce("irka", fom, r, update="bt", maxit=40)
        seen.append((r, res.info["converged"], res.info["cycle_detected"], res.info["iterations"]))
        if not res.info["converged"]:
            assert ms.ConvergenceWarning in _cats(W)
        if res.info["cycle_detected"]:
            _check_cycle_outcome(res, W)
            return
    pytest.fail(f"no cycle found on tcom(nc=200) with update='bt': {seen}")


# -- ADI with poor shifts ----------------------------------------------------------------------
def test_adi_with_poor_shifts_stops_at_maxiter_with_residual_and_warning():
    lradi_mod = pytest.importorskip("morsuite.linalg.lradi")
    fom = ms.models.dsms(60)
    with pytest.warns(ms.ConvergenceWarning, match=r"maxiter = 4\b.*relative residual"):
        res = lradi_mod.lradi(fom, shifts=[-1e-7], maxiter=4, tol=1e-10)
    assert res.converged is False and res.iterations == 4
    assert res.residuals.shape == (5,) and res.residuals[0] == 1.0
    assert np.all(np.isfinite(res.residuals)) and res.residuals[-1] > 1e-10
    assert res.summary()["residual"] == res.residuals[-1]


def test_bt_with_poor_adi_reports_nonconvergence():
    if "bt" not in ms.reducers.available():
        pytest.skip("reducer 'bt' is not registered yet")
    cls = ms.reducers.get_class("bt")
    maxit_opt = next((k for k in cls.OPTIONS if "maxit" in k or "maxiter" in k), None)
    if maxit_opt is None:
        pytest.skip("bt has no ADI iteration cap option")
    fom = ms.models.tcom(nc=200)
    res, W = _reduce("bt", fom, 10, **{maxit_opt: 2})
    assert res.info["converged"] is False
    assert ms.ConvergenceWarning in _cats(W)
    assert any("residual" in k for k in res.info)


# -- duplicate outputs and zero inputs -----------------------------------------------------------
@pytest.mark.parametrize("method", IRKAS)
def test_duplicate_outputs_dsms(method):
    """DSMS outputs 2 and 3 coincide (rank-1 T): the ROM must still interpolate and stay finite."""
    fom = ms.models.dsms(200)
    T = fom.transfer(0.1j)
    assert np.allclose(T[1], T[2], rtol=1e-12, atol=0)
    out = S.check_reduction(fom, method, 6)
    assert out.outcome == "pass", out
    assert out.metrics["hermite_error"] <= out.metrics["hermite_tol"]


@pytest.mark.parametrize("method", IRKAS)
def test_a_zero_input_column_and_a_zero_output_row(method):
    d = ms.models.dsms(50)
    F = np.zeros((50, 2))
    F[0, 0] = 1.0
    L = np.vstack([d.L, np.zeros((1, 50))])
    fom = d.with_io(F=F, L=L)
    out = S.check_reduction(fom, method, 4)
    assert out.outcome in ("pass", "not-converged"), out
    res, _ = _reduce(method, fom, 4)
    H = res.rom.freqresp(np.logspace(-2, 0, 10))
    assert np.all(H[:, :, 1] == 0) or np.max(np.abs(H[:, :, 1])) < 1e-12 * np.max(np.abs(H))
    assert np.max(np.abs(H[:, 3, :])) < 1e-12 * np.max(np.abs(H))


def test_inputs_acting_only_on_constrained_coordinates():
    """A force on a fixed coordinate (x_a = 0) does nothing: T has a zero column, the ROM as well."""
    base = ms.models.random_constrained(n1=30, n2=3, m=1, p=2, seed=2, constraints="fixes")
    fixed = base.G.indices[0]
    F = np.zeros((30, 2))
    F[fixed, 0] = 1.0
    F[(fixed + 7) % 30, 1] = 1.0
    fom = base.with_io(F=F)
    assert np.max(np.abs(fom.transfer(1j)[:, 0])) < 1e-14 * np.max(np.abs(fom.transfer(1j)))
    out = S.check_reduction(fom, "irka", 3)
    assert out.outcome in ("pass", "not-converged"), out


# -- undamped modes: T(j omega) nearly infinite on the grid ------------------------------------------
def _constrained_eigenfrequencies(fom):
    N = sla.null_space(fom.G.toarray())
    lam = sla.eigh(N.T @ fom.K.toarray() @ N, N.T @ fom.M.toarray() @ N, eigvals_only=True)
    return np.sqrt(lam)


def test_undamped_model_at_an_eigenfrequency_is_huge_or_refused_never_nan():
    fom = ms.models.random_constrained(n1=30, n2=2, m=2, p=2, seed=5, damping="none")
    w0 = _constrained_eigenfrequencies(fom)[3]
    near = np.abs(fom.transfer(1j * w0 * (1 + 1e-3))).max()
    try:
        H = fom.freqresp([w0])
    except ms.SingularShiftError:
        return  # documented: the solver saw a singular matrix
    assert np.all(np.isfinite(H))
    assert np.abs(H).max() > 1e6 * near  # a resonance of an undamped mode: nearly infinite
    with pytest.raises(ms.SingularShiftError):
        fom.new_solver(rcond_tol=1e-12).factor(1j * w0)


def test_errors_on_a_grid_through_undamped_resonances_are_finite():
    fom = ms.models.random_constrained(n1=30, n2=2, m=2, p=2, seed=5, damping="none")
    w = _constrained_eigenfrequencies(fom)
    omega = np.sort(np.r_[w[:4], np.logspace(np.log10(fom.band[0]), np.log10(fom.band[1]), 30)])
    out = S.check_reduction(fom, "irka", 4, {"maxit": 30}, omega=omega)
    assert out.outcome in ("pass", "not-converged", "refused"), out
    res, W = _reduce("irka", fom, 4, maxit=30)
    try:
        df = ms.analysis.errors(fom, res.rom, omega)
    except ms.MorsuiteError:
        return
    assert not df[["sigma_full", "sigma_rom", "abs_error"]].isna().any().any()
    if not res.info["stable"]:
        assert ms.StabilityWarning in _cats(W)
