r"""The H2 descent of a SISO reduced model in cluster-polynomial coordinates, its residues eliminated in
the orthonormal Takenaka-Malmquist basis: well conditioned where poles cluster.

A SISO reduced model of McMillan degree n with relative degree 2 (the second-order models with
:math:`\hat M = I`, :mod:`~morsuite.reducers.h2.poles`) is :math:`T_r = p/q`, :math:`\deg p \le n - 2`. For a fixed
denominator q the best such model is the H2-orthogonal projection of T onto
:math:`V_0 = \{p/q\}`; in the orthonormal basis :math:`x_1 = (sI - A_1)^{-1}\beta_1` of the pole
sequence (:func:`~morsuite.reducers.h2.orthonormal.tm_realization`) it is :math:`T_r = \alpha^Tx_1` with

.. math::

    \alpha = (I - \hat\beta_1\hat\beta_1^T)\,\overline{v_1},\quad v_1 = T(-A_1)\beta_1,\qquad
    J(q) = \|T\|^2 - \|\alpha\|^2

(variable projection with no residues and no Gram matrix to invert). The outer coordinates are the
coefficients of one real monic polynomial per *cluster* of poles (poles within ``ctol`` times their
damping :math:`|\mathrm{Re}\,\lambda|` of each other, by single linkage; a conjugate pair is a
quadratic): :math:`q = \prod_cq_c`, :math:`q_c(s) = \tilde s^{m_c} + \sum_{j<m_c}y_{c,j}\tilde s^j`,
:math:`\tilde s = (s - \mu_c)/\sigma_c` (shift: the cluster's mean, scale: its spread, at least a
tenth of its damping). Their derivatives stay bounded where poles of a cluster meet, where the
residues, and the pole-residue Hessian, do not (``docs/design/so_h2.md``, 2026-11-26).

With :math:`h_{c,j} = \partial_{y_{c,j}}q/q = \tilde s^j/q_c` and :math:`g_{c,j} = T_rh_{c,j}`
(:math:`\partial T_r/\partial y_{c,j} = -g_{c,j}` with p held at its optimum), both in the tangent space
:math:`V = \{u/q^2\}` spanned by the orthonormal basis :math:`x_2 = (sI - A_2)^{-1}\beta_2` of the
sequence with every pole twice,

.. math::

    \partial J/\partial y_{c,j} = 2\,\mathrm{Re}\,u_{c,j}^He,\qquad
    G = 2\,\mathrm{Re}\,(\tilde U^H\tilde U),\quad \tilde U = U - Z_{12}^T\overline W,

with :math:`e = E(-A_2)\beta_2`, :math:`u_{c,j} = g_{c,j}(-A_2)\beta_2` and
:math:`w_{c,j} = (I - \hat\beta_1\hat\beta_1^T)g_{c,j}(-A_1)\beta_1` (the part of :math:`g_{c,j}` in
:math:`V_0` removed: Kaufman's Gauss-Newton matrix of variable projection; :math:`\Pi_0g_{c,j} =
\overline{w_{c,j}}^Tx_1` has :math:`(\Pi_0g_{c,j})(-A_2)\beta_2 = Z_{12}^T\overline{w_{c,j}}` with
:math:`A_1Z_{12} + Z_{12}A_2^T + \beta_1\beta_2^T = 0`, so :math:`\tilde U` holds :math:`(I - \Pi_0)g_{c,j}`
with no difference of two Gram matrices); each
:math:`g_{c,j}(-A)\beta` is one Sylvester solve with the cascade realization of :math:`T_r` and
:math:`h_{c,j}` (companion form in :math:`\tilde s`), one per cluster. The relative gradient is
:math:`\rho = \|(I - \hat\beta_2\hat\beta_2^T)e\|/\sqrt J` (:func:`~morsuite.reducers.h2.orthonormal.tm_rho`).

The descent (:func:`cluster_descent`) is a trust region with Kaufman's matrix (Gauss-Newton, the
default ``"gn"``; a secant or a differenced Hessian as options), in the norm of its diagonal; the clusters
are re-formed when it stalls. Gauss-Newton is blind to negative curvature and plateaus near saddles
(relative gradient about 0.1 at tcom(2000), r = 30); :func:`alternating_descent` alternates it with the
pole-residue descent of :mod:`~morsuite.reducers.h2.poles_descent` (exact Hessian), which leaves them. Cost per
evaluation: the target's values :math:`T(-A)\beta` for the sequences of n and 2n poles (a modal target of
order N: the all-pass product form, :math:`O(nN)`, :meth:`ModalTM.tm_values`), three triangular Sylvester
solves (the cross Gramians of the two bases and the clusters' cascades, all clusters at once) and
:math:`O(n^3)` dense work. Measurements: ``docs/design/so_h2.md`` (2026-11-26, second and third sessions).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ...errors import InputError
from .orthonormal import tm_realization, tm_rho
from .poles import Coordinates, optimal_residues
from .poles_descent import _next_radius, _tr_step, pole_descent

__all__ = ["Clusters", "ModalTM", "ClusterEvaluation", "cluster_evaluate", "cluster_descent", "pole_coordinates",
           "alternating_descent", "CTOL", "MAX_DEGREE"]

EPS = np.finfo(float).eps

#: poles closer than this times their damping are in one cluster (one polynomial)
CTOL = 0.5
#: the largest number of poles (counting conjugates) in one cluster
MAX_DEGREE = 8


class ModalTM:
    r"""A dense SISO target in modal form :math:`T = \sum_j\psi_j/(s - \mu_j)` for :func:`cluster_evaluate`:
    ``tm_values(A, beta)`` :math:`= T(-A)\beta` (:func:`~morsuite.reducers.h2.orthonormal.modal_tm_values`)."""

    def __init__(self, target):
        self.mu = np.asarray(target.poles)
        self.psi = np.asarray(target.C)[0] * np.asarray(target.B)[:, 0]
        self.norm2, self.norm2_floor = float(target.norm2), float(target.norm2_floor)

    def tm_values(self, A, beta, sequence=None):
        r""":math:`T(-A)\beta` (class docstring). With the pole ``sequence`` of a Takenaka-Malmquist
        realization (:func:`~morsuite.reducers.h2.orthonormal.tm_realization`: ``A = tm_realization(sequence)[0]``), by the
        product form :math:`T(-A)\beta = \sum_j\psi_jx(-\mu_j)`,

        .. math::

            x_k(s) = \frac{\beta_k}{s - a_k}\prod_{i<k}\frac{s + \bar a_i}{s - a_i}

        (all-pass factors of modulus below one for s in the right half-plane): :math:`O(nN)`; without
        it, one triangular Sylvester solve :math:`AZ + Z\,\mathrm{diag}(\mu) = -\beta 1^T`,
        :math:`O(n^2N + nN^2)`."""
        if sequence is None:
            Z = _tri_sylvester(A, np.diag(self.mu.astype(complex)), -np.outer(beta, np.ones(self.mu.size)))
            return Z @ self.psi
        a = np.asarray(sequence, dtype=complex)[:, None]
        s = -self.mu[None, :]
        den = s - a
        blaschke = np.cumprod((s + np.conj(a)) / den, axis=0)
        X = np.empty_like(den)
        X[0] = 1.0 / den[0]
        X[1:] = blaschke[:-1] / den[1:]
        return (np.asarray(beta)[:, None] * X) @ self.psi


class Clusters:
    r"""Cluster-polynomial coordinates of a set of poles closed under conjugation (module docstring).

    ``Clusters(poles, ctol)`` groups the poles; ``y`` holds the coefficients of every cluster's monic
    polynomial in :math:`\tilde s`; ``poles(y)`` returns the roots (conjugate-closed), ``None`` when one
    is not in the open left half-plane."""

    def __init__(self, poles, ctol: float = CTOL, max_degree: int = MAX_DEGREE):
        lam = np.asarray(poles, dtype=complex)
        up = lam[lam.imag >= 0]
        # single linkage on the upper members and the real poles
        k = up.size
        parent = list(range(k))

        def find(i):
            while parent[i] != i:
                parent[i] = parent[parent[i]]
                i = parent[i]
            return i
        size = [1 if u.imag == 0 else 2 for u in up]
        pairs = sorted((abs(up[i] - up[j]) / max(abs(up[i].real), abs(up[j].real)), i, j)
                       for i in range(k) for j in range(i + 1, k))
        for dist, i, j in pairs:        # closest first; no cluster above max_degree roots
            a, b = find(i), find(j)
            if dist <= ctol and a != b and size[a] + size[b] <= max_degree:
                parent[a] = b
                size[b] += size[a]
        groups = {}
        for i in range(k):
            groups.setdefault(find(i), []).append(i)
        self.mu, self.sigma, self.m, coefs = [], [], [], []
        for idx in groups.values():
            roots = []
            for i in idx:
                roots += [up[i]] if up[i].imag == 0 else [up[i], np.conj(up[i])]
            roots = np.array(roots)
            mu = float(np.mean(roots.real))
            sigma = float(max(np.max(np.abs(roots - mu)), 0.1 * np.mean(np.abs(roots.real))))
            c = np.real(np.poly((roots - mu) / sigma))
            self.mu.append(mu)
            self.sigma.append(sigma)
            self.m.append(roots.size)
            coefs.append(c[1:][::-1])          # y_0 .. y_{m-1}
        self.y = np.concatenate(coefs)
        self.offsets = np.concatenate([[0], np.cumsum(self.m)])
        self.ctol = ctol

    def coefficients(self, y, c):
        """y_0 .. y_{m-1} of cluster c."""
        return y[self.offsets[c]:self.offsets[c + 1]]

    def poles(self, y):
        """The roots of all clusters (module docstring); None if one has Re >= 0 or is not finite."""
        out = []
        for c in range(len(self.m)):
            yc = self.coefficients(y, c)
            if self.m[c] == 2:     # the quadratic formula (np.roots' companion eigenvalues cost 0.15 ms)
                h = -0.5 * yc[1]
                d = np.sqrt(complex(h * h - yc[0]))
                r = np.array([h + d, h - d]) if d.real == 0 else np.array([h + d, yc[0] / (h + d)] if h >= 0
                                                                          else [h - d, yc[0] / (h - d)])
            else:
                r = np.roots(np.concatenate([[1.0], yc[::-1]])) if self.m[c] > 1 else np.array([-yc[0]])
            out.append(self.mu[c] + self.sigma[c] * r.astype(complex))
        lam = np.concatenate(out)
        if not (np.all(np.isfinite(lam)) and np.all(lam.real < 0)):
            return None
        return lam

    def h_realization(self, y, c):
        r"""(A_h, b_h) with :math:`h_{c,j}(s) = e_j^T(sI - A_h)^{-1}b_h` (companion form in :math:`\tilde s`)."""
        m, yc = self.m[c], self.coefficients(y, c)
        Ac = np.zeros((m, m))
        Ac[:-1, 1:] = np.eye(m - 1)
        Ac[-1, :] = -yc
        b = np.zeros(m)
        b[-1] = self.sigma[c]
        return self.mu[c] * np.eye(m) + self.sigma[c] * Ac, b


def _sequence(lam):
    """Poles ordered: each upper member followed by its conjugate, then the real ones."""
    up = lam[lam.imag > 0]
    re = lam[lam.imag == 0]
    out = []
    for u in up:
        out += [u, np.conj(u)]
    return np.array(out + list(re), dtype=complex)


def _tri_sylvester(A_low, B_low, C):
    r"""X with :math:`A X + X B^T = C` for lower triangular A and B (LAPACK ``ztrsyl``)."""
    X, scale, info = sla.lapack.ztrsyl(np.conj(A_low).T, np.asarray(B_low, dtype=complex).T,
                                       np.asarray(C, dtype=complex), trana="C")
    if info < 0:
        raise np.linalg.LinAlgError("ztrsyl failed")
    return X / scale


def _cascade_values(schur_h, bh, alpha, Z1, A_right):
    r""":math:`g_j(-A_r)\beta_r` for all coordinates j of all clusters (rows), with :math:`Z_1` solving
    :math:`A_1Z_1 + Z_1A_r^T + \beta_1\beta_r^T = 0`: the cascade :math:`T_r` then :math:`h`, its second
    block row :math:`A_hZ_h + Z_hA_r^T + b_h\alpha^TZ_1 = 0` with :math:`A_h` the block diagonal of the
    clusters' companion matrices (``schur_h`` = (R, Q), its complex Schur form) and :math:`b_h` their
    stacked input vectors: one triangular Sylvester solve for every cluster at once."""
    R, Q = schur_h
    rhs = -(Q.conj().T @ np.outer(bh, alpha @ Z1))
    Y, scale, info = sla.lapack.ztrsyl(R, np.asarray(A_right, dtype=complex).T, rhs)
    if info < 0:
        raise np.linalg.LinAlgError("ztrsyl failed")
    return Q @ (Y / scale)


@dataclass
class ClusterEvaluation:
    """J, its floor, the gradient in y, Kaufman's Gauss-Newton matrix, the relative gradient, and the
    optimal model's poles and orthonormal coefficients."""

    y: np.ndarray
    value: float
    floor: float
    g: np.ndarray
    G: np.ndarray
    rho: float
    poles: np.ndarray
    A1: np.ndarray
    beta1: np.ndarray
    alpha: np.ndarray

    def realization(self):
        """A real first-order realization (A, b, c) of the model (block form of the complex TM one:
        conjugate blocks combined)."""
        A1, b1, a = self.A1, self.beta1, self.alpha
        n = A1.shape[0]
        Ac = np.block([[A1, np.zeros_like(A1)], [np.zeros_like(A1), A1.conj()]])
        Bc = np.concatenate([b1, b1]).astype(complex) / 2
        Cc = np.concatenate([a, a.conj()])
        S = np.block([[np.eye(n), np.eye(n)], [-1j * np.eye(n), 1j * np.eye(n)]]) / np.sqrt(2)
        Si = np.linalg.inv(S)
        return (np.real(S @ Ac @ Si), np.real(S @ Bc), np.real(Cc @ Si))


