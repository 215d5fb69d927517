"""Saddle-point solves reach the backward-error target, also at lightly damped resonances (issue 45, item 1).

References are independent of the code under test: a dense LU (LAPACK) refined with the exact residual
of :func:`support.exact_saddle_residual` (Dekker's exact products and ``math.fsum``, no compiled kernel),
itself checked against exact rational arithmetic. Models: ``random_constrained(n1=1000)`` at modal
damping 1e-2 to 1e-5, evaluated at its first two undamped frequencies (the resonance peaks), every
LU backend forced as ``tests/test_backends.py`` does. Before issue 45 every backend missed 1e-11 at
zeta = 1e-5 on the chain with few extra springs (3.4e-11: no refinement against the exact S(j omega)) and
rslab's LDL^T also at 1e-4 on the issue's model with three extra springs per mass (2.8e-8).
"""

from __future__ import annotations

import json
import warnings
from fractions import Fraction

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp
from support import exact_saddle_residual, reference_transfer

import morsuite as ms
from morsuite.errors import AccuracyWarning
from morsuite.linalg import accuracy
from morsuite.linalg.backends_ext import available

ZETAS = (1e-2, 1e-3, 1e-4, 1e-5)
#: every backend on a chain with few extra springs (RCM kl + ku = 114: a band the banded LU factors fast),
#: rslab also on the issue's model (three extra springs per mass, kl + ku = 1230)
CASES = [(b, z, 0.05) for b in ("rslab", "klu", "banded", "superlu") for z in ZETAS] + \
    [("rslab", 1e-4, 3.0), ("rslab", 1e-5, 3.0)]


def _model(zeta, springs):
    return ms.models.random_constrained(n1=1000, n2=10, m=2, p=2, seed=1, zeta=zeta, extra_springs=springs)


_CACHE: dict = {}


def _resonances(springs):
    """The first two undamped frequencies of the constrained model (dense null-space eigenproblem; they do
    not depend on zeta: Rayleigh damping is added to the same M and K)."""
    if ("w", springs) not in _CACHE:
        fom = _model(1e-2, springs)
        Z = sla.null_space(fom.G.toarray())
        lam = sla.eigh(Z.T @ fom.K.toarray() @ Z, Z.T @ fom.M.toarray() @ Z, eigvals_only=True, subset_by_index=[0, 1])
        _CACHE["w", springs] = np.sqrt(lam)
    return _CACHE["w", springs]


def _reference(zeta, springs):
    key = ("ref", zeta, springs)
    if key not in _CACHE:
        fom = _model(zeta, springs)
        _CACHE[key] = np.stack([reference_transfer(fom, w) for w in _resonances(springs)])
    return _CACHE[key]


def _need(backend):
    if backend in ("klu", "rslab") and not available()[backend]:
        pytest.skip(f"{backend} is not installed")


def test_exact_residual_of_the_reference_is_exact():
    """The reference's residual equals exact rational arithmetic (rounded once) on a small model."""
    fom = ms.models.random_constrained(n1=12, n2=2, m=1, p=1, seed=4, zeta=1e-3, extra_springs=1.0)
    rng = np.random.default_rng(0)
    w = 0.7310925301
    x = rng.standard_normal(12) + 1j * rng.standard_normal(12)
    z = rng.standard_normal(2) + 1j * rng.standard_normal(2)
    b = rng.standard_normal(12) + 1j * rng.standard_normal(12)
    r = exact_saddle_residual(fom, w, x, z, b)
    W = Fraction(w)
    M, D, K, G = (sp.coo_matrix(X) for X in (fom.M, fom.D, fom.K, fom.G))

    def exact(part):  # part 0: real, 1: imaginary (Fractions of doubles: exact)
        xr, xi = [Fraction(v) for v in x.real], [Fraction(v) for v in x.imag]
        xp, xq = (xr, xi) if part == 0 else (xi, xr)
        zp = [Fraction(v) for v in (z.real if part == 0 else z.imag)]
        out = [Fraction(v) for v in (b.real if part == 0 else b.imag)] + [Fraction(0)] * 2
        for i, j, v in zip(K.row, K.col, K.data):
            out[i] -= Fraction(v) * xp[j]
        for i, j, v in zip(M.row, M.col, M.data):
            out[i] += W * W * Fraction(v) * xp[j]
        for i, j, v in zip(D.row, D.col, D.data):
            out[i] += (1 if part == 0 else -1) * W * Fraction(v) * xq[j]
        for k, j, v in zip(G.row, G.col, G.data):
            out[j] -= Fraction(v) * zp[k]
            out[12 + k] -= Fraction(v) * xp[j]
        return np.array([float(v) for v in out])

    assert np.array_equal(r.real, exact(0)) and np.array_equal(r.imag, exact(1))


