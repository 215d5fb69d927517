r"""Subspace-accelerated quadratic dominant pole algorithm (SAQDPA) through saddle-point solves.

The poles :math:`\lambda_i` of :math:`T(s) = LX(s)`, :math:`S(s)[X; Z] = [F; 0]`, are the finite
eigenvalues of the constrained quadratic problem :math:`(\lambda^2M + \lambda D + K)x + G^Tz = 0`,
:math:`Gx = 0`; for a symmetric model (left eigenvectors equal to the right ones) the residue of a
simple pole is

.. math::

    R_i = \frac{(Lx_i)(x_i^TF)}{x_i^T(2\lambda_iM + D)x_i},\qquad
    T(s) = \sum_i \Bigl(\frac{R_i}{s - \lambda_i} + \frac{\bar R_i}{s - \bar\lambda_i}\Bigr) + \dots

and its *dominance over the band* :math:`[\omega_1, \omega_2]` is
:math:`d_i = \sigma_{\max}(R_i) / \min_{\omega_1\le\omega\le\omega_2}|j\omega - \lambda_i|`: the peak of
its term over the band (:math:`\sigma_{\max}(R_i)/|\operatorname{Re}\lambda_i|` for a pole whose
frequency lies in the band).

QDPA (Rommes and Martins, "Computing transfer function dominant poles of large-scale second-order
dynamical systems", SIAM J. Sci. Comput. 30(4):2137-2157, 2008) is Newton's method on
:math:`1/T`, one LU per step: at a shift :math:`s_k`, :math:`v = A(s_k)^{-1}F` and
:math:`w = A(s_k)^{-T}L^T` (one LU, a right and a transposed solve). With subspace acceleration the
v and w of every step span a search space V (real and imaginary parts, in :math:`\ker G`); the
quadratic problem projected onto it (Galerkin: :math:`V^TMV` etc., structure and symmetry kept) gives
Ritz triplets :math:`(\theta_j, Vq_j)`, their residues and dominance from the reduced matrices, and
the next shift is the most dominant Ritz value not converged yet (not a shift already used). A Ritz
pair is converged when its constrained residual
:math:`\|P(\theta^2M + \theta D + K)x\| / ((|\theta|^2\|M\|_1 + |\theta|\|D\|_1 + \|K\|_1)\|x\|)`
(P the orthogonal projection onto :math:`\ker G`: the residual may have a part :math:`G^Tz`) is at
most ``tol``; converged poles are kept and never chosen again as a shift (deflation by selection:
the search space keeps their eigenvectors, so they stay converged). Starting at :math:`s_0 = 0`
puts the static responses :math:`K^{-1}F`, :math:`K^{-1}L^T` into the search space (the static
correction of the modal model needs the first).

Cost: one sparse LU per step (complex, the first real), m + p solves, the projection of the new
columns (three sparse products each), and a dense eigenproblem of twice the search space's size;
the residuals of the candidate Ritz pairs, three sparse products each.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse.linalg as spla

from ...errors import SingularShiftError
from ...linalg.dense import sigma_max
from ..krylov.soar import KernelProjector, RealBasis

__all__ = ["Pole", "SAQDPA", "band_distance"]


def band_distance(lam, band) -> np.ndarray:
    r""":math:`\min_{\omega_1\le\omega\le\omega_2}|j\omega - \lambda|` for each :math:`\lambda` (the conjugate's
    distance for :math:`\operatorname{Im}\lambda < 0`)."""
    lam = np.asarray(lam, dtype=complex)
    w = np.clip(np.abs(lam.imag), band[0], band[1])
    return np.abs(1j * w - (lam.real + 1j * np.abs(lam.imag)))


@dataclass
class Pole:
    """A converged pole (the member of its conjugate pair with Im >= 0) and what the model keeps of it."""

    value: complex
    shape: np.ndarray  # (n1,) complex, unit norm
    residue: np.ndarray  # (p, m)
    dominance: float
    residual: float
    step: int  # the SAQDPA step (LU) at which it converged
    multiplicity: int = 1  # shapes kept of this pole; residue and dominance are then the eigenspace's


@dataclass
class SAQDPA:
    """The state of the subspace-accelerated iteration: search space, shifts, converged poles.

    Parameters
    ----------
    fom : Index3Model
        A model with symmetric M, D, K (the reducer checks).
    solver : SaddlePointSolver
        Its LUs (``cache_size=0``).
    band : (float, float)
    tol : float
        Residual of a converged pole.
    orth_tol : float
        Deflation tolerance of the search space's basis.
    """

    fom: object
    solver: object
    band: tuple
    tol: float = 1e-8
    orth_tol: float = 1e-10
    basis: RealBasis = None
    shifts: list = field(default_factory=list)
    poles: list = field(default_factory=list)
    steps: int = 0
    solves: int = 0
    seconds: float = 0.0
    static: np.ndarray | None = None  # K^{-1} F from the first step at s = 0 (None: singular there)
    _products: dict = field(default_factory=dict)

    def __post_init__(self):
        fom = self.fom
        self.project = KernelProjector(fom.G) if fom.n2 else None
        self.basis = RealBasis(fom.n1, self.orth_tol, 2, self.project)
        self._norms = tuple(float(spla.norm(X, 1)) for X in (fom.M, fom.D, fom.K))
        self._products = {"cols": 0, "MV": None, "DV": None, "KV": None}

    # -- one Newton step: one LU ----------------------------------------------------------------------
    def step(self, s) -> None:
        """Factor :math:`S(s)`, add :math:`A(s)^{-1}F` and :math:`A(s)^{-T}L^T` to the search space."""
        fom = self.fom
        t0 = time.perf_counter()
        s = complex(s)
        try:
            lu = self.solver.factor(s.real if s.imag == 0 else s)
        except SingularShiftError:  # s is a pole to working precision: step off by a relative 1e-8
            s = s + 1e-8 * max(abs(s), 1.0)
            lu = self.solver.factor(s)
        X = lu.solve(fom.F)
        Y = lu.solve(fom.L.T.astype(X.dtype), trans=True)
        del lu
        if s == 0:
            self.static = np.real(X)
        self.basis.add(X)
        self.basis.add(Y)
        self.shifts.append(s)
        self.steps += 1
        self.solves += fom.m + fom.p
        self.seconds += time.perf_counter() - t0

    # -- Ritz triplets of the search space --------------------------------------------------------------
    def reduced(self):
        """(V, Mr, Dr, Kr, Fr, Lr): the search space's Galerkin projection (products grown by new columns)."""
        fom, pr = self.fom, self._products
        V = self.basis.V
        c0 = pr["cols"]
        if c0 < V.shape[1]:
            new = V[:, c0:]
            for key, A in (("MV", fom.M), ("DV", fom.D), ("KV", fom.K)):
                block = A @ new
                pr[key] = block if pr[key] is None else np.hstack([pr[key], block])
            pr["cols"] = V.shape[1]
        sym = lambda A: 0.5 * (A + A.T)  # noqa: E731
        return (V, sym(V.T @ pr["MV"]), sym(V.T @ pr["DV"]), sym(V.T @ pr["KV"]), V.T @ fom.F, fom.L @ V)

    def ritz(self):
        """Ritz values (Im >= 0), vectors q (reduced), residues and dominance, most dominant first."""
        V, Mr, Dr, Kr, Fr, Lr = self.reduced()
        r = Mr.shape[0]
        A = np.block([[np.zeros((r, r)), np.eye(r)], [-Kr, -Dr]])
        E = sla.block_diag(np.eye(r), Mr)
        theta, Z = sla.eig(A, E)
        ok = np.isfinite(theta) & (theta.imag >= 0)
        theta, Q = theta[ok], Z[:r, ok]
        Q = Q / np.linalg.norm(Q, axis=0)
        den = np.einsum("ij,ij->j", Q, (Mr @ Q) * (2 * theta)[None, :] + Dr @ Q)  # q^T (2 theta Mr + Dr) q
        R = np.einsum("pj,jm->jpm", Lr @ Q, (Q.T @ Fr)) / den[:, None, None]
        dom = sigma_max(R) / np.maximum(band_distance(theta, self.band), np.finfo(float).tiny)
        order = np.argsort(-dom, kind="stable")
        return theta[order], Q[:, order], R[order], dom[order], V

    def residual(self, theta, x) -> float:
        """The constrained residual of :math:`(\\theta, x)` relative to the pencil's scale (module docstring)."""
        fom = self.fom
        r = (theta * theta) * (fom.M @ x) + theta * (fom.D @ x) + fom.K @ x
        if self.project is not None:
            r = self.project(r.real) + 1j * self.project(r.imag)
        nM, nD, nK = self._norms
        a = abs(theta)
        return float(np.linalg.norm(r) / ((a * a * nM + a * nD + nK) * np.linalg.norm(x)))

    def update(self, candidates: int = 8):
        """Check the most dominant Ritz pairs for convergence (keep the new poles); return the next shift:
        the most dominant unconverged Ritz value not used as a shift yet (None if there is none).

        A Ritz pair at a known pole counts as known only if its vector lies in the span of that pole's kept
        shapes: a multiple pole (the square sections of a finite-element block) keeps one shape per dimension
        of its eigenspace, and its contribution to T is their sum.
        """
        theta, Q, R, dom, V = self.ritz()
        nxt = None
        checked = 0
        for j in range(theta.size):
            t = theta[j]
            x = None
            same = [p for p in self.poles if abs(t - p.value) <= 1e-8 * max(abs(t), 1.0)]
            if same:
                x = V @ Q[:, j]
                S = np.column_stack([p.shape for p in same])
                Qs, _ = np.linalg.qr(S)
                if np.linalg.norm(x - Qs @ (Qs.conj().T @ x)) <= 1e-6 * np.linalg.norm(x):
                    continue  # this pole's eigenspace is kept already
            if checked < candidates:
                x = V @ Q[:, j] if x is None else x
                res = self.residual(t, x)
                checked += 1
                if res <= self.tol:
                    self.poles.append(Pole(complex(t), x / np.linalg.norm(x), R[j], float(dom[j]), res, self.steps))
                    if same:
                        self._group_residue(same + [self.poles[-1]])
                    continue
            if nxt is None and not same and all(abs(t - s) > 1e-10 * max(abs(t), 1.0) for s in self.shifts):
                nxt = complex(t)
            if nxt is not None and checked >= candidates:
                break
        return nxt

    def _group_residue(self, group):
        r"""A multiple pole: the residue of its eigenspace, :math:`(LX)(X^T(2\lambda M + D)X)^{-1}(X^TF)` with X its
        kept shapes (how it splits between the shapes depends on the basis of the eigenspace), in every member."""
        fom = self.fom
        lam = group[0].value
        X = np.column_stack([p.shape for p in group])
        B = X.T @ ((2 * lam) * (fom.M @ X) + fom.D @ X)
        Rg = (fom.L @ X) @ np.linalg.solve(B, X.T @ fom.F)
        d = float(sigma_max(Rg[None])[0] / max(band_distance([lam], self.band)[0], np.finfo(float).tiny))
        for p in group:
            p.residue, p.dominance, p.multiplicity = Rg, d, len(group)
