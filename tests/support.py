"""Assertions shared by the tests: sets of computed numbers compared by matching, not by sorting.

Eigenvalues, poles, shifts and Hankel singular values come from different code paths
(LAPACK drivers, BLAS kernels, thread counts) with different last bits. Sorting them
and comparing index by index breaks when two values are close: ``np.sort_complex``
orders the two members of a conjugate pair by the rounding of their real parts, which
are equal in exact arithmetic. These helpers match the sets optimally
(:func:`morsuite.linalg.dense.match_sets`) against tolerances that the caller scales by
the conditioning of the problem (:func:`eig_tolerance` for eigenvalues).

Import with ``from support import ...`` (pytest puts ``tests/`` on ``sys.path`` because
``tests/conftest.py`` lives there; the stress tests import ``stress_support`` the same way).
"""

from __future__ import annotations

import inspect
import os

import numpy as np
import scipy.linalg as sla

from morsuite.linalg.dense import match_sets

EPS = np.finfo(float).eps


def rounding_unit(n) -> float:
    """The rounding level of a product or orthogonalization over n terms: 10 sqrt(n) eps.

    Tolerances at the rounding level are this unit times the problem's scale and condition
    number (e.g. ``rounding_unit(n) * kappa ** 2`` for a Cholesky-QR span, ``rounding_unit(n)``
    for the orthogonality of a reorthogonalized basis), never a fixed 1e-14: the last bits
    differ between BLAS kernels and thread counts."""
    return 10.0 * np.sqrt(n) * EPS


def solve_tolerance(A, factor=1.0) -> float:
    r"""Relative forward-error level of a backward-stable solve with the dense matrix A:
    ``factor`` :math:`\times` :func:`rounding_unit` (n) :math:`\times \kappa_2(A)`.

    Two backward-stable solves of :math:`A x = b` (a sparse LU and ``np.linalg.solve``, two
    BLAS kernels, two thread counts) agree to about :math:`n \epsilon \kappa(A)` in
    :math:`\|x_1 - x_2\| / \|x\|` (the 10 in :func:`rounding_unit` covers the constant of the
    backward error and the two solves; ``factor`` is for a longer chain of operations).
    :math:`\kappa_2(A)` from ``np.linalg.cond``: an SVD, small matrices only."""
    A = np.asarray(A)
    return factor * rounding_unit(A.shape[0]) * float(np.linalg.cond(A))


def transfer_tolerance(P, B, C, factor=1.0) -> float:
    r"""Relative rounding level of a transfer function value :math:`H = C P^{-1} B` computed by a
    backward-stable solve with the dense matrix P: :func:`solve_tolerance` (P) times
    :math:`\|C\|_2 \|P^{-1} B\|_F / \|H\|_F`, the amplification by the output map (a first-order
    realization's velocities grow with the frequency while C reads the positions; outputs that
    cancel). Compare :math:`\|H_1 - H_2\|_F / \|H_2\|_F` of two realizations with the sum of
    their levels."""
    P = np.asarray(P)
    X = np.linalg.solve(P, np.asarray(B))
    H = np.asarray(C) @ X
    return solve_tolerance(P, factor) * np.linalg.norm(C, 2) * np.linalg.norm(X) / np.linalg.norm(H)


