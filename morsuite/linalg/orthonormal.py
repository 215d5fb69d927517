r"""Orthonormal bases of tall n x k blocks by column-pivoted Gram-Schmidt.

:func:`gram_schmidt` returns an orthonormal basis :math:`Q` of the numerical
range of :math:`X` by modified Gram-Schmidt with one reorthogonalisation of
every accepted vector, in pivoted (rank-revealing) or given column order.
Unlike Householder QR (:func:`~morsuite.linalg.dense.orth`) it keeps the
rounding of each entry relative to the entries it combines, which matters for
localised columns (entries spanning many orders of magnitude). Cost
:math:`O(n k^2)` flops, level-2 BLAS. Why IRKA uses it: ``docs/design/irka.md``.
"""

from __future__ import annotations

import numpy as np

from . import kernels

__all__ = ["gram_schmidt"]


def gram_schmidt(X, rank_tol, pivot=True):
    r"""Orthonormal basis of the numerical range of X by modified Gram-Schmidt.

    Columns are scaled to unit norm; at each step the remaining column with the
    largest residual norm is accepted unless that norm is at most ``rank_tol``
    (``pivot=False``: the columns in their order, dropping those whose residual
    is at most ``rank_tol``). Every accepted vector is orthogonalised once more
    against the accepted ones (:math:`q \leftarrow q - Q (Q^T q)`).

    Parameters
    ----------
    X : ndarray, shape (n, k)
    rank_tol : float
        Residual norm (of the unit-scaled columns) at or below which a column is
        taken as dependent.
    pivot : bool, default True
        Column pivoting by largest residual; False keeps the column order.

    Returns
    -------
    Q : ndarray, shape (n, j)
        Orthonormal columns, j <= k.
    s : ndarray, shape (j,)
        Residual norms of the accepted columns (a rank-revealing stand-in for the
        singular values).
    """
    n, k = X.shape
    if k == 0:
        return X[:, :0].copy(), np.zeros(0)
    norms = np.linalg.norm(X, axis=0)
    norms[norms == 0] = 1.0
    R = np.asfortranarray(X / norms)  # columns m: are the residuals still to be taken
    Q = np.empty((n, k), order="F")
    tmp = np.empty(n)
    s = []
    m = 0
    while m < k:
        res = np.sqrt(np.einsum("ij,ij->j", R[:, m:k], R[:, m:k]))
        j = m + int(np.argmax(res)) if pivot else m
        rj = res[j - m]
        if rj <= rank_tol:
            if pivot:
                break
            R[:, m:k - 1] = R[:, m + 1:k].copy()  # drop column m, keep the order of the rest
            k -= 1
            continue
        if j != m:
            R[:, [m, j]] = R[:, [j, m]]
        q = R[:, m] / rj
        q -= Q[:, :m] @ (Q[:, :m].T @ q)  # the reorthogonalisation
        q /= np.linalg.norm(q)
        Q[:, m] = q
        s.append(rj)
        m += 1
        if m < k:
            _remove_direction(R, q, m, k, tmp)
    return Q[:, :m], np.asarray(s)


def _remove_direction(R, q, m, k, tmp):
    """R[:, m:k] -= outer(q, q @ R[:, m:k]), a column at a time: the same products and
    differences as with np.outer, bit for bit (tested), without the n x (k - m) temporary;
    compiled (one pass over each column, ``_update_columns``) when numba is there."""
    c = q @ R[:, m:k]
    if R.flags.f_contiguous and R.dtype == np.float64 and kernels.use_kernels():
        kernels.compiled(_update_columns)(R, q, c, m, k)
        return
    for j in range(m, k):
        np.multiply(q, c[j - m], out=tmp)
        np.subtract(R[:, j], tmp, out=R[:, j])


def _update_columns(R, q, c, m, k):
    """R[i, j] = R[i, j] - q[i] * c[j - m] for j in m..k-1: a product rounded, then a difference
    rounded (no fused multiply-add: numba compiles without fastmath), as numpy does it."""
    n = R.shape[0]
    for j in range(m, k):
        cj = c[j - m]
        for i in range(n):
            R[i, j] = R[i, j] - q[i] * cj