@pytest.mark.parametrize("backend, zeta, springs", CASES)
def test_resonance_response_within_1e11_of_the_exact_reference(backend, zeta, springs):
    """T(j omega) at the first two resonances by freqresp and transfer, every backend, zeta 1e-2..1e-5:
    within 1e-11 (relative, max entry) of the reference; every solve at or below the backward-error
    target, with no LU beyond one per frequency."""
    _need(backend)
    fom = _model(zeta, springs)
    fom.lu_backend = backend
    w = _resonances(springs)
    ref = _reference(zeta, springs)
    H = fom.freqresp(w)
    stats = fom.last_freqresp_stats
    assert stats["factorizations"] == len(w) and stats["refactorizations"] == 0
    assert stats["checked_solves"] == len(w) * fom.m and stats["above_target"] == 0
    assert 0 < stats["backward_error_max"] <= accuracy.BACKWARD_TARGET
    for k in range(len(w)):
        scale = np.max(np.abs(ref[k]))
        # measured <= 3e-16 (0 in most cases); the target is the issue's
        assert np.max(np.abs(H[k] - ref[k])) <= 1e-11 * scale, (k, np.max(np.abs(H[k] - ref[k])) / scale)
        assert np.max(np.abs(fom.transfer(1j * w[k]) - ref[k])) <= 1e-11 * scale
    if backend == "rslab":
        assert type(fom.solver.factor(1j * w[0]).lu).__name__ == "RslabLDLT"


def test_ldlt_reaches_the_target_by_refinement_on_its_own_lu():
    """rslab's LDL^T at zeta = 1e-5: its solve alone stops at a backward error of about 6e-12 (the check
    before issue 45 accepted it: up to 1e-10); the target is reached by refinement with the same LU."""
    _need("rslab")
    fom = _model(1e-5, 3.0)
    s = 1j * _resonances(3.0)[0]
    old = fom.new_solver(backend="rslab", backward_target=0)
    f = old.factor(s)
    assert type(f.lu).__name__ == "RslabLDLT"
    assert f.backward_error(fom.F) > 100 * accuracy.BACKWARD_TARGET  # measured 5.8e-12
    new = fom.new_solver(backend="rslab")
    f = new.factor(s)
    f.solve(fom.F)
    f.solve(fom.L.T, trans=True)
    st = new.stats
    assert st.factorizations == 1 and st.refactorizations == 0 and st.refinement_steps >= 1
    assert st.backward_error_max <= accuracy.BACKWARD_TARGET and st.above_target == 0


def test_certificate_in_double_bounds_the_exact_backward_error(tcom20):
    """On a chain the target is certified from the double residual plus its rounding bound; that bound is
    never below the backward error of the exact residual (exact rational sums), for the LU's solution
    (certified below the target) and for one 1e-13 off."""
    f = tcom20.new_solver(backend="superlu").factor(0.4j)
    n = tcom20.n1 + tcom20.n2
    b = f._to_lu_space(np.vstack([tcom20.F, np.zeros((tcom20.n2, 1))]).astype(complex), False)
    x0 = f._lu_solve(b, False)
    A = f.matrix.toarray()
    norm_a = np.abs(A).sum(axis=0).max()
    rng = np.random.default_rng(1)
    for x, certified in ((x0, True), (x0 * (1 + 1e-13 * rng.standard_normal(x0.shape)), False)):
        bounds, _, ext = f._measure(b, x, False)
        assert not ext  # certified in double: no extended residual
        bound = bounds[0]
        exact = 0.0
        for i in range(n):
            re = Fraction(b[i, 0].real) - sum(Fraction(A[i, j].real) * Fraction(x[j, 0].real)
                                              - Fraction(A[i, j].imag) * Fraction(x[j, 0].imag)
                                              for j in np.flatnonzero(A[i]))
            im = Fraction(b[i, 0].imag) - sum(Fraction(A[i, j].real) * Fraction(x[j, 0].imag)
                                              + Fraction(A[i, j].imag) * Fraction(x[j, 0].real)
                                              for j in np.flatnonzero(A[i]))
            exact += abs(complex(float(re), float(im)))
        eta = exact / (norm_a * np.abs(x).sum() + np.abs(b).sum())
        assert eta <= bound and (bound <= accuracy.BACKWARD_TARGET) == certified, (eta, bound)


def _perturbed(f, delta):
    """A factor of the LU's matrix perturbed by ``delta`` (relative, on the diagonal): an inexact LU."""
    import scipy.sparse.linalg as spla

    A = f.matrix.tocsc()
    return spla.splu((A + delta * sp.diags(np.abs(A.diagonal()) + 1.0)).tocsc(), permc_spec="COLAMD")


