r"""Low-rank ADI for the projected Lyapunov equations of an index-3 second-order system.

The system :math:`M\ddot x + D\dot x + Kx + G^T z = Fu`, :math:`Gx = 0`,
:math:`y = Lx` is written in first-order form on the hidden manifold
:math:`\{(x, v) : Gx = 0,\ Gv = 0\}`,

.. math::

    E = \begin{bmatrix} I & 0 \\ 0 & M \end{bmatrix},\quad
    A = \begin{bmatrix} 0 & I \\ -K & -D \end{bmatrix},\quad
    B = \begin{bmatrix} 0 \\ F \end{bmatrix},\quad
    C = \begin{bmatrix} L & 0 \end{bmatrix},

every equation read modulo :math:`\operatorname{range}(G^T)`, i.e. projected with
:math:`\Pi = I - G^T (G M^{-1} G^T)^{-1} G M^{-1}` (``models.md``). The Gramians
solve the projected Lyapunov equations

.. math::

    A P E^T + E P A^T = -\Pi_l B B^T \Pi_l^T, \qquad
    A^T Q E + E^T Q A = -\Pi_r^T C^T C \Pi_r,

with :math:`\Pi_l = \mathrm{blkdiag}(I, \Pi)`, and :math:`P \approx ZZ^T`,
:math:`Q \approx YY^T` for real low-rank factors (rows ``[position; velocity]``).

The G-LR-ADI iteration (Benner, Kürschner, Saak 2013, Algorithm 4) with shifts
:math:`p_j` in the open left half-plane is

.. math::

    V_j = (A + p_j E)^{-1} W_{j-1},\quad
    W_j = W_{j-1} - 2\,\mathrm{Re}(p_j)\, E V_j,\quad
    Z_j = [Z_{j-1},\ \sqrt{-2\,\mathrm{Re}\,p_j}\, V_j],\qquad W_0 = \Pi_l B,

(:math:`A^T, E^T` and :math:`W_0 = \Pi_r^T C^T` for Q). The residual of the
Lyapunov equation is :math:`W_jW_j^T`, so the stopping test
:math:`\|W_j^TW_j\|_2/\|W_0^TW_0\|_2 \le \mathrm{tol}` costs an m x m eigenvalue.
A complex pair :math:`p, \bar p` is one complex solve and two real columns (the
real double step, ibid. Algorithm 3); it counts as two iterations.

Shifted solves never form :math:`\Pi`. With :math:`S(s) = s^2M + sD + K`,
:math:`(A + \mu E)[v_1; v_2] = [w_1; w_2]` is

.. math::

    \begin{bmatrix} S(-\mu) & G^T \\ G & 0 \end{bmatrix}
    \begin{bmatrix} v_1 \\ \lambda \end{bmatrix} =
    \begin{bmatrix} (\mu M - D) w_1 - w_2 \\ 0 \end{bmatrix},\qquad
    v_2 = w_1 - \mu v_1,

and :math:`(A + \mu E)^T [v_1; v_2] = [w_1; w_2]` is

.. math::

    \begin{bmatrix} S(-\mu) & G^T \\ G & 0 \end{bmatrix}^T
    \begin{bmatrix} v_2 \\ \gamma \end{bmatrix} =
    \begin{bmatrix} \mu w_2 - w_1 \\ 0 \end{bmatrix},\qquad
    v_1 = \Pi\,\bigl(w_2 - (\mu M^T - D^T) v_2\bigr),

one sparse LU of the saddle-point matrix at :math:`s = -\mu` serving both
(``SaddlePointSolver.factor(-mu)``). In the controllability iteration both
blocks of :math:`V_j` lie in :math:`\ker G` and :math:`W_j` stays in
:math:`\ker G \times \operatorname{range}\Pi` without any projection. In the
observability iteration the position block :math:`v_1` is a covector, defined
only modulo :math:`\operatorname{range}(G^T)`; unprojected, that component piles
up in the position block of :math:`W_j`, whose norm then stalls. The position
blocks are projected with :math:`\Pi b = Mx`,
:math:`[[M, G^T], [G, 0]][x; l] = [b; 0]` (one real LU per run), or, where
only :math:`\Pi b` is needed, in the range-space form
:math:`b - G^T(GM^{-1}G^T)^{-1}GM^{-1}b` with the n1 x n2 matrix
:math:`M^{-T}G^T(GM^{-T}G^T)^{-1}` solved for once
(:meth:`ManifoldProjector.project`): that of
:math:`W_j` before its norm is taken (the solves never see the
:math:`\operatorname{range}(G^T)` part: it only shifts the multiplier), that of
the factor once, when it is asked for (balanced truncation only multiplies it
with vectors in :math:`\ker G` and does not need it). So :math:`W_jW_j^T`, with
:math:`W_j = \Pi_r^TW_j`, is the residual of the projected equation, and the
factor's position block lies in :math:`\operatorname{range}\Pi` (both checked
against a dense null-space computation in ``tests/test_lradi.py``).

Shifts, one function per strategy:

:func:`projection_shifts` (default)
    Ritz values of the pencil projected onto the latest ADI block and the
    current residual (structure-preserving: the quadratic pencil on the span of
    the position/velocity columns), unstable ones mirrored; the ``num_shifts``
    whose Ritz vectors carry most of the current residual are used next
    (``selection="residual"``), or those where the ADI rational function of
    the shifts used so far is largest (``selection="gain"``, Penzl's greedy).
:func:`penzl_shifts`
    Penzl's heuristic: Arnoldi Ritz values of :math:`E^{-1}A` and
    :math:`A^{-1}E` on the hidden manifold, a fixed set used cyclically.

:func:`lradi_pair` runs both equations in lock step on one shift sequence, so
that each LU serves the right and the transposed left solve (``design.md``).

Measured (tol 1e-10, iterations controllability / observability, LUs):
dsms(6000) 24 / 28, 15 LUs; tcom(nc=2000) 937 / 969, 488 LUs (separate runs
966 / 1045 with 1012 LUs; ``selection="gain"`` 1424 / 1424; Penzl's shifts
1.3e-2 after 1500). The TCOM's spectrum hugs the imaginary axis
(:math:`\mathrm{Re}\,\lambda \approx -0.005(1 + \omega^2)` for
:math:`|\omega|` up to 6.3) and the load excites it throughout, so every
rational ADI function needs many poles: even the exact eigenvalues as shifts,
taken greedily by residual content, need 128 / 372 / 606 iterations for
nc = 50 / 200 / 500 (a dense modal simulation), against 350 / 774 / 898 here.
"""