def _tm_values(target, A, beta, sequence):
    """``target.tm_values`` with the product form where the target has it (:meth:`ModalTM.tm_values`)."""
    if isinstance(target, ModalTM):
        return target.tm_values(A, beta, sequence)
    return target.tm_values(A, beta)


def cluster_evaluate(cl: Clusters, y, target, *, derivatives: int = 2):
    """J (with ``derivatives`` >= 1 the gradient and rho, 2 (default) Kaufman's matrix too) at y against ``target``
    (anything with ``tm_values(A, beta)`` and ``norm2``, ``norm2_floor``); None outside the domain
    (module docstring)."""
    lam = cl.poles(y)
    if lam is None:
        return None
    seq = _sequence(lam)
    A1, b1 = tm_realization(seq)
    v1 = _tm_values(target, A1, b1, seq)
    bh1 = b1 / np.linalg.norm(b1)
    alpha = np.conj(v1)
    alpha = alpha - bh1 * (bh1 @ alpha)
    a2 = float(np.real(np.vdot(alpha, alpha)))
    J = target.norm2 - a2
    floor = target.norm2_floor + 4.0 * EPS * np.sqrt(seq.size) * (target.norm2 + a2)
    if not derivatives:
        return ClusterEvaluation(np.asarray(y, float), J, floor, None, None, np.nan, lam, A1, b1, alpha)
    seq2 = np.repeat(seq, 2)
    A2, b2 = tm_realization(seq2)
    Z12 = _tri_sylvester(A1, A2, -np.outer(b1, b2))
    Z11 = _tri_sylvester(A1, A1, -np.outer(b1, b1)) if derivatives > 1 else None
    e = _tm_values(target, A2, b2, seq2) - alpha @ Z12
    rho = tm_rho(e, b2, J)
    hs = [cl.h_realization(y, c) for c in range(len(cl.m))]
    schur_h = sla.schur(sla.block_diag(*[h[0] for h in hs]).astype(complex), output="complex")
    bh = np.concatenate([h[1] for h in hs])
    U = _cascade_values(schur_h, bh, alpha, Z12, A2).T       # columns per coordinate
    g = 2.0 * np.real(U.conj().T @ e)
    G = None
    if derivatives > 1:
        W = _cascade_values(schur_h, bh, alpha, Z11, A1)
        W = W - np.outer(W @ bh1, bh1)
        # (I - Pi_0) g in the doubled basis: the rows of Z12 are the basis x_1 in it; no difference of Grams
        Ut = U - Z12.T @ np.conj(W.T)
        G = 2.0 * np.real(Ut.conj().T @ Ut)
        G = 0.5 * (G + G.T)
    return ClusterEvaluation(np.asarray(y, float), J, floor, g, G, rho, lam, A1, b1, alpha)


