"""Compiled kernels (morsuite.linalg.kernels): the banded LU against LAPACK's and dense solves, the
half-sweeps with skipped leading rows, the bordered LU with either kernel, the one-pass assembly
against numpy's, and the kernels on two threads."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.linalg.lapack as lapack

from morsuite.linalg import kernels
from morsuite.linalg.backends import BandedBorderLU
from morsuite.reducers.irka.shift_solves import map_threads
from support import EPS, assert_rounding, rounding_unit, solve_tolerance

pytestmark = pytest.mark.skipif(not kernels.available(), reason="numba is not installed")


def _band(n, kl, ku, dtype, rng, dominant):
    """A random band matrix (dense) and its transposed LAPACK band array (n, 2 kl + ku + 1)."""
    A = np.zeros((n, n), dtype=dtype)
    for d in range(-kl, ku + 1):
        v = rng.standard_normal(n - abs(d))
        if dtype == np.complex128:
            v = v + 1j * rng.standard_normal(n - abs(d))
        A += np.diag(v, d)
    if dominant:
        A += np.diag(np.full(n, 3.0 * (kl + ku + 1)))
    ab = np.zeros((n, 2 * kl + ku + 1), dtype=dtype)
    for j in range(n):
        for i in range(max(0, j - ku), min(n, j + kl + 1)):
            ab[j, kl + ku + i - j] = A[i, j]
    return A, ab


@pytest.mark.parametrize("dtype", [np.float64, np.complex128])
@pytest.mark.parametrize("kl,ku", [(2, 2), (3, 1), (1, 4), (0, 2)])
def test_gbtrf_matches_lapack_and_solves(dtype, kl, ku):
    """Factors and pivots as LAPACK's ?gbtrf (the same algorithm); solves and transposed solves
    of well-conditioned matrices to backward error ~eps against the dense matrix."""
    rng = np.random.default_rng(kl * 10 + ku)
    n = 120
    A, ab = _band(n, kl, ku, dtype, rng, dominant=False)
    ref, piv_ref, info_ref = getattr(lapack, ("z" if dtype == np.complex128 else "d") + "gbtrf")(
        ab.T.copy(order="F"), kl, ku)
    piv, dinv, info = kernels.gbtrf(ab, kl, ku)
    assert info == info_ref == 0
    np.testing.assert_array_equal(piv, piv_ref)  # partial pivoting: the same pivot rows
    # the same operations in another order: the factors' rounding, relative to their largest entry
    # (the growth of partial pivoting included) and over a row of U and L (kl + ku + 1 terms): measured 0, bound 5e-15
    assert_rounding(np.abs(ab.T - ref).max() / np.abs(ref).max(), rounding_unit(kl + ku + 1), "factors")
    np.testing.assert_allclose(dinv, 1.0 / ab[:, kl + ku], rtol=1e-15)  # one division each: correctly rounded
    # solves: a well-conditioned matrix of the same pattern
    A, ab = _band(n, kl, ku, dtype, rng, dominant=True)
    piv, dinv, info = kernels.gbtrf(ab, kl, ku)
    for k in (1, 3):
        B = rng.standard_normal((n, k)).astype(dtype)
        for trans in (False, True):
            X = kernels.gbtrs(ab, kl, ku, piv, dinv, B.copy(), trans)
            Aop = A.T if trans else A
            eta = np.abs(Aop @ X - B).max() / (np.abs(Aop).sum(axis=1).max() * np.abs(X).max())
            # over a band row's terms: measured <= 2e-16, bounds >= 4e-15
            assert_rounding(eta, rounding_unit(2 * kl + ku + 1), "backward error")
            ref = np.linalg.solve(Aop, B)
            # measured <= 2e-16, bounds >= 5e-14
            assert_rounding(np.linalg.norm(X - ref) / np.linalg.norm(ref), solve_tolerance(Aop), "solve")


def test_gbtrf_reports_exact_singularity():
    """A zero column gives LAPACK's info (1-based index of the first zero pivot)."""
    rng = np.random.default_rng(3)
    A, ab = _band(30, 2, 2, np.float64, rng, dominant=True)
    ab[7, :] = 0.0  # column 7 of A is zero
    _, _, info = kernels.gbtrf(ab, 2, 2)
    assert info == 8


