r"""The pole-residue phase of ``so-h2`` for single-input models with several outputs (SIMO; the DSMS).

A second-order reduced model with one input, :math:`T_r(s) = \hat L(s^2I + s\hat D + \hat K)^{-1}\hat f`,
is a first-order model of degree 2r whose vector residues :math:`\varphi_k\in\mathbb C^p` (the
residue of output i: :math:`\varphi_k^{(i)}`) sum to zero, and, generically, back
(:func:`second_order_of`: rows :math:`U` that hold the rows of C, with :math:`Ub = 0`). For fixed poles
:math:`\lambda` the H2 error separates over the outputs,

.. math::

    J(\lambda, \varphi) = \sum_{i=1}^p J_i(\lambda, \varphi^{(i)}),\qquad
    J_i = \|T_i - \textstyle\sum_k\varphi_k^{(i)}/(s - \lambda_k)\|^2,

each :math:`J_i` the SISO objective of :mod:`morsuite.reducers.h2.poles` for output i with the same poles
and its own constraint :math:`\sum_k\varphi_k^{(i)} = 0`. So the gradient and Hessian in
:math:`(\lambda, \varphi^{(1)}, \dots, \varphi^{(p)})` are assembled from the p SISO ones: the pole
blocks summed, the residue blocks block-diagonal (the outputs do not couple through the residues).
Variable projection (each output's residues by one solve) and the trust-region Newton over the poles
with the Schur complement (:func:`~morsuite.reducers.h2.poles_descent.varpro_descent`) then run
unchanged; the Schur complement is the sum of the outputs' Schur complements. A model with one output
and several inputs is the transpose of one of these (not used: so-h2 takes this path for m = 1).

At the DSMS's errors (1e-8 to 1e-10 of :math:`\|T\|` from r = 10) three things decide whether the descent
moves: the error's values at the mirrored poles are formed in long double against the surrogate
(:class:`SimoModalValues`; in double they were rounding to 1e-7 of themselves, 1e-4 of the gradient); the
trust region's decisions read J as the value of the projection (:meth:`SimoModalValues.projected`, smooth in
the poles to 1e-5 of J where the residual form's rounding is 1e-3 of it); the poles' gradient is that of
:math:`J(\lambda)` with the residues' remaining gradient eliminated (``reduced_gradient`` of
:func:`~morsuite.reducers.h2.poles_descent.varpro_descent`). Measurements: ``docs/design/so_h2.md``
(2026-11-28, second session).

Against the full model the values :math:`T(\sigma)` (p entries) and :math:`T'(\sigma)` need one LU per
real point or conjugate pair, one right solve with F and p transposed solves with the rows of L
(:class:`FullValues`, refined in long double). Cost: p times the SISO dense work per iteration.
Measurements: ``docs/design/so_h2.md`` (2026-11-28).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.linalg as sla

from ...errors import InputError
from .poles import (EPS_EXTENDED, Coordinates, PoleEvaluation, _real_modal, chord_step, evaluate,
                    relative_gradient)
from .poles_descent import varpro_descent
from .starts import standard_realization

__all__ = ["SimoCoordinates", "SimoModalValues", "SimoFullValues", "simo_evaluate", "simo_optimal_residues",
           "simo_descent",
           "simo_second_order_of", "simo_phase"]


class _Out:
    """What :func:`~morsuite.reducers.h2.poles.evaluate` reads of a target when its values are given."""

    def __init__(self, norm2, norm2_floor):
        # long double kept where given (SimoModalValues: poles.evaluate's extended branch reads it)
        self.norm2, self.norm2_floor = norm2, float(norm2_floor)


class SimoCoordinates:
    r"""Real coordinates of a SIMO model: the poles' coordinates once, then each output's residue
    coordinates (the layout of :class:`~morsuite.reducers.h2.poles.Coordinates` per output, each with its
    own pivot eliminating its constraint). Full vector: ``[poles (n), residues of output 1 (n), ...]``;
    reduced (``Z``): the pivots removed, the pole coordinates first (``lam_mask``)."""

    def __init__(self, nr: int, nc: int, pivots):
        self.cos = [Coordinates(nr, nc, pivot=int(j)) for j in pivots]
        co = self.cos[0]
        self.nr, self.nc, self.n, self.p = co.nr, co.nc, co.n, len(self.cos)
        is_lam = np.zeros(co.d, bool)
        is_lam[:co.nr] = True
        is_lam[2 * co.nr:2 * co.nr + 2 * co.nc] = True
        self._lam_full = np.flatnonzero(is_lam)
        self._phi_full = np.flatnonzero(~is_lam)
        n, p = self.n, self.p
        self.d = n + p * n
        # Z: the pole block identity, each output's residue block its Coordinates' Z restricted to residues
        Z = np.zeros((self.d, n + p * (n - 1)))
        Z[:n, :n] = np.eye(n)
        for i, c in enumerate(self.cos):
            zi = c.Z[np.ix_(self._phi_full, ~c.lam_mask)]
            Z[n + i * n:n + (i + 1) * n, n + i * (n - 1):n + (i + 1) * (n - 1)] = zi
        self.Z = Z
        self.lam_mask = np.zeros(Z.shape[1], bool)
        self.lam_mask[:n] = True

    def siso(self, x, i):
        """The SISO coordinates vector of output i."""
        xi = np.empty(self.cos[0].d)
        xi[self._lam_full] = x[:self.n]
        xi[self._phi_full] = x[self.n + i * self.n:self.n + (i + 1) * self.n]
        return xi

    def split(self, x):
        """(lam (n,), phi (p, n)) over all poles (real, upper, lower)."""
        lam = self.cos[0].split(self.siso(x, 0))[0]
        return lam, np.array([self.cos[i].split(self.siso(x, i))[1] for i in range(self.p)])

    def valid(self, x) -> bool:
        """Stable, every pair still a pair, finite."""
        return bool(self.cos[0].valid(self.siso(x, 0)) and np.all(np.isfinite(x)))

    def realization(self, x):
        r"""A real block-diagonal realization (A, b (N, 1), C (p, N)) of the model at x."""
        A, b, _ = _real_modal(self.cos[0], self.siso(x, 0))
        C = np.array([_real_modal(self.cos[i], self.siso(x, i))[2] for i in range(self.p)])
        return A, b[:, None], C

    @classmethod
    def of_model(cls, A, B, C):
        """(SimoCoordinates, x) of a stable first-order model (A, B (N, 1), C (p, N)) with distinct poles;
        each output's pivot is its residue coordinate of largest modulus, its constraint enforced through it."""
        lam, X = sla.eig(A)
        Xn = X / np.linalg.norm(X, axis=0)
        phi = (C @ Xn) * np.linalg.solve(Xn, B)[:, 0][None, :]
        real = lam.imag == 0
        up = lam.imag > 0
        co0 = Coordinates(int(real.sum()), int(up.sum()))
        if co0.n != lam.size:
            raise InputError("the poles are not closed under conjugation")
        xs, pivots = [], []
        for i in range(C.shape[0]):
            xi = co0.join(lam[real], phi[i, real], lam[up], phi[i, up])
            piv = int(np.argmax(np.where(co0.a != 0, np.abs(xi), -1.0)))
            if not co0.a[piv]:      # an output with all residues zero: any residue coordinate
                piv = int(np.flatnonzero(co0.a)[0])
            xi[piv] -= (co0.a @ xi) / co0.a[piv]
            xs.append(xi)
            pivots.append(piv)
        sco = cls(co0.nr, co0.nc, pivots)
        x = np.concatenate([xs[0][sco._lam_full]] + [xi[sco._phi_full] for xi in xs])
        return sco, x