def condest(A) -> float:
    r"""Estimate of :math:`\kappa_\infty(D_r A)`, :math:`D_r` scaling each row of the sparse square
    matrix A to largest entry 1: the :math:`\kappa` of :func:`solve_tolerance` for a matrix too large
    for an SVD.

    It bounds Skeel's condition number :math:`\|\,|A^{-1}|\,|A|\,\|_\infty`, which governs the
    forward error of an LU with partial pivoting and does not change with the rows' scaling (a
    first-order realization's rows differ by orders of magnitude; the plain :math:`\kappa(A)`
    would then be a loose bound). Hager-Higham estimate (``scipy.sparse.linalg.onenormest``)
    on :math:`(D_r A)^T`; cost: one sparse LU and a few solves."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    A = sp.csr_matrix(A)
    X = sp.csc_matrix((sp.diags(1.0 / abs(A).max(axis=1).toarray().ravel()) @ A).T)  # kappa_inf(Y) = kappa_1(Y^T)
    lu = spla.splu(X)
    inv = spla.LinearOperator(X.shape, matvec=lu.solve, rmatvec=lambda x: lu.solve(x, trans="H"), dtype=X.dtype)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # onenormest's sign vectors of zeros
        return float(spla.onenormest(X) * spla.onenormest(inv))


def backward_error(A, x, b) -> float:
    r"""Normwise backward error :math:`\|A x - b\|_F / (\|A\|_F \|x\|_F + \|b\|_F)` of an
    approximate solution x of :math:`A x = b` (any number of columns; A dense or sparse).

    A backward-stable solver makes it a few :func:`rounding_unit` (n) whatever the
    conditioning of A: compare it with ``rounding_unit(n)``, not with a fixed constant, and
    not the residual relative to ``b`` alone (which carries :math:`\kappa(A)`)."""
    x = np.asarray(x)
    b = np.asarray(b)
    norm_a = sla.norm(A.toarray()) if hasattr(A, "toarray") else np.linalg.norm(np.asarray(A))
    r = A @ x - b
    return float(np.linalg.norm(r) / (norm_a * np.linalg.norm(x) + np.linalg.norm(b)))


def assert_rounding(value, bound, what="error") -> None:
    """Assert ``value <= bound`` for a rounding-level check, with both numbers in the message.

    With the environment variable ``MORSUITE_TOL_LOG`` naming a file, each call appends a
    line ``test-id:line value bound ratio``: run the suite with it on a new machine, BLAS or
    thread count to see the margin of every rounding-level check (the comments beside them
    give the values measured when they were written)."""
    value, bound = float(value), float(bound)
    log = os.environ.get("MORSUITE_TOL_LOG")
    if log:
        caller = inspect.currentframe().f_back
        where = f"{os.environ.get('PYTEST_CURRENT_TEST', '?').split(' ')[0]}:{caller.f_lineno}"
        with open(log, "a") as fh:
            fh.write(f"{where} {what!r} {value:.3e} {bound:.3e} {value / bound if bound else np.inf:.2e}\n")
    assert value <= bound, f"{what}: {value:.3e} > rounding-level bound {bound:.3e}"


def orthonormality_error(V, M=None) -> tuple[float, float]:
    r"""(:math:`\max|V^T M V - I|`, its rounding level) for a basis orthonormalized in the M inner product
    (M = None: the identity): the products' rounding, :func:`rounding_unit` (n) times
    :math:`\|M\|\,\|V\|_2^2` (:math:`\|V\|_2^2 \le 1/\lambda_{\min}(M)`: it carries M's conditioning;
    :math:`\|M\|` from the 1-norm, an upper bound of the 2-norm of a symmetric M), times 10 for the
    orthogonalization's own passes. A fixed 1e-12 is too tight on a large or ill-scaled M and too loose
    on a small one."""
    V = np.asarray(V)
    n, k = V.shape
    if M is None:
        gram, norm_m = V.conj().T @ V, 1.0
    else:
        gram = V.conj().T @ (M @ V)
        norm_m = float(abs(M).sum(axis=0).max())
    err = float(np.abs(gram - np.eye(k)).max())
    return err, 10.0 * rounding_unit(n) * norm_m * np.linalg.norm(V, 2) ** 2


def assert_sets_close(actual, desired, rtol=0.0, atol=0.0, what="values"):
    r"""Assert that two sets agree after an optimal one-to-one matching.

    Element :math:`j` of ``desired`` has the tolerance
    :math:`\mathrm{atol}_j + \mathrm{rtol} |d_j|`; the assertion holds iff some
    permutation matches every element of ``actual`` to an element of ``desired`` within
    its tolerance (a bottleneck assignment decides it exactly). A conjugate pair is
    matched to a conjugate pair when both sets are closed under conjugation.

    Parameters
    ----------
    actual, desired : array_like
        1-D sets of real or complex numbers, of equal size.
    rtol : float
        Relative tolerance: a documented multiple of the rounding the computation allows.
    atol : float or array_like
        Absolute tolerance, a scalar or one entry per element of ``desired`` (e.g. the
        ``tol`` of :func:`eig_tolerance`, scaled by eigenvalue condition numbers).
    what : str
        What the numbers are, for the message ("poles", "shifts", "HSVs").

    Returns
    -------
    perm : ndarray of int
        ``desired[perm]`` is matched with ``actual``, for follow-up checks on pairs.

    Raises
    ------
    AssertionError
        If the sizes differ or the best matching leaves an element outside its
        tolerance; the message gives the worst pair, its distance and tolerance, and how
        many pairs fail.
    """
    a = np.ravel(np.asarray(actual))
    d = np.ravel(np.asarray(desired))
    if a.size != d.size:
        raise AssertionError(f"{what}: {a.size} computed against {d.size} expected:\n  {a}\n  {d}")
    tol = np.broadcast_to(np.asarray(atol, dtype=float), d.shape) + rtol * np.abs(d)
    perm, dist = match_sets(a, d, scale=tol)
    bad = dist > 1
    if np.any(bad):
        i = int(np.argmax(dist))
        j = perm[i]
        raise AssertionError(
            f"{what}: {int(bad.sum())} of {a.size} not within tolerance after optimal matching; worst: "
            f"{a[i]!r} against {d[j]!r}, |difference| {abs(a[i] - d[j]):.3e} > tolerance {tol[j]:.3e} "
            f"(rtol {rtol:g}, atol {np.max(np.broadcast_to(atol, d.shape)):.3e})")
    return perm


def eig_tolerance(A, E=None, factor=10.0, balance=False):
    r"""Eigenvalues of :math:`(A, E)` and a first-order bound of their rounding errors.

    For a simple eigenvalue :math:`\lambda` with right and left eigenvectors :math:`x, y`,
    a backward-stable solver (QR or QZ) perturbs :math:`A` and :math:`E` by about
    :math:`\epsilon \|A\|` and :math:`\epsilon \|E\|`, which moves :math:`\lambda` by at most

    .. math:: \epsilon \, \kappa \, (\|A\|_2 + |\lambda| \, \|E\|_2), \qquad
              \kappa = \frac{\|x\| \, \|y\|}{|y^H E x|}

    to first order (a standard problem, ``E = None``, has no :math:`|\lambda| \|E\|` term).
    ``tol`` is ``factor`` times that (the constant of the backward error grows mildly with
    the size). ``balance=True`` measures :math:`\kappa` and the norm on
    the balanced matrix (``scipy.linalg.matrix_balance``, standard problems only), which is
    what LAPACK's ``geev`` (``np.linalg.eigvals``) works on.

    Returns
    -------
    lam, tol : ndarray
        The eigenvalues (``scipy.linalg.eig``) and one absolute tolerance per eigenvalue.
    """
    A = np.asarray(A)
    if balance:
        if E is not None:
            raise ValueError("eig_tolerance: balance=True is for standard problems (E = None)")
        A = sla.matrix_balance(A, permute=True, separate=False)[0]
    Em = np.eye(A.shape[0]) if E is None else np.asarray(E)
    lam, yl, xr = sla.eig(A, None if E is None else Em, left=True, right=True)
    gap = np.abs(np.einsum("ij,ij->j", yl.conj(), Em @ xr))
    kappa = np.linalg.norm(xr, axis=0) * np.linalg.norm(yl, axis=0) / gap
    norm_e = 0.0 if E is None else np.linalg.norm(Em, 2)
    tol = factor * EPS * kappa * (np.linalg.norm(A, 2) + np.abs(lam) * norm_e)
    return lam, tol


def dense_modes(fom):
    """Undamped constrained eigenpairs of a small model from a dense null-space basis Z of G:
    eigh(Z^T K Z, Z^T M Z); frequencies sign(lam) sqrt(|lam|), shapes Z Y (M-orthonormal)."""
    Z = sla.null_space(fom.G.toarray()) if fom.n2 else np.eye(fom.n1)
    lam, Y = sla.eigh(Z.T @ (fom.K @ Z), Z.T @ (fom.M @ Z))
    return np.sign(lam) * np.sqrt(np.abs(lam)), Z @ Y


def dense_reduced(fom):
    """(M, D, K, F, L) of the dense system on ker G: Z from scipy.linalg.null_space (small models only)."""
    from morsuite.utils import blas_threads

    with blas_threads(1):  # small dense work: threads only add synchronisation on a loaded machine
        Z = sla.null_space(fom.G.toarray())
        return tuple(Z.T @ (X.toarray() @ Z) for X in (fom.M, fom.D, fom.K)) + (Z.T @ fom.F, fom.L @ Z)


def moments(M, D, K, F, L, s0, k):
    """T^(j)(s0)/j!, j < k, of the dense second-order system (Taylor recurrence, dense LU)."""
    lu = sla.lu_factor(s0 * s0 * M + s0 * D + K)
    A1 = 2 * s0 * M + D
    X = [sla.lu_solve(lu, F.astype(complex))]
    for j in range(1, k):
        X.append(-sla.lu_solve(lu, A1 @ X[-1] + (M @ X[-2] if j >= 2 else 0)))
    return [L @ x for x in X]


def _split(a):
    """Veltkamp's splitting: a = hi + lo exactly, hi and lo with at most 26 significant bits."""
    c = 134217729.0 * a  # 2^27 + 1
    hi = c - (c - a)
    return hi, a - hi