from __future__ import annotations

import time
import warnings
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from ..errors import ModelError, ConvergenceWarning, InputError
from ..utils import blas_threads

__all__ = ["LRADIResult", "lradi", "lradi_pair", "projection_shifts", "penzl_shifts", "select_shifts",
           "ManifoldProjector"]

EQUATIONS = ("controllability", "observability")
STRATEGIES = ("projection", "penzl")
SELECTIONS = ("residual", "gain")
_IMAG_TOL = 1e-12  # relative imaginary part below which a shift counts as real
#: projection shifts: reciprocal condition of X^T M X above which the Ritz values come from the
#: standard eigenproblem (geev) instead of QZ (recorded in every result's summary)
STANDARD_RCOND = 1e-8


@dataclass
class LRADIResult:
    r"""Result of one LR-ADI run (plain data).

    Attributes
    ----------
    position, velocity : ndarray, (n1, k), real
        The blocks of the Gramian factor :math:`Z = [Z_p; Z_v]` (``Z`` stacks
        them): :math:`P \approx ZZ^T` (controllability; both blocks in
        :math:`\ker G`) or :math:`Q \approx ZZ^T` (observability; position block
        in :math:`\operatorname{range}\Pi`, velocity block in :math:`\ker G`).
        ``position`` is a property: the observability position block is
        projected on first access (range-space form: two products with n2 columns).
    position_unprojected : ndarray, (n1, k)
        The position block as iterated: equal to ``position`` for
        controllability; for observability equal to it modulo
        :math:`\operatorname{range}(G^T)`, so products with vectors in
        :math:`\ker G` (all that balanced truncation needs) are the same.
    equation : str
        "controllability" or "observability".
    residuals : ndarray
        :math:`\|W_j^TW_j\|_2 / \|W_0^TW_0\|_2` after each step, ``residuals[0] = 1``
        (one entry per real step or complex double step).
    shifts : ndarray, complex
        Shifts used, in order; a complex pair appears as :math:`p, \bar p`.
    iterations : int
        ADI iterations, a complex pair counting two (``len(shifts)``).
    converged : bool
        ``residuals[-1] <= tol``.
    lu_count : int
        Sparse LUs made by the run (the shared ones of :func:`lradi_pair` are in
        both results).
    times : dict
        Seconds: "factor" (LUs, shared), "solve" (this equation's solves and
        updates), "shifts" (shift computations, shared), "residual", "total".
    strategy, selection, tol, maxiter, num_shifts
        What was asked for.
    shift_batches : list of int
        Shifts (a pair counted once) delivered by each shift computation.
    """

    position_unprojected: np.ndarray
    velocity: np.ndarray
    equation: str
    residuals: np.ndarray
    shifts: np.ndarray
    iterations: int
    converged: bool
    lu_count: int
    times: dict
    strategy: str
    selection: str
    tol: float
    maxiter: int
    num_shifts: int
    shift_batches: list = field(default_factory=list)
    projector: object = field(default=None, repr=False, compare=False)

    @property
    def position(self) -> np.ndarray:
        r"""Position block; for observability the :math:`\Pi`-representative (computed once)."""
        if self.projector is not None:
            self.position_unprojected = self.projector.project(self.position_unprojected)
            self.projector = None
        return self.position_unprojected

    @property
    def Z(self) -> np.ndarray:
        """The factor ``[position; velocity]``, (2 n1, k) (a new array on each access)."""
        return np.vstack([self.position, self.velocity])

    @property
    def rank(self) -> int:
        """Number of columns of the factor."""
        return int(self.velocity.shape[1])

    @property
    def residual(self) -> float:
        """The final relative residual norm."""
        return float(self.residuals[-1])

    def summary(self, history: bool = True) -> dict:
        """Everything but the factor (and, with ``history=False``, the residual history) as plain data."""
        out = {"equation": self.equation, "iterations": self.iterations, "converged": self.converged,
               "residual": self.residual, "rank": self.rank,
               "lu_count": self.lu_count, "strategy": self.strategy, "selection": self.selection,
               "num_shifts": self.num_shifts, "shifts": self.shifts.tolist(),
               "shift_batches": list(self.shift_batches), "times": dict(self.times),
               "ritz_standard_rcond": STANDARD_RCOND if self.strategy == "projection" else None}
        if history:
            out["residuals"] = self.residuals.tolist()
        return out


