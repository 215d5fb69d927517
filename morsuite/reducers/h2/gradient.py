r"""The H2 error of a second-order reduced model and its gradient, against a dense or the full model.

The reduced model is kept with :math:`\hat M = I` (any model with an
invertible :math:`\hat M` is one, after :math:`\hat M^{-1}` is applied):

.. math::

    T_r(s) = \hat L(s^2I + s\hat D + \hat K)^{-1}\hat F, \qquad
    A_r = \begin{bmatrix} 0 & I \\ -\hat K & -\hat D \end{bmatrix},\;
    B_r = \begin{bmatrix} 0 \\ \hat F \end{bmatrix},\;
    C_r = \begin{bmatrix} \hat L & 0 \end{bmatrix}.

For a target :math:`T = C(sE - A)^{-1}B` (:class:`ModalTarget`, a dense
first-order model in modal form; :class:`FullTarget`, the index-3 model on its
hidden manifold) and the solutions :math:`X`, :math:`Y` of

.. math::

    AX + EXA_r^T + BB_r^T = 0, \qquad A^TY + E^TYA_r + C^TC_r = 0,

and the reduced Gramians :math:`A_rP_r + P_rA_r^T + B_rB_r^T = 0`,
:math:`A_r^TQ_r + Q_rA_r + C_r^TC_r = 0`,

.. math::

    J = \|T - T_r\|_{\mathcal H_2}^2 = \|T\|^2 - 2\,\mathrm{tr}(CXC_r^T) + \mathrm{tr}(C_rP_rC_r^T),

and Wilson's gradient (Wilson 1970; van Dooren, Gallivan and Absil 2008)

.. math::

    \nabla_{A_r}J = 2(Q_rP_r - Y^TEX),\quad \nabla_{B_r}J = 2(Q_rB_r - Y^TB),\quad
    \nabla_{C_r}J = 2(C_rP_r - CX),

so by the chain rule :math:`\partial J/\partial\hat K = -(\nabla_{A_r}J)_{21}`,
:math:`\partial J/\partial\hat D = -(\nabla_{A_r}J)_{22}`,
:math:`\partial J/\partial\hat F = (\nabla_{B_r}J)_2`,
:math:`\partial J/\partial\hat L = (\nabla_{C_r}J)_1` (:func:`h2_objective`).

The three terms of :math:`J` are of size :math:`\|T\|^2` and cancel (rounding
:math:`\varepsilon\|T\|^2`). Against a dense target the value is instead taken from

.. math::

    J = \mathrm{tr}(R_B^TQR_B) + \mathrm{tr}(R_CP_rR_C^T),\qquad
    R_B = B - XP_r^{-1}B_r,\quad R_C = CXP_r^{-1} - C_r

(:math:`E = I`, :math:`Q` the target's observability Gramian), two
non-negative terms made of residuals that vanish as :math:`T_r \to T`: with
:math:`V = XP_r^{-1}` the error is :math:`T - T_r = C(sI-A)^{-1}R_B\,\Theta(s) +
R_C(sI-A_r)^{-1}B_r`, :math:`\Theta(s) = I - B_r^TP_r^{-1}(sI-A_r)^{-1}B_r` is inner,
and the two parts are orthogonal (``docs/design/so_h2.md``). Its rounding is of
the order of :math:`\varepsilon\|T\|\,\|T - T_r\|` instead.

Cost: against a :class:`ModalTarget` of order N, :math:`O(N(2r)^2)` per
evaluation, no LU; against the :class:`FullTarget`, one sparse LU per real
pole or conjugate pair of the reduced model (r LUs for 2r complex poles), one
right and one transposed solve with each, and :math:`O(n_1 r^2)` products.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
from scipy.linalg.lapack import ztrsyl as _trsyl

from ...errors import InputError
from ...linalg.system import check_system, new_solver

__all__ = ["second_order_realization", "ModalTarget", "FullTarget", "H2Evaluation", "h2_value", "h2_objective",
           "gauss_newton_diagonal", "EPS"]

EPS = np.finfo(float).eps


def second_order_realization(K, D, F, L):
    """(A_r, B_r, C_r) of :math:`\\hat M = I`, :math:`\\hat D`, :math:`\\hat K`, :math:`\\hat F`, :math:`\\hat L`."""
    r = K.shape[0]
    I, Z = np.eye(r), np.zeros((r, r))
    A = np.block([[Z, I], [-K, -D]])
    B = np.vstack([np.zeros((r, F.shape[1])), F])
    C = np.hstack([L, np.zeros((L.shape[0], r))])
    return A, B, C


@dataclass
class _Rom:
    """The reduced model's first-order data of one evaluation (Schur form, Gramians)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    T: np.ndarray          # complex Schur form A = Q T Q^H
    Q: np.ndarray
    P: np.ndarray = None
    Qo: np.ndarray = None

    @property
    def poles(self):
        return np.diag(self.T)