def _near_pole():
    """An undamped random model and a shift 1e-12 (relative) from its first pole."""
    fom = ms.models.random_constrained(n1=120, n2=4, m=1, p=1, seed=2, damping="none", extra_springs=0.5)
    Z = sla.null_space(fom.G.toarray())
    lam = sla.eigh(Z.T @ fom.K.toarray() @ Z, Z.T @ fom.M.toarray() @ Z, eigvals_only=True)
    return fom, 1j * np.sqrt(lam[0]) * (1 + 1e-12)


def test_a_solve_that_cannot_reach_the_target_is_flagged():
    """Next to a pole (condition about 1e13) an inexact factor (a 1e-12 perturbation: backward error about
    1e-12, below backward_tol) cannot be refined to the target: the solve comes back flagged (counted,
    warned, in the run's record), never as if it had; with its one fallback LU (counted) it is met."""
    fom, s = _near_pole()
    solver = fom.new_solver(backend="superlu")
    f = solver.factor(s)
    f.lu, f.fallback = _perturbed(f, 1e-12), ()
    with accuracy.recording() as rec, pytest.warns(AccuracyWarning, match="backward-error target"):
        f.solve(fom.F)
    st = solver.stats
    assert st.above_target == 1 and st.checked_solves == 1 and st.refinement_steps >= 1
    assert accuracy.BACKWARD_TARGET < st.backward_error_max <= solver.backward_tol
    info = rec.as_info()
    assert not info["met"] and info["above_target"] == 1 and info["backward_error"] == st.backward_error_max
    # the same inexact factor with the solver's fallback list: one more LU, counted, and the target met
    solver = fom.new_solver(backend="superlu")
    f = solver.factor(s)
    f.lu = _perturbed(f, 1e-12)
    with warnings.catch_warnings():
        warnings.simplefilter("error", AccuracyWarning)
        f.solve(fom.F)
    st = solver.stats
    assert st.factorizations == 2 and st.refactorizations == 1 and st.target_fallbacks == 1
    assert st.above_target == 0 and st.backward_error_max <= accuracy.BACKWARD_TARGET


def test_reducer_info_records_the_worst_backward_error(monkeypatch):
    """info["solve_backward_error"] is the worst of the run's checked solves (the solver's own counter,
    an independent path); a run whose solves miss the target says so (met False, a warning)."""
    fom = _model(1e-3, 0.05)
    res = ms.reducers.make("krylov", fom).reduce(4)
    acc = res.info["solve_accuracy"]
    assert acc["met"] and acc["checked"] >= 1 and acc["target"] == accuracy.BACKWARD_TARGET
    assert res.info["solve_backward_error"] == res.info["solver_stats"]["backward_error_max"]
    assert 0 < res.info["solve_backward_error"] <= accuracy.BACKWARD_TARGET
    json.dumps(res.info)
    # an unreachable target (1e-30, below the rounding of any double solution) is flagged, not hidden
    monkeypatch.setattr("morsuite.linalg.accuracy.default_target", lambda: 1e-30)
    with pytest.warns(AccuracyWarning):
        res = ms.reducers.make("krylov", _model(1e-3, 0.05)).reduce(4)
    acc = res.info["solve_accuracy"]
    assert not acc["met"] and acc["above_target"] >= 1 and acc["fallback_lus"] >= 1
    assert res.info["solve_backward_error"] > 1e-30
    assert any("backward-error target" in w for w in res.info["warnings"])


STUDY = """
name = "accuracy"
title = "solve accuracy in the manifest"

[models]
light = "random:n1=200,n2=4,m=1,p=1,seed=1,zeta=1e-4,extra_springs=0.05"

[grids]
g = { band = [0.05, 5.0], n = 12 }

[methods.krylov]
label = "Krylov"

[[scenes]]
name = "err"
kind = "error"
model = "light"
grid = "g"
r = 4
"""


def test_study_manifest_records_the_solves(tmp_path):
    """The manifest's full response and reduction carry what their solves reached; the full response
    checked every solve of its sweep (per frequency [F; 0] and the transposed [L^T; 0] of the derivative)."""
    from morsuite.studies import run

    spec = tmp_path / "accuracy.toml"
    spec.write_text(STUDY)
    m = run(spec, out=tmp_path / "out", use_cache=False, quiet=True, formats=()).manifest
    json.dumps(m)
    fom = next(a for a in m["artifacts"] if a["kind"] == "fom_response")
    red = next(a for a in m["artifacts"] if a["kind"] == "reduction")
    assert fom["solve_accuracy"]["checked"] == 12 * (1 + 1) and fom["solve_accuracy"]["met"]
    for a in (fom, red):
        assert 0 < a["solve_backward_error"] <= accuracy.BACKWARD_TARGET
        assert a["solve_accuracy"]["backward_error"] == a["solve_backward_error"]