class SimoModalValues:
    r"""A dense single-input target in modal form, :math:`T(s) = \sum_j\psi_j/(s - \mu_j)` with
    :math:`\psi_j\in\mathbb C^p`, its values and derivatives by output, and the cancellation-free value
    (:func:`~morsuite.reducers.h2.gradient.h2_value`)."""

    def __init__(self, target):
        L = np.clongdouble
        self.target = target
        self.mu = np.asarray(target.poles).astype(L)
        # the target as given (double) is the target; its values, norms and errors are formed in long double
        # (poles.evaluate's extended branch): the error's values at 1e-11 of the terms keep their digits
        self.psi = np.asarray(target.C).astype(L) * np.asarray(target.B)[:, 0].astype(L)[None, :]     # (p, N)
        S = -(self.mu[:, None] + np.conj(self.mu)[None, :])
        n2 = np.real(np.einsum("ij,jk,ik->i", self.psi, 1.0 / S, np.conj(self.psi)))
        self.outputs = [_Out(v, 2.0 * EPS_EXTENDED * self.mu.size * abs(v)) for v in n2]
        self.norm2, self.norm2_floor = float(target.norm2), float(target.norm2_floor)
        self.lu_count = 0

    def values(self, s, second: bool = True):
        """(T(s), T'(s), T''(s) or None), each (p, len(s)), in long double (``clongdouble``)."""
        R = 1.0 / (np.asarray(s).astype(np.clongdouble)[:, None] - self.mu[None, :])
        R2 = R * R
        t0 = (R @ self.psi.T).T
        t1 = -(R2 @ self.psi.T).T
        t2 = 2.0 * ((R2 * R) @ self.psi.T).T if second else None
        return t0, t1, t2

    def precise(self, co, x):
        r"""(J, floor) without the pole-residue formula's cancellation (the residual form of
        :func:`~morsuite.reducers.h2.gradient.h2_value`). Its floor, :math:`4\varepsilon\kappa\|T\|\|E\|`, is a
        worst case that exceeded the spread of J over orthogonally transformed realizations of the same model
        by about 1e3 at the DSMS's errors of 1e-10 (docs/design/so_h2.md, 2026-11-28): the floor returned is
        the smaller of that bound and an estimate, ``SPREAD_SAFETY`` times the difference between J of the
        realization and of one fixed orthogonal transformation of it, plus :math:`4\varepsilon J`."""
        from .gradient import h2_value
        A, B, C = co.realization(x)
        ev = h2_value(self.target, A, B, C)
        if not np.isfinite(ev.value):
            return ev.value, ev.floor
        Q = _rotation(A.shape[0])
        ev2 = h2_value(self.target, Q.T @ A @ Q, Q.T @ B, C @ Q)
        spread = SPREAD_SAFETY * abs(ev.value - ev2.value) + 4.0 * np.finfo(float).eps * abs(ev.value)
        return ev.value, float(min(ev.floor, spread))


    def projected(self, co, x):
        r"""(J, floor) of the best model with the poles of x (each output's residues the optimal ones, as
        the variable projection makes them), without cancellation:
        :func:`~morsuite.reducers.h2.orthonormal.projection_value` with the outputs' values summed (its
        floor a bound on the rounding of its sums). The descent's decisions below the pole-residue
        formula's rounding use it (:func:`~morsuite.reducers.h2.poles_descent.varpro_descent`)."""
        from .orthonormal import projection_value
        t = self.target
        return projection_value(co.split(x)[0], t.poles, t.B[:, 0], t.C, t.gramian_factor)