@dataclass
class Cross:
    """What the target contributes to J and its gradient: :math:`CX`, :math:`Y^TB`, :math:`Y^TEX`,
    :math:`\\langle T, T_r\\rangle = \\mathrm{tr}(CXC_r^T)`, the sum of moduli of its terms, and the
    cancellation-free value of J where the target has one."""

    CX: np.ndarray
    YB: np.ndarray
    YEX: np.ndarray
    inner: float
    inner_abs: float
    residual_value: float | None = None
    residual_floor: float | None = None
    lu_count: int = 0
    details: dict = field(default_factory=dict)


def _modal_sylvester(lam, G, T, upper):
    r"""Z with :math:`\Lambda Z + ZT^T = -G` (``upper``: back substitution over T's columns, T upper
    triangular, the X equation) or :math:`\Lambda Z + ZT = -G` (forward, the Y equation)."""
    n = T.shape[0]
    Z = np.empty((lam.size, n), dtype=complex)
    if upper:
        for j in range(n - 1, -1, -1):
            rhs = -G[:, j] - Z[:, j + 1:] @ T[j, j + 1:]
            Z[:, j] = rhs / (lam + T[j, j])
    else:
        for j in range(n):
            rhs = -G[:, j] - Z[:, :j] @ T[:j, j]
            Z[:, j] = rhs / (lam + T[j, j])
    return Z


class ModalTarget:
    r"""A stable dense first-order target in modal form, :math:`T(s) = C(sI - \Lambda)^{-1}B`.

    The model is this modal form (complex, closed under conjugation), exactly
    as stored: the eigenvector transformation that produced it perturbs the
    original realization once, not the comparisons between reduced models.
    The Sylvester equations are solved entry by entry against the reduced
    model's complex Schur form (:math:`O(N(2r)^2)`), and the Hermitian form of
    the observability Gramian, :math:`\tilde Q_{ij} = (C^HC)_{ij}/(-(\bar\lambda_i + \lambda_j))`,
    is factored once for the cancellation-free value.

    Parameters
    ----------
    poles : (N,) complex, all with negative real part
    B : (N, m) complex
    C : (p, N) complex
    """

    def __init__(self, poles, B, C):
        lam = np.asarray(poles, dtype=complex)
        if lam.ndim != 1 or not np.all(np.isfinite(lam)) or not np.all(lam.real < 0):
            raise InputError("poles must be a finite 1-D array in the open left half-plane")
        self.poles, self.B, self.C = lam, np.asarray(B, dtype=complex), np.asarray(C, dtype=complex)
        if self.B.shape[0] != lam.size or self.C.shape[1] != lam.size:
            raise InputError(f"B must have {lam.size} rows and C {lam.size} columns; got {self.B.shape}, "
                             f"{self.C.shape}")
        self.m, self.p = self.B.shape[1], self.C.shape[0]
        Qh = (self.C.conj().T @ self.C) / (-(lam.conj()[:, None] + lam[None, :]))
        Qh = 0.5 * (Qh + Qh.conj().T)
        w, U = np.linalg.eigh(Qh)
        keep = w > 0
        self._qfactor = U[:, keep] * np.sqrt(w[keep])   # Qh = F F^H
        Ph = (self.B @ self.B.conj().T) / (-(lam[:, None] + lam.conj()[None, :]))
        self.norm2 = float(np.real(np.sum((self.C @ Ph) * self.C.conj())))
        self.norm2_floor = 2.0 * EPS * np.sqrt(lam.size) * self.norm2

    @property
    def gramian_factor(self):
        """F with :math:`FF^H` the observability Gramian of the modal realization (positive eigenvalues kept)."""
        return self._qfactor

    @property
    def order(self) -> int:
        """Number of poles of the modal target."""
        return self.poles.size

    def cross(self, rom: _Rom) -> Cross:
        """The cross terms of ``rom`` against the modal target: two modal Sylvester equations, no LU;
        with a definite :math:`P_r`, also the cancellation-free residual value and its floor."""
        lam, T, Q = self.poles, rom.T, rom.Q
        Xt = _modal_sylvester(lam, self.B @ (rom.B.T @ Q.conj()), T, True) @ Q.T
        Yt = _modal_sylvester(lam, self.C.T @ (rom.C @ Q), T, False) @ Q.conj().T
        CX = self.C @ Xt
        terms = np.sum(CX * rom.C, axis=0)
        out = Cross(CX.real, (Yt.T @ self.B).real, (Yt.T @ Xt).real, float(np.sum(terms).real),
                    float(np.sum(np.abs(terms))))
        try:
            S = np.linalg.cholesky(rom.P)
        except np.linalg.LinAlgError:
            return out  # P_r not numerically definite: no cancellation-free value
        XS = sla.solve_triangular(S, Xt.T, lower=True).T             # X P^{-1} = (X S^{-T}) S^{-1}
        SB = sla.solve_triangular(S, rom.B, lower=True)
        RB = self.B - XS @ SB
        RCS = (self.C @ XS).real - rom.C @ S
        j1 = float(np.sum(np.abs(self._qfactor.conj().T @ RB) ** 2))
        j2 = float(np.sum(RCS * RCS))
        out.residual_value = j1 + j2
        # R_B and R_C S are differences of terms of the size of B and C X S^-T: their rounding, of
        # relative size eps * cond(S), enters J linearly
        d = np.abs(np.diag(S))
        kap = float(d.max() / d.min())  # a lower bound of cond(S), the scale that matters here
        size_b = float(np.linalg.norm(self._qfactor.conj().T @ self.B))
        size_c = float(np.linalg.norm(rom.C @ S))
        out.residual_floor = 4.0 * EPS * kap * (np.sqrt(j1) * size_b + np.sqrt(j2) * size_c) + 4.0 * EPS * (j1 + j2)
        return out


