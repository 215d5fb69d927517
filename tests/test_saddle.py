"""SaddlePointSolver: caching, conjugate reuse, transposed solves, singular
shifts, against dense numpy solves of the assembled matrix."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import morsuite as ms
from morsuite.linalg import SaddlePointSolver
from support import assert_rounding, backward_error, rounding_unit, solve_tolerance


def rel_err(a, b):
    return np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(np.asarray(b))


def explicit_matrix(fom, s):
    """The saddle matrix assembled independently with numpy."""
    M, D, K, G = (X.toarray() for X in (fom.M, fom.D, fom.K, fom.G))
    n2 = fom.n2
    return np.block([[s * s * M + s * D + K, G.T], [G, np.zeros((n2, n2))]])


def assembly_bound(fom, a, b, c):
    """Rounding bound of forming a M + b D + c K entrywise (a few units of roundoff of the
    terms; no cancellation can make it relative to the sum), zero on the G blocks."""
    M, D, K = (abs(X).toarray() for X in (fom.M, fom.D, fom.K))
    n2 = fom.n2
    top = 8 * np.finfo(float).eps * (abs(a) * M + abs(b) * D + abs(c) * K)
    return np.block([[top, np.zeros((fom.n1, n2))], [np.zeros((n2, fom.n1)), np.zeros((n2, n2))]])


def padded(fom, b):
    return np.vstack([b, np.zeros((fom.n2, b.shape[1]))])


@pytest.fixture
def solver(small_random):
    return small_random.new_solver()


@pytest.mark.parametrize("s", [0.3 + 0.8j, 0.5, 0.0, -1j])
def test_matrix_equals_explicit_assembly(small_random, solver, s):
    S = solver.matrix(s)
    assert sp.issparse(S) and S.format == "csc" and S.shape == (14, 14)
    assert np.all(np.abs(S.toarray() - explicit_matrix(small_random, s)) <= assembly_bound(small_random, s * s, s, 1))


def test_matrix_coeffs(small_random, solver):
    a, b, c = 2.0, -1.0 + 1j, 0.5
    M, D, K, G = (X.toarray() for X in (small_random.M, small_random.D, small_random.K, small_random.G))
    ref = np.block([[a * M + b * D + c * K, G.T], [G, np.zeros((2, 2))]])
    assert np.all(np.abs(solver.matrix(coeffs=(a, b, c)).toarray() - ref) <= assembly_bound(small_random, a, b, c))
    with pytest.raises(ms.InputError, match="either s or coeffs"):
        solver.matrix()


@pytest.mark.parametrize("s", [0.3 + 0.8j, 0.7])
def test_solve_vs_dense(small_random, solver, s):
    F = small_random.F
    x = solver.factor(s).solve(F)
    ref = np.linalg.solve(explicit_matrix(small_random, s), padded(small_random, F))
    tol = solve_tolerance(explicit_matrix(small_random, s))  # measured <= 5e-16, bounds >= 2e-12
    assert x.shape == F.shape
    assert_rounding(rel_err(x, ref[:12]), tol, "sparse against dense solve")
    xf = solver.factor(s).solve(F, full=True)
    assert xf.shape == (14, 2)
    assert_rounding(rel_err(xf, ref), tol, "full sparse against dense solve")


def test_conjugate_shift_one_factorization(small_random):
    s = 0.2 + 0.9j
    solver = small_random.new_solver()
    f1 = solver.factor(s)
    f2 = solver.factor(np.conj(s))
    assert solver.stats.factorizations == 1
    assert solver.stats.reused == 1
    assert f2.conjugate and not f1.conjugate
    rhs = small_random.F + 1j * np.arange(24.0).reshape(12, 2)
    x2 = f2.solve(rhs)
    # against a fresh solver without cache ...
    fresh = small_random.new_solver(cache_size=0)
    y = fresh.factor(np.conj(s)).solve(rhs)
    assert fresh.stats.factorizations == 1
    S = solver.matrix(np.conj(s)).toarray()
    tol = solve_tolerance(S)  # measured <= 3e-16, bounds >= 2e-12
    assert_rounding(rel_err(x2, y), tol, "conjugate view against a fresh LU")
    # ... and a dense solve of the assembled conjugate matrix
    ref = np.linalg.solve(S, padded(small_random, rhs))[:12]
    assert_rounding(rel_err(x2, ref), tol, "conjugate view against dense")
    # transposed solves through the conjugate view
    xt = f2.solve(rhs, trans=True)
    reft = np.linalg.solve(S.T, padded(small_random, rhs))[:12]
    assert_rounding(rel_err(xt, reft), tol, "transposed conjugate view against dense")
    assert solver.stats.factorizations == 1


def test_conjugate_of_conjugate_view_reuses(small_random):
    s = 0.1 + 2j
    solver = small_random.new_solver()
    solver.factor(np.conj(s))
    f = solver.factor(s)
    assert f.conjugate and solver.stats.factorizations == 1
    f = solver.factor(np.conj(s))
    assert not f.conjugate and solver.stats.factorizations == 1


def test_no_conjugate_reuse_without_cache(small_random):
    solver = small_random.new_solver(cache_size=0)
    solver.factor(0.5 + 1j)
    solver.factor(0.5 - 1j)
    assert solver.stats.factorizations == 2


def test_cache_lru(small_random):
    solver = small_random.new_solver(cache_size=2)
    for s in (1j, 2j, 3j):
        solver.factor(s)
    assert solver.stats.factorizations == 3
    solver.factor(3j)
    solver.factor(-2j)  # conjugate of a cached one
    assert solver.stats.factorizations == 3
    solver.factor(1j)   # dropped: least recently used
    assert solver.stats.factorizations == 4
    solver.clear()
    solver.factor(1j)
    assert solver.stats.factorizations == 5


def test_same_shift_reused(solver):
    solver.factor(0.5j)
    solver.factor(0.5j)
    solver.factor(coeffs=(-0.25, 0.5j, 1.0))
    assert solver.stats.factorizations == 1 and solver.stats.reused == 2


@pytest.mark.parametrize("s", [0.3 + 0.8j, 0.7])
def test_transposed_solve_vs_dense(small_random, solver, s):
    rhs = small_random.L.T
    x = solver.factor(s).solve(rhs, trans=True)
    S = explicit_matrix(small_random, s)
    ref = np.linalg.solve(S.T, padded(small_random, rhs))[:12]
    # measured <= 4e-16, bounds >= 2e-12
    assert_rounding(rel_err(x, ref), solve_tolerance(S), "transposed solve against dense")
    # the model's D is not symmetric, so the transposed solve really differs
    plain = solver.factor(s).solve(rhs)
    assert rel_err(plain, ref) > 1e-6


@pytest.mark.parametrize("trans", [False, True])
def test_complex_rhs_on_real_lu(small_random, solver, trans):
    s = 0.7
    f = solver.factor(s)
    assert not f.complex_lu
    rhs = small_random.F + 1j * np.ones((12, 2))
    x = f.solve(rhs, trans=trans)
    assert np.iscomplexobj(x)
    S = explicit_matrix(small_random, s)
    ref = np.linalg.solve(S.T if trans else S, padded(small_random, rhs))[:12]
    tol = solve_tolerance(S)  # measured <= 5e-16, bounds >= 3e-12
    assert_rounding(rel_err(x, ref), tol, "complex rhs on a real LU")
    xv = f.solve(rhs[:, 0], trans=trans)
    assert xv.shape == (12,)
    assert_rounding(rel_err(xv, ref[:, 0]), tol, "one complex column on a real LU")


def test_full_rhs_with_constraint_block(small_random, solver):
    s = 0.1 + 0.5j
    b = np.arange(14.0) - 3
    x = solver.factor(s).solve(b, full=True)
    # measured 1e-17, bound 8e-15
    assert_rounding(backward_error(explicit_matrix(small_random, s), x, b), rounding_unit(14), "backward error")


def test_rhs_wrong_rows(solver):
    with pytest.raises(ms.InputError, match=r"rhs has 5 rows; expected n1 = 12 or n1 \+ n2 = 14"):
        solver.factor(1j).solve(np.ones(5))


def test_stats_counts(small_random, solver):
    f = solver.factor(1j)
    f.solve(small_random.F)
    f.solve(small_random.L.T, trans=True)
    d = solver.stats.as_dict()
    assert d["factorizations"] == 1 and d["solves"] == 2 + 3
    snap = solver.stats.copy()
    solver.factor(2j).solve(small_random.F)
    assert solver.stats.since(snap)["factorizations"] == 1


def test_inputs_not_mutated(small_random):
    mats = {k: getattr(small_random, k).copy() for k in ("M", "D", "K", "G")}
    solver = SaddlePointSolver(small_random.M, small_random.D, small_random.K, small_random.G)
    for s in (0.3 + 1j, 0.3 - 1j, 0.5):
        f = solver.factor(s)
        for trans in (False, True):
            for rhs in (np.asfortranarray(small_random.F.copy()), small_random.F.copy(),
                        small_random.F + 1j, np.ones(14, dtype=complex)):
                keep = rhs.copy()
                f.solve(rhs, trans=trans, full=rhs.shape[0] == 14)
                assert np.array_equal(rhs, keep)
    for k, X in mats.items():
        Y = getattr(small_random, k)
        assert abs(X - Y).max() == 0 and X.nnz == Y.nnz, k


def singular_2x2_model():
    """Two free masses joined by a spring, no constraint: K is singular, s = 0 a pole."""
    K = sp.csr_matrix(np.array([[1.0, -1.0], [-1.0, 1.0]]))
    return ms.models.Index3Model(sp.identity(2), 0.1 * K, K, None, [[1.0], [0.0]], [[1.0, 0.0]])


def test_singular_shift_raises():
    fom = singular_2x2_model()
    with pytest.raises(ms.SingularShiftError, match="singular"):
        fom.transfer(0.0)
    with pytest.raises(ms.SingularShiftError):
        fom.solver.factor(0.0)
    with pytest.raises(ArithmeticError):
        fom.freqresp([0.0])
    # the same model is fine off the pole
    assert np.isfinite(fom.transfer(0.5j)).all()


def test_singular_shift_constrained():
    """A constraint that fixes the only flexible coordinate: S(0) is singular
    although G has full row rank."""
    K = sp.csr_matrix(np.array([[1.0, -1.0, 0.0], [-1.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    G = sp.csr_matrix(np.array([[0.0, 0.0, 1.0]]))
    fom = ms.models.Index3Model(sp.identity(3), 0.1 * K, K, G, [[1.0], [0.0], [0.0]],
                                [[1.0, 0.0, 0.0]])
    with pytest.raises(ms.SingularShiftError):
        fom.transfer(0.0)


def test_exact_pole_raises():
    # M = 1, D = 0, K = 1 (one mass, no constraint): poles at s = +-1j
    fom = ms.models.Index3Model([[1.0]], [[0.0]], [[1.0]], None, [[1.0]], [[1.0]])
    with pytest.raises(ms.SingularShiftError, match="exactly singular"):
        fom.transfer(1j)


def test_near_pole_checks():
    """s at a pole up to rounding: caught by the opt-in checks, not returned as a number."""
    # two uncoupled masses, poles at +-1j and +-sqrt(2)j
    fom = ms.models.Index3Model(np.eye(2), np.zeros((2, 2)), np.diag([1.0, 2.0]), None,
                                [[1.0], [1.0]], [[1.0, 1.0]])
    s = 1j * (1 + 2.2e-16)
    with pytest.raises(ms.SingularShiftError, match="pivot"):
        fom.new_solver(pivot_tol=1e-15, ruiz_sweeps=0).factor(s)  # on equilibrated factors it cannot see this
    with pytest.raises(ms.SingularShiftError, match="reciprocal condition"):
        fom.new_solver(rcond_tol=1e-14).factor(s)
    # with the checks off (the default) the (meaningless) huge number comes back
    x = fom.new_solver().factor(s).solve([1.0, 1.0])
    assert abs(x[0]) > 1e14


def test_rcond_check_accepts_high_frequency(dsms50):
    """The condition estimate is scale-aware: s = 1e7j is no pole of the DSMS."""
    f = dsms50.new_solver(rcond_tol=1e-14).factor(1e7j)
    assert f.min_pivot_ratio > 1e-14


def test_high_frequency_is_not_a_pole(dsms50):
    s = 1e7j
    Z = np.linalg.svd(dsms50.G.toarray())[2][1:].T  # orthonormal basis of ker G
    M, D, K = (X.toarray() for X in (dsms50.M, dsms50.D, dsms50.K))
    ref = dsms50.L @ Z @ np.linalg.solve(Z.T @ (s * s * M + s * D + K) @ Z, Z.T @ dsms50.F)
    assert rel_err(dsms50.transfer(s), ref) < 1e-10


def test_unstable_lu_is_refactored_not_returned(dsms50):
    """An LU whose solves are off (an unstable pivot sequence: seen with COLAMD and threshold
    0.1 on tcom(nc=3334), backward error 5e-4) fails the backward-error check; the solver
    refactors once with partial pivoting and returns the right answer, not a wrong number."""
    solver = dsms50.new_solver()
    f = solver.factor(0.3j)
    good = f.lu

    class Off:  # stands for the unstable factorization: every solve 1e-3 off
        def solve(self, b, trans="N"):
            return good.solve(b, trans=trans) * (1 + 1e-3)

    f.lu = Off()
    x = f.solve(dsms50.F)
    ref = np.linalg.solve(solver.matrix(0.3j).toarray(), np.vstack([dsms50.F, np.zeros((1, 1))]))[:50]
    assert np.allclose(x, ref, rtol=1e-10, atol=0)
    assert f.refactored and solver.stats.refactorizations == 1 and solver.stats.factorizations == 2


@pytest.mark.parametrize("scaling", ["diagonal", "none", "ruiz"])
@pytest.mark.parametrize("reuse", [True, False])
def test_reused_ordering_solves_vs_dense(small_random, scaling, reuse):
    """Later shifts factor the column-permuted matrix with the first shift's ordering;
    plain, transposed, full, conjugate and unchecked solves must still be exact."""
    fom = small_random
    solver = SaddlePointSolver(fom.M, fom.D, fom.K, fom.G, scaling=scaling, reuse_ordering=reuse,
                               backend="superlu")
    rng = np.random.default_rng(3)
    B = rng.standard_normal((fom.n1 + fom.n2, 2)) + 1j * rng.standard_normal((fom.n1 + fom.n2, 2))
    for s in (0.4 + 0.2j, 1.5j, 0.7, 0.3 - 2j):
        S = explicit_matrix(fom, s)
        f = solver.factor(s)
        tol = solve_tolerance(S)  # measured <= 6e-16, bounds >= 2e-12 (Sc = conj(S): the same condition number)
        assert_rounding(rel_err(f.solve(B, full=True), np.linalg.solve(S, B)), tol, "solve")
        assert_rounding(rel_err(f.solve(B, trans=True, full=True), np.linalg.solve(S.T, B)), tol, "transposed")
        assert_rounding(rel_err(f._raw_solve(B, False), np.linalg.solve(S, B)), tol, "unchecked")
        assert_rounding(rel_err(f._raw_solve(B, True), np.linalg.solve(S.T, B)), tol, "unchecked transposed")
        g = solver.factor(np.conj(s))  # conjugate view of the same LU
        Sc = explicit_matrix(fom, np.conj(s))
        assert_rounding(rel_err(g.solve(B, full=True), np.linalg.solve(Sc, B)), tol, "conjugate view")
        assert_rounding(rel_err(g.solve(B, trans=True, full=True), np.linalg.solve(Sc.T, B)), tol,
                        "transposed conjugate view")
    reused = ("ordering", "COLAMD") in solver.pattern
    assert reused == (reuse and scaling != "ruiz")
    if reused:  # the model's other solvers see the same ordering
        other = SaddlePointSolver(fom.M, fom.D, fom.K, fom.G, pattern=solver.pattern, backend="superlu")
        assert other._ordering() is solver.pattern[("ordering", "COLAMD")]


def test_reused_ordering_rcond_check():
    """The condition estimate goes through the permuted LU: a pole is still found."""
    fom = ms.models.Index3Model(np.eye(2), np.zeros((2, 2)), np.diag([1.0, 2.0]), None,
                                [[1.0], [1.0]], [[1.0, 1.0]])
    for backend in ("superlu", "banded"):
        solver = fom.new_solver(rcond_tol=1e-14, backend=backend)
        assert solver.factor(0.5j).min_pivot_ratio > 0.1  # rcond of a well-conditioned shift
        with pytest.raises(ms.SingularShiftError, match="reciprocal condition"):
            solver.factor(1j * (1 + 2.2e-16))
    assert ("ordering", "COLAMD") in solver.pattern
    with pytest.raises(ms.SingularShiftError, match="reciprocal condition"):
        solver.factor(1j * (1 + 2.2e-16))


def test_pattern_of_other_model_refused(small_random, dsms50):
    with pytest.raises(ms.MorsuiteError, match="pattern"):
        SaddlePointSolver(dsms50.M, dsms50.D, dsms50.K, dsms50.G, pattern=small_random.solver.pattern)


def test_fallbacks_are_tried_in_order_and_exhausted_raises(dsms50):
    """Refactorizations follow the fallback list until one passes the check; if none does,
    SingularShiftError (never the inaccurate number)."""
    solver = dsms50.new_solver()
    f = solver.factor(0.3j)
    good = f.lu

    class Off:
        def solve(self, b, trans="N"):
            return good.solve(b, trans=trans) * (1 + 1e-3)

    # the banded LU pivots within the (1,1) block only: SuperLU on the same matrix comes first
    assert solver.backend == "banded" and len(f.fallback) == 4
    assert isinstance(f.fallback[0](), spla.SuperLU)
    calls = []
    f.lu = Off()
    f.fallback = (lambda: calls.append(1) or Off(), lambda: calls.append(2) or good, lambda: calls.append(3) or good)
    x = f.solve(dsms50.F)
    ref = np.linalg.solve(solver.matrix(0.3j).toarray(), np.vstack([dsms50.F, np.zeros((1, 1))]))[:50]
    assert np.allclose(x, ref, rtol=1e-10, atol=0)
    assert calls == [1, 2] and solver.stats.refactorizations == 2

    g = solver.factor(0.5j)
    g.lu = Off()
    g.fallback = (lambda: Off(),)
    with pytest.raises(ms.SingularShiftError, match="backward error"):
        g.solve(dsms50.F)


def test_backward_error_of_a_factorization(dsms50):
    f = dsms50.new_solver().factor(0.3j)
    n = dsms50.n1 + dsms50.n2  # measured <= 1e-16, bounds >= 2e-14
    assert_rounding(f.backward_error(dsms50.F), rounding_unit(n), "backward error")
    assert_rounding(f.backward_error(dsms50.L.T, trans=True), rounding_unit(n), "transposed backward error")
    good = f.lu

    class Off:  # every solve 1e-3 off
        def solve(self, b, trans="N"):
            return good.solve(b, trans=trans) * (1 + 1e-3)

    f.lu = Off()
    assert 1e-5 < f.backward_error(dsms50.F) < 1e-2  # far above the 1e-10 the solver accepts
    with pytest.raises(ms.InputError, match="backward_tol"):
        dsms50.new_solver(backward_tol=0).factor(0.3j).backward_error(dsms50.F)