class ManifoldProjector:
    r"""Apply :math:`\Pi` through the saddle-point matrix of M: :math:`\Pi b = Mx`,

    .. math:: \begin{bmatrix} M & G^T \\ G & 0 \end{bmatrix}
              \begin{bmatrix} x \\ l \end{bmatrix} = \begin{bmatrix} b \\ 0 \end{bmatrix}.

    One real LU (``solver.factor(coeffs=(1, 0, 0))``) serves every call.
    ``proj(b)`` returns ``(Pi b, x)``; :math:`x = M^{-1}\Pi b \in \ker G` is
    the primal vector the shift strategies use. Without constraints both are ``b``.

    The matrix does not depend on the shift, so its LU is checked once, by the
    backward error of one solve, instead of after every solve (on dsms(6000)
    the solver's check and padding cost more than the solve itself: 1.7 ms
    against 0.7 ms); an LU that fails the check keeps the checked solves.

    ``proj.project(b)`` returns :math:`\Pi b` alone in range-space form,
    :math:`\Pi b = b - G^T X^T b` with
    :math:`X = M^{-T}G^T(GM^{-T}G^T)^{-1}` (n1 x n2, the first block of one
    checked transposed solve with :math:`[0; I_{n_2}]`): two products with n2
    columns instead of a sparse solve. The observability residual norm needs it
    every step (measured: the LU form took 0.4 ms a call on dsms(6000), 12 ms
    of a 0.16 s bt run, and 0.17 s for the 1200 calls of tcom(2000)).
    """

    #: largest normwise backward error accepted from the one-time check
    BACKWARD_TOL = 1e-12
    #: most constraints for which ``project`` keeps the dense n1 x n2 matrix X (above: solves)
    RANGE_FORM_MAX_N2 = 64

    def __init__(self, fom, solver):
        self.fom = fom
        self.lu = None
        self._raw = None  # the SuperLU object, used directly once the LU has passed the check
        self._X = None  # M^{-T} G^T (G M^{-T} G^T)^{-1}, for project()
        if fom.n2:
            lu = solver.factor(coeffs=(1.0, 0.0, 0.0))
            self.lu = lu
            # one check of the fixed LU (the solver's own measure), then unchecked solves
            ok = lu.matrix is None or lu.backward_error(np.cos(np.arange(fom.n1))) <= self.BACKWARD_TOL
            if ok and not lu.conjugate and not lu.complex_lu:
                self._raw = lu.lu
            if fom.n2 <= self.RANGE_FORM_MAX_N2:
                rhs = np.vstack([np.zeros((fom.n1, fom.n2)), np.eye(fom.n2)])
                self._X = np.ascontiguousarray(lu.solve(rhs, trans=True))  # checked (and refined) solve
                self._GT = fom.G.T.tocsr()

    def project(self, b):
        r""":math:`\Pi b` alone: :math:`b - G^T X^T b` (range-space form) for at most
        ``RANGE_FORM_MAX_N2`` constraints, else the solve of ``__call__``."""
        if self._X is None:
            return self(b)[0]
        return b - self._GT @ (self._X.T @ b)

    def __call__(self, b):
        if self.lu is None:
            return b, b
        if self._raw is None:  # an LU that failed the check: the solver's checked, refined solves
            x = self.lu.solve(b)
        else:  # real LU, zero constraint block; complex right-hand sides as 2k real columns
            if b.ndim == 1:
                Pb, x = self(b[:, None])
                return Pb[:, 0], x[:, 0]
            n1, k = self.fom.n1, b.shape[1]
            cplx = np.iscomplexobj(b)
            buf = np.zeros((n1 + self.fom.n2, 2 * k if cplx else k), order="F")
            if cplx:
                buf[:n1, :k], buf[:n1, k:] = b.real, b.imag
            else:
                buf[:n1] = b
            y = self.lu._raw_solve(buf, False)[:n1]  # unchecked, but with the equilibration
            x = y[:, :k] + 1j * y[:, k:] if cplx else y
        return self.fom.M @ x, x


def _is_symmetric(X) -> bool:
    """Exact symmetry of a sparse matrix."""
    return (X != X.T).nnz == 0