def _pairs(lam, R):
    """Order eigenpairs as [real, upper, conj(upper)] with exactly conjugate partners; None if impossible."""
    up = np.flatnonzero(lam.imag > 0)
    down = np.flatnonzero(lam.imag < 0)
    real = np.flatnonzero(lam.imag == 0)
    if up.size != down.size:
        return None
    lam_o = np.concatenate([lam[real].real.astype(complex), lam[up], lam[up].conj()])
    R_o = np.hstack([R[:, real].real.astype(complex), R[:, up], R[:, up].conj()])
    return lam_o, R_o, real.size, up.size


class FullTarget:
    r"""The index-3 model as target: its cross terms from saddle-point solves at the mirrored poles.

    With the reduced eigen-decomposition :math:`A_rR = R\Lambda`,
    :math:`\beta_k^T = (R^{-1}B_r)_k`, :math:`\gamma_k = C_rr_k`, :math:`\sigma_k = -\lambda_k`,
    and :math:`v_k = P(\sigma_k)^{-1}F\beta_k`, :math:`w_k = P(\sigma_k)^{-T}L^T\gamma_k`
    (:math:`P(s) = s^2M + sD + K` restricted to :math:`\ker G`: the saddle-point solve,
    Lemma 1 of the paper),

    .. math::

        CX = [Lv_k]R^T,\quad Y^TB = R^{-T}[w_k^TF]_k,\quad
        Y^TEX = R^{-T}\,\bigl[w_k^T((\sigma_k + \sigma_l)M + D)v_l\bigr]_{kl}\,R^T,

    and :math:`\langle T, T_r\rangle = \sum_k\gamma_k^TT(\sigma_k)\beta_k`. One LU per real pole
    or conjugate pair (the conjugate's solves are the conjugates), one right and one transposed
    solve with it. Accuracy is bounded by the condition number of :math:`R` (``details["kappa"]``).

    Parameters
    ----------
    system : ConstrainedSystem
    norm2, norm2_floor : float
        :math:`\|T\|_{\mathcal H_2}^2` and its absolute accuracy (:func:`morsuite.linalg.h2.norm_squared`).
    """

    def __init__(self, system, norm2: float, norm2_floor: float = 0.0):
        self.system = check_system(system)
        self.norm2, self.norm2_floor = float(norm2), float(norm2_floor)
        self.m, self.p = system.m, system.p
        self.solver = new_solver(system, cache_size=2)

    @property
    def lu_count(self) -> int:
        """Sparse LUs made so far (one per real pole or conjugate pair evaluated)."""
        return int(self.solver.stats.factorizations)

    def cross(self, rom: _Rom) -> Cross:
        """The cross terms of ``rom`` against the full model: one LU per real mirrored pole or
        conjugate pair, one right and one transposed solve with it."""
        sysm = self.system
        lam, R = np.linalg.eig(rom.A)
        paired = _pairs(lam, R)
        if paired is None:
            raise InputError("the reduced model's poles are not closed under conjugation")
        lam, R, nreal, nup = paired
        Ri = np.linalg.inv(R)
        Bh = Ri @ rom.B                 # rows beta_k^T
        Ch = rom.C @ R                  # columns gamma_k
        n = lam.size
        k_solve = nreal + nup
        before = self.lu_count
        V = np.empty((sysm.n1, n), dtype=complex)
        W = np.empty((sysm.n1, n), dtype=complex)
        for k in range(k_solve):
            lu = self.solver.factor(-lam[k])
            V[:, k] = lu.solve(sysm.F @ Bh[k]).reshape(-1)
            W[:, k] = lu.solve(sysm.L.T @ Ch[:, k], trans=True).reshape(-1)
        V[:, k_solve:] = V[:, nreal:k_solve].conj()
        W[:, k_solve:] = W[:, nreal:k_solve].conj()
        sig = -lam
        LV = sysm.L @ V
        FW = sysm.F.T @ W
        G = (W.T @ (sysm.M @ V)) * (sig[:, None] + sig[None, :]) + W.T @ (sysm.D @ V)
        terms = np.sum(Ch * LV, axis=0)
        kappa = float(np.linalg.cond(R / np.linalg.norm(R, axis=0)))
        return Cross((LV @ R.T).real, (Ri.T @ FW.T).real, (Ri.T @ G @ R.T).real, float(np.sum(terms).real),
                     float(np.sum(np.abs(terms))), lu_count=self.lu_count - before,
                     details={"kappa": kappa, "shifts": (-lam[:k_solve]).tolist()})


