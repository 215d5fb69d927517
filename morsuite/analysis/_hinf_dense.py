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

Modal truncation with a bound (``budget > 0``, :math:`n_1 - n_2 \ge` :data:`MODAL_MIN`). With
the eigendecomposition :math:`A_1 = V\Lambda V^{-1}` (computed once per model, cached), the
model is the sum of its modes, :math:`T(s) = \sum_i C_1v_i\,w_i^HB_1/(s - \lambda_i)`
(:math:`w_i^H` the rows of :math:`V^{-1}`), and dropping a set :math:`\mathcal D` of modes
(closed under conjugation) changes it by at most

.. math::

    \delta = \sum_{i \in \mathcal D} \frac{\|C_1v_i\|\,\|w_i^HB_1\|}{|\mathrm{Re}\,\lambda_i|}
    \;\ge\; \|T - \hat T\|_{\mathcal H_\infty}.

The modes with the smallest terms are dropped while :math:`\delta \le` ``budget``; the kept
ones are realized in real modal form (a conjugate pair :math:`a \pm jb` as the block
:math:`[a, b; -b, a]` on :math:`[\mathrm{Re}\,v, \mathrm{Im}\,v]`). On the TCOM and the DSMS
about half the modes have residues at the rounding level (symmetric structures a single
input does not excite), so the level-set test's eigenvalue problem shrinks about
:math:`2^3`-fold. Not used where :math:`\kappa_1(V) >` :data:`MODAL_COND` (the modal form's
rounding would exceed the certificate's resolution) or where it would keep more than 90%
of the order. Cost: one dense eigendecomposition of order :math:`2(n_1 - n_2)` with
eigenvectors and one inverse, once per model.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

__all__ = ["hidden_realization", "error_realization", "MODAL_MIN", "MODAL_COND"]

#: smallest n1 - n2 for which the modal truncation is tried (below it the full test is cheap)
MODAL_MIN = 150
#: largest condition number kappa_1 of the eigenvector matrix for which the modal form is used
MODAL_COND = 1e4


def _full(fom):
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


def _modes(fom):
    """The model's modes on the hidden manifold, cached: None where the modal form is not used, else a
    dict with the real modal realization of every mode (``A`` block diagonal, ``B``, ``C``), ``units``
    (the index lists of a real eigenvalue or a conjugate pair), their bound terms, ``cond`` and ``time_s``."""
    cache = getattr(fom, "cache", None)
    key = ("hidden_modes",)
    if cache is not None and key in cache:
        return cache[key]
    t0 = time.perf_counter()
    A, B, C, _ = _full(fom)
    lam, V = sla.eig(A, check_finite=False)
    out = None
    try:
        W = np.linalg.inv(V)  # rows: left eigenvectors w_i^H with w_i^H v_j = delta_ij
        cond = float(np.linalg.norm(V, 1) * np.linalg.norm(W, 1))  # kappa_1(V), within a factor n of kappa_2
    except np.linalg.LinAlgError:  # a defective A
        cond = np.inf
    if np.isfinite(cond) and cond <= MODAL_COND:
        n = lam.size
        X, Yt, Ar = np.empty((n, n)), np.empty((n, n)), sp.lil_matrix((n, n))
        units, terms = [], []
        i = 0
        while i < n:
            a, b = lam[i].real, lam[i].imag
            term = np.linalg.norm(C @ V[:, i]) * np.linalg.norm(W[i] @ B) / abs(a) if a != 0 else np.inf
            if b != 0 and not (i + 1 < n and lam[i + 1] == np.conj(lam[i])):
                break  # LAPACK returns a conjugate pair together, the positive imaginary part first
            if b != 0:
                # A [Re v, Im v] = [Re v, Im v] [a, b; -b, a];
                # the projector v w^H + its conjugate = [Re v, Im v] [2 Re w^H; -2 Im w^H]
                X[:, i], X[:, i + 1] = V[:, i].real, V[:, i].imag
                Yt[i], Yt[i + 1] = 2.0 * W[i].real, -2.0 * W[i].imag
                Ar[i, i], Ar[i, i + 1], Ar[i + 1, i], Ar[i + 1, i + 1] = a, b, -b, a
                units.append([i, i + 1])
                terms.append(2.0 * term)
                i += 2
            else:
                X[:, i], Yt[i], Ar[i, i] = V[:, i].real, W[i].real, a
                units.append([i])
                terms.append(term)
                i += 1
        if i == n:
            out = {"A": Ar.tocsr(), "B": Yt @ B, "C": C @ X, "units": units, "terms": np.array(terms), "cond": cond}
    if out is not None:
        out["time_s"] = time.perf_counter() - t0
    if cache is not None:
        cache[key] = out
    return out


def hidden_realization(fom, budget: float = 0.0):
    r"""``(A, B, C, D, delta, info)``: the model on its hidden manifold (module docstring), full
    (``delta = 0``) or, with ``budget > 0`` where it pays, modally truncated with
    :math:`\|T - \hat T\|_{\mathcal H_\infty} \le \delta \le` ``budget``; ``info`` records the
    truncation (None where the full realization is returned)."""
    full = _full(fom)
    k = fom.n1 - fom.n2
    if not budget > 0 or k < MODAL_MIN:
        return (*full, 0.0, None)
    modes = _modes(fom)
    if modes is None:
        return (*full, 0.0, {"modal": False, "reason": f"eigenvector condition number above {MODAL_COND:.0e}"})
    terms = modes["terms"]
    order = np.argsort(terms, kind="stable")
    spent = np.cumsum(terms[order])
    drop = order[: int(np.searchsorted(spent, budget, side="right"))]
    delta = float(spent[drop.size - 1]) if drop.size else 0.0
    dropped = set(drop.tolist())
    keep = np.array(sorted(j for u, idx in enumerate(modes["units"]) if u not in dropped for j in idx), dtype=int)
    n = full[0].shape[0]
    info = {"modal": True, "kept": int(keep.size), "of": n, "bound": delta, "cond": modes["cond"],
            "modal_s": modes["time_s"]}
    if keep.size > 0.9 * n:
        info.update(modal=False, reason="the truncation would keep more than 90% of the order")
        return (*full, 0.0, info)
    return (modes["A"][keep][:, keep].toarray(), modes["B"][keep], modes["C"][:, keep], full[3], delta, info)


def error_realization(fom, arrays, budget: float = 0.0):
    """``(A, B, C, D, delta, info)`` of :math:`T - T_r` for the reduced model's first-order ``arrays``
    (E, A, B, C, D), the model's part as :func:`hidden_realization` gives it for ``budget``."""
    A1, B1, C1, _, delta, info = hidden_realization(fom, budget)
    E, Ar, Br, Cr, Dr = arrays
    Ar, Br = np.linalg.solve(E, Ar), np.linalg.solve(E, Br)
    return (sla.block_diag(A1, Ar), np.vstack([B1, Br]), np.hstack([C1, -Cr]), -np.asarray(Dr, dtype=float),
            delta, info)