class _Iteration:
    """State of one LR-ADI iteration (controllability or observability)."""

    def __init__(self, fom, equation, proj, operators):
        self.fom, self.equation, self.proj = fom, equation, proj
        # [M; D] (controllability) or [M^T; D^T] (observability) stacked: one sparse product a step
        self.Mt, self.MD, self.symmetric_M = operators[equation]
        n1 = fom.n1
        if equation == "controllability":
            b, x = proj(fom.F)
            self.W1, self.W2 = np.zeros((n1, fom.m)), np.array(b, dtype=float)
        else:
            b, x = proj(fom.L.T)
            self.W1, self.W2 = np.array(b, dtype=float), np.zeros((n1, fom.p))
        self.primal0 = np.array(x, dtype=float)
        self.norm0 = self._norm2()
        if not self.norm0 > 0:
            raise InputError(f"the right-hand side of the {equation} equation is zero: matrix "
                             f"{'F' if equation == 'controllability' else 'L'} vanishes on the hidden manifold")
        # position and velocity blocks of the factor, column-major, grown by doubling (tried:
        # reserving maxiter columns up front saved 0.1-0.2 s of 4 s on tcom(2000), but numpy's
        # allocations are what tracemalloc counts, so the scaling benchmark's memory would show
        # the reservation, and a library should not reserve 128 MB for a 20-step run)
        self.Z1 = np.empty((n1, 32 * self.W1.shape[1]), order="F")
        self.Z2 = np.empty_like(self.Z1, order="F")
        self.k = 0
        self.residuals = [1.0]
        self.shifts = []
        self.iterations = 0
        self.done = self.converged = False
        self.block = []  # primal n1-columns produced since the last shift computation
        self.t_solve = self.t_res = 0.0

    def _norm2(self) -> float:
        r""":math:`\|W^TW\|_2` of the projected residual factor (an m x m or p x p eigenvalue).

        The observability iteration keeps :math:`W_1` modulo
        :math:`\operatorname{range}(G^T)` (nothing else depends on that
        component) and projects it here (:meth:`ManifoldProjector.project`: two
        products with n2 columns per step instead of a solve for the complex
        :math:`v_1`).
        """
        W1 = self.W1 if self.equation == "controllability" else self.proj.project(self.W1)
        return float(np.linalg.eigvalsh(W1.T @ W1 + self.W2.T @ self.W2)[-1])

    def step(self, lu, p):
        """One step with shift p (Re p < 0); a complex p is the double step for p and conj(p)."""
        t0 = time.perf_counter()
        fom = self.fom
        n1 = fom.n1
        if self.equation == "controllability":
            MD = self.MD @ self.W1
            V1 = lu.solve(p * MD[:n1] - MD[n1:] - self.W2)
            V2 = self.W1 - p * V1
            prim = V1  # V2 = W1 - p V1 adds nothing to the span but W1
        else:
            V2 = lu.solve(p * self.W2 - self.W1, trans=True)
            MD = self.MD @ V2
            V1 = self.W2 - p * MD[:n1] + MD[n1:]  # projected in _norm2 and factors()
            prim = V2  # the primal block: approximates left eigenvectors of the quadratic pencil
        t1 = time.perf_counter()
        if p.imag != 0:
            g = 2.0 * np.sqrt(-p.real)
            d = p.real / p.imag
            R1, R2 = V1.real + d * V1.imag, V2.real + d * V2.imag
            c = g * np.sqrt(d * d + 1.0)
            self._append(g, R1, R2)
            self._append(c, V1.imag, V2.imag)
            self._update(g * g, R1, R2)
            self.shifts += [p, np.conj(p)]
            self.iterations += 2
            self.block += [prim.real, prim.imag]
        else:
            pr = p.real
            V1, V2 = np.real(V1), np.real(V2)
            self._append(np.sqrt(-2.0 * pr), V1, V2)
            self._update(-2.0 * pr, V1, V2)
            self.shifts.append(complex(pr))
            self.iterations += 1
            self.block.append(np.real(prim))
        t2 = time.perf_counter()
        self.residuals.append(self._norm2() / self.norm0)
        self.t_solve += t1 - t0
        self.t_res += time.perf_counter() - t2

    def _append(self, c, X1, X2):
        """Append the columns c [X1; X2] to the factor (written in place: no temporaries)."""
        k, j = self.k, X1.shape[1]
        if k + j > self.Z1.shape[1]:
            for name in ("Z1", "Z2"):
                Z = np.empty((self.fom.n1, 2 * (k + j)), order="F")
                Z[:, :k] = getattr(self, name)[:, :k]
                setattr(self, name, Z)
        np.multiply(X1, c, out=self.Z1[:, k:k + j])
        np.multiply(X2, c, out=self.Z2[:, k:k + j])
        self.k = k + j

    def _update(self, c, R1, R2):
        r""":math:`W \leftarrow W + c\,ER` (controllability) or :math:`W + c\,E^TR` (observability)."""
        self.W1 = self.W1 + c * R1
        if self.equation == "controllability":
            self.W2 = self.W2 + c * (self.fom.M @ R2)
        elif self.symmetric_M:
            self.W2 = self.W2 + c * (self.Mt @ R2)
        else:  # M^T ker G is not range(Pi) when M is not symmetric
            self.W2 = self.W2 + c * self.proj.project(self.Mt @ R2)

    def take_block(self):
        """The primal columns produced since the last call, and the primal residual directions."""
        cols = list(self.block)
        self.block = []
        # E^{-1}W (controllability) or its primal counterpart (observability): where the residual lives
        cols += [self.W1, self.proj(self.W2)[1]] if self.equation == "controllability" else \
            [self.proj(self.W1)[1], self.proj(self.W2)[1]]
        return np.column_stack(cols)

    def factor(self):
        """The position and velocity blocks of the factor (n1 x k views; the observability
        position block unprojected, see LRADIResult.position)."""
        return self.Z1[:, : self.k], self.Z2[:, : self.k]


# -- shift strategies -------------------------------------------------------------
def _as_pairs(lam) -> np.ndarray:
    """Representatives (Im >= 0) of a set closed under conjugation; near-real ones made real."""
    lam = np.asarray(lam, dtype=complex).ravel()
    real = np.abs(lam.imag) <= _IMAG_TOL * np.abs(lam)
    lam = np.where(real, lam.real + 0j, lam)
    return lam[real | (lam.imag > 0)]


def _adi_gain(x, shifts) -> np.ndarray:
    r""":math:`\prod_j |x - \bar p_j| / |x + p_j|` over the closed set of ``shifts`` (representatives)."""
    x = np.asarray(x, dtype=complex)
    out = np.ones(x.shape)
    for p in shifts:
        out *= np.abs((x - np.conj(p)) / (x + p))
        if p.imag != 0:
            out *= np.abs((x - p) / (x + np.conj(p)))
    return out