#: the rounding of the cancellation-free value is estimated as this times its spread over two realizations
SPREAD_SAFETY = 10.0


def _rotation(n):
    """A fixed orthogonal n x n matrix (Householder reflection of a fixed vector: no random numbers, no
    factorisation whose rounding could depend on the BLAS)."""
    v = np.cos(np.arange(1, n + 1) * 1.3)
    v /= np.linalg.norm(v)
    return np.eye(n) - 2.0 * np.outer(v, v)


class SimoFullValues:
    r"""The index-3 model with one input as target: :math:`T(\sigma) = Lx`,
    :math:`T'(\sigma)_i = -w_i^T(2\sigma M + D)x` from :math:`P(\sigma)x = f`, :math:`P(\sigma)^Tw_i = l_i`
    (one LU per real point or conjugate pair, refined ``refine`` times in long double)."""

    def __init__(self, full, refine: int = 2):
        from .stationarity import saddle_solver_refined
        self.full = full
        self.norm2, self.norm2_floor = full.norm2, full.norm2_floor
        self._solves = saddle_solver_refined(full, refine)
        sysm = full.system
        # the outputs' own squared norms are not needed against the full model: J is their sum, and the
        # descent reads only the sum (norm2 split evenly keeps evaluate's arithmetic; its floor holds for the sum)
        p = sysm.L.shape[0]
        self.outputs = [_Out(self.norm2 / p, self.norm2_floor / p) for _ in range(p)]

    @property
    def lu_count(self):
        """Sparse LUs made by the underlying solver so far."""
        return self.full.lu_count

    def values(self, s, second: bool = False):
        """(T(s), T'(s), None), each (p, len(s)), at points closed under conjugation."""
        sysm = self.full.system
        p = sysm.L.shape[0]
        t0 = np.empty((p, s.size), dtype=complex)
        t1 = np.empty((p, s.size), dtype=complex)
        done = np.zeros(s.size, bool)
        for k in range(s.size):
            if done[k]:
                continue
            x = None
            for i in range(p):
                xi, w = self._solves(s[k], sysm.F[:, 0], sysm.L[i])
                x = xi if x is None else x
                t1[i, k] = -(w @ (2.0 * s[k] * (sysm.M @ x) + sysm.D @ x))
            t0[:, k] = sysm.L @ x
            done[k] = True
            if s[k].imag != 0:
                j = np.flatnonzero(~done & (s == np.conj(s[k])))
                if j.size:
                    t0[:, j[0]], t1[:, j[0]], done[j[0]] = np.conj(t0[:, k]), np.conj(t1[:, k]), True
        return t0, t1, None