def test_forward_sweeps_skip_leading_zero_rows():
    """The forward half-sweeps with each column's first nonzero row give the sweeps over all rows."""
    rng = np.random.default_rng(5)
    n, kl, ku = 200, 2, 3
    A, ab = _band(n, kl, ku, np.complex128, rng, dominant=False)
    piv, dinv, _ = kernels.gbtrf(ab, kl, ku)
    starts = np.array([0, 17, 17, 90, 199])
    B = np.zeros((n, starts.size), dtype=complex)
    for c, s0 in enumerate(starts):
        B[s0:, c] = rng.standard_normal(n - s0) + 1j * rng.standard_normal(n - s0)
    for part in (kernels.L_FORWARD, kernels.UT_FORWARD):
        full = kernels.sweep(ab, kl, ku, piv, dinv, B.copy(), part)
        skip = kernels.sweep(ab, kl, ku, piv, dinv, B.copy(), part, starts)
        np.testing.assert_array_equal(skip, full)
        one = kernels.sweep(ab, kl, ku, piv, dinv, B[:, 3:4].copy(), part, starts[3:4])
        # the same arithmetic per column whatever the others (measured equal): at most a reordering
        np.testing.assert_allclose(one, full[:, 3:4], rtol=1e-13, atol=1e-13 * np.abs(full).max())
    with pytest.raises(ValueError, match="starts"):
        kernels.sweep(ab, kl, ku, piv, dinv, B.copy(), kernels.L_FORWARD, starts[::-1])


@pytest.mark.parametrize("which", ["dsms", "tcom"])
def test_bordered_lu_both_kernels(which, dsms50, tcom20, monkeypatch):
    """BandedBorderLU with the compiled kernel and with LAPACK's: the same solutions, backward error
    ~eps against the assembled saddle matrix, one and several right-hand sides, both transposes."""
    fom = {"dsms": dsms50, "tcom": tcom20}[which]
    solver = fom.new_solver(backend="banded", cache_size=0)
    perm = solver._ordering()
    an = solver.analysis
    rng = np.random.default_rng(2)
    for s in (0.3 + 2.0j, 1.7, 1e-3j):
        _, _, As, _ = solver._assemble_scaled(*solver._coeffs(s, None), perm)
        X = {}
        for kernel in ("numba", "lapack"):
            monkeypatch.setenv("MORSUITE_BAND_KERNEL", kernel)
            lu = BandedBorderLU(As.data, solver.n1, solver.n2, an["kl"], an["ku"], perm["banded"])
            assert lu.kernel == kernel
            for k in (1, 3):
                B = rng.standard_normal((solver.N, k)) + 1j * rng.standard_normal((solver.N, k))
                for trans in ("N", "T"):
                    x = lu.solve(B, trans)
                    Aop = As.T if trans == "T" else As
                    eta = np.abs(Aop @ x - B).max() / (abs(Aop).sum(axis=1).max() * np.abs(x).max())
                    # measured <= 4e-16, bounds >= 2e-14
                    assert_rounding(eta, rounding_unit(solver.N), f"{kernel} s={s} k={k} {trans}")
                    X[kernel, k, trans] = (B, x)
        for key in [key for key in X if key[0] == "numba"]:
            B, x = X[key]
            x_l = BandedBorderLU(As.data, solver.n1, solver.n2, an["kl"], an["ku"], perm["banded"]).solve(
                B, key[2])  # LAPACK's kernel (the environment still says so)
            np.testing.assert_allclose(x, x_l, rtol=1e-9, atol=1e-9 * np.abs(x_l).max())


@pytest.mark.parametrize("which", ["dsms", "tcom"])
def test_assembly_kernel_matches_numpy(which, dsms50, tcom20, monkeypatch):
    """The one-pass assembly gives numpy's entries and the 1-norm SaddleLU would compute."""
    fom = {"dsms": dsms50, "tcom": tcom20}[which]
    solver = fom.new_solver(backend="superlu", cache_size=0)
    perm = solver._ordering()
    for s in (0.3 + 2.0j, 1.7, 1e-3j):
        coeffs = solver._coeffs(s, None)
        monkeypatch.setenv("MORSUITE_BAND_KERNEL", "numba")
        d1, _, A1, n1 = solver._assemble_scaled(*coeffs, perm)
        monkeypatch.setenv("MORSUITE_BAND_KERNEL", "lapack")
        d2, _, A2, n2 = solver._assemble_scaled(*coeffs, perm)
        assert A1.dtype == A2.dtype
        np.testing.assert_allclose(d1, d2, rtol=0, atol=0)
        # a fixed formula per entry (three products, two sums; measured equal bits): no size or conditioning
        np.testing.assert_allclose(A1.data, A2.data, rtol=1e-15, atol=1e-15 * np.abs(A2.data).max())
        colsum = np.add.reduceat(np.abs(A2.data), A2.indptr[:-1])
        assert n1["1"] == pytest.approx(colsum.max(), rel=1e-14)
        assert n2 == {}


