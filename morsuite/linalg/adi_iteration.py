r"""One LR-ADI iteration: the shifted solves, the factor and the residual of one equation.

With :math:`S(s) = s^2M + sD + K`, the shifted solve
:math:`(A + \mu E)[v_1; v_2] = [w_1; w_2]` of the first-order form
(:mod:`morsuite.linalg.lradi`) is

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
(``SaddlePointSolver.factor(-mu)``); :math:`\Pi` is never formed. In the
controllability iteration both blocks of :math:`V_j` lie in :math:`\ker G` and
:math:`W_j` stays in :math:`\ker G \times \operatorname{range}\Pi` without any
projection. In the observability iteration the position block :math:`v_1` is a
covector, defined only modulo :math:`\operatorname{range}(G^T)`: it is kept
unprojected (the solves only see it through the multiplier) and projected by
:meth:`ManifoldProjector.project` where it matters, in :math:`W_j` before its
norm is taken, so that :math:`W_jW_j^T` is the residual of the projected
equation, and in the factor once, when it is asked for.

With ``refine`` > 0 each shifted solve is refined that many times with the
same LU and a residual in ``np.longdouble``
(:func:`~morsuite.linalg.refine.refine_columns`). An unrefined solve at a
shift next to a lightly damped or slow pole has a forward error of about
:math:`\kappa\varepsilon`, and the Gramian inherits it: on tcom(nc = 2000)
:math:`\|LZ_p\|_F^2` was 7.9e-12 relative off the exact
:math:`\|T\|_{\mathcal H_2}^2` at every ADI tolerance, 8e-15 with one step
of the controllability solves (``docs/design/norms.md``). The largest first correction (relative, per
column: the unrefined solves' forward error) is kept in ``rho``.

Cost per step: one solve (plain or transposed) with an LU made by the driver,
one sparse product with :math:`[M; D]`, an m x m (p x p) symmetric eigenvalue
for the residual norm; no LU of its own; per refinement step and column one
long-double product with the saddle-point matrix and one pair of triangular
solves.
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import InputError
from .refine import refine_columns

__all__ = ["ADIIteration", "FactorStore"]


class FactorStore:
    r"""The columns of a low-rank factor :math:`Z = [Z_1; Z_2]` (n1-blocks), kept plain or compressed.

    ``tol = 0``: the columns are stored as appended (blocks grown by doubling: a run should
    not reserve ``maxiter`` columns it may never use).

    ``tol > 0``: column compression as the factor grows. The store holds
    :math:`ZZ^T = QFF^TQ^T` with :math:`Q = [Q_1; Q_2]` orthonormal (stacked) and F
    square. Appended columns wait in a buffer of ``chunk`` columns, then are absorbed:
    with :math:`C = Q^TB` and :math:`B - QC = Q_bR_b` (classical Gram-Schmidt twice, then
    a Householder QR and the SVD of :math:`R_b`, which drops only numerically null
    directions, singular values below :math:`10\varepsilon\,\sigma_1(Z)`), Q gains those
    of :math:`Q_b` and F becomes the triangular factor of :math:`[[F, C], [0, R_b]]`.
    When Q has grown by half since the last
    truncation (and at the end), the small SVD :math:`F = U\Sigma V^T` truncates: the
    singular values below ``tol`` times :math:`\sigma_1(Z)` are dropped,
    :math:`Q \leftarrow QU_t` (in place, by row blocks) and :math:`F = \Sigma_t`. A
    truncation changes :math:`ZZ^T` by at most :math:`\mathrm{tol}^2\sigma_1(Z)^2`
    (the rank-revealing SVD of Z itself); an absorption by at most
    :math:`20\sqrt{b}\,\varepsilon\,\sigma_1(Z)^2`. Every kept column is a combination
    of appended ones, so the store commutes with any projection applied to the rows
    (the observability position block is kept unprojected, see :class:`ADIIteration`).

    Memory: plain, the blocks grow by doubling and are trimmed to the columns in use at
    :meth:`finish`; compressed, by an eighth (at least ``chunk`` columns).

    Cost with r kept columns: an absorption of b columns :math:`8n_1rb` flops (two
    Gram-Schmidt passes) plus a QR of :math:`2n_1 \times b`; a truncation
    :math:`4n_1 r t` (the rotation; t kept), at most about :math:`\log_{1.5}` of the
    final rank times. Memory: at most 1.5 times the kept columns plus ``chunk``, instead
    of every column produced.
    """

    def __init__(self, n1, tol=0.0, chunk=64):
        self.n1, self.tol, self.chunk = int(n1), float(tol), int(chunk)
        self.Z1 = np.empty((self.n1, 0), order="F")
        self.Z2 = np.empty((self.n1, 0), order="F")
        self.k = 0           # plain: columns stored; compressed: columns of Q
        self.F = np.zeros((0, 0))
        self.buf1, self.buf2 = [], []
        self.columns = 0     # columns appended in all
        self.compressions = 0  # truncations
        self.k_truncated = 0   # rank after the last truncation
        self.k_peak = 0        # most columns held at once (compressed: before a truncation)
        self.t_compress = 0.0
        self.done = False

    def _reserve(self, cols):
        """Room for ``cols`` columns: plain, doubled (amortised appends); compressed, ``cols`` plus
        an eighth or one ``chunk``, whichever is more (its column count is bounded by the truncation
        rule, and a doubled Q at n1 = 1e6 would hold gigabytes of unused columns)."""
        if cols > self.Z1.shape[1]:
            room = max(2 * cols, 32) if self.tol == 0 else cols + max(self.chunk, cols // 8)
            for name in ("Z1", "Z2"):
                Z = np.empty((self.n1, room), order="F")
                Z[:, :self.k] = getattr(self, name)[:, :self.k]
                setattr(self, name, Z)

    def _trim(self):
        """Release the unused columns of the blocks (one block copied at a time): the factor
        is kept for the reducer's life, and a doubled store can hold twice its columns."""
        for name in ("Z1", "Z2"):
            Z = getattr(self, name)
            if Z.shape[1] > self.k + max(8, self.k // 16):
                setattr(self, name, np.array(Z[:, :self.k], order="F"))

    def append(self, c, X1, X2):
        """Append the columns c [X1; X2]."""
        j = X1.shape[1]
        self.columns += j
        if self.tol == 0:
            self._reserve(self.k + j)
            np.multiply(X1, c, out=self.Z1[:, self.k:self.k + j])
            np.multiply(X2, c, out=self.Z2[:, self.k:self.k + j])
            self.k += j
            return
        self.buf1.append(c * X1)
        self.buf2.append(c * X2)
        if sum(b.shape[1] for b in self.buf1) >= self.chunk:
            self._absorb()
            if self.k >= max(2 * self.chunk, 1.5 * self.k_truncated):
                self._truncate()

    def _absorb(self):
        if not self.buf1:
            return
        t0 = time.perf_counter()
        B1, B2 = np.hstack(self.buf1), np.hstack(self.buf2)
        self.buf1, self.buf2 = [], []
        r, b, n1 = self.k, B1.shape[1], self.n1
        C = np.zeros((r, b))
        if r:
            Q1, Q2 = self.Z1[:, :r], self.Z2[:, :r]
            for _ in range(2):  # classical Gram-Schmidt twice (BLAS 3)
                H = Q1.T @ B1 + Q2.T @ B2
                B1 -= Q1 @ H
                B2 -= Q2 @ H
                C += H
        Qb, Rb = np.linalg.qr(np.vstack([B1, B2]))  # Householder (BLAS 3)
        Ub, sb, Vbt = np.linalg.svd(Rb)  # B - QC = (Qb Ub) diag(sb) Vbt: its numerical rank
        big = np.block([[self.F, C], [np.zeros((sb.size, r)), sb[:, None] * Vbt]])
        s1 = np.linalg.norm(big, 2)
        t = int(np.sum(sb > 10 * np.finfo(float).eps * s1)) if s1 > 0 else 0
        Qb = Qb @ Ub[:, :t]
        self.F = np.linalg.qr(big[:r + t].T, mode="r").T  # big big^T = F F^T
        self._reserve(r + t)
        self.Z1[:, r:r + t] = Qb[:n1, :t]
        self.Z2[:, r:r + t] = Qb[n1:, :t]
        self.k = r + t
        self.k_peak = max(self.k_peak, self.k)
        self.t_compress += time.perf_counter() - t0

    def _rotate(self, X):
        """:math:`Q \\leftarrow QX` in place (X is k x t, t <= k), by row blocks."""
        r, t = X.shape
        step = max(1, 2 ** 22 // max(r, 1))
        for Z in (self.Z1, self.Z2):
            for i in range(0, self.n1, step):
                Z[i:i + step, :t] = Z[i:i + step, :r] @ X
        self.k = t

    def _truncate(self):
        """Drop the singular values of F below tol times the largest (rotating Q)."""
        t0 = time.perf_counter()
        U, s, _ = np.linalg.svd(self.F)
        t = int(np.sum(s > self.tol * s[0])) if s.size and s[0] > 0 else 0
        self._rotate(U[:, :t])
        self.F = np.diag(s[:t])
        self.k_truncated = t
        self.compressions += 1
        self.t_compress += time.perf_counter() - t0

    def finish(self):
        """Absorb the buffer, truncate, and turn Q into the factor :math:`QF` (in place); once.
        The blocks are then trimmed to the columns in use."""
        if self.done:
            return
        if self.tol == 0:
            self._trim()
            self.done = True
            return
        self._absorb()
        self._truncate()
        t0 = time.perf_counter()
        self._rotate(self.F)  # F is diagonal: Q U_t Sigma_t
        self._trim()
        self.done = True
        self.t_compress += time.perf_counter() - t0

    def blocks(self):
        """The factor's blocks (n1 x rank views); after :meth:`finish` when compressing."""
        if not self.done:
            raise RuntimeError("FactorStore.blocks before finish")
        return self.Z1[:, :self.k], self.Z2[:, :self.k]


class ADIIteration:
    """State of one LR-ADI iteration (controllability or observability).

    Parameters
    ----------
    fom : ConstrainedSystem
        Reads M, F, L, n1, m, p.
    equation : {"controllability", "observability"}
    proj : ManifoldProjector
    operators : dict
        ``{equation: (Mt, MD, symmetric_M)}``: :math:`M` or :math:`M^T`, the
        stacked :math:`[M; D]` or :math:`[M^T; D^T]` (one sparse product a
        step), and whether M is symmetric.
    refine : int
        Long-double refinement steps of each shifted solve (0: none).
    saddle : SaddleOperator or None
        :math:`S(a)x` in long double on the solver's pattern (needed when ``refine`` > 0).
    compress_tol : float
        Column compression of the factor (:class:`FactorStore`; 0: none).
    """

    def __init__(self, fom, equation, proj, operators, refine=0, saddle=None, compress_tol=0.0):
        self.fom, self.equation, self.proj = fom, equation, proj
        self.refine, self.saddle = int(refine), saddle
        self.rho = 0.0  # the largest first correction of a refined solve, relative
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
        self.store = FactorStore(n1, compress_tol, chunk=max(64, 8 * self.W1.shape[1]))
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
            V1 = self._solve(lu, p * MD[:n1] - MD[n1:] - self.W2, False, p)
            V2 = self.W1 - p * V1
            prim = V1  # V2 = W1 - p V1 adds nothing to the span but W1
        else:
            V2 = self._solve(lu, p * self.W2 - self.W1, True, p)
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

    def _solve(self, lu, rhs, trans, p):
        """The shifted solve with the LU of :math:`S(-p)`, refined ``refine`` times."""
        if not self.refine:
            return lu.solve(rhs, trans=trans)
        x = lu.solve(rhs, trans=trans, full=True)
        xr, xi, rho = refine_columns(lu, rhs, x, trans, -p if p.imag else -p.real, self.saddle,
                                     steps=self.refine)
        self.rho = max(self.rho, rho)
        n1 = self.fom.n1
        return xr[:n1].astype(float) if xi is None else xr[:n1].astype(float) + 1j * xi[:n1].astype(float)

    def _append(self, c, X1, X2):
        """Append the columns c [X1; X2] to the factor."""
        self.store.append(c, X1, X2)

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

    def finish(self):
        """Complete the factor (absorb the last compressed columns); call once, after the last step."""
        self.store.finish()

    @property
    def columns(self) -> int:
        """Columns produced by the steps."""
        return self.store.columns

    @property
    def compressions(self) -> int:
        """Blocks absorbed by column compression."""
        return self.store.compressions

    @property
    def t_compress(self) -> float:
        """Seconds spent compressing."""
        return self.store.t_compress

    def factor(self):
        """The position and velocity blocks of the factor (n1 x k views; the observability
        position block unprojected, see LRADIResult.position)."""
        return self.store.blocks()