def two_prod(a, b):
    """Dekker's exact product, elementwise: a * b = p + e exactly (IEEE doubles, round to nearest, no
    overflow), without a fused multiply-add: independent of the compiled kernels under test."""
    a, b = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    p = a * b
    ah, al = _split(a)
    bh, bl = _split(b)
    return p, ((ah * bh - p) + ah * bl + al * bh) + al * bl


def _expand(factors):
    """The exact expansion (a list of arrays whose sum is the product, elementwise) of a product of arrays."""
    terms = [np.asarray(factors[0], dtype=float)]
    for f in factors[1:]:
        terms = [t for u in terms for t in two_prod(u, f)]
    return terms


def exact_row_sums(n, rows, terms):
    """Correctly rounded ``sum over the terms of each row`` (math.fsum: exact summation of doubles)."""
    import math

    rows = np.concatenate([np.broadcast_to(r, t.shape) for r, t in zip(rows, terms)])
    vals = np.concatenate(terms)
    order = np.argsort(rows, kind="stable")
    rows, vals = rows[order], vals[order]
    cuts = np.searchsorted(rows, np.arange(n + 1))
    return np.array([math.fsum(vals[cuts[i]:cuts[i + 1]]) for i in range(n)])


def exact_saddle_residual(fom, omega, x, z, b):
    r"""The residual :math:`[b; 0] - S(j\omega)[x; z]` of the saddle system of ``fom`` at :math:`s = j\omega`,
    exact and rounded once to double (real and imaginary parts by :func:`exact_row_sums` over exact
    product expansions: :math:`\omega^2 M` and :math:`\omega D` are never rounded). Independent of
    morsuite's solvers and kernels (numpy and math.fsum only)."""
    import scipy.sparse as sp

    n1, n2 = fom.n1, fom.n2
    out = []
    for part, (xp, xq, zp, bp) in enumerate(((x.real, x.imag, z.real, b.real), (x.imag, x.real, z.imag, b.imag))):
        sign = 1.0 if part == 0 else -1.0  # Re: +omega D x_im, Im: -omega D x_re
        rows, terms = [np.arange(n1)], [np.asarray(bp, dtype=float)]
        for X, coeffs, vec, sgn in ((fom.K, (), xp, -1.0), (fom.M, (omega, omega), xp, 1.0),
                                    (fom.D, (omega,), xq, sign)):
            C = sp.coo_matrix(X)
            for t in _expand([C.data, *[np.full(C.nnz, c) for c in coeffs], vec[C.col]]):
                rows.append(C.row)
                terms.append(sgn * t)
        G = sp.coo_matrix(fom.G)
        for t in _expand([G.data, zp[G.row]]):  # G^T z in the first block
            rows.append(G.col)
            terms.append(-t)
        r1 = exact_row_sums(n1, rows, terms)
        r2 = exact_row_sums(n2, [G.row] * 2, [-t for t in _expand([G.data, xp[G.col]])]) if n2 else np.zeros(0)
        out.append(np.concatenate([r1, r2]))
    return out[0] + 1j * out[1]