def simo_evaluate(co: SimoCoordinates, x, target, *, hessian: bool = True, values=None,
                  precise: bool = True) -> PoleEvaluation | None:
    """J and its derivatives at x (module docstring: the outputs' SISO evaluations assembled); None
    outside the domain. Where the pole-residue value of J is below ten of its floors and the target has a
    cancellation-free value (:meth:`SimoModalValues.precise`), J and its floor are that value's (``precise``;
    False keeps the pole-residue value, for intermediate evaluations)."""
    if not co.valid(x):
        return None
    lam = co.split(x)[0]
    vals = values if values is not None else target.values(-lam, second=hessian)
    n, p = co.n, co.p
    dim = n + p * (n - 1)
    g = np.zeros(dim)
    G = np.zeros((dim, dim))
    H = np.zeros((dim, dim)) if hessian else None
    J = floor = 0.0
    for i, c in enumerate(co.cos):
        vi = (vals[0][i], vals[1][i], None if vals[2] is None else vals[2][i])
        ev = evaluate(c, co.siso(x, i), target.outputs[i], hessian=hessian, values=vi)
        lm = c.lam_mask
        idx = np.concatenate([np.arange(n), n + i * (n - 1) + np.arange(n - 1)])
        # the SISO reduced coordinates in the order (poles, residues)
        order = np.concatenate([np.flatnonzero(lm), np.flatnonzero(~lm)])
        g[idx] += ev.g[order]
        G[np.ix_(idx, idx)] += ev.G[np.ix_(order, order)]
        if hessian:
            H[np.ix_(idx, idx)] += ev.H[np.ix_(order, order)]
        J += ev.value
        floor += ev.floor
    if precise and not J > 10.0 * floor and hasattr(target, "precise"):
        # the pole-residue value is rounding (errors near sqrt(eps) ||T||): the cancellation-free one, so that
        # the relative gradient and the trust region's decisions see J
        J, floor = target.precise(co, x)
    return PoleEvaluation(np.asarray(x, float), float(J), float(floor), g, H, G, vals)


def simo_optimal_residues(co: SimoCoordinates, x, target, *, hessian: bool = True) -> PoleEvaluation | None:
    """The evaluation at the poles of x with each output's residues those that minimise J for them
    (variable projection; the residue block of the Gauss-Newton matrix is block diagonal)."""
    if not co.valid(x):
        return None
    vals = target.values(-co.split(x)[0], second=hessian)
    y = ~co.lam_mask
    for _ in range(1 + VP_REFINE):
        ev = simo_evaluate(co, x, target, hessian=False, values=vals, precise=False)
        try:
            dy = -np.linalg.solve(ev.G[np.ix_(y, y)], ev.g[y])
        except np.linalg.LinAlgError:
            return None
        x = ev.x + co.Z[:, y] @ dy
    ev = simo_evaluate(co, x, target, hessian=hessian, values=vals, precise=False)
    if not ev.value > 10.0 * ev.floor and hasattr(target, "projected"):
        # J below the pole-residue formula's resolution: the value of the projection (the residues are the
        # optimal ones), cancellation-free and smooth in the poles (floor about 1e-5 of J on the DSMS at
        # r = 10, where the residual form's rounding was 1e-3 of J)
        J, floor = target.projected(co, x)
        ev = replace(ev, value=float(J), floor=float(floor), _rho=None)
    return ev


#: refinement steps of the variable projection's solve (the residue gradient recomputed at the new residues,
#: in long double against the surrogate, and solved again): the Gauss-Newton block of clustered poles is
#: ill-conditioned, and one solve leaves residues whose error moves the poles' gradient
VP_REFINE = 1


def simo_descent(co, x, target, *, maxit, gtol):
    """:func:`~morsuite.reducers.h2.poles_descent.varpro_descent` over the poles of a SIMO model."""
    return varpro_descent(co, x, target, maxit=maxit, gtol=gtol, optimal=simo_optimal_residues,
                          reduced_gradient=True)


