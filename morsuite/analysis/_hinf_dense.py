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
the eigendecomposition :math:`A_1V = V\Lambda`, :math:`W \approx V^{-1}` (computed once per model,
cached), the model is the sum of its modes, :math:`T(s) = \sum_i C_1v_i\,w_i^HB_1/(s - \lambda_i)`
(:math:`w_i^H` the rows of :math:`W`), and dropping a set :math:`\mathcal D` of modes (closed under
conjugation) changes that sum by at most

.. math::

    \delta = \sum_{i \in \mathcal D} \frac{\|C_1v_i\|\,\|w_i^HB_1\|}{|\mathrm{Re}\,\lambda_i|}.

The modal form is not the model: :math:`V`, :math:`\Lambda` and :math:`W` are rounded (issue 45: on
tcom(100), :math:`\kappa_1(V) = 1.4\cdot10^3`, the kept modes differed from :math:`(A_1, B_1, C_1)` by
1.3e-7 where :math:`\delta` was 1e-22). Its deviation is bounded a posteriori: with the residuals
:math:`R = A_1V - V\Lambda`, :math:`E = VW - I` (exact identities, no approximation),

.. math::

    T - \hat T_{\rm all} = C_1(sI - A_1)^{-1}\bigl[EB_1 - R(sI - \Lambda)^{-1}WB_1\bigr],\qquad
    C_1(sI - A_1)^{-1}\bigl[I + E - R(sI - \Lambda)^{-1}W\bigr] = C_1V(sI - \Lambda)^{-1}W,

so that on a frequency interval :math:`J`, with :math:`d_i = \mathrm{dist}(\lambda_i, jJ)`,

.. math::

    \sup_{\omega \in J}\|T - \hat T_{\rm all}\| \le
    \frac{\sum_i \|C_1v_i\|\|w_i\|/d_i}{1 - \|E\| - \sum_i \|r_i\|\|w_i\|/d_i}
    \Bigl(\|EB_1\| + \sum_i \frac{\|r_i\|\,\|w_i^HB_1\|}{d_i}\Bigr)