def select_shifts(candidates, num, used=()) -> np.ndarray:
    r"""Greedy choice of at most ``num`` shifts (a pair counted once) among ``candidates``.

    Each pick is the candidate where the ADI rational function of the shifts
    already applied (``used``) and already picked is largest,

    .. math:: p_{k+1} = \arg\max_{x \in \mathcal{R}} \prod_j
              \left|\frac{x - \bar p_j}{x + p_j}\right|,

    Penzl's min-max heuristic (Penzl 1999, Algorithm 5.1); without history the
    first pick is the candidate whose own rational function is smallest over
    the set. Deterministic.

    Parameters
    ----------
    candidates : array_like, complex
        Shifts in the open left half-plane (a set closed under conjugation, or
        its representatives with Im >= 0).
    num : int
    used : array_like, complex
        Shifts already applied.

    Returns
    -------
    ndarray, complex
        Representatives (Im >= 0) of the chosen shifts.
    """
    cand = _as_pairs(candidates)
    cand = cand[np.lexsort((cand.imag, cand.real))]
    if cand.size <= num:
        return cand
    chosen = []
    history = list(_as_pairs(used))
    if not history:
        i = int(np.argmin([np.max(_adi_gain(cand, [c])) for c in cand]))
        chosen.append(cand[i])
        cand = np.delete(cand, i)
    while len(chosen) < num and cand.size:
        i = int(np.argmax(_adi_gain(cand, history + chosen)))
        chosen.append(cand[i])
        cand = np.delete(cand, i)
    return np.array(chosen, dtype=complex)


def _orthonormal_map(X, rank_tol=1e-12):
    r"""Columns of X scaled to unit norm, and T with :math:`(XT)^T(XT) = I` on the numerical span.

    The span is orthonormalised through the eigendecomposition of the small
    Gram matrix (eigenvalues below ``rank_tol`` times the largest dropped)
    rather than a QR of the tall X: k x k work and one tall product, accurate
    enough for Ritz values.
    """
    norms = np.sqrt(np.einsum("ij,ij->j", X, X))
    X = X[:, norms > 0] / norms[norms > 0]
    if X.shape[1] == 0:
        return X, np.zeros((0, 0))
    w, U = np.linalg.eigh(X.T @ X)
    ok = w > rank_tol * w[-1]
    return X, U[:, ok] / np.sqrt(w[ok])