def _fd_hessian(cl, ev, target, h=1e-6):
    """The Hessian by forward differences of the gradient (d evaluations without Kaufman's matrix)."""
    d = ev.y.size
    sc = 1.0 / np.sqrt(np.maximum(np.diag(ev.G), 1e-300))
    H = np.zeros((d, d))
    for j in range(d):
        e = np.zeros(d)
        e[j] = h * sc[j] * max(1.0, np.sqrt(ev.value))
        ep = cluster_evaluate(cl, ev.y + e, target, derivatives=1)
        if ep is None:
            ep = cluster_evaluate(cl, ev.y - e, target, derivatives=1)
            e = -e
        H[:, j] = (ep.g - ev.g) / e[j]
    return 0.5 * (H + H.T)


def cluster_descent(poles, target, *, ctol: float = CTOL, maxit: int = 200, gtol: float = 1e-7,
                    hessian: str = "gn", restarts: int = 10, plateau: tuple | None = None):
    r"""Trust-region descent in cluster-polynomial coordinates from the poles ``poles`` (module
    docstring). Model Hessian: ``hessian="gn"`` (default): Kaufman's matrix G alone; ``"sr1"``: G plus a
    symmetric rank-one secant estimate S of the rest (the terms in E), updated with
    :math:`y^\# = g_+ - g - G_+p` (structured quasi-Newton, as NL2SOL; 3.4x the time of "gn" for the same
    plateau at tcom(2000), r = 30); ``"fd"``: the
    Hessian by differences of the gradient (diagnostics, 2d evaluations per iteration). Trust region in
    the norm of G's diagonal, starting at :math:`\sqrt J`; a step is taken when it decreases J by at
    least 1e-4 of the predicted decrease (below 10 floors of J the decrease is the trapezoidal rule on
    the gradients along the step). The clusters are fixed until the descent stalls; then re-formed
    from the poles (S reset), at most ``restarts`` times. Stops at ``rho <= gtol`` (``"converged"``),
    at a stall with no restarts left (``"stalled"``), ``maxit`` (``"cap"``) or, with ``plateau = (k, f)``, when
    :math:`\sqrt J` decreased by less than the fraction f over the last k iterations (``"plateau"``). Returns ``(evaluation,
    iterations, reason, history of sqrt(J))``. Cost per iteration: one evaluation per trial step
    (module docstring)."""
    if hessian not in ("gn", "sr1", "fd"):
        raise InputError(f"hessian must be 'gn', 'sr1' or 'fd', got {hessian!r}")
    if not ctol > 0:
        raise InputError(f"ctol must be positive, got {ctol!r}")
    cl = Clusters(poles, ctol)
    ev = cluster_evaluate(cl, cl.y, target)
    if ev is None:
        raise InputError("poles: the start's poles are not in the open left half-plane")
    hist = [float(np.sqrt(max(ev.value, 0.0)))]
    radius = r0 = np.sqrt(max(ev.value, 0.0))
    S = np.zeros_like(ev.G)
    reason, it, restarted = "cap", 0, 0
    for it in range(1, maxit + 1):
        if ev.rho <= gtol:
            reason, it = "converged", it - 1
            break
        D = np.maximum(np.diag(ev.G), 1e-12 * np.max(np.diag(ev.G)))
        H = _fd_hessian(cl, ev, target) if hessian == "fd" else ev.G + S
        accepted = None
        while radius > 1e-10 * r0:
            p, pred = _tr_step(H, D, ev.g, radius)
            trial = cluster_evaluate(cl, ev.y + p, target)
            if trial is None:
                radius *= 0.25
                continue
            if hessian == "sr1":
                r = (trial.g - ev.g) - trial.G @ p - S @ p
                den = float(r @ p)
                if abs(den) > 1e-8 * np.linalg.norm(r) * np.linalg.norm(p):
                    S = S + np.outer(r, r) / den
            act = ev.value - trial.value
            fl = max(ev.floor, trial.floor)
            if pred <= 10.0 * fl:
                # below the rounding of J: the decrease by the trapezoidal rule on the gradients
                # (accurate to the step's cube; the gradients carry no cancellation of size ||T||^2)
                act, fl = -0.5 * float((ev.g + trial.g) @ p), 0.0
            ratio = act / pred if pred > 0 else 0.0
            if ratio >= 1e-4 and act > -fl:
                accepted = trial
                radius = _next_radius(radius, ratio, np.linalg.norm(np.sqrt(D) * p))
                break
            radius = 0.25 * np.linalg.norm(np.sqrt(D) * p)
            if hessian == "sr1":
                H = ev.G + S
        if accepted is None:
            if restarted >= restarts:
                reason, it = "stalled", it - 1
                break
            # new clusters at the current poles (a change of coordinates: the model is unchanged)
            restarted += 1
            cl = Clusters(ev.poles, ctol)
            ev = cluster_evaluate(cl, cl.y, target)
            S = np.zeros_like(ev.G)
            radius = np.sqrt(max(ev.value, 0.0))
            continue
        ev = accepted
        hist.append(float(np.sqrt(max(ev.value, 0.0))))
        if plateau is not None and len(hist) > plateau[0] and hist[-1] > (1.0 - plateau[1]) * hist[-1 - plateau[0]]:
            reason = "plateau"
            break
    else:
        if ev.rho <= gtol:
            reason = "converged"
    return ev, it, reason, hist