#: singular values of the reduced C below this fraction of the largest are rounding (equal outputs)
RANK_TOL = 1e-10


def simo_second_order_of(co: SimoCoordinates, x):
    r"""(K, D, F, L) with :math:`\hat M = I` of the SIMO model at x (each output's residues summing to 0).

    From the real block-diagonal realization (A, b, C): :math:`x_1 = Ux`, :math:`x_2 = UAx` with rows
    :math:`U` = an orthonormal basis :math:`Q_c^T` of C's rows at their numerical rank k (singular values
    above ``RANK_TOL`` of the largest; made exactly orthogonal to b, as :math:`Cb = 0` by the constraint)
    and r - k of the rows orthogonal to b (a pair's imaginary coordinate, two real poles'
    difference), chosen greedily for the best-conditioned :math:`[U; UA]`; then
    :math:`[-K, -D] = UA^2[U; UA]^{-1}`, :math:`F = UAb`, :math:`L = [CQ_c, 0]`. Raises InputError when
    no choice gives an invertible :math:`[U; UA]` (or k > r)."""
    A, b, C = co.realization(x)
    N = A.shape[0]
    if N % 2:
        raise InputError("an odd number of poles has no second-order realization")
    r = N // 2
    # the row space of C at its numerical rank (outputs that are equal to rounding, as two of the DSMS's,
    # leave a direction of C that is rounding, not orthogonal to b), made exactly orthogonal to b
    Uc, sv, Vt = np.linalg.svd(C, full_matrices=False)
    k = int(np.sum(sv > RANK_TOL * sv[0])) if sv.size and sv[0] > 0 else 0
    if k > r:
        raise InputError(f"a second-order model of order {r} cannot have {k} independent outputs")
    bn = b[:, 0] / np.linalg.norm(b)
    Qc = np.linalg.qr((Vt[:k] - np.outer(Vt[:k] @ bn, bn)).T)[0]         # (N, k), orthogonal to b
    Lk = C @ Qc                                                            # y = C x = (C Qc)(Qc^T x)
    p = k
    rows = [np.eye(N)[co.nr + 2 * j + 1] for j in range(co.nc)]
    for i in range(0, co.nr - 1, 2):
        rows.append(np.eye(N)[i] - np.eye(N)[i + 1])
    chosen = list(range(len(rows)))
    # drop rows one at a time (the one whose removal leaves the best-conditioned basis) until r remain
    while len(chosen) > r - p:
        best = None
        for drop in chosen:
            keep = [j for j in chosen if j != drop]
            U = np.vstack([Qc.T] + [rows[j] for j in keep])
            kap = np.linalg.cond(np.vstack([U, U @ A]))
            if best is None or kap < best[0]:
                best = (kap, keep)
        chosen = best[1]
    U = np.vstack([Qc.T] + [rows[j] for j in chosen])
    if U.shape[0] != r:
        raise InputError("no second-order realization of the pole-residue model: too few free rows")
    S = np.vstack([U, U @ A])
    if not np.linalg.cond(S) < 1e12:
        raise InputError("no well-conditioned second-order realization of the pole-residue model was found")
    KD = -np.linalg.solve(S.T, (U @ A @ A).T).T
    L = np.zeros((C.shape[0], r))
    L[:, :k] = Lk
    return KD[:, :r], KD[:, r:], U @ A @ b, L