def projection_shifts(fom, basis, num, *, residuals=(), selection="residual", used=(),
                      standard_rcond=None) -> np.ndarray:
    r"""Projection shifts: Ritz values of the pencil on a block of ADI columns, mirrored into :math:`\mathbb{C}^-`.

    With :math:`X` an orthonormal basis of ``basis`` (n1-vectors in
    :math:`\ker G`: the latest ADI block and the residual directions), the
    pencil :math:`(A, E)` is projected onto :math:`\mathrm{blkdiag}(X, X)`,

    .. math::

        \hat E = \begin{bmatrix} I & 0 \\ 0 & X^TMX \end{bmatrix},\qquad
        \hat A = \begin{bmatrix} 0 & I \\ -X^TKX & -X^TDX \end{bmatrix},

    whose :math:`2k` eigenvalues are those of the projected quadratic pencil
    (stable whenever M, K are positive definite and D semidefinite). Ritz values
    with :math:`\mathrm{Re}\,\lambda \ge 0` are mirrored to
    :math:`-\mathrm{Re}\,\lambda + i\,\mathrm{Im}\,\lambda`.

    Parameters
    ----------
    fom : Index3Model
    basis : ndarray (n1, k)
        Columns in :math:`\ker G`.
    num : int
        Shifts returned at most (a complex pair counted once).
    residuals : sequence of (equation, W1, W2)
        Current residual factors; used by ``selection="residual"``.
    selection : {"residual", "gain"}
        ``"residual"``: the Ritz values whose Ritz vectors carry the largest part
        of the current residuals. With right and left eigenvectors
        :math:`\hat x_i, \hat y_i` of :math:`(\hat A, \hat E)` and the projected
        residual :math:`\hat w = [X^TW_1; X^TW_2]`, the score of
        :math:`\lambda_i` is
        :math:`\|\hat y_i^H \hat w\|\,\|\hat x_i\| / |\hat y_i^H \hat E \hat x_i|`
        (controllability; the roles of :math:`\hat x, \hat y` swap for
        observability), each equation's scores scaled to a maximum of 1.
        ``"gain"``: :func:`select_shifts` with the history ``used``.
    used : array_like
        Shifts already applied (``selection="gain"``).
    standard_rcond : float, optional
        Default ``STANDARD_RCOND`` (1e-8). When the estimated reciprocal 1-norm condition of :math:`X^TMX` exceeds
        this, it is inverted and the eigenproblem solved in standard form
        (LAPACK geev on :math:`\hat E^{-1}\hat A`, left vectors mapped back by
        :math:`\hat E^{-T}`); otherwise, and with 0, by QZ on the pencil. Same
        Ritz values to rounding; measured with bt (tol 1e-12): the dsms(6000)
        shift sequence agrees with QZ's to 5e-15, tcom(2000)'s drifts to 3e-5
        over its 600 shifts (rounding amplified through the iterates) with
        the same iteration counts (1167 / 1205) and Hankel singular values
        to 4e-11; geev with both vectors at 2k = 110 took 5.5 ms against
        11.5 ms for QZ.

    Returns
    -------
    ndarray, complex
        Representatives (Im >= 0) of the chosen shifts, in the open left half-plane.
    """
    X, T = _orthonormal_map(np.asarray(basis, dtype=float))
    k = T.shape[1]
    if k == 0:
        return np.zeros(0, dtype=complex)
    XT = X @ T
    Mk, Dk, Kk = (XT.T @ (Y @ XT) for Y in (fom.M, fom.D, fom.K))
    I, Z0 = np.eye(k), np.zeros((k, k))
    Eh = np.block([[I, Z0], [Z0, Mk]])
    # QZ on the balanced pencil lambda = g mu, g = sqrt(|K| / |M|) (physical units,
    # M ~ 1e-6 and K ~ 1e9, made ggev fail on the raw one); vectors mapped back
    nm, nk = np.linalg.norm(Mk, 1), np.linalg.norm(Kk, 1)
    g = np.sqrt(nk / nm) if nm > 0 and nk > 0 else 1.0
    # a well-conditioned X^T M X is inverted: the standard eigenproblem of Ehs^{-1} Ahs (geev) has
    # the pencil's eigenvalues and right vectors, and its left vectors are Ehs^T times the pencil's
    mlu = None
    standard_rcond = STANDARD_RCOND if standard_rcond is None else standard_rcond
    if standard_rcond > 0 and nm > 0:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sla.LinAlgWarning)  # a singular Mk: dgecon says so
            mlu = sla.lu_factor(Mk, check_finite=False)
        rcond, info = sla.lapack.dgecon(mlu[0], nm, norm="1")
        if info != 0 or not rcond > standard_rcond:
            mlu = None
    if mlu is not None:
        B = np.block([[Z0, I], [sla.lu_solve(mlu, Kk, check_finite=False) / (-g * g),
                                 sla.lu_solve(mlu, Dk, check_finite=False) / (-g)]])
    else:
        Ehs = np.block([[I, Z0], [Z0, g * g * Mk]])
        Ahs = np.block([[Z0, I], [-Kk, -g * Dk]])
    if selection == "gain" or not residuals:
        lam = g * (sla.eigvals(B, check_finite=False) if mlu is not None else sla.eigvals(Ahs, Ehs))
        lam = lam[np.isfinite(lam)]
        shifts = np.where(lam.real > 0, -lam.real + 1j * lam.imag, lam)
        return select_shifts(shifts[shifts.real < 0], num, used)
    if mlu is not None:
        mu, yl, xr = sla.eig(B, left=True, right=True, check_finite=False)
        yl[k:] = sla.lu_solve(mlu, yl[k:], trans=1, check_finite=False) / (g * g)  # Ehs^{-T} y
    else:
        mu, yl, xr = sla.eig(Ahs, Ehs, left=True, right=True)
    ok = np.isfinite(mu)
    lam, yl, xr = g * mu[ok], yl[:, ok], xr[:, ok]
    xr[k:] *= g        # right vectors [u; mu u] -> [u; lambda u]
    yl[:k] /= g        # left vectors of (Ah, Eh): diag(I / g, I) times those of the scaled pencil
    den = np.abs(np.einsum("ij,ij->j", yl.conj(), Eh @ xr))
    den[den == 0] = np.inf
    score = np.zeros(lam.size)
    for equation, W1, W2 in residuals:
        w = np.vstack([XT.T @ W1, XT.T @ W2])
        if equation == "controllability":
            s = np.linalg.norm(yl.conj().T @ w, axis=1) * np.linalg.norm(xr, axis=0) / den
        else:
            s = np.linalg.norm(xr.T @ w, axis=1) * np.linalg.norm(yl, axis=0) / den
        if s.size and s.max() > 0:  # no finite Ritz value: nothing to score (stress suite)
            score = np.maximum(score, s / s.max())
    shifts = np.where(lam.real > 0, -lam.real + 1j * lam.imag, lam)
    real = np.abs(shifts.imag) <= _IMAG_TOL * np.abs(shifts)
    keep = (real | (shifts.imag > 0)) & (shifts.real < 0)
    shifts = np.where(real, shifts.real + 0j, shifts)[keep]
    order = np.argsort(-score[keep], kind="stable")[:num]
    return shifts[order]


def penzl_shifts(fom, solver, num, *, kp=None, km=None, projector=None) -> np.ndarray:
    r"""Penzl's heuristic shifts on the hidden manifold (Penzl 1999, Algorithm 5.1).

    ``kp`` Arnoldi steps with :math:`E^{-1}A` and ``km`` with :math:`A^{-1}E`,
    both restricted to :math:`\ker G \times \ker G` by saddle-point solves with
    M and with K, from :math:`[0; M^{-1}\Pi F]`, give Ritz values
    :math:`\mathcal{R}_+ \cup 1/\mathcal{R}_-`; the stable ones are reduced to
    ``num`` shifts by :func:`select_shifts`. Ritz values of :math:`A^{-1}E` at
    rounding level (a Krylov space that closed early) are discarded: they would
    give shifts of modulus 1e13 that wreck the iteration.

    Parameters
    ----------
    fom : Index3Model
    solver : SaddlePointSolver
    num : int
        Shifts returned (a complex pair counted once).
    kp, km : int, optional
        Arnoldi steps; default ``2 num + 10`` and ``num + 5``.
    projector : ManifoldProjector, optional

    Returns
    -------
    ndarray, complex
        Representatives (Im >= 0) of the shifts.
    """
    n1 = fom.n1
    kp = 2 * num + 10 if kp is None else int(kp)
    km = num + 5 if km is None else int(km)
    proj = projector or ManifoldProjector(fom, solver)
    v0 = np.concatenate([np.zeros(n1), proj(fom.F[:, 0])[1]])
    K_lu = solver.factor(coeffs=(0.0, 0.0, 1.0))

    def e_inv_a(v):
        return np.concatenate([v[n1:], proj(-(fom.K @ v[:n1]) - fom.D @ v[n1:])[1]])

    def a_inv_e(v):  # the shifted solve with mu = 0
        return np.concatenate([K_lu.solve(-(fom.D @ v[:n1]) - fom.M @ v[n1:]), v[:n1]])

    rp = _arnoldi_ritz(e_inv_a, v0, kp)
    rm = _arnoldi_ritz(a_inv_e, v0, km)
    rm = rm[np.abs(rm) > 1e-8 * np.abs(rm).max()]
    cand = np.concatenate([rp, 1.0 / rm])
    return select_shifts(cand[np.isfinite(cand) & (cand.real < 0)], num)


