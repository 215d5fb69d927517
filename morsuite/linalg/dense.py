r"""Small dense kernels: balanced truncation, orthonormal bases, shift and set matching, sigma_max.

Used on r x r and 2r x 2r matrices only (the IRKA shift update, the BT of the
reduced first-order realization).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
from scipy.optimize import linear_sum_assignment
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import maximum_bipartite_matching

from ..errors import InputError, MorsuiteError

__all__ = ["dense_bt", "orth", "cholesky_qr2", "right_solve", "shift_distance", "match_sets", "lyap_factor", "sigma_max",
           "BTResult", "UnstableError"]


class UnstableError(MorsuiteError, ArithmeticError):
    """Balanced truncation of a model with poles in the closed right half-plane."""


class BTResult:
    """Reduced standard realization (A, B, C) with E = I, and the Hankel singular values."""

    def __init__(self, A, B, C, hsv, Tl, Tr):
        self.A, self.B, self.C, self.hsv, self.Tl, self.Tr = A, B, C, hsv, Tl, Tr

    @property
    def order(self):
        """Number of states of the reduced realization, ``A.shape[0]``."""
        return self.A.shape[0]

    def bound(self) -> float:
        """The a-priori H-infinity error bound 2 * sum of the discarded HSVs."""
        return 2.0 * float(np.sum(self.hsv[self.order:]))


def lyap_factor(X: np.ndarray) -> np.ndarray:
    """A factor S with S S^T = X for a symmetric positive semidefinite X (eigh, negatives clipped)."""
    X = 0.5 * (X + X.T)
    w, U = np.linalg.eigh(X)
    w = np.clip(w, 0.0, None)
    keep = w > 0
    return U[:, keep] * np.sqrt(w[keep])


def dense_bt(E, A, B, C, order: int | None = None, *, hsv_tol: float = 0.0) -> BTResult:
    r"""Square-root balanced truncation of a small stable descriptor system (E nonsingular).

    Solves :math:`A_s P + P A_s^T + B_s B_s^T = 0` and
    :math:`A_s^T Q + Q A_s + C^T C = 0` for :math:`A_s = E^{-1}A`,
    :math:`B_s = E^{-1}B` (Bartels-Stewart), factors :math:`P = S S^T`,
    :math:`Q = R R^T`, and truncates the SVD of :math:`R^T S` (the Hankel
    singular values).

    Parameters
    ----------
    order : int, optional
        Reduced order; None keeps every HSV above ``hsv_tol * hsv[0]``.
    hsv_tol : float
        Relative floor on the kept HSVs: the order is capped so that no kept
        HSV is below it (tiny HSVs make the balancing transformation blow up).

    Raises
    ------
    UnstableError
        If :math:`(A, E)` has an eigenvalue with nonnegative real part.
    """
    E = np.eye(A.shape[0]) if E is None else E
    As = np.linalg.solve(E, A)
    Bs = np.linalg.solve(E, B)
    lam = np.linalg.eigvals(As)
    if lam.size and np.max(lam.real) >= 0:
        raise UnstableError(f"dense_bt: the system has an eigenvalue with real part {np.max(lam.real):.3e} >= 0")
    P = sla.solve_continuous_lyapunov(As, -Bs @ Bs.T)
    Q = sla.solve_continuous_lyapunov(As.T, -C.T @ C)
    S, R = lyap_factor(P), lyap_factor(Q)
    U, hsv, Vt = np.linalg.svd(R.T @ S, full_matrices=False)
    n_pos = int(np.sum(hsv > max(hsv_tol, np.finfo(float).eps) * (hsv[0] if hsv.size else 0)))
    k = n_pos if order is None else min(int(order), n_pos)
    if order is not None and int(order) < 0:
        raise InputError(f"order must be >= 0; got {order}")
    sq = np.sqrt(hsv[:k])
    Tl = R @ U[:, :k] / sq
    Tr = S @ Vt[:k].T / sq
    return BTResult(Tl.T @ As @ Tr, Tl.T @ Bs, C @ Tr, hsv, Tl, Tr)


def orth(X: np.ndarray, rank_tol: float = 1e-12, max_rank: int | None = None, method: str = "auto",
         ill_tol: float | None = None):
    """Orthonormal basis of the numerical range of X (columns scaled to unit norm first).

    Returns (Q, s): Q has the leading left singular vectors whose singular
    values exceed ``rank_tol * s[0]`` (at most ``max_rank``), s all singular values.
    Q is Fortran-ordered for a tall real X.

    ``method``: ``"householder"`` (QR, then the SVD of R) or ``"auto"``: two
    Cholesky-QR passes (:func:`cholesky_qr2`) when the scaled X has relative
    singular values above 1e-6, where they give an orthonormal factor to
    rounding, else Householder. BLAS-3 instead of the BLAS-2 of Householder on a
    tall, thin matrix: measured 1.7 ms against 5.0 ms for 6001 x 20 on one thread.
    ``ill_tol``: when given and the smallest kept singular value is below
    ``ill_tol * s[0]``, Q is None and not formed (the caller wants another method then).
    For a tall real X the Householder QR is LAPACK's geqrf, the orthonormal factor
    (orgqr) formed only when it is returned: numpy.linalg.qr took 5x their time on
    2e5 x 10 (docs/design/irka.md).
    """
    if method not in ("auto", "householder"):
        raise InputError(f"method must be 'auto' or 'householder'; got {method!r}")
    tall = 0 < X.shape[1] and X.shape[0] > 4 * X.shape[1]
    if method == "auto" and tall and not np.iscomplexobj(X):
        U, s = _orth_cholesky(X, rank_tol, max_rank)
        if s is not None:
            return (None, s) if _ill(s, _kept(s, rank_tol, max_rank), ill_tol) else (U, s)
    norms = np.linalg.norm(X, axis=0)
    norms[norms == 0] = 1.0
    if tall and not np.iscomplexobj(X):
        return _orth_householder(X, norms, rank_tol, max_rank, ill_tol)
    Xn = X / norms
    if tall:
        Q0, R0 = np.linalg.qr(Xn)
        U, s, _ = np.linalg.svd(R0)
        U = Q0 @ U
    else:
        U, s, _ = np.linalg.svd(Xn, full_matrices=False)
    k = _kept(s, rank_tol, max_rank)
    return (None, s) if _ill(s, k, ill_tol) else (U[:, :k], s)


def _ill(s, k, ill_tol):
    """Whether the k-th singular value is below ill_tol * s[0] (ill_tol None: never)."""
    return ill_tol is not None and k > 0 and s[k - 1] < ill_tol * s[0]


def _orth_householder(X, norms, rank_tol, max_rank, ill_tol):
    """(U, s) of :func:`orth` for a tall real X by LAPACK geqrf on the scaled X, the SVD of R,
    and (unless ill, see ``ill_tol``) orgqr and U = Q0 Ur for the kept columns only."""
    geqrf, orgqr = sla.get_lapack_funcs(("geqrf", "orgqr"), (X,))
    Xn = np.array(X, order="F", dtype=float)
    Xn /= norms
    qr, tau, _, info = geqrf(Xn, overwrite_a=1)
    if info != 0:  # pragma: no cover - LAPACK argument error
        raise np.linalg.LinAlgError(f"geqrf failed (info {info})")
    Ur, s, _ = np.linalg.svd(np.triu(qr[:X.shape[1]]))
    k = _kept(s, rank_tol, max_rank)
    if _ill(s, k, ill_tol):
        return None, s
    Q0, _, info = orgqr(qr, tau, overwrite_a=1)
    if info != 0:  # pragma: no cover - LAPACK argument error
        raise np.linalg.LinAlgError(f"orgqr failed (info {info})")
    return Q0 @ Ur[:, :k], s


def _kept(s, rank_tol, max_rank):
    """The number of singular values s above rank_tol * s[0], at most max_rank."""
    k = int(np.sum(s > rank_tol * s[0])) if s.size and s[0] > 0 else 0
    return k if max_rank is None else min(k, max_rank)


def _orth_cholesky(X, rank_tol, max_rank):
    """(U, s) of :func:`orth` by two Cholesky-QR passes on the unit-scaled X, or (None, None) when
    a pass fails or the relative singular values reach 1e-6. Four passes over X: its Gram
    matrix (the column norms are its diagonal, the scaled X is never formed), Q1 = X (R1 D)^-1,
    the Gram matrix of Q1, and U = Q1 (R2^-1 Ur) for the kept columns only."""
    G = X.T @ X
    norms = np.sqrt(np.diag(G)).copy()
    norms[norms == 0] = 1.0
    try:
        R1 = np.linalg.cholesky(G / np.outer(norms, norms)).T
        d = np.abs(np.diag(R1))
        if not d.min() > 1e-6 * d.max():
            return None, None
        Q1 = right_solve(X, R1 * norms)  # X D^-1 R1^-1
        R2 = np.linalg.cholesky(Q1.T @ Q1).T
    except np.linalg.LinAlgError:
        return None, None
    Ur, s, _ = np.linalg.svd(R2 @ R1)
    if not s[-1] > 1e-6 * s[0]:
        return None, None
    k = _kept(s, rank_tol, max_rank)
    return Q1 @ sla.solve_triangular(R2, Ur[:, :k], check_finite=False), s


def right_solve(X, R):
    r"""The product :math:`X R^{-1}` for an upper triangular R, by one triangular solve.

    Parameters
    ----------
    X : ndarray, shape (n, k)
        Real or complex; not modified.
    R : ndarray, shape (k, k)
        Upper triangular, nonsingular (its strictly lower part is not read).

    Returns
    -------
    ndarray, shape (n, k), Fortran order

    Notes
    -----
    BLAS ``trsm`` (side right) in place on a Fortran-ordered copy of X: one pass to copy X
    and one to solve, :math:`n k^2` flops; ``scipy.linalg.solve_triangular(R, X.T, trans="T")``
    transposes X on the way in and out.
    """
    trsm = sla.get_blas_funcs("trsm", (R, X))
    return trsm(1.0, np.asfortranarray(R), np.array(X, order="F"), side=1, lower=0, trans_a=0,
                overwrite_b=True)


def cholesky_qr2(X, min_diag=0.0):
    """X = Q R by two Cholesky-QR passes (Q orthonormal to rounding for cond(X) up to
    about 1e6). Raises LinAlgError when a Cholesky factorization fails or, in the
    first pass, a diagonal entry of R is at most ``min_diag`` times the largest."""
    R1 = np.linalg.cholesky(X.T @ X).T
    d = np.abs(np.diag(R1))
    if not d.min() > min_diag * d.max():
        raise np.linalg.LinAlgError("ill-conditioned")
    Q = right_solve(X, R1)
    R2 = np.linalg.cholesky(Q.T @ Q).T
    trsm = sla.get_blas_funcs("trsm", (R2, Q))
    Q = trsm(1.0, np.asfortranarray(R2), Q, side=1, lower=0, trans_a=0, overwrite_b=True)  # Q is ours
    return Q, R2 @ R1


def shift_distance(new, old) -> float:
    """Largest relative distance between two shift sets after optimal matching.

    Sets of different sizes are compared on the best-matched common part, and
    the distance is then at least 1 (they are not the same set).
    """
    new, old = np.asarray(new, dtype=complex), np.asarray(old, dtype=complex)
    if new.size == 0 or old.size == 0:
        return np.inf
    if not (np.all(np.isfinite(new)) and np.all(np.isfinite(old))):
        return np.inf
    scale = np.maximum(np.maximum(np.abs(new)[:, None], np.abs(old)[None, :]), np.finfo(float).tiny)
    cost = np.abs(new[:, None] - old[None, :]) / scale
    i, j = linear_sum_assignment(cost)
    d = float(cost[i, j].max())
    return d if new.size == old.size else max(d, 1.0)


def sigma_max(H) -> np.ndarray:
    """Largest singular value of each matrix of a response array.

    Parameters
    ----------
    H : array_like, shape (k, p, m) or (p, m)

    Returns
    -------
    ndarray, shape (k,) (or a scalar for one matrix)
    """
    H = np.asarray(H)
    if H.ndim == 2:
        return float(np.linalg.norm(H, 2))
    if H.ndim != 3:
        raise InputError(f"H must have shape (k, p, m) or (p, m); got {H.shape}")
    if min(H.shape[1:]) == 1:
        return np.sqrt(np.sum(np.abs(H) ** 2, axis=(1, 2)))
    return np.linalg.svd(H, compute_uv=False)[:, 0]


def match_sets(a, b, scale=None):
    r"""Optimal one-to-one matching of two sets of numbers (eigenvalues, poles, shifts, HSVs).

    With the normalized distances :math:`d_{ij} = |a_i - b_j| / s_{ij}`, finds the
    permutation :math:`p` that minimizes the largest :math:`d_{i p_i}` (a bottleneck
    assignment) and, among those, their sum (:func:`scipy.optimize.linear_sum_assignment`).
    The bottleneck comes first because it decides whether the sets agree within a
    tolerance: a minimal sum can trade one large mismatch for several small ones.

    The cost is invariant under conjugating both sets, so when both are closed under
    conjugation a unique optimum maps each conjugate pair onto a conjugate pair; unlike
    sorting, the result does not depend on the last bits of real parts that are equal in
    exact arithmetic (``np.sort_complex`` orders a computed pair by its rounding).

    Parameters
    ----------
    a, b : array_like
        The two sets, 1-D, of equal size, finite, real or complex.
    scale : None, "relative" or array_like, optional
        :math:`s_{ij}`: None gives absolute distances (:math:`s = 1`); ``"relative"``
        gives :math:`\max(|a_i|, |b_j|)`, as :func:`shift_distance`; an array of
        ``len(b)`` nonnegative entries gives :math:`s_{ij} = s_j`, a tolerance per element
        of ``b`` (then the sets agree to it iff ``dist.max() <= 1``). A zero scale counts
        only an exact match.

    Returns
    -------
    perm : ndarray of int
        ``b[perm]`` is matched with ``a`` element by element.
    dist : ndarray of float
        :math:`d_{i p_i}`, the normalized distance of each matched pair, in the order of ``a``.

    Raises
    ------
    InputError
        If ``a`` or ``b`` is not 1-D or not finite, their sizes differ, or ``scale`` is
        neither None, ``"relative"`` nor a nonnegative array of ``len(b)`` entries.

    Notes
    -----
    Cost: :math:`O(n^3)` for the assignment and :math:`O(n^2 \log n)` bipartite matchings
    for the bottleneck search; meant for the r to a few hundred values a reduced model has.
    """
    a, b = (np.asarray(x) for x in (a, b))
    for name, x in (("a", a), ("b", b)):
        if x.ndim != 1 or not np.issubdtype(x.dtype, np.number):
            raise InputError(f"match_sets: {name} must be a 1-D numeric array; got shape {x.shape}, dtype {x.dtype}")
        if not np.all(np.isfinite(x)):
            raise InputError(f"match_sets: {name} has non-finite entries")
    if a.size != b.size:
        raise InputError(f"match_sets: a and b must have the same size; got {a.size} and {b.size}")
    diff = np.abs(a[:, None] - b[None, :])
    if scale is None:
        s = np.ones_like(diff)
    elif isinstance(scale, str) and scale == "relative":
        s = np.maximum(np.abs(a)[:, None], np.abs(b)[None, :])
    else:
        try:
            s = np.asarray(scale, dtype=float)
        except (TypeError, ValueError):
            s = None
        if s is None or s.shape != b.shape or not np.all(s >= 0):
            raise InputError(f"match_sets: scale must be None, 'relative' or {b.size} nonnegative numbers "
                             f"(one per element of b); got {scale!r}")
        s = np.broadcast_to(s[None, :], diff.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        cost = np.where(diff == 0, 0.0, diff / s)  # 0/0: an exact match; x/0: inf
    if a.size == 0:
        return np.zeros(0, dtype=int), np.zeros(0)
    # the smallest threshold that still admits a perfect matching (bisection over the cost values)
    levels = np.unique(cost)
    lo, hi = 0, levels.size - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if np.all(maximum_bipartite_matching(csr_matrix(cost <= levels[mid]), perm_type="column") >= 0):
            hi = mid
        else:
            lo = mid + 1
    bottleneck = levels[lo]
    finite = cost[np.isfinite(cost)]
    # entries above the bottleneck are forbidden by a cost larger than any admissible sum
    big = (a.size + 1.0) * (finite.max() if finite.size else 1.0) + 1.0
    capped = np.where(cost <= bottleneck, np.where(np.isfinite(cost), cost, big), 2 * big)
    i, j = linear_sum_assignment(capped)
    perm = np.empty(a.size, dtype=int)
    perm[i] = j
    return perm, cost[np.arange(a.size), perm]