@dataclass
class H2Evaluation:
    """One evaluation of :func:`h2_objective`.

    ``value``: :math:`J = \\|T - T_r\\|^2` (the cancellation-free form where the target has
    one, else the three-term form); ``floor``: its estimated absolute accuracy; ``three_term``
    and ``three_term_floor``: the three-term form and its rounding; ``gradient``: (dK, dD, dF,
    dL) or None; ``stable``; ``lu_count``; ``details``.
    """

    value: float
    floor: float
    three_term: float
    three_term_floor: float
    gradient: tuple | None
    stable: bool
    lu_count: int = 0
    details: dict = field(default_factory=dict)


def _unstable(reason):
    return H2Evaluation(np.inf, 0.0, np.inf, 0.0, None, False, details={"reason": reason})


def _lyapunov(T, Q, W, adjoint):
    r"""Real X with :math:`AX + XA^T + W = 0` (``adjoint``: :math:`A^TX + XA + W = 0`) from the complex
    Schur form :math:`A = QTQ^H` of a real A: one triangular Sylvester solve (LAPACK trsyl)."""
    Wh = Q.conj().T @ W @ Q
    if adjoint:
        Xh, scale, info = _trsyl(T, T, -Wh, trana="C", tranb="N")
    else:
        Xh, scale, info = _trsyl(T, T, -Wh, trana="N", tranb="C")
    if info < 0:
        raise InputError(f"trsyl failed (info {info})")
    X = (Q @ (Xh / scale) @ Q.conj().T).real
    return 0.5 * (X + X.T)


def _psd_factor(X):
    """S with S S^T = X for a symmetric positive semidefinite X (eigh; negative rounding clipped)."""
    w, U = np.linalg.eigh(X)
    return U * np.sqrt(np.clip(w, 0.0, None))


def _balancing(P, Qo):
    r"""(T, T^{-1}) with :math:`T^{-1}PT^{-T} = T^TQ_oT = \Sigma`, or None when a Hankel singular value is
    below ``BALANCE_TOL`` of the largest (the reduced model is numerically not minimal)."""
    Sp, Sq = _psd_factor(P), _psd_factor(Qo)
    U, hsv, Vt = np.linalg.svd(Sq.T @ Sp)
    if not hsv.size or not hsv[-1] > BALANCE_TOL * hsv[0]:
        return None
    s = 1.0 / np.sqrt(hsv)
    return Sp @ Vt.T * s, (U * s).T @ Sq.T


