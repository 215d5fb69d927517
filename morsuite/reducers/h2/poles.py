r"""The H2 error of a SISO reduced model in pole-residue coordinates: value, gradient, Hessian, the
residues that minimise it for given poles, the relative gradient, and the way back to second order.

A second-order reduced model :math:`T_r(s) = \hat L(s^2I + s\hat D + \hat K)^{-1}\hat F` of order r
is a first-order model of McMillan degree 2r with :math:`C_rB_r = 0`; conversely a generic SISO
:math:`T_r(s) = \sum_{k=1}^{2r}\varphi_k/(s - \lambda_k)` with :math:`\sum_k\varphi_k = 0` has
second-order realizations (:func:`second_order_of`: pick rows :math:`U` with :math:`c\in U`,
:math:`Ub = 0` and :math:`[U; UA]` invertible; :math:`x_1 = Ux`, :math:`x_2 = UAx`). Both sets have
dimension :math:`4r - 1`, so the second-order H2 problem is the first-order one under the linear
constraint :math:`\sum_k\varphi_k = 0`, in coordinates with no redundancy (the :math:`2r^2 + 2r`
entries of :math:`\hat K, \hat D, \hat F, \hat L` have :math:`2r^2 - 2r + 1` directions that leave
:math:`T_r` unchanged). The descent is in :mod:`~morsuite.reducers.h2.poles_descent`.

With :math:`E = T - T_r` and the holomorphic extension over all 2r poles,

.. math::

    J = \|T\|^2 - 2\sum_k\varphi_kT(-\lambda_k) + \sum_{k,l}\frac{\varphi_k\varphi_l}{-(\lambda_k+\lambda_l)},\quad
    \frac{\partial J}{\partial\varphi_k} = -2E(-\lambda_k),\quad
    \frac{\partial J}{\partial\lambda_k} = 2\varphi_kE'(-\lambda_k),

.. math::

    \frac{\partial^2J}{\partial\varphi_k\partial\varphi_l} = \frac{-2}{\lambda_k+\lambda_l},\quad
    \frac{\partial^2J}{\partial\lambda_l\partial\varphi_k} = \frac{2\varphi_l}{(\lambda_k+\lambda_l)^2}
    + 2\delta_{kl}E'(-\lambda_k),\quad
    \frac{\partial^2J}{\partial\lambda_k\partial\lambda_l} = \frac{-4\varphi_k\varphi_l}{(\lambda_k+\lambda_l)^3}
    - 2\delta_{kl}\varphi_kE''(-\lambda_k).

The terms without :math:`E` are the Gauss-Newton matrix :math:`G = 2\langle\partial T_r, \partial T_r\rangle`.
The real coordinates :math:`x` hold a real pole and residue per real slot, real and imaginary
parts per conjugate pair; derivatives in :math:`x` are :math:`P^T\nabla` and :math:`P^THP` with
:math:`P = \partial z/\partial x`. The constraint is eliminated by expressing the real part of
the largest residue by the others.

**Relative gradient** (:func:`relative_gradient`): :math:`\rho = (g^TG^{-1}g/(2J))^{1/2}
= \|\Pi E\|/\|E\|` with :math:`\Pi` the H2-orthogonal projection onto the tangent space of the
reduced models at :math:`T_r`: the cosine of the angle between the error and that tangent space,
in :math:`[0, 1]`, invariant under reparametrisation; 0 exactly at a stationary point. Against a
surrogate :math:`T_N`, the full model's :math:`\rho` differs by at most
:math:`\|T - T_N\|/\|E\|` (Cauchy-Schwarz).

Cost: :math:`O(nN)` for the target's values at the :math:`n = 2r` mirrored poles (a modal target
of order N), or one sparse LU per real pole or conjugate pair (the full model, first derivative
only), and :math:`O(r^3)` dense work per Hessian. Measurements: ``docs/design/so_h2.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ...errors import InputError

__all__ = ["Coordinates", "ModalValues", "FullValues", "PoleEvaluation", "evaluate", "optimal_residues",
           "chord_step", "relative_gradient", "second_order_of", "EPS"]

EPS = np.finfo(float).eps


class Coordinates:
    """Real coordinates of a SISO model with ``nr`` real poles and ``nc`` conjugate pairs.

    ``x = [lam_real (nr), phi_real (nr), Re lam (nc), Im lam (nc), Re phi (nc), Im phi (nc)]``; the
    holomorphic variables ``z = [lam (n), phi (n)]`` over all n = nr + 2 nc poles (real, upper,
    lower). ``Z`` (d x (d-1)) spans the constraint :math:`\\sum\\varphi = 0`.
    """

    def __init__(self, nr: int, nc: int, pivot: int | None = None):
        self.nr, self.nc = int(nr), int(nc)
        self.n = self.nr + 2 * self.nc
        self.d = 2 * self.nr + 4 * self.nc
        n, d, nr, nc = self.n, self.d, self.nr, self.nc
        P = np.zeros((2 * n, d), dtype=complex)
        for i in range(nr):
            P[i, i] = 1.0
            P[n + i, nr + i] = 1.0
        o = 2 * nr
        for j in range(nc):
            up, lo = nr + j, nr + nc + j
            P[up, o + j], P[up, o + nc + j] = 1.0, 1j
            P[lo, o + j], P[lo, o + nc + j] = 1.0, -1j
            P[n + up, o + 2 * nc + j], P[n + up, o + 3 * nc + j] = 1.0, 1j
            P[n + lo, o + 2 * nc + j], P[n + lo, o + 3 * nc + j] = 1.0, -1j
        self.P = P
        a = np.zeros(d)
        a[nr:2 * nr] = 1.0
        a[o + 2 * nc:o + 3 * nc] = 2.0
        self.a = a
        self.set_pivot(pivot if pivot is not None else int(np.flatnonzero(a)[0]))

    def set_pivot(self, j: int):
        """Eliminate coordinate j (a residue's real part) by the constraint."""
        a, d = self.a, self.d
        if a[j] == 0:
            raise InputError("the pivot must be a residue coordinate")
        keep = np.array([i for i in range(d) if i != j])
        Z = np.zeros((d, d - 1))
        Z[keep, np.arange(d - 1)] = 1.0
        Z[j, :] = -a[keep] / a[j]
        self.Z, self.pivot = Z, j
        is_lam = np.zeros(d, bool)
        is_lam[:self.nr] = True
        is_lam[2 * self.nr:2 * self.nr + 2 * self.nc] = True
        self.lam_mask = is_lam[keep]   # in reduced coordinates

    def split(self, x):
        """(lam, phi), each of length n (real, upper, lower)."""
        nr, nc = self.nr, self.nc
        o = 2 * nr
        lc = x[o:o + nc] + 1j * x[o + nc:o + 2 * nc]
        pc = x[o + 2 * nc:o + 3 * nc] + 1j * x[o + 3 * nc:o + 4 * nc]
        lam = np.concatenate([x[:nr].astype(complex), lc, lc.conj()])
        phi = np.concatenate([x[nr:2 * nr].astype(complex), pc, pc.conj()])
        return lam, phi

    def join(self, lam_real, phi_real, lam_up, phi_up):
        """x of real poles and residues and of the upper members of the conjugate pairs."""
        return np.concatenate([np.real(lam_real), np.real(phi_real), lam_up.real, lam_up.imag, phi_up.real,
                               phi_up.imag]).astype(float)

    def valid(self, x) -> bool:
        """Stable, and every pair still a pair (its imaginary part positive)."""
        lam, _ = self.split(x)
        nr, nc = self.nr, self.nc
        return bool(np.all(lam.real < 0) and np.all(lam[nr:nr + nc].imag > 0) and np.all(np.isfinite(x)))

    @classmethod
    def of_model(cls, A, B, C):
        """(Coordinates, x) of a stable SISO first-order model (A, B, C) with distinct poles; the pivot is
        the residue of largest modulus."""
        lam, X = sla.eig(A)
        Xn = X / np.linalg.norm(X, axis=0)
        phi = (C @ Xn)[0] * np.linalg.solve(Xn, B)[:, 0]
        real = lam.imag == 0
        up = lam.imag > 0
        co = cls(int(real.sum()), int(up.sum()))
        if co.n != lam.size:
            raise InputError("the poles are not closed under conjugation")
        x = co.join(lam[real], phi[real], lam[up], phi[up])
        # the constraint held by the model up to rounding: enforce it through the pivot
        w = np.abs(co.a * x)
        co.set_pivot(int(np.argmax(np.where(co.a != 0, np.abs(x), -1.0))) if w.any() else co.pivot)
        x[co.pivot] -= (co.a @ x) / co.a[co.pivot]
        return co, x


class ModalValues:
    r"""A dense SISO target in modal form, :math:`T(s) = \sum_j\psi_j/(s - \mu_j)`, and its derivatives."""

    def __init__(self, target):
        self.mu = np.asarray(target.poles)
        self.psi = np.asarray(target.C)[0] * np.asarray(target.B)[:, 0]
        self.norm2, self.norm2_floor = float(target.norm2), float(target.norm2_floor)
        self.lu_count = 0
        self.target = target

    def precise(self, co, x):
        r"""(J, floor) at x without the cancellation of the pole-residue formula: the residual form of
        :func:`~morsuite.reducers.h2.gradient.h2_value` on a real realization (its rounding
        :math:`\varepsilon\kappa\|T\|\|E\|` instead of :math:`\varepsilon\|T\|^2`)."""
        from .gradient import h2_value
        ev = h2_value(self.target, *_real_modal(co, x)[:1], *_bc(co, x))
        return ev.value, ev.floor

    def projected(self, co, x):
        r"""(J, floor) of the best model with the poles of x (the residues the optimal ones, as variable
        projection makes them): :func:`~morsuite.reducers.h2.orthonormal.projection_value`, cancellation-free like
        :meth:`precise` and without its Schur forms, Lyapunov solves and balancing (timings:
        ``docs/design/so_h2.md``, 2026-11-26, third session)."""
        from .orthonormal import projection_value
        t = self.target
        return projection_value(co.split(x)[0], t.poles, t.B[:, 0], t.C[0], t.gramian_factor)

    def values(self, s, second: bool = True):
        """(T(s), T'(s), T''(s) or None) at the points s."""
        R = 1.0 / (s[:, None] - self.mu[None, :])
        t0 = R @ self.psi
        R2 = R * R
        t1 = -(R2 @ self.psi)
        t2 = 2.0 * ((R2 * R) @ self.psi) if second else None
        return t0, t1, t2


def _bc(co, x):
    A, b, c = _real_modal(co, x)
    return b[:, None], c[None, :]


class FullValues:
    r"""The index-3 model as target: :math:`T(\sigma) = Lx`, :math:`T'(\sigma) = -w^T(2\sigma M + D)x` from
    the saddle-point solves :math:`P(\sigma)x = F`, :math:`P(\sigma)^Tw = L^T` (one LU per real point or
    conjugate pair, through the :class:`~morsuite.reducers.h2.gradient.FullTarget`'s solver), refined
    ``refine`` times in long double."""

    def __init__(self, full, refine: int = 2):
        from .stationarity import saddle_solver_refined
        self.full = full
        self.norm2, self.norm2_floor = full.norm2, full.norm2_floor
        self._solves = saddle_solver_refined(full, refine)

    @property
    def lu_count(self):
        """Sparse LUs made by the underlying solver so far."""
        return self.full.lu_count

    def values(self, s, second: bool = False):
        """(T(s), T'(s), None) at points s closed under conjugation (one LU per real point or pair)."""
        sysm = self.full.system
        t0 = np.empty(s.size, dtype=complex)
        t1 = np.empty(s.size, dtype=complex)
        done = np.zeros(s.size, bool)
        for k in range(s.size):
            if done[k]:
                continue
            x, w = self._solves(s[k], sysm.F[:, 0], sysm.L[0])
            t0[k] = sysm.L[0] @ x
            t1[k] = -(w @ (2.0 * s[k] * (sysm.M @ x) + sysm.D @ x))
            done[k] = True
            if s[k].imag != 0:
                j = np.flatnonzero(~done & (s == np.conj(s[k])))
                if j.size:
                    t0[j[0]], t1[j[0]], done[j[0]] = np.conj(t0[k]), np.conj(t1[k]), True
        return t0, t1, None


@dataclass
class PoleEvaluation:
    """J, its rounding floor, and (reduced by the constraint) gradient, Hessian, Gauss-Newton matrix,
    relative gradient."""

    x: np.ndarray
    value: float
    floor: float
    g: np.ndarray
    H: np.ndarray | None
    G: np.ndarray
    values: tuple = None
    _rho: float | None = None

    @property
    def rho(self) -> float:
        """The relative gradient (:func:`relative_gradient`), computed on first use."""
        if self._rho is None:
            self._rho = relative_gradient(self.g, self.G, self.value)
        return self._rho


#: unit roundoff of the extended precision of :func:`evaluate` with long-double values (1.1e-19 on x86-64,
#: the double's 2.2e-16 where long double is double)
EPS_EXTENDED = float(np.finfo(np.longdouble).eps)


def evaluate(co: Coordinates, x, target, *, hessian: bool = True, values=None) -> PoleEvaluation | None:
    """J and its derivatives at x against ``target`` (:class:`ModalValues` or :class:`FullValues`;
    ``hessian`` needs the target's second derivative); None outside the domain (module docstring).
    ``values``: the target's values at the mirrored poles if known."""
    if not co.valid(x):
        return None
    lam, phi = co.split(x)
    n = co.n
    t0, t1, t2 = values if values is not None else target.values(-lam, second=hessian)
    # the error's values and J in the precision of the target's values: long double (``clongdouble``,
    # the SIMO surrogate) keeps the rounding of the error at eps_ext ||T|| instead of eps ||T||: on
    # dsms(g=60) at r = 10 the gradient from double values was off by 4e-5 to 7e-4 of its norm against a
    # 34-digit reference, from long-double ones by 7e-8 to 4e-7; the target's ``norm2`` is then read in
    # long double and the floor is in the extended unit
    ext = np.asarray(t0).dtype == np.clongdouble
    lamX, phiX = (lam.astype(np.clongdouble), phi.astype(np.clongdouble)) if ext else (lam, phi)
    norm2 = np.longdouble(target.norm2) if ext else target.norm2
    iSX = 1.0 / (lamX[:, None] + lamX[None, :])
    iS2X = iSX * iSX
    e0, e1 = t0 - (-(iSX @ phiX)), t1 - (-(iS2X @ phiX))
    e2 = t2 - (-2.0 * ((iS2X * iSX) @ phiX)) if hessian else None
    cross = phiX * t0
    selfm = phiX[:, None] * phiX[None, :] * (-iSX)
    J = float(norm2 - 2.0 * np.sum(cross).real + np.sum(selfm).real)
    floor = float(target.norm2_floor) + 2.0 * (EPS_EXTENDED if ext else EPS) * np.sqrt(n) * float(
        abs(norm2) + 2.0 * np.sum(np.abs(cross)) + np.sum(np.abs(selfm)))
    if ext:  # the derivatives' assembly in double
        e0, e1, e2 = e0.astype(complex), e1.astype(complex), None if e2 is None else e2.astype(complex)
        iSX = 1.0 / (lam[:, None] + lam[None, :])
        iS2X = iSX * iSX
    g, G, H = _derivatives(co, phi, iSX, iS2X, e0, e1, e2)
    return PoleEvaluation(np.asarray(x, float), J, float(floor), g, H, G, (t0, t1, t2))


def _derivatives(co, phi, iS, iS2, e0, e1, e2):
    """(g, G, H or None) in the reduced real coordinates from the error's values e0, e1 (and e2 for H) at
    the mirrored poles; ``iS`` = 1 / (lambda_k + lambda_l), ``iS2`` its square (module docstring)."""
    n = co.n
    P, Z = co.P, co.Z
    gz = np.concatenate([2.0 * phi * e1, -2.0 * e0])
    g = Z.T @ (P.T @ gz).real
    Hgn = np.empty((2 * n, 2 * n), dtype=complex)
    Hgn[:n, :n] = -4.0 * phi[:, None] * phi[None, :] * iS2 * iS
    Hgn[:n, n:] = 2.0 * phi[:, None] * iS2
    Hgn[n:, :n] = Hgn[:n, n:].T
    Hgn[n:, n:] = -2.0 * iS
    G = Z.T @ (P.T @ Hgn @ P).real @ Z
    H = None
    if e2 is not None:
        Hz = Hgn.copy()
        idx = np.arange(n)
        Hz[idx, idx] += -2.0 * phi * e2
        Hz[idx, n + idx] += 2.0 * e1
        Hz[n + idx, idx] += 2.0 * e1
        H = Z.T @ (P.T @ Hz @ P).real @ Z
    return g, G, H


def relative_gradient(g, G, J) -> float:
    r""":math:`\rho = (g^TG^+g/(2J))^{1/2}`: the norm of the error's projection onto the tangent space of
    the reduced models over the error's norm (module docstring); ``inf`` for :math:`J \le 0`.
    Cost: one symmetric eigen-decomposition of G."""
    if not J > 0:
        return np.inf
    d = np.sqrt(np.maximum(np.diag(G), np.finfo(float).tiny))
    w, U = np.linalg.eigh(G / d[:, None] / d[None, :])
    keep = w > 1e-13 * w.max()
    y = U[:, keep].T @ (g / d)
    return float(np.sqrt(max(float(np.sum(y * y / w[keep])), 0.0) / (2.0 * J)))


def _scaling(H, G):
    """The damping diagonal: the Gauss-Newton diagonal, raised to the Hessian's where that is larger
    (a pole whose residue vanishes has no Gauss-Newton curvature but can have a Hessian one), and to
    1e-12 of the largest."""
    d = np.maximum(np.diag(G), np.abs(np.diag(H)))
    return np.maximum(d, 1e-12 * d.max())


def _step(H, G, g, mu):
    """The Levenberg-Marquardt / trust-region step (H + mu D) p = -g (D: :func:`_scaling`); None if
    not positive definite."""
    A = H + mu * np.diag(_scaling(H, G))
    try:
        c = sla.cho_factor(A)
    except (np.linalg.LinAlgError, ValueError):
        return None
    return -sla.cho_solve(c, g)


def optimal_residues(co: Coordinates, x, target, *, hessian: bool = True) -> PoleEvaluation | None:
    r"""The evaluation at the poles of x with the residues that minimise J for them: J is quadratic in
    the residues with the Gauss-Newton block as its Hessian, so one solve gives them (variable
    projection). One evaluation of the target's values."""
    if not co.valid(x):
        return None
    vals = target.values(-co.split(x)[0], second=hessian)
    ev = evaluate(co, x, target, hessian=False, values=vals)
    y = ~co.lam_mask
    try:
        dy = -np.linalg.solve(ev.G[np.ix_(y, y)], ev.g[y])
    except np.linalg.LinAlgError:
        return None
    x2 = ev.x + co.Z[:, y] @ dy
    return evaluate(co, x2, target, hessian=hessian, values=ev.values)


def chord_step(co: Coordinates, ev_full: PoleEvaluation, H_sur, mu: float = 0.0):
    r"""x of a Newton step on the full model's gradient with the surrogate's Hessian,
    :math:`x - Z(H_s + \mu\,\mathrm{diag}(G))^{-1}g` (None if not positive definite)."""
    p = _step(H_sur, ev_full.G, ev_full.g, mu)
    return None if p is None else ev_full.x + co.Z @ p


def _real_modal(co: Coordinates, x):
    """A real block-diagonal realization (A, b, c) of the model at x: a real pole as it is, a pair
    :math:`\\lambda = a + ib`, :math:`\\varphi = \\alpha + i\\beta` as [[a, -b], [b, a]], [1; 0],
    [2 alpha, -2 beta]."""
    lam, phi = co.split(x)
    nr, nc = co.nr, co.nc
    N = nr + 2 * nc
    A = np.zeros((N, N))
    b = np.zeros(N)
    c = np.zeros(N)
    for i in range(nr):
        A[i, i], b[i], c[i] = lam[i].real, 1.0, phi[i].real
    for j in range(nc):
        l, f = lam[nr + j], phi[nr + j]
        i = nr + 2 * j
        A[i:i + 2, i:i + 2] = [[l.real, -l.imag], [l.imag, l.real]]
        b[i] = 1.0
        c[i], c[i + 1] = 2.0 * f.real, -2.0 * f.imag
    return A, b, c


def second_order_of(co: Coordinates, x):
    r"""(K, D, F, L) with :math:`\hat M = I` of the SISO model at x (its residues summing to 0).

    From a real block-diagonal realization (A, b, c), :math:`x_1 = Ux`, :math:`x_2 = UAx` with rows
    :math:`U` = c and the "position" rows :math:`e_{2j}` of all pairs but one (and the real poles
    taken two by two), the dropped pair chosen for the best-conditioned :math:`[U; UA]`; then
    :math:`[-K, -D] = UA^2[U; UA]^{-1}`, :math:`F = UAb`, :math:`L = (\|c\|, 0, \dots)`.
    Raises InputError when no choice gives an invertible :math:`[U; UA]`.
    """
    A, b, c = _real_modal(co, x)
    N = A.shape[0]
    if N % 2:
        raise InputError("an odd number of poles has no second-order realization")
    r = N // 2
    # rows orthogonal to b: a pair's imaginary coordinate (b = [1; 0] there), a real pole's pair of
    # coordinates combined as e_i - e_j (b = 1 at both)
    rows = [np.eye(N)[co.nr + 2 * j + 1] for j in range(co.nc)]
    for i in range(0, co.nr - 1, 2):
        rows.append(np.eye(N)[i] - np.eye(N)[i + 1])
    cn = c / np.linalg.norm(c)
    best = None
    for drop in range(len(rows)):
        U = np.vstack([cn] + [rw for k, rw in enumerate(rows) if k != drop][:r - 1])
        if U.shape[0] != r:
            continue
        S = np.vstack([U, U @ A])
        kap = np.linalg.cond(S)
        if best is None or kap < best[0]:
            best = (kap, U, S)
    if best is None or not best[0] < 1e12:
        raise InputError("no well-conditioned second-order realization of the pole-residue model was found")
    _, U, S = best
    KD = -np.linalg.solve(S.T, (U @ A @ A).T).T
    K, D = KD[:, :r], KD[:, r:]
    F = (U @ A @ b)[:, None]
    L = np.zeros((1, r))
    L[0, 0] = np.linalg.norm(c)
    return K, D, F, L