def _arnoldi_ritz(op, v0, k) -> np.ndarray:
    n = v0.size
    k = min(k, n - 1)
    Q = np.zeros((n, k + 1))
    H = np.zeros((k + 1, k))
    Q[:, 0] = v0 / np.linalg.norm(v0)
    for j in range(k):
        w = op(Q[:, j])
        for _ in range(2):  # classical Gram-Schmidt, twice
            h = Q[:, : j + 1].T @ w
            w = w - Q[:, : j + 1] @ h
            H[: j + 1, j] += h
        H[j + 1, j] = np.linalg.norm(w)
        if H[j + 1, j] <= 1e-14 * np.abs(H[: j + 2, j]).max():
            k = j + 1
            break
        Q[:, j + 1] = w / H[j + 1, j]
    return np.linalg.eigvals(H[:k, :k])


# -- drivers ------------------------------------------------------------------------
def _positive_int(name, value):
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < 1:
        raise InputError(f"{name} must be a positive integer; got {value!r}")
    return int(value)


def _check_shifts(shifts):
    if isinstance(shifts, str):
        if shifts not in STRATEGIES:
            raise InputError(f"shifts must be one of {', '.join(map(repr, STRATEGIES))} or an array of "
                             f"shifts in the open left half-plane; got {shifts!r}")
        return shifts
    try:
        arr = np.asarray(shifts)
    except (TypeError, ValueError) as exc:
        raise InputError(f"shifts must be a strategy name or a 1-D array of numbers; got {shifts!r}") from exc
    if arr.ndim != 1 or arr.size == 0 or not np.issubdtype(arr.dtype, np.number) or not np.all(np.isfinite(arr)):
        raise InputError("shifts must be a strategy name or a non-empty 1-D array of finite numbers")
    arr = arr.astype(complex)
    if np.any(arr.real >= 0):
        raise InputError(f"shifts must lie in the open left half-plane (Re p < 0); got max Re p = "
                         f"{arr.real.max():.3g}")
    reps = _as_pairs(arr)
    up, down = reps[reps.imag > 0], arr[arr.imag < -_IMAG_TOL * np.abs(arr)]
    if up.size != down.size or not np.allclose(np.sort_complex(up), np.sort_complex(np.conj(down)),
                                               rtol=1e-12, atol=0):
        raise InputError("shifts must be closed under complex conjugation")
    return reps


def _run(fom, equations, tol, maxiter, shifts, num_shifts, selection, solver):
    from ..models.index3 import Index3Model

    if not isinstance(fom, Index3Model):
        raise InputError(f"fom must be an Index3Model; got {type(fom).__name__}")
    if isinstance(tol, (bool, np.bool_)) or not isinstance(tol, (int, float, np.floating)) \
            or not 0 < float(tol) < 1:
        raise InputError(f"tol must be a float in (0, 1); got {tol!r}")
    maxiter = _positive_int("maxiter", maxiter)
    num_shifts = _positive_int("num_shifts", num_shifts)
    if selection not in SELECTIONS:
        raise InputError(f"selection must be one of {', '.join(map(repr, SELECTIONS))}; got {selection!r}")
    strategy = _check_shifts(shifts)
    with blas_threads(1):
        return _iterate(fom, equations, float(tol), maxiter, strategy, num_shifts, selection, solver)