#: smallest relative Hankel singular value of a reduced model that is balanced before an evaluation
BALANCE_TOL = 1e-13


def h2_value(target, A, B, C, *, gradient: bool = False, balance: bool = True) -> H2Evaluation:
    r""":math:`J = \|T - T_r\|_{\mathcal H_2}^2` for a stable first-order :math:`T_r = C(sI - A)^{-1}B`.

    With ``gradient=True``, ``H2Evaluation.gradient`` is Wilson's
    :math:`(\nabla_AJ, \nabla_BJ, \nabla_CJ)` (module docstring). ``value = inf``
    and ``stable = False`` when a pole has a real part :math:`\ge 0` (no solve is made).

    ``balance``: the evaluation is made in the reduced model's balanced coordinates
    (:math:`P_r = Q_r = \Sigma_r`; the gradient is mapped back), where the Cholesky
    factor of :math:`P_r` in the cancellation-free value has condition
    :math:`(\sigma_1/\sigma_{2r})^{1/2}`; in the coordinates of a second-order model,
    :math:`P_r` is often singular to working precision (dsms(600) at r = 10). The
    transformation perturbs the reduced model by about :math:`\varepsilon\kappa(T)`, which
    changes :math:`J` by :math:`2\varepsilon\kappa(T)\|T_r\|\,\|T - T_r\|` only. Skipped
    when a Hankel singular value is below ``BALANCE_TOL`` of the largest. Cost: two
    Schur forms, four triangular Sylvester solves, an SVD, all 2r x 2r.
    """
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B)) and np.all(np.isfinite(C))):
        return _unstable("non-finite reduced matrices")
    T, Q = sla.schur(np.asarray(A, dtype=complex), output="complex")
    poles = np.diag(T)
    if not np.all(poles.real < 0):
        return _unstable(f"unstable reduced model (max real part {poles.real.max():.3e})")
    P, Qo = _lyapunov(T, Q, B @ B.T, False), _lyapunov(T, Q, C.T @ C, True)
    tb = _balancing(P, Qo) if balance else None
    if tb is None:
        rom = _Rom(A, B, C, T, Q, P, Qo)
    else:
        A1, B1, C1 = tb[1] @ A @ tb[0], tb[1] @ B, C @ tb[0]
        T1, Q1 = sla.schur(A1.astype(complex), output="complex")
        rom = _Rom(A1, B1, C1, T1, Q1, _lyapunov(T1, Q1, B1 @ B1.T, False), _lyapunov(T1, Q1, C1.T @ C1, True))
    cr = target.cross(rom)
    self2 = float(np.trace(rom.C @ rom.P @ rom.C.T))
    three = target.norm2 - 2.0 * cr.inner + self2
    three_floor = (target.norm2_floor
                   + 2.0 * EPS * (target.norm2 + 2.0 * cr.inner_abs + abs(self2)) * np.sqrt(A.shape[0]))
    value, floor = three, three_floor
    if cr.residual_value is not None and cr.residual_floor < three_floor:
        value, floor = cr.residual_value, cr.residual_floor
    grad = None
    if gradient:
        gA = 2.0 * (rom.Qo @ rom.P - cr.YEX)
        gB = 2.0 * (rom.Qo @ rom.B - cr.YB)
        gC = 2.0 * (rom.C @ rom.P - cr.CX)
        if tb is not None:  # A1 = Ti A T, B1 = Ti B, C1 = C T
            Tm, Ti = tb
            gA, gB, gC = Ti.T @ gA @ Tm.T, Ti.T @ gB, gC @ Tm.T
        grad = (gA, gB, gC)
    details = {"max_pole_real": float(poles.real.max()), "rom_norm2": self2, "balanced": tb is not None,
               **cr.details}
    return H2Evaluation(float(value), float(floor), float(three), float(three_floor), grad, True, cr.lu_count,
                        details)