def simo_phase(roms, order, sur, full, *, gtol, maxit, chord_maxit, starts, probe=30):
    r"""The SIMO counterpart of :func:`~morsuite.reducers.h2.siso.pole_phase` (without its restructuring
    and cluster rounds): from each of the ``starts`` best candidates (by surrogate error) ``probe``
    iterations of :func:`simo_descent` against the surrogate to a surrogate relative gradient of
    ``1e-3 * gtol``; the best by the cancellation-free surrogate error continues to ``maxit``; then chord
    steps against the full model (its gradient, one LU per pole pair; the surrogate's Hessian) until the
    full model's relative gradient is at most ``gtol`` or ``chord_maxit`` steps or no step decreases J
    beyond twice its floor (where J is below ten floors of the pole-residue formula: no step decreases the
    relative gradient, whose :math:`\|E\|^2` is then the surrogate's cancellation-free value); then the
    second-order realization (:func:`simo_second_order_of`).

    Ties between starts (results equal to the surrogate's floor, as every start reaches the same
    minimum) are broken by the order of ``order``, not by rounding: a start replaces an earlier one only
    when its value is lower by more than ``TIE`` of it plus the floors.

    Returns ``((K, D, F, L) or None, record)`` with the record keys of ``pole_phase``."""
    tv = SimoModalValues(sur)
    runs, results = {}, {}
    for label in list(order)[:starts]:
        A, B, C = standard_realization(roms[label])
        try:
            co, x = SimoCoordinates.of_model(A, B, C)
            ev, its, reason, hist = simo_descent(co, x, tv, maxit=min(probe, maxit), gtol=1e-3 * gtol)
        except (InputError, np.linalg.LinAlgError, ValueError) as exc:
            runs[label] = {"failed": f"{type(exc).__name__}: {exc}"}
            continue
        results[label] = [co, ev, its, reason, hist]
        runs[label] = {"surrogate_h2_error_start": hist[0], "iterations": its, "reason": reason}

    def score(label):
        co, ev = results[label][:2]
        return tv.projected(co, ev.x)

    def pick():
        best, bv = None, None
        for label in order:              # the order of the candidates breaks ties (docstring)
            if label not in results:
                continue
            v = scores[label]
            if best is None or v[0] < bv[0] - TIE * bv[0] - v[1] - bv[1]:
                best, bv = label, v
        return best

    scores = {k: score(k) for k in results}
    rec = {"starts": runs, "history": [], "history_full": [], "iterations_full": 0, "stop_reason": "no start",
           "stop_reason_full": None, "relative_gradient_full": None, "descended_from": None,
           "iterations_surrogate": 0}
    label = pick()
    if label is None:
        return None, rec
    co, ev, its, reason, hist = results[label]
    if reason != "converged" and maxit > probe:
        ev, its2, reason, hist2 = simo_descent(co, ev.x, tv, maxit=maxit - probe, gtol=1e-3 * gtol)
        results[label] = [co, ev, its + its2, reason, hist + hist2[1:]]
        runs[label].update(iterations=its + its2, reason=reason)
        co, ev, its, reason, hist = results[label]
    for k in results:
        v = scores[k] if k != label else score(k)
        runs[k].update(surrogate_h2_error=float(np.sqrt(max(v[0], 0.0))),
                       relative_gradient=float(results[k][1].rho))
    rec.update(descended_from=label, history=hist, stop_reason=reason,
               iterations_surrogate=sum(v.get("iterations", 0) for v in runs.values()))
    fv = SimoFullValues(full)
    evf = simo_evaluate(co, ev.x, fv, hessian=False)
    if evf is None:
        rec["stop_reason_full"] = "the surrogate's result is outside the domain"
        return None, rec
    def rho_of(e):
        # below ten floors the pole-residue value is rounding: ||E||^2 from the surrogate's cancellation-free
        # value (within the surrogate's distance), the gradient and metric from the full model's values
        if e.value > 10.0 * e.floor:
            return e.rho
        return relative_gradient(e.g, e.G, tv.projected(co, e.x)[0])

    rho_f = rho_of(evf)
    rec["history_full"] = [float(np.sqrt(max(evf.value, 0.0)))]
    steps, why = 0, "converged"
    while rho_f > gtol:
        if steps >= chord_maxit:
            why = "cap"
            break
        trial = None
        for mu in (0.0, 1e-4, 1e-2, 1.0):
            xn = chord_step(co, evf, ev.H, mu=mu)
            trial = None if xn is None else simo_evaluate(co, xn, fv, hessian=False)
            if trial is not None:
                resolved = min(evf.value - 10.0 * evf.floor, trial.value - 10.0 * trial.floor) > 0
                if resolved and trial.value <= evf.value + 2.0 * max(evf.floor, trial.floor):
                    break
                if not resolved and rho_of(trial) < rho_f:
                    break
            trial = None
        steps += 1
        if trial is None:
            why = "stalled"
            break
        evf = trial
        rho_f = rho_of(evf)
        rec["history_full"].append(float(np.sqrt(max(evf.value, 0.0))))
    js, js_floor = tv.precise(co, evf.x)
    rec.update(iterations_full=steps, stop_reason_full=why, relative_gradient_full=float(rho_f),
               surrogate_value=float(js), surrogate_value_floor=float(js_floor))
    try:
        return simo_second_order_of(co, evf.x), rec
    except (InputError, np.linalg.LinAlgError) as exc:
        rec["stop_reason_full"] = f"no second-order realization: {exc}"
        return None, rec


#: relative margin by which a start's surrogate value must beat an earlier one's (beyond their floors)
TIE = 1e-9