def _iterate(fom, equations, tol, maxiter, strategy, num_shifts, selection, solver):
    t_start = time.perf_counter()
    solver = fom.new_solver(cache_size=0) if solver is None else solver
    stats0 = solver.stats.copy()
    proj = ManifoldProjector(fom, solver)
    sym_m = _is_symmetric(fom.M)
    Mt = fom.M if sym_m else fom.M.T.tocsr()
    operators = {"controllability": (fom.M, sp.vstack([fom.M, fom.D], format="csr"), sym_m),
                 "observability": (Mt, sp.vstack([Mt, fom.D.T], format="csr"), sym_m)}
    its = [_Iteration(fom, eq, proj, operators) for eq in equations]
    given = not isinstance(strategy, str)
    label = "given" if given else strategy
    queue: deque = deque()
    used, batches = [], []
    fixed = None  # a shift set used cyclically (given or Penzl)
    t_shift = 0.0
    t0 = time.perf_counter()
    if given:
        fixed = list(strategy)
    elif strategy == "penzl":
        fixed = list(penzl_shifts(fom, solver, num_shifts, projector=proj))
    else:
        first = projection_shifts(fom, np.hstack([it.primal0 for it in its]), num_shifts,
                                  residuals=[(it.equation, it.W1, it.W2) for it in its], selection=selection)
        queue.extend(first)
        batches.append(len(first))
    t_shift += time.perf_counter() - t0
    while True:
        active = [it for it in its if not it.done]
        if not active:
            break
        if not queue:
            t0 = time.perf_counter()
            if fixed is not None:
                new = fixed
            else:
                basis = np.hstack([it.take_block() for it in active])
                new = list(projection_shifts(fom, basis, num_shifts,
                                             residuals=[(it.equation, it.W1, it.W2) for it in active],
                                             selection=selection, used=used))
                if not new:  # no usable Ritz value (cannot happen for SPD M, K): recycle
                    new = used[-max(batches[-1], 1):]
            if not new:
                raise ModelError("lradi: no usable shift: the projected pencil has no finite stable Ritz value "
                                 "(seen on models whose M and K scales differ by 1e15 or more); try "
                                 "shifts='penzl'")
            queue.extend(new)
            batches.append(len(new))
            t_shift += time.perf_counter() - t0
        p = complex(queue.popleft())
        for it in active:  # a complex pair is two iterations: never step past maxiter
            if it.iterations + (2 if p.imag else 1) > maxiter:
                it.done = True
        active = [it for it in active if not it.done]
        if not active:
            break
        lu = solver.factor(-p if p.imag else -p.real)
        used.append(p)
        for i, it in enumerate(active):
            # the first solve with an LU is checked (backward error, refinement); that
            # check probes the stability of the factors, which the second solve shares
            it.step(lu if i == 0 or lu.matrix is None else replace(lu, matrix=None), p)
            if it.residuals[-1] <= tol:
                it.done = it.converged = True
            elif it.iterations >= maxiter:
                it.done = True
    total = time.perf_counter() - t_start
    st = solver.stats.since(stats0)
    out = []
    for it in its:
        if not it.converged:
            warnings.warn(f"LR-ADI ({it.equation}) did not converge: maxiter = {maxiter} iterations reached "
                          f"with relative residual {it.residuals[-1]:.2e} > tol = {tol:.1e}",
                          ConvergenceWarning, stacklevel=4)
        times = {"factor": st["factor_time_s"] + st["assemble_time_s"], "solve": it.t_solve,
                 "shifts": t_shift, "residual": it.t_res, "total": total}
        Zp, Zv = it.factor()
        out.append(LRADIResult(position_unprojected=Zp, velocity=Zv, equation=it.equation,
                               residuals=np.array(it.residuals), shifts=np.array(it.shifts, dtype=complex),
                               iterations=it.iterations, converged=it.converged,
                               lu_count=int(st["factorizations"]), times=times, strategy=label,
                               selection=selection, tol=tol, maxiter=maxiter,
                               num_shifts=num_shifts, shift_batches=list(batches),
                               projector=proj if it.equation == "observability" and proj.lu is not None else None))
    return out


def lradi(fom, equation="controllability", *, tol=1e-10, maxiter=2000, shifts="projection", num_shifts=16,
          selection="residual", solver=None) -> LRADIResult:
    r"""Low-rank ADI for one projected Lyapunov equation (see the module docstring).

    Parameters
    ----------
    fom : Index3Model
    equation : {"controllability", "observability"}
        :math:`APE^T + EPA^T = -\Pi_lBB^T\Pi_l^T` (from F) or
        :math:`A^TQE + E^TQA = -\Pi_r^TC^TC\Pi_r` (from :math:`L^T`).
    tol : float in (0, 1)
        Stop when :math:`\|W^TW\|_2 / \|W_0^TW_0\|_2 \le` tol.
    maxiter : int
        Largest number of iterations (a complex pair counts two).
    shifts : {"projection", "penzl"} or array_like
        Strategy, or explicit shifts in the open left half-plane, closed under
        conjugation, used cyclically.
    num_shifts : int
        Shifts (a pair counted once) taken from each shift computation.
    selection : {"residual", "gain"}
        How projection shifts are chosen among the Ritz values
        (:func:`projection_shifts`).
    solver : SaddlePointSolver, optional
        Default ``fom.new_solver(cache_size=0)``.

    Returns
    -------
    LRADIResult

    Raises
    ------
    InputError
        For a bad argument (the message names it).

    Warns
    -----
    ConvergenceWarning
        If ``maxiter`` iterations did not reach ``tol``; the result then has
        ``converged=False`` and holds the last iterate.
    """
    if equation not in EQUATIONS:
        raise InputError(f"equation must be 'controllability' or 'observability'; got {equation!r}")
    return _run(fom, (equation,), tol, maxiter, shifts, num_shifts, selection, solver)[0]


def lradi_pair(fom, *, tol=1e-10, maxiter=2000, shifts="projection", num_shifts=16, selection="residual",
               solver=None):
    r"""Both projected Lyapunov equations in lock step: one shift sequence, one LU per shift.

    Each LU of :math:`[[S(-p), G^T], [G, 0]]` serves the controllability solve
    and the transposed observability solve; projection shifts are computed from
    the latest blocks and residuals of both iterations. An equation that has
    converged stops and the other goes on alone. Parameters as in :func:`lradi`.

    Returns
    -------
    (LRADIResult, LRADIResult)
        Controllability and observability; ``lu_count``, ``times["factor"]``,
        ``times["shifts"]`` and ``times["total"]`` are those of the shared run.
    """
    c, o = _run(fom, EQUATIONS, tol, maxiter, shifts, num_shifts, selection, solver)
    return c, o