def reference_transfer(fom, omega, steps=12):
    r""":math:`T(j\omega)` of ``fom`` to about the rounding of double, independently of morsuite's solvers:
    a dense LU (LAPACK) of :math:`S(j\omega)` assembled in double, refined with the exact residual of
    :func:`exact_saddle_residual` until the correction is at most :math:`\varepsilon` of the solution
    (max-norms; a contraction of about :math:`\kappa\varepsilon` per step: converges while that is below
    one; the solution is then its exact value to a few units of roundoff of its largest entry), and
    :math:`L x` summed exactly. Small models only (a dense matrix of order n1 + n2)."""
    import math

    n1, n2 = fom.n1, fom.n2
    M, D, K = (np.asarray(X.toarray() if hasattr(X, "toarray") else X) for X in (fom.M, fom.D, fom.K))
    G = fom.G.toarray() if hasattr(fom.G, "toarray") else np.asarray(fom.G).reshape(n2, n1)
    S = np.zeros((n1 + n2, n1 + n2), dtype=complex)
    S[:n1, :n1] = K - omega * omega * M + 1j * omega * D
    S[:n1, n1:], S[n1:, :n1] = G.T, G
    lu = sla.lu_factor(S)
    F = np.asarray(fom.F.toarray() if hasattr(fom.F, "toarray") else fom.F, dtype=float)
    B = np.vstack([F, np.zeros((n2, F.shape[1]))]).astype(complex)
    X = sla.lu_solve(lu, B)
    for _ in range(steps):
        R = np.column_stack([exact_saddle_residual(fom, omega, X[:n1, j], X[n1:, j], B[:n1, j])
                             for j in range(B.shape[1])])
        dX = sla.lu_solve(lu, R)
        X = X + dX
        if np.max(np.abs(dX)) <= EPS * np.max(np.abs(X)):
            break
    else:
        raise AssertionError(f"the reference's refinement did not converge at omega = {omega}")
    L = np.asarray(fom.L.toarray() if hasattr(fom.L, "toarray") else fom.L, dtype=float)
    T = np.empty((L.shape[0], B.shape[1]), dtype=complex)
    for i in range(L.shape[0]):
        for j in range(B.shape[1]):
            re = _expand([L[i], X[:n1, j].real])
            im = _expand([L[i], X[:n1, j].imag])
            T[i, j] = math.fsum(np.concatenate(re)) + 1j * math.fsum(np.concatenate(im))
    return T
