r"""The Jacobian of the first-order tangential IRKA map against a modal surrogate, in closed form.

The interpolant of the surrogate :math:`T_s(s) = C_s(sI - \mathrm{diag}(\mu))^{-1}B_s` at data
:math:`(\sigma_i, b_i, c_i)` has, in the complex basis of the columns
:math:`v_i = R_{:,i}\circ B_sb_i`, :math:`w_i = R_{:,i}\circ C_s^Tc_i`,
:math:`R_{ni} = (\sigma_i - \mu_n)^{-1}`, the realization

.. math::

    E_c = W^TV,\quad A_c = W^T\mathrm{diag}(\mu)V,\quad B_c = W^TB_s,\quad C_c = C_sV,

congruent to the real interpolant of :meth:`~morsuite.reducers.irka.surrogate.ModalSurrogate.interpolant`
(same poles and residues). A parameter of slot i (its shift, an entry of :math:`b_i` or of
:math:`c_i`) moves only column i of V and of W, by :math:`\delta v` and :math:`\delta w`
(:math:`\partial v_i/\partial\sigma_i = -R_{:,i}\circ v_i`, :math:`\partial v_i/\partial b_{iq} = R_{:,i}\circ B_{s,:q}`,
likewise for W), so :math:`\delta E = e_i\,\delta w^TV + W^T\delta v\,e_i^T` (likewise
:math:`\delta A` with :math:`\mu\circ V`), :math:`\delta B = e_i\,\delta w^TB_s`,
:math:`\delta C = C_s\delta v\,e_i^T`. With right and left eigenvectors :math:`x_k`, :math:`y_k`
of :math:`(A_c, E_c)`, :math:`\nu_k = y_k^TE_cx_k` and
:math:`G_{lk} = y_l^T(\delta A - \lambda_k\delta E)x_k` (first-order perturbation theory of
simple eigenvalues),

.. math::

    \delta\lambda_k = G_{kk}/\nu_k,\qquad
    \delta x_k = \sum_{l\ne k}x_l\frac{G_{lk}}{(\lambda_k - \lambda_l)\nu_l},\qquad
    \delta y_k = \sum_{l\ne k}y_l\frac{y_k^T(\delta A - \lambda_k\delta E)x_l}{(\lambda_k - \lambda_l)\nu_l},

and the residue directions :math:`c_k \propto C_cx_k`, :math:`b_k \propto B_c^Ty_k` move by
:math:`\delta C x_k + C_c\delta x_k` and :math:`\delta B^Ty_k + B_c^T\delta y_k` (the
components along :math:`x_k`, :math:`y_k` only rescale them, which the chart's pivot
normalisation removes). The map sends the data to :math:`(-\lambda_k, b_k, c_k)`. In the real
coordinates of :class:`~morsuite.reducers.irka.surrogate.Chart` a pair's upper member :math:`z` and its conjugate
are independent complex parameters with :math:`\partial/\partial\mathrm{Re}\,z = \partial_z + \partial_{\bar z}`,
:math:`\partial/\partial\mathrm{Im}\,z = i(\partial_z - \partial_{\bar z})`; an output coordinate's
derivative is the real or imaginary part of the holomorphic one.

Cost: one complex QZ of the k x k pencil with both eigenvector sets, then
:math:`O(k(1 + m + p)(Nk + k^2(m + p)))` flops (the eigenvector perturbations enter only
through :math:`C_c\delta x_k` and :math:`B_c^T\delta y_k` at the image's poles, never as k x k
products; SISO: :math:`O(kN)` per parameter, the eigenvalues' derivatives only), against one map
evaluation per real coordinate (about :math:`k(m + p - 1)` of them)
for forward differences. Checked against central differences in ``tests/test_irka_jacobian.py``;
measurements in ``docs/design/irka_fo.md`` (2026-11-26).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

__all__ = ["map_jacobian"]


def map_jacobian(mu, Bs, Cs, chart, x, y):
    r"""The map's Jacobian :math:`f'(x)` in ``chart`` coordinates (module docstring).

    Parameters
    ----------
    mu : ndarray
        The surrogate's N poles.
    Bs, Cs : ndarray
        Its modal input (N x m) and output (p x N) matrices.
    chart : Chart
        The coordinates of x and y.
    x, y : ndarray
        The point and its image :math:`f(x)` in chart coordinates.

    Returns
    -------
    ndarray or None
        The real Jacobian, or None where the closed form does not apply (an image shift that is
        not a mirrored pole, poles that are not simple, a vanishing :math:`y_k^TE_cx_k` or pivot
        entry): the caller falls back to differences. Cost: module docstring.
    """
    m, p = Bs.shape[1], Cs.shape[0]
    alpha, bd, cd = chart.decode(x)
    k = alpha.size
    R = 1.0 / (alpha[None, :] - mu[:, None])
    V, W = R * (Bs @ bd.T), R * (Cs.T @ cd.T)
    # diagonal scaling for the QZ (eigenvalues unchanged; eigenvectors mapped back)
    sc = 1.0 / np.sqrt(np.maximum(np.linalg.norm(V, axis=0) * np.linalg.norm(W, axis=0), np.finfo(float).tiny))
    Ec, Ac = W.T @ V, W.T @ (mu[:, None] * V)
    Bc, Cc = W.T @ Bs, Cs @ V
    try:
        lam, Yl, Xs = sla.eig(Ac * np.outer(sc, sc), Ec * np.outer(sc, sc), left=True, right=True)
    except (np.linalg.LinAlgError, ValueError):
        return None
    if not np.all(np.isfinite(lam)):
        return None
    X, Y = sc[:, None] * Xs, sc[:, None] * Yl.conj()
    nu = np.sum(Y * (Ec @ X), axis=0)
    if np.any(np.abs(nu) <= 1e-13 * np.linalg.norm(X, axis=0) * np.linalg.norm(Y, axis=0) * np.linalg.norm(Ec, 2)):
        return None
    gap = lam[None, :] - lam[:, None]  # gap[l, k] = lambda_k - lambda_l
    np.fill_diagonal(gap, 1.0)
    if np.min(np.abs(gap)) <= 1e-10 * np.max(np.abs(lam)):
        return None
    # the image's slots: the pole each mirrors
    out = chart.decode(y)[0]
    S, nr = chart.shifts.size, chart.n_real
    first = np.concatenate([np.arange(nr), nr + 2 * np.arange(S - nr)])  # index of each slot's member in out
    pole = np.empty(S, dtype=int)
    for s in range(S):
        dist = np.abs(-lam - out[first[s]])
        kk = int(np.argmin(dist))
        second = np.partition(dist, 1)[1] if dist.size > 1 else np.inf
        if dist[kk] > 1e-3 * abs(out[first[s]]) or dist[kk] > 0.1 * second:
            return None  # a mirrored unstable pole, a nudged one: not -lambda
        pole[s] = kk
    cK, bK = Cc @ X[:, pole], Bc.T @ Y[:, pole]  # residue directions of the image's slots (p x S, m x S)
    jb, jc = chart.jb, chart.jc
    piv_b, piv_c = bK[jb, np.arange(S)], cK[jc, np.arange(S)]
    if np.any(np.abs(piv_b) == 0) or np.any(np.abs(piv_c) == 0):
        return None
    YtW, YtWmu, VX, muVX = Y.T @ W.T, Y.T @ (W.T * mu[None, :]), V @ X, (mu[:, None] * V) @ X
    CcX, BcY = Cc @ X, Bc.T @ Y
    keep_b, keep_c = chart._masks()

    def image_derivative(i, dv, dw):
        """d(output chart quantities) for a parameter moving column i of V by dv and of W by dw:
        per output slot, (d shift, d free b entries, d free c entries), complex."""
        rE = dw @ VX if dw is not None else np.zeros(k, complex)
        rA = dw @ muVX if dw is not None else np.zeros(k, complex)
        cE = YtW @ dv if dv is not None else np.zeros(k, complex)
        cA = YtWmu @ dv if dv is not None else np.zeros(k, complex)
        if m == 1 and p == 1:
            # SISO: the chart holds the shifts only, so only the eigenvalues' derivatives are needed: the
            # diagonal of G below (the same products, in the same order), O(k) instead of O(k^2)
            dG = Y[i] * rA - Y[i] * rE * lam + (cA - cE * lam) * X[i]
            return -(dG / nu)[pole][:, None]
        # G[l, k] = y_l^T (dA - lambda_k dE) x_k ; H[k, l] = y_k^T (dA - lambda_k dE) x_l
        G = np.outer(Y[i], rA) - np.outer(Y[i], rE) * lam[None, :] + (cA[:, None] - cE[:, None] * lam[None, :]) * X[i][None, :]
        H = (Y[i][:, None] * (rA[None, :] - lam[:, None] * rE[None, :])
             + (cA - lam * cE)[:, None] * X[i][None, :])
        dlam = np.diag(G) / nu
        A_ = G / (gap * nu[:, None])
        np.fill_diagonal(A_, 0.0)
        B_ = H / (gap.T * nu[None, :])
        np.fill_diagonal(B_, 0.0)
        # C_c dx_k = (C_c X) A_[:, k] and B_c^T dy_k = (B_c^T Y) B_[k, :]^T, for the image's poles only:
        # O(k^2 (m + p)) per parameter instead of the O(k^3) of dX = X A_ and dY = Y B_^T
        dc = CcX @ A_[:, pole]
        db = BcY @ B_[pole, :].T
        if dv is not None:
            dc = dc + np.outer(Cs @ dv, X[i, pole])
        if dw is not None:
            db = db + np.outer(Bs.T @ dw, Y[i, pole])
        # d(v / v[pivot]) = (dv - (v / v[pivot]) dv[pivot]) / v[pivot]
        tb = (db - (bK / piv_b) * db[jb, np.arange(S)]) / piv_b
        tc = (dc - (cK / piv_c) * dc[jc, np.arange(S)]) / piv_c
        return np.concatenate([-dlam[pole][:, None], tb.T[keep_b].reshape(S, m - 1),
                               tc.T[keep_c].reshape(S, p - 1)], axis=1)

    # holomorphic derivatives per (member index i, parameter): shift, b entries, c entries
    nfree = 1 + (m - 1) + (p - 1)
    members = np.concatenate([np.arange(nr), nr + 2 * np.arange(S - nr)])
    cols = []
    for s in range(S):
        idx = [members[s]] if s < nr else [members[s], members[s] + 1]
        per = []
        for i in idx:
            d = []
            d.append(image_derivative(i, -R[:, i] * V[:, i], -R[:, i] * W[:, i]))
            d.extend(image_derivative(i, R[:, i] * Bs[:, q], None) for q in range(m) if q != jb[s])
            d.extend(image_derivative(i, None, R[:, i] * Cs[q, :]) for q in range(p) if q != jc[s])
            per.append(d)
        for t in range(nfree):
            if s < nr:
                cols.append(per[0][t])
            else:
                cols.append((per[0][t] + per[1][t], 1j * (per[0][t] - per[1][t])))
    # assemble: rows in chart order (real slots: real parts; pairs: real parts, then imaginary parts)
    J = np.empty((x.size, x.size))
    c = 0
    for s in range(S):
        items = [cols[s * nfree + t] for t in range(nfree)]
        if s < nr:
            for it in items:
                J[:, c] = _rows(it, nr)
                c += 1
        else:
            for part in (0, 1):
                for it in items:
                    J[:, c] = _rows(it[part], nr)
                    c += 1
    return J


def _rows(d, nr):
    """Chart-ordered real column from per-slot complex derivatives d (S x nfree)."""
    return np.concatenate([d[:nr].real.ravel(), np.concatenate([d[nr:].real, d[nr:].imag], axis=1).ravel()])