def pole_coordinates(poles):
    r"""(Coordinates, x) of :mod:`~morsuite.reducers.h2.poles` at the given poles (conjugate-closed) with zero residues, the
    first residue coordinate the pivot (for :func:`~morsuite.reducers.h2.poles.optimal_residues`)."""
    lam = np.asarray(poles, dtype=complex)
    re, up = lam[lam.imag == 0].real, lam[lam.imag > 0]
    co = Coordinates(re.size, up.size)
    return co, co.join(re, np.zeros(re.size), up, np.zeros(up.size))


def alternating_descent(co: Coordinates, x, target, *, rounds: int = 3, cluster_maxit: int = 150,
                        pole_maxit: int = 150, gtol: float = 1e-7, plateau: tuple | None = None):
    r"""Alternate :func:`cluster_descent` (Gauss-Newton in cluster-polynomial coordinates: moves clusters
    of poles the pole-residue metric cannot) and :func:`~morsuite.reducers.h2.poles_descent.pole_descent` (exact Hessian in
    pole-residue coordinates: leaves the saddles that Gauss-Newton, blind to negative curvature, plateaus
    at), from the pole-residue point x against the dense modal ``target`` (a
    :class:`~morsuite.reducers.h2.poles.ModalValues`), for at most ``rounds`` rounds; stops after a round that does not
    decrease J (the cancellation-free value), or with ``"converged"`` when the pole descent converges or
    the orthonormal relative gradient of the round's result (the certified form, which the pole-residue
    one underestimates at clusters) is at most ``10 * gtol``. Returns ``(Coordinates, evaluation,
    iterations, reason, record)`` of the best point by J; ``record``: per round the target's H2 errors
    after each half, the iterations, reasons and the relative gradients.
    Measurements: ``docs/design/so_h2.md`` (2026-11-26, second session)."""
    tt = ModalTM(target.target)
    ev = optimal_residues(co, x, target)
    best = (target.precise(co, ev.x)[0], co, ev)
    reason, total, record = "stalled", 0, []
    for _ in range(rounds):
        lam = co.split(ev.x)[0]
        try:
            evc, itc, rc, _ = cluster_descent(lam, tt, maxit=cluster_maxit, gtol=gtol, hessian="gn", plateau=plateau)
            co2, x2 = pole_coordinates(evc.poles)
            pr = optimal_residues(co2, x2, target)
            if pr is None:
                break
            co2, ev2, itp, reason, _, _ = pole_descent(co2, pr.x, target, maxit=pole_maxit, gtol=gtol)
        except (InputError, np.linalg.LinAlgError, ValueError):
            break
        total += itc + itp
        v = target.precise(co2, ev2.x)[0]
        lam2 = co2.split(ev2.x)[0]
        cl2 = Clusters(lam2)
        ev_tm = cluster_evaluate(cl2, cl2.y, tt, derivatives=1)
        record.append({"rho_pole_orthonormal": float(ev_tm.rho) if ev_tm is not None else None,"h2_cluster": float(np.sqrt(max(evc.value, 0.0))), "iterations_cluster": itc,
                       "reason_cluster": rc, "rho_cluster": float(evc.rho),
                       "h2_pole": float(np.sqrt(max(v, 0.0))), "iterations_pole": itp, "reason_pole": reason,
                       "rho_pole_residue": float(ev2.rho)})
        if not v < best[0]:
            break
        best = (v, co2, ev2)
        co, ev = co2, ev2
        if ev_tm is not None and ev_tm.rho <= 10.0 * gtol:
            reason = "converged"    # the orthonormal rho (the certified form) is small on the target
        if reason == "converged":
            break
    _, co, ev = best
    return co, ev, total, reason, record