where the denominator is positive. :math:`\|r_i\|`, :math:`\|E\|` and :math:`\|EB_1\|` are the computed
values plus the rounding bounds of their computation (:math:`\gamma_{n+2}|A_1||V|`,
:math:`\gamma_{n+2}|V||W|`, Higham's :math:`\gamma_k = k\varepsilon/(1 - k\varepsilon)`), so the bound holds
for the exact residuals; the products :math:`C_1X`, :math:`YB_1` that make the real modal form add
:math:`\gamma_n` terms per mode. The supremum is taken over a partition of :math:`[0, \infty)` into
intervals graded around every :math:`|\mathrm{Im}\,\lambda_i|` (widths :math:`|\mathrm{Re}\,\lambda_i|/4`
to :math:`2^{11}|\mathrm{Re}\,\lambda_i|`), so it is a bound, not a sample. This rounding bound
:math:`\Delta` is a constant of the model (``info["rounding"]``). Dropping modes stops where
:math:`\delta + \Delta` would exceed ``budget``; where :math:`\Delta` alone exceeds it (the bound is
conservative: :math:`\gamma_n` rounding terms, sums over all modes), the full realization is returned.
On the TCOM and the DSMS about half the modes have residues at the rounding level (symmetric
structures a single input does not excite), so where the modal form is used the level-set test's
eigenvalue problem shrinks about :math:`2^3`-fold. Not used either where :math:`\kappa_1(V) >`
:data:`MODAL_COND` or where it would keep more than 90% of the order. Cost: one dense
eigendecomposition of order :math:`2(n_1 - n_2)` with eigenvectors, one inverse and four products of
that order for the residuals, once per model.

:func:`realization_response` evaluates a realization returned here at given frequencies (the
certificate compares it with the sparse model's samples: :mod:`morsuite.analysis._hinf_certify`).
With a reduced model, the realization's :math:`E_r^{-1}` (a dense solve, skipped where
:math:`E_r = I`) is not bounded here; that comparison measures it with the rest.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

__all__ = ["hidden_realization", "error_realization", "realization_response", "modal_form", "truncate",
           "MODAL_MIN", "MODAL_COND"]

EPS = np.finfo(float).eps

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


def _gamma(k: int) -> float:
    """Higham's :math:`\\gamma_k = k\\varepsilon / (1 - k\\varepsilon)`: the rounding bound of a k-term dot product."""
    return k * EPS / (1.0 - k * EPS)


def _graded_partition(lam) -> np.ndarray:
    """Break points of a partition of [0, hi] graded around every :math:`|\\mathrm{Im}\\,\\lambda|` (widths
    :math:`|\\mathrm{Re}\\,\\lambda|/4` near it, doubling outward), with a log grid; hi = 10 max|lambda|."""
    rho, nu = np.abs(lam.real), np.abs(lam.imag)
    hi = 10.0 * float(np.abs(lam).max())
    steps = np.concatenate([[0.0, 0.25, 0.5, 0.75], 2.0 ** np.arange(12)])
    steps = np.concatenate([-steps[:0:-1], steps])
    low = max(float(np.abs(lam).min()) * 1e-3, hi * 1e-12)
    pts = np.concatenate([[0.0, hi], np.logspace(np.log10(low), np.log10(hi), 200),
                          (nu[:, None] + rho[:, None] * steps[None, :]).ravel()])
    return np.unique(pts[(pts >= 0) & (pts <= hi)])


def _sup_on_partition(lam, points, fn, chunk=1024) -> float:
    """:math:`\\sup_{\\omega \\ge 0}` of a bound ``fn(inv_d)`` that grows with each :math:`1/|j\\omega - \\lambda_i|`:
    on each interval :math:`J` of the partition ``points`` (and :math:`[hi, \\infty)`), ``inv_d`` holds
    :math:`1/\\mathrm{dist}(\\lambda_i, jJ)`; the largest value over the intervals."""
    rho, nu = np.abs(lam.real), lam.imag
    a, b = points[:-1], points[1:]
    best = 0.0
    for i0 in range(0, a.size, chunk):
        aa, bb = a[i0:i0 + chunk, None], b[i0:i0 + chunk, None]
        off = np.maximum(0.0, np.maximum(aa - nu[None, :], nu[None, :] - bb))
        best = max(best, float(np.max(fn(1.0 / np.hypot(rho[None, :], off)))))
    tail = np.maximum(0.0, points[-1] - nu)  # [hi, inf): every eigenvalue lies below hi
    return max(best, float(np.max(fn(1.0 / np.hypot(rho, tail)[None, :]))))


def _split(X, t, axis):
    r"""``(X1, X2)`` with ``X = X1 + X2`` exactly: X1 holds the leading ``t`` bits of X relative to the largest
    entry of its row (``axis=1``) or column (``axis=0``), a power-of-two scale, X2 the rest
    (:math:`|X_2| \le 2^{-t}` that maximum)."""
    big = np.max(np.abs(X), axis=axis, keepdims=True)
    big = np.where(big > 0, big, 1.0)
    unit = np.ldexp(1.0, (np.ceil(np.log2(big)) - t).astype(int))  # a power of two: the scaling is exact
    X1 = np.round(X / unit) * unit
    return X1, X - X1


def _two_sum(a, b):
    """Knuth's error-free sum: ``(s, e)`` with ``s = fl(a + b)`` and ``a + b = s + e`` exactly."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def _two_prod(a, b):
    """Dekker's error-free product: ``(p, e)`` with ``p = fl(ab)`` and ``ab = p + e`` exactly (no FMA)."""
    p = a * b
    c = 134217729.0  # 2^27 + 1
    ah = c * a
    ah = ah - (ah - a)
    bh = c * b
    bh = bh - (bh - b)
    al, bl = a - ah, b - bh
    return p, ((ah * bh - p) + ah * bl + al * bh) + al * bl


def _residual(A, V, lam):
    r"""The eigenvector residual :math:`R = AV - V\Lambda` (complex, n x n) to a few units of its own size
    and a bound of its error per column: :math:`A = A_1 + A_2`, :math:`V = V_1 + V_2` split so that
    :math:`A_1V_1` is exact in double whatever the summation order (:math:`2t + \log_2 n \le 52` bits),
    :math:`A_1V_2 + A_2V` of size :math:`2^{-t}|A||V|` rounded, :math:`V\Lambda` and the cancelling sum
    error-free (Ozaki, Ogita, Oishi and Rump 2012; Dekker; Knuth). Six real products of order n where
    :math:`\gamma_{n+2}(|A||V| + |V||\Lambda|)`, the plain product's rounding bound, was 40x the
    residual at tcom(100)."""
    n = A.shape[0]
    t = int((52 - np.ceil(np.log2(max(n, 2)))) // 2)
    A1, A2 = _split(A, t, axis=1)
    (R1, R2), (I1, I2) = _split(V.real, t, axis=0), _split(V.imag, t, axis=0)
    # (V Lambda): real part Vr lr - Vi li, imaginary part Vr li + Vi lr, each product error-free
    out = []
    for X1, X2, X, (pa, ea), (pb, eb) in (
            (R1, R2, V.real, _two_prod(V.real, lam.real[None, :]), _two_prod(-V.imag, lam.imag[None, :])),
            (I1, I2, V.imag, _two_prod(V.real, lam.imag[None, :]), _two_prod(V.imag, lam.real[None, :]))):
        P = A1 @ X1  # exact
        Q = A1 @ X2 + A2 @ X  # small: |Q| <= 2^(1-t) |A||V| roughly, rounded
        h, l1 = _two_sum(P, -pa)
        h, l2 = _two_sum(h, -pb)
        rest = (l1 + l2 - ea - eb) + Q
        R = h + rest
        # rounding of the six last additions (each at most eps times the sum of the terms' magnitudes) and of
        # Q (gamma_{n+2} |A1||X2| + |A2||X|; the columns' 2-norms bounded through Frobenius norms)
        err = 8.0 * EPS * (np.abs(h) + np.abs(l1) + np.abs(l2) + np.abs(ea) + np.abs(eb) + np.abs(Q))
        qb = _gamma(n + 2) * (np.linalg.norm(A1) * np.linalg.norm(X2, axis=0)
                              + np.linalg.norm(A2) * np.linalg.norm(X, axis=0))
        out.append((R, np.linalg.norm(err, axis=0) + qb))
    (Rr, er), (Ri, ei) = out
    return Rr + 1j * Ri, er + ei


def _rounding_bound(A, B, C, lam, V, W, X, Yt, units):
    r"""Upper bound of :math:`\sup_\omega \|T(j\omega) - \hat T(j\omega)\|` for the real modal form
    :math:`(\Lambda, Y^TB, CX)` of :math:`(A, B, C)` from the computed :math:`V, W`: the transformation's
    residuals and the products' rounding (module docstring). ``W`` holds the rows the modal form uses.
    Returns ``(bound, record)``; ``inf`` where the resolvent bound's denominator reaches 0."""
    n = lam.size
    g = _gamma(n + 2)
    nv = np.linalg.norm(V, axis=0)
    nw = np.linalg.norm(W, axis=1)
    R, rerr = _residual(A, V, lam)
    r = np.linalg.norm(R, axis=0) * (1.0 + 4.0 * EPS) + rerr
    VW = V @ W
    VW[np.diag_indices(n)] -= 1.0
    fro_vw = float(np.linalg.norm(V) * np.linalg.norm(W))  # || |V||W| ||_F <= ||V||_F ||W||_F
    e_norm = float(np.linalg.norm(VW)) + g * fro_vw
    WB = W @ B
    nB = float(np.linalg.norm(B))
    # E B = V (W B) - B in long double (n^2 m operations): its rounding, gamma_n in long double, is negligible
    WBx = W.astype(np.clongdouble) @ B.astype(np.longdouble)
    eb = float(np.linalg.norm((V.astype(np.clongdouble) @ WBx - B).astype(complex)))
    eb += 4.0 * n * float(np.finfo(np.longdouble).eps) * fro_vw * nB + EPS * eb
    cv = np.linalg.norm(C @ V, axis=0) + g * float(np.linalg.norm(C)) * nv
    wb = np.linalg.norm(WB, axis=1) + g * nw * nB
    out_w, in_r, res_w = cv * nw, r * wb, r * nw
    # the real form's products C X and Y^T B, per unit: ||dC_u|| ||B_u|| + ||C_u|| ||dB_u|| (+ product)
    absC, absB = np.abs(C), np.abs(B)
    Bh, Ch = Yt @ B, C @ X
    dC = g * np.linalg.norm(absC @ np.abs(X), axis=0)
    dB = g * np.linalg.norm(np.abs(Yt) @ absB, axis=1)
    form = np.zeros(n)
    for idx in units:  # the block of a unit is normal: ||(sI - block)^-1|| = 1 / min |s - lambda|
        cu, bu = float(np.linalg.norm(Ch[:, idx])), float(np.linalg.norm(Bh[idx]))
        du, dbu = float(np.linalg.norm(dC[idx])), float(np.linalg.norm(dB[idx]))
        form[idx[0]] = du * bu + cu * dbu + du * dbu  # charged to the unit's first eigenvalue

    def bound(inv_d):
        den = 1.0 - e_norm - inv_d @ res_w
        with np.errstate(divide="ignore", invalid="ignore"):
            val = (inv_d @ out_w) * (eb + inv_d @ in_r) / den + inv_d @ form
        return np.where(den > 0, val, np.inf)
    sup = _sup_on_partition(lam, _graded_partition(lam), bound)
    return sup, {"residual": float(r.max()), "inverse": e_norm, "EB": eb}


def modal_form(A, B, C, max_cond: float = np.inf):
    r"""The real modal form of the standard realization ``(A, B, C)``: None where the eigenvector matrix's
    :math:`\kappa_1` exceeds ``max_cond`` (or A is defective), else a dict with the real modal realization
    of every mode (``A`` block diagonal, sparse; ``B``, ``C``), ``units`` (the index lists of a real
    eigenvalue or a conjugate pair), their truncation-bound ``terms``, ``cond`` and ``rounding`` (the bound
    of the form's deviation from ``(A, B, C)``, :func:`_rounding_bound`, with its record and time)."""
    lam, V = sla.eig(A, check_finite=False)
    try:
        W = np.linalg.inv(V)  # rows: left eigenvectors w_i^H with w_i^H v_j = delta_ij
        cond = float(np.linalg.norm(V, 1) * np.linalg.norm(W, 1))  # kappa_1(V), within a factor n of kappa_2
    except np.linalg.LinAlgError:  # a defective A
        cond = np.inf
    if not (np.isfinite(cond) and cond <= max_cond):
        return None
    n = lam.size
    X, Yt, Ar = np.empty((n, n)), np.empty((n, n)), sp.lil_matrix((n, n))
    units, terms = [], []
    ng = _gamma(n)
    nC, nB = float(np.linalg.norm(C)), float(np.linalg.norm(B))
    i = 0
    while i < n:
        a, b = lam[i].real, lam[i].imag
        # the norms with their products' rounding: the dropped modes' contribution is bounded for the
        # exact C v and w^H B
        cv = np.linalg.norm(C @ V[:, i]) + ng * nC * np.linalg.norm(V[:, i])
        wb = np.linalg.norm(W[i] @ B) + ng * nB * np.linalg.norm(W[i])
        term = cv * wb / abs(a) if a != 0 else np.inf
        if b != 0 and not (i + 1 < n and lam[i + 1] == np.conj(lam[i])):
            return None  # LAPACK returns a conjugate pair together, the positive imaginary part first
        if b != 0:
            # A [Re v, Im v] = [Re v, Im v] [a, b; -b, a];
            # the projector v w^H + its conjugate = [Re v, Im v] [2 Re w^H; -2 Im w^H]
            X[:, i], X[:, i + 1] = V[:, i].real, V[:, i].imag
            Yt[i], Yt[i + 1] = 2.0 * W[i].real, -2.0 * W[i].imag
            W[i + 1] = np.conj(W[i])  # the form uses w_i for both: the rounding bound sees that W
            Ar[i, i], Ar[i, i + 1], Ar[i + 1, i], Ar[i + 1, i + 1] = a, b, -b, a
            units.append([i, i + 1])
            terms.append(2.0 * term)
            i += 2
        else:
            X[:, i], Yt[i], Ar[i, i] = V[:, i].real, W[i].real, a
            units.append([i])
            terms.append(term)
            i += 1
    t1 = time.perf_counter()
    rounding, rrec = _rounding_bound(A, B, C, lam, V, W, X, Yt, units)
    return {"A": Ar.tocsr(), "B": Yt @ B, "C": C @ X, "units": units, "terms": np.array(terms), "cond": cond,
            "rounding": rounding, "rounding_record": rrec, "rounding_s": time.perf_counter() - t1}


def truncate(modes, budget):
    r"""The modal form ``modes`` (:func:`modal_form`) with the modes of smallest terms dropped while their sum
    plus the form's rounding bound stays at most ``budget``: ``(A, B, C, delta, kept)``, :math:`\delta` that
    sum plus the rounding bound; None where the rounding bound alone is not below ``budget``."""
    rounding = modes["rounding"]
    if not rounding < budget:
        return None
    terms = modes["terms"]
    order = np.argsort(terms, kind="stable")
    spent = np.cumsum(terms[order])
    drop = order[: int(np.searchsorted(spent, budget - rounding, side="right"))]
    trunc = float(spent[drop.size - 1]) if drop.size else 0.0
    dropped = set(drop.tolist())
    keep = np.array(sorted(j for u, idx in enumerate(modes["units"]) if u not in dropped for j in idx), dtype=int)
    return modes["A"][keep][:, keep].toarray(), modes["B"][keep], modes["C"][:, keep], trunc + rounding, keep


def _modes(fom):
    r""":func:`modal_form` of the model on its hidden manifold (None where :math:`\kappa_1(V) >` :data:`MODAL_COND`),
    cached in ``fom.cache`` with its time ``time_s``."""
    cache = getattr(fom, "cache", None)
    key = ("hidden_modes",)
    if cache is not None and key in cache:
        return cache[key]
    t0 = time.perf_counter()
    A, B, C, _ = _full(fom)
    out = modal_form(A, B, C, MODAL_COND)
    if out is not None:
        out["time_s"] = time.perf_counter() - t0
    if cache is not None:
        cache[key] = out
    return out


def hidden_realization(fom, budget: float = 0.0):
    r"""``(A, B, C, D, delta, info)``: the model on its hidden manifold (module docstring), full
    (``delta = 0``) or, with ``budget > 0`` where it pays, modally truncated with
    :math:`\|T_1 - \hat T\|_{\mathcal H_\infty} \le \delta \le` ``budget`` (:math:`T_1` the full dense
    realization's transfer function; :math:`\delta` the dropped modes' bound plus the modal form's
    rounding bound); ``info`` records the truncation (None where the modal form was not tried)."""
    full = _full(fom)
    k = fom.n1 - fom.n2
    if not budget > 0 or k < MODAL_MIN:
        return (*full, 0.0, None)
    modes = _modes(fom)
    if modes is None:
        return (*full, 0.0, {"modal": False, "reason": f"eigenvector condition number above {MODAL_COND:.0e}"})
    n = full[0].shape[0]
    rounding = modes["rounding"]
    info = {"modal": False, "of": n, "cond": modes["cond"], "rounding": rounding, "modal_s": modes["time_s"]}
    cut = truncate(modes, budget)
    if cut is None:
        info["reason"] = f"the modal form's rounding bound {rounding:.2e} is not below the budget {budget:.2e}"
        return (*full, 0.0, info)
    At, Bt, Ct, delta, keep = cut
    info.update(kept=int(keep.size), bound=delta - rounding)
    if keep.size > 0.9 * n:
        info["reason"] = "the truncation would keep more than 90% of the order"
        return (*full, 0.0, info)
    info["modal"] = True
    return At, Bt, Ct, full[3], delta, info


def _rom_block(arrays):
    """The reduced model's standard realization :math:`(E_r^{-1}A_r, E_r^{-1}B_r, C_r, D_r)` (no solve where
    :math:`E_r = I`: exact)."""
    E, Ar, Br, Cr, Dr = arrays
    if not np.array_equal(E, np.eye(E.shape[0])):
        Ar, Br = np.linalg.solve(E, Ar), np.linalg.solve(E, Br)
    return Ar, Br, Cr, Dr


def error_realization(fom, arrays, budget: float = 0.0):
    """``(A, B, C, D, delta, info)`` of :math:`T - T_r` for the reduced model's first-order ``arrays``
    (E, A, B, C, D), the model's part as :func:`hidden_realization` gives it for ``budget``."""
    A1, B1, C1, _, delta, info = hidden_realization(fom, budget)
    Ar, Br, Cr, Dr = _rom_block(arrays)
    return (sla.block_diag(A1, Ar), np.vstack([B1, Br]), np.hstack([C1, -Cr]), -np.asarray(Dr, dtype=float),
            delta, info)


def realization_response(fom, real, ws, arrays=None) -> np.ndarray:
    r""":math:`\hat G(j\omega)` (len(ws), p, m) of the realization ``real`` from :func:`hidden_realization`
    (``arrays`` None) or :func:`error_realization` (the reduced model's first-order ``arrays``) before
    truncation: where it is the modal form, with every mode (the dropped ones' sum is bounded exactly;
    what is measured is the modal form's deviation from the model), block by block, :math:`O(n)` per
    frequency; else the full realization by dense LU solves (:math:`O(n^3)`: as accurate as the
    realization itself; a Hessenberg form, :math:`O(n^2)` per frequency, was 40x less accurate at
    tcom(100)'s first resonance, 2026-12-02); the reduced model by dense solves."""
    info = real[5]
    p, m = fom.p, fom.m
    out = np.empty((len(ws), p, m), dtype=complex)
    if info and info.get("modal"):
        modes = _modes(fom)
        Bm, Cm = modes["B"], modes["C"]
        first = np.array([u[0] for u in modes["units"]])
        second = np.array([u[-1] for u in modes["units"]])
        paired = first != second
        a = modes["A"].diagonal()[first]
        b = np.where(paired, np.append(modes["A"].diagonal(1), 0.0)[first], 0.0)
        c1, c2, b1, b2 = Cm[:, first], Cm[:, second] * paired, Bm[first], Bm[second] * paired[:, None]
        for k, w in enumerate(ws):
            s = 1j * float(w)
            # a pair's block [a, b; -b, a]: (sI - block)^-1 = [s - a, b; -b, s - a] / ((s - a)^2 + b^2)
            den = (s - a) ** 2 + b * b
            x11, x12 = (s - a) / den, b / den
            out[k] = (c1 * x11) @ b1 + (c1 * x12) @ b2 - (c2 * x12) @ b1 + (c2 * x11) @ b2
    else:
        A1, B1, C1, _ = _full(fom)
        I = np.eye(A1.shape[0])
        for k, w in enumerate(ws):
            out[k] = C1 @ np.linalg.solve(1j * float(w) * I - A1, B1)
    if arrays is not None:
        Ar, Br, Cr, Dr = _rom_block(arrays)
        I = np.eye(Ar.shape[0])
        for k, w in enumerate(ws):
            out[k] -= Cr @ np.linalg.solve(1j * float(w) * I - Ar, Br) + Dr
    return out