def h2_objective(target, K, D, F, L, *, gradient: bool = True) -> H2Evaluation:
    r""":math:`J = \|T - T_r\|_{\mathcal H_2}^2` and its gradient in :math:`(\hat K, \hat D, \hat F, \hat L)`.

    Parameters
    ----------
    target : ModalTarget or FullTarget
    K, D : (r, r) arrays; F : (r, m); L : (p, r)
        The reduced model with :math:`\hat M = I`.
    gradient : bool
        Also compute the gradient (module docstring): the cross terms, which the
        value needs anyway, and one more r x r Lyapunov solve.

    Returns
    -------
    H2Evaluation
        ``gradient = (dJ/dK, dJ/dD, dJ/dF, dJ/dL)``; ``value = inf`` and
        ``stable = False`` when a reduced pole has a real part :math:`\ge 0`.
    """
    ev = h2_value(target, *second_order_realization(K, D, F, L), gradient=gradient)
    if ev.gradient is not None:
        gA, gB, gC = ev.gradient
        r = K.shape[0]
        ev.gradient = (-gA[r:, :r], -gA[r:, r:], gB[r:], gC[:, :r])
    return ev


def gauss_newton_diagonal(K, D, F, L, *, n_log: int = 300, n_peak: int = 24):
    r"""Diagonal of the Gauss-Newton matrix :math:`2\langle\partial_jT_r, \partial_jT_r\rangle_{\mathcal H_2}`
    for the entries of :math:`\hat K, \hat D, \hat F, \hat L` (a preconditioner of the descent).

    With :math:`R(s) = (s^2I + s\hat D + \hat K)^{-1}`, :math:`a(s) = \hat LR(s)`,
    :math:`b(s) = R(s)\hat F`: :math:`\partial T_r/\partial\hat K_{ij} = -a_{:,i}b_{j,:}`,
    :math:`\partial T_r/\partial\hat D_{ij} = -s\,a_{:,i}b_{j,:}`,
    :math:`\partial T_r/\partial\hat F_{jq} = a_{:,j}e_q^T`,
    :math:`\partial T_r/\partial\hat L_{qi} = e_qb_{i,:}`, so the diagonal is
    :math:`\frac2\pi\int_0^\infty |a_{:,i}|^2|b_{j,:}|^2\,(1, \omega^2)\,d\omega`,
    :math:`\frac2\pi\int|a_{:,j}|^2`, :math:`\frac2\pi\int|b_{i,:}|^2`, integrated by the
    trapezoidal rule on ``n_log`` log-spaced frequencies around the reduced poles
    plus ``n_peak`` points across each resonance (a lightly damped pole
    :math:`-\delta + j\omega_p` has its peak of width :math:`\delta` resolved). It is
    exact for no parameter and need not be: it sets the scales of the variables,
    which differ by many orders of magnitude where poles are near the axis.

    Returns
    -------
    (HK, HD, HF, HL) with the shapes of K, D, F, L. Cost: one dense r x r solve per
    frequency (``n_log + n_peak r`` of them).
    """
    r = K.shape[0]
    lam = sla.eigvals(np.block([[np.zeros((r, r)), np.eye(r)], [-K, -D]]))
    lam = lam[np.isfinite(lam)]
    mags = np.abs(lam[np.abs(lam) > 0])
    if not mags.size:
        mags = np.ones(1)
    nodes = [np.geomspace(mags.min() / 30.0, mags.max() * 30.0, n_log)]
    t = np.tan(np.linspace(-1.45, 1.45, n_peak))
    for mu in lam[lam.imag > 0]:
        nodes.append(mu.imag + abs(mu.real) * t)
    w = np.unique(np.concatenate(nodes))
    w = w[w > 0]
    wt = np.gradient(w)
    s = 1j * w
    P = s[:, None, None] ** 2 * np.eye(r) + s[:, None, None] * D + K
    Rs = np.linalg.inv(P)
    a2 = np.sum(np.abs(L @ Rs) ** 2, axis=1)            # (nw, r): |a_{:,i}|^2
    b2 = np.sum(np.abs(Rs @ F) ** 2, axis=2)            # (nw, r): |b_{i,:}|^2
    c = 2.0 / np.pi
    HK = c * (a2 * wt[:, None]).T @ b2
    HD = c * (a2 * (wt * w * w)[:, None]).T @ b2
    HF = c * np.repeat((wt @ a2)[:, None], F.shape[1], axis=1)
    HL = c * np.repeat((wt @ b2)[None, :], L.shape[0], axis=0)
    return HK, HD, HF, HL
