r"""Dense standard realization of the model (and of an error system) on the hidden manifold.

With an orthonormal basis :math:`N` of :math:`\ker G` (the last :math:`n_1 - n_2` columns of
a full QR factorization of :math:`G^T`), :math:`x = Nq` and :math:`\hat M = N^TMN = R_MR_M^T`
(Cholesky), the coordinates :math:`w = [q;\ R_M^T\dot q]` give

.. math::

    A_1 = \begin{bmatrix} 0 & R_M^{-T} \\ -R_M^{-1}N^TKN & -R_M^{-1}N^TDNR_M^{-T}\end{bmatrix},\quad
    B_1 = \begin{bmatrix} 0 \\ R_M^{-1}N^TF \end{bmatrix},\quad
    C_1 = \begin{bmatrix} LN & 0 \end{bmatrix},

the first-order form :math:`E = \mathrm{blkdiag}(I, \hat M)` made standard without
inverting :math:`\hat M`. The error system stacks the reduced model's
:math:`(E_r^{-1}A_r, E_r^{-1}B_r, C_r, D_r)` with the output :math:`C_1w - C_rw_r` and
feedthrough :math:`-D_r`. Cost: :math:`O(n_1^2 n_2 + n_1^2(n_1 - n_2))` flops and
:math:`(2(n_1 - n_2))^2` doubles, kept in ``fom.cache`` (the model's part only).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

__all__ = ["hidden_realization", "error_realization"]


def hidden_realization(fom):
    """(A, B, C, D) of the model on its hidden manifold (module docstring), cached in ``fom.cache``."""
    cache = getattr(fom, "cache", None)
    key = ("hidden_realization",)
    if cache is not None and key in cache:
        return cache[key]
    n1, n2 = fom.n1, fom.n2
    if n2:
        Q, _ = sla.qr(fom.G.toarray().T, mode="full")
        N = Q[:, n2:]
    else:
        N = np.eye(n1)
    Mk, Dk, Kk = (N.T @ (X @ N) for X in (fom.M, fom.D, fom.K))
    Rm = np.linalg.cholesky(0.5 * (Mk + Mk.T))
    k = N.shape[1]
    solve = lambda X, trans=0: sla.solve_triangular(Rm, X, lower=True, trans=trans)  # noqa: E731
    RiK = solve(Kk)
    RiDRt = solve(solve(Dk).T).T  # R^-1 D R^-T (D symmetric or not: row-wise then column-wise)
    Rt_inv = solve(np.eye(k), trans=1)  # R^-T
    A = np.block([[np.zeros((k, k)), Rt_inv], [-RiK, -RiDRt]])
    B = np.vstack([np.zeros((k, fom.m)), solve(N.T @ fom.F)])
    C = np.hstack([fom.L @ N, np.zeros((fom.p, k))])
    out = (A, B, C, np.zeros((fom.p, fom.m)))
    if cache is not None:
        cache[key] = out
    return out


def error_realization(fom, arrays):
    """(A, B, C, D) of :math:`T - T_r` for the reduced model's first-order ``arrays`` (E, A, B, C, D)."""
    A1, B1, C1, _ = hidden_realization(fom)
    E, Ar, Br, Cr, Dr = arrays
    Ar, Br = np.linalg.solve(E, Ar), np.linalg.solve(E, Br)
    return sla.block_diag(A1, Ar), np.vstack([B1, Br]), np.hstack([C1, -Cr]), -np.asarray(Dr, dtype=float)