def test_kernels_on_two_threads(tcom20):
    """Factorizations and solves on two threads (the kernels release the GIL) equal the serial ones."""
    shifts = [0.1j, 0.5 + 1j, 2.0j, 0.01 + 0.2j]

    def run(s):
        solver = tcom20.new_solver(backend="banded", cache_size=0)
        return solver.factor(s).solve(tcom20.F)

    serial = [run(s) for s in shifts]
    threaded = map_threads(run, shifts, 2)
    for a, b in zip(serial, threaded):
        np.testing.assert_array_equal(a, b)
    assert sla.norm(serial[0]) > 0


def _pencil_rounding(K, M, D, s):
    """Entrywise rounding bound of K + s^2 M + s D formed in any order: a few units of roundoff of the
    terms (complex products included), not relative to the sum (its terms may cancel)."""
    return 8 * EPS * (np.abs(K) + abs(s) ** 2 * np.abs(M) + abs(s) * np.abs(D))


@pytest.mark.parametrize("s", [0.25 + 1.5j, -0.7])
def test_dense_pencil_matches_numpy(s):
    """K + s^2 M + s D in one compiled pass equals numpy's three passes (complex and real shifts), and the
    projected IRKA's pencil is the same with the kernel off."""
    rng = np.random.default_rng(3)
    K, M, D = (np.asfortranarray(rng.standard_normal((7, 5))) for _ in range(3))
    out = np.empty((7, 5), dtype=complex if isinstance(s, complex) else float, order="F")
    got = kernels.dense_pencil(K, M, D, s, out)
    assert got is out and got.dtype == out.dtype
    assert np.all(np.abs(got - (K + s * s * M + s * D)) <= _pencil_rounding(K, M, D, s))  # measured 0


def test_projected_pencil_same_with_and_without_the_kernel(monkeypatch):
    import morsuite as ms

    red = ms.reducers.make("irka-projected", ms.models.dsms(g=30))
    red.reduce(2)
    pm = red._model
    assert pm.K.flags.f_contiguous
    fast = pm.pencil(0.3 + 0.8j)
    monkeypatch.setenv("MORSUITE_BAND_KERNEL", "lapack")
    assert np.all(np.abs(pm.pencil(0.3 + 0.8j) - fast) <= _pencil_rounding(pm.K, pm.M, pm.D, 0.3 + 0.8j))  # measured 0


@pytest.mark.parametrize("s, trans", [(0.3 + 0.7j, False), (0.3 + 0.7j, True), (1.7, False), (1.7, True)])
def test_dot2_residual_against_exact_rational_arithmetic(s, trans):
    """The backward-error certificate's residual b - A x (dd_kernels.residual, Dot2) of an LU solution,
    where it cancels to about eps |A||x|, equals exact rational arithmetic to a rounding of the result
    plus about (2k u)^2 of each row's |b| + |A||x| (Ogita-Rump-Oishi), plain and transposed, complex
    and real; a residual in double keeps no digit there."""
    from fractions import Fraction as Q

    import morsuite as ms
    from morsuite.linalg import dd_kernels
    from morsuite.linalg.accuracy import _segments

    if not kernels.available():
        pytest.skip("numba is not installed")
    fom = ms.models.tcom(nc=6)
    f = fom.new_solver(backend="superlu").factor(s)
    A = f.matrix
    N = A.shape[0]
    rng = np.random.default_rng(5)
    b = rng.standard_normal(N) + (1j * rng.standard_normal(N) if np.iscomplexobj(A.data) else 0)
    x = f._lu_solve(b[:, None], trans)[:, 0]
    r = dd_kernels.residual(_segments(A, None, trans), A.data, x, b)
    D = (A.T if trans else A).toarray()
    size = np.abs(b) + np.abs(D) @ np.abs(x)
    k = np.count_nonzero(D, axis=1)
    ar, ai, xr, xi = D.real, D.imag, x.real, np.imag(x)
    for part in (np.real, np.imag):
        if part is np.imag and not np.iscomplexobj(r):
            continue
        exact = []
        for i in range(N):
            acc = Q(part(b[i]))
            for j in np.flatnonzero(D[i]):  # Re: ar xr - ai xi, Im: ar xi + ai xr (exact rationals)
                if part is np.real:
                    acc -= Q(ar[i, j]) * Q(xr[j]) - Q(ai[i, j]) * Q(xi[j])
                else:
                    acc -= Q(ar[i, j]) * Q(xi[j]) + Q(ai[i, j]) * Q(xr[j])
            exact.append(float(acc))
        exact = np.array(exact)
        got = part(r)
        assert np.abs(exact).max() < 1e-13 * size.max()  # it does cancel
        assert np.all(np.abs(got - exact) <= EPS * np.abs(exact) + (4 * k * EPS) ** 2 * size), part
        double = part(b - (A.T if trans else A) @ x)
        assert np.abs(double - exact).max() > 10 * np.abs(got - exact).max()
