r"""First-order optimality of a reduced model for the H2 error: the relative gradient, against any target.

A reduced model of McMillan degree n with distinct poles is
:math:`T_r(s) = \sum_k c_kb_k^T/(s - \lambda_k)`. Its tangent space, among models of that degree
with :math:`C_rB_r = 0` (second-order models with :math:`\hat M = I`: the two sets coincide
generically, :mod:`morsuite.reducers.h2.poles`), is spanned by

.. math::

    \Phi_{k,\lambda} = \frac{c_kb_k^T}{(s - \lambda_k)^2},\quad
    \Phi_{k,b,q} = \frac{c_ke_q^T}{s - \lambda_k},\quad
    \Phi_{k,c,q} = \frac{e_qb_k^T}{s - \lambda_k}

with coefficients whose residue sum :math:`\sum_k(\delta c_kb_k^T + c_k\delta b_k^T)` vanishes.
With :math:`E = T - T_r`, the H2 inner products are closed form,
:math:`\langle uv^T/(s-\lambda)^a, u'v'^T/(s-\mu)^{a'}\rangle = (u^Hu')(v^Hv')K_{aa'}`,
:math:`K_{11} = -1/(\bar\lambda + \mu)`, :math:`K_{12} = K_{21} = (\bar\lambda + \mu)^{-2}`,
:math:`K_{22} = -2(\bar\lambda + \mu)^{-3}`, and :math:`\langle uv^T/(s-\lambda), E\rangle = u^HE(-\bar\lambda)\bar v`,
:math:`\langle uv^T/(s-\lambda)^2, E\rangle = -u^HE'(-\bar\lambda)\bar v`. The **relative gradient**

.. math::

    \rho = \frac{\|\Pi E\|_{\mathcal H_2}}{\|E\|_{\mathcal H_2}}\in[0, 1]

(:math:`\Pi` the orthogonal projection onto the tangent space) is the cosine of the angle between
the error and the tangent space: invariant under any reparametrisation of the reduced models,
zero exactly at a stationary point of :math:`\|T - T_r\|^2`; :math:`\rho^2 J` is the decrease a
Gauss-Newton step predicts. It needs :math:`E(-\lambda_k)b_k`, :math:`c_k^TE(-\lambda_k)` and
:math:`c_k^TE'(-\lambda_k)b_k`: against the index-3 model one sparse LU per real pole or conjugate
pair, one right and one transposed saddle-point solve with it (Lemma 1 of the paper), the values
that tangential IRKA's interpolation conditions test.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from ...linalg.h2 import modal_form, pole_residue_squared
from .orthonormal import TMRecursion, realization_tm_values, tm_realization, tm_rho
from ...linalg.refine import SaddleOperator, refined_solve

__all__ = ["relative_gradient_rank_one", "full_stationarity", "saddle_solver_refined", "TM_CONDITION"]

#: the orthonormal form of rho is computed (SISO) when the scaled Gram matrix of the partial-fraction
#: tangent vectors has a smallest-to-largest eigenvalue ratio below this (the partial-fraction form
#: drops eigenvalues below 1e-12 of the largest); above it the two agreed to 1e-4 or better (docs/design/so_h2.md)
TM_CONDITION = 1e-9


def relative_gradient_rank_one(poles, C, B, Eb, cE, dE, J) -> float:
    """ρ (module docstring) from the reduced model's poles, residue directions ``C`` (p x n, columns
    c_k) and ``B`` (n x m, rows b_k), and the error's values at the mirrored poles: ``Eb`` (p x n,
    :math:`E(-\\lambda_k)b_k`), ``cE`` (n x m, :math:`c_k^TE(-\\lambda_k)`), ``dE`` (n,
    :math:`c_k^TE'(-\\lambda_k)b_k`); ``J`` = :math:`\\|E\\|^2`. The poles must be closed under
    conjugation with conjugate data. Returns ``inf`` for J <= 0. Eigenvalues of the scaled Gram
    matrix below 1e-12 of the largest are dropped: where poles cluster, rho can be underestimated
    (:mod:`morsuite.reducers.h2.orthonormal`). Cost: an eigen-decomposition of order n(1 + m + p)."""
    if not J > 0:
        return np.inf
    lam = np.asarray(poles)
    n = lam.size
    p, m = C.shape[0], B.shape[1]
    partner = np.array([int(np.argmin(np.abs(lam - np.conj(lk)))) for lk in lam])
    U, V, A, K, g, R = [], [], [], [], [], []
    Ip, Im = np.eye(p), np.eye(m)
    for k in range(n):
        kk = partner[k]
        U.append(C[:, k]); V.append(B[k]); A.append(2); K.append(k); g.append(-dE[kk])
        R.append(np.zeros((p, m)))
        for q in range(m):
            U.append(C[:, k]); V.append(Im[q]); A.append(1); K.append(k); g.append(cE[kk, q])
            R.append(np.outer(C[:, k], Im[q]))
        for q in range(p):
            U.append(Ip[q]); V.append(B[k]); A.append(1); K.append(k); g.append(Eb[q, kk])
            R.append(np.outer(Ip[q], B[k]))
    U, V, A, K = np.array(U), np.array(V), np.array(A), np.array(K)
    g = np.array(g, dtype=complex)
    S = np.conj(lam[K])[:, None] + lam[K][None, :]
    Kmat = np.where((A[:, None] == 1) & (A[None, :] == 1), -1.0 / S,
                    np.where((A[:, None] == 2) & (A[None, :] == 2), -2.0 / S ** 3, 1.0 / S ** 2))
    Gm = (U.conj() @ U.T) * (V.conj() @ V.T) * Kmat
    Rm = np.array([x.ravel() for x in R]).T            # (pm, nb)
    N = sla.null_space(Rm) if np.any(Rm) else np.eye(Rm.shape[1])
    Gr = N.conj().T @ Gm @ N
    gr = N.conj().T @ g
    d = np.sqrt(np.maximum(np.real(np.diag(Gr)), np.finfo(float).tiny))
    w, Q = np.linalg.eigh(0.5 * (Gr + Gr.conj().T) / d[:, None] / d[None, :])
    keep = w > 1e-12 * w.max()
    y = Q[:, keep].conj().T @ (gr / d)
    return float(np.sqrt(max(float(np.sum(np.abs(y) ** 2 / w[keep])), 0.0) / J))


def saddle_solver_refined(full, steps: int):
    """(lu, s) -> (x solve, transposed solve) closures for the model's solver, each refined ``steps``
    times in long double (:mod:`morsuite.linalg.refine`; 0: the LU's solution)."""
    op = SaddleOperator(full.solver.pattern) if steps else None

    def solves(s, rhs_right, rhs_left):
        lu = full.solver.factor(s)
        if not steps:
            return lu.solve(rhs_right).reshape(-1), lu.solve(rhs_left, trans=True).reshape(-1)
        return (refined_solve(lu, rhs_right, False, s, op, steps=steps, ext=True),
                refined_solve(lu, rhs_left, True, s, op, steps=steps, ext=True))

    def right(s):
        """rhs -> P(s)^-1 rhs (refined), with the LU at s (the solver keeps the last ones)."""
        lu = full.solver.factor(s)
        if not steps:
            return lambda rhs: lu.solve(rhs).reshape(-1)
        return lambda rhs: refined_solve(lu, rhs, False, s, op, steps=steps, ext=True)
    solves.right = right
    return solves


def full_stationarity(full, A, B, C, *, refine: int = 2, orthonormal: bool = True, reference=None) -> dict:
    r"""J, its floor and ρ of the real first-order model (A, B, C) (E = I) against the index-3 model
    ``full`` (a :class:`~morsuite.reducers.h2.gradient.FullTarget`): one LU per real pole or conjugate
    pair, right solves with :math:`Fb_k` and transposed solves with :math:`L^Tc_k`, each refined
    ``refine`` times in long double (at the mirrored poles of lightly damped reduced poles the
    unrefined solves' errors dominate E: on tcom(2000) at r = 22 they gave 12.76 for an error of
    17.94); J by the pole-residue formula of :mod:`morsuite.linalg.h2` from the same solves.

    SISO with ``orthonormal`` (default) where the partial-fraction Gram matrix is ill-conditioned
    (``gram_condition``, the smallest over the largest eigenvalue of the scaled Gram matrix of
    :math:`1/(s - \lambda_k)`, :math:`\varphi_k/(s - \lambda_k)^2`, at most :data:`TM_CONDITION`):
    ``rho`` in the orthonormal Takenaka-Malmquist basis of the tangent space
    (:mod:`morsuite.reducers.h2.orthonormal`; two more refined right solves per pole with the same LU,
    which triples the certificate's solves), accurate where poles cluster; ``rho_form`` says which.
    The partial-fraction form (:func:`relative_gradient_rank_one`) is ``rho_pole_residue``.

    ``reference``: None, or ``(J, floor)`` of the same model from a more accurate evaluator
    (:func:`~morsuite.reducers.h2_decision.decision_h2`); used as :math:`\|E\|^2` in :math:`\rho` where its
    floor is below the pole-residue formula's (errors near :math:`\sqrt\varepsilon\|T\|`, where that
    formula's value is rounding: the DSMS from r = 10; ``value_form`` says which).

    Returns a dict: ``value`` (J), ``floor``, ``value_form``, ``rho``, ``rho_pole_residue``, ``rho_form``,
    ``gram_condition``, ``lu_count``, ``kappa`` (of the reduced
    model's eigenvectors)."""
    sysm = full.system
    md = modal_form(np.eye(A.shape[0]), A, B, C, np.zeros((C.shape[0], B.shape[1])))
    lam, Cm, Bm = md.poles, md.C, md.B
    n = lam.size
    p, m = Cm.shape[0], Bm.shape[1]
    Tb = np.empty((p, n), dtype=complex)
    cT = np.empty((n, m), dtype=complex)
    dT = np.empty(n, dtype=complex)
    lu0 = full.lu_count
    solves = saddle_solver_refined(full, refine)
    done = np.zeros(n, bool)
    cond = _partial_fraction_condition(lam, Cm[0] * Bm[:, 0]) if p == 1 and m == 1 else np.nan
    siso = p == 1 and m == 1 and orthonormal and not cond > TM_CONDITION
    if siso:    # the orthonormal basis of the tangent space, poles in the loop's order (h2_orthonormal)
        seq = _tm_sequence(lam)
        A_tm, beta = tm_realization(seq)
        tm, v_tm, pos = TMRecursion(sysm), np.empty(seq.size, dtype=complex), 0
    for k in np.argsort(-lam.imag, kind="stable"):      # upper members first, their partners by conjugation
        if done[k]:
            continue
        s = -lam[k]
        x, w = solves(s, sysm.F @ Bm[k], sysm.L.T @ Cm[:, k])
        if siso and lam[k].imag >= 0:     # the pair's conjugate is taken with it (_tm_sequence)
            right = solves.right(s)
            for _ in range(2):
                v_tm[pos] = tm.step(right, s, beta[pos])
                pos += 1
            if lam[k].imag != 0:    # P(conj s)^-1 r = conj(P(s)^-1 conj(r)): the same LU
                for _ in range(2):
                    v_tm[pos] = tm.step(lambda r: np.conj(right(np.conj(r))), np.conj(s), beta[pos])
                    pos += 1
        Tb[:, k], cT[k], dT[k] = sysm.L @ x, w @ sysm.F, -(w @ (2.0 * s * (sysm.M @ x) + sysm.D @ x))
        done[k] = True
        if lam[k].imag != 0:
            j = np.flatnonzero(~done & np.isclose(lam, np.conj(lam[k]), rtol=1e-12, atol=0))
            if j.size:
                # the partner's directions are the conjugates up to a complex scale: solve exactly
                # for it from the conjugate solves, T(conj s) = conj T(s)
                jj = j[0]
                tb = np.conj(Tb[:, k])
                a_b = _scale(Bm[jj], np.conj(Bm[k]))
                a_c = _scale(Cm[:, jj], np.conj(Cm[:, k]))
                Tb[:, jj], cT[jj], dT[jj] = a_b * tb, a_c * np.conj(cT[k]), a_b * a_c * np.conj(dT[k])
                done[jj] = True
    if p == 1 and m == 1:
        Rs = np.stack([np.linalg.inv(sk * np.eye(A.shape[0]) - A) for sk in -lam])       # (n, N, N)
        RB = Rs @ B                                                                       # (n, N, m)
        TrB = np.einsum("pn,knm,km->pk", C, RB, Bm)
        cTr = np.einsum("pk,pn,knm->km", Cm, C, RB)
        dTr = -np.array([Cm[:, k] @ C @ Rs[k] @ RB[k] @ Bm[k] for k in range(n)])
    else:
        TrB, cTr, dTr = _modal_values_extended(lam, Cm, Bm)
    terms = np.array([Cm[:, k] @ Tb[:, k] for k in range(n)])
    e2, floor, _ = pole_residue_squared(full.norm2, full.norm2_floor, complex(np.sum(terms)),
                                        float(np.sum(np.abs(terms))), md)
    form = "pole-residue"
    if reference is not None and reference[1] < floor:
        e2, floor, form = float(reference[0]), float(reference[1]), "reference"
    rho_pr = relative_gradient_rank_one(lam, Cm, Bm, Tb - TrB, cT - cTr, dT - dTr, e2)
    rho = rho_pr
    if siso:
        rho = tm_rho(v_tm - realization_tm_values(A_tm, beta, A, B, C), beta, e2)
    return {"value": float(e2), "floor": float(floor), "value_form": form, "rho": rho, "rho_pole_residue": rho_pr,
            "rho_form": "orthonormal" if siso else "pole-residue", "gram_condition": cond,
            "lu_count": full.lu_count - lu0, "kappa": float(md.kappa)}


def _modal_values_extended(lam, Cm, Bm):
    r"""The reduced model's :math:`T_r(-\lambda_k)b_k`, :math:`c_k^TT_r(-\lambda_k)` and
    :math:`c_k^TT_r'(-\lambda_k)b_k` from its modal form :math:`T_r = \sum_lc_lb_l^T/(s - \lambda_l)`, summed in
    long double (several inputs or outputs). The resolvents of the real realization that the SISO
    certificate uses carry the rounding :math:`\varepsilon\kappa(\sigma I - A)\|T_r\|`: on the DSMS at r = 6
    (error 4.5e-7 of the norm) it made the certificate's :math:`\rho` 2.7e-5 and 1.0e-4 for two reduced models
    whose dense :math:`\rho` (derivative systems) is 1.7e-6 and 2.2e-6 (docs/design/so_h2.md, 2026-11-28,
    second session)."""
    L = np.clongdouble
    lamL, CmL, BmL = lam.astype(L), Cm.astype(L), Bm.astype(L)
    R = 1.0 / (-lamL[:, None] - lamL[None, :])          # R[k, l] = 1 / (sigma_k - lambda_l), sigma_k = -lambda_k
    W = BmL @ BmL.T                                      # W[l, k] = b_l^T b_k
    X = CmL.T @ CmL                                      # X[k, l] = c_k^T c_l
    TrB = CmL @ (R * W.T).T                              # sum_l c_l (b_l^T b_k) R[k, l]
    cTr = (R * X) @ BmL                                  # sum_l (c_k^T c_l) R[k, l] b_l^T
    dTr = -np.sum(X * (R * R) * W.T, axis=1)              # -sum_l (c_k^T c_l)(b_l^T b_k) R[k, l]^2
    return TrB.astype(complex), cTr.astype(complex), dTr.astype(complex)


def _partial_fraction_condition(lam, phi) -> float:
    r"""Smallest over largest eigenvalue of the diagonally scaled Gram matrix of the SISO tangent
    vectors :math:`1/(s - \lambda_k)`, :math:`\varphi_k/(s - \lambda_k)^2` (the inner products of
    :func:`relative_gradient_rank_one`)."""
    S = np.conj(lam)[:, None] + lam[None, :]
    G = np.block([[-1.0 / S, phi[None, :] / S ** 2], [np.conj(phi)[:, None] / S ** 2,
                                                       -2.0 * np.outer(np.conj(phi), phi) / S ** 3]])
    d = np.sqrt(np.maximum(np.real(np.diag(G)), np.finfo(float).tiny))
    w = np.linalg.eigvalsh(0.5 * (G + G.conj().T) / d[:, None] / d[None, :])
    return float(max(w[0], 0.0) / w[-1])


def _tm_sequence(lam):
    """The poles in the order of :func:`full_stationarity`'s loop (upper members of the pairs by
    decreasing imaginary part, then the real ones), each pair followed by its conjugate, every pole
    twice."""
    out = []
    for k in np.argsort(-lam.imag, kind="stable"):
        if lam[k].imag < 0:
            continue
        out += [lam[k], lam[k]] + ([np.conj(lam[k])] * 2 if lam[k].imag > 0 else [])
    return np.array(out, dtype=complex)


def _scale(a, b) -> complex:
    """The complex t with a = t b (least squares)."""
    return complex(np.vdot(b, a) / np.vdot(b, b))
