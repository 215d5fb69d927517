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
same LU and a residual beyond double precision
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
from .factor_store import FactorStore
from .refine import refine_columns

__all__ = ["ADIIteration", "FactorStore"]  # FactorStore: from linalg.factor_store (its home since 2026-12-02)


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
    compress_from_mib : float
        With ``compress_tol`` > 0, the factor is kept plain up to this many MiB (:class:`FactorStore`).
    """

    def __init__(self, fom, equation, proj, operators, refine=0, saddle=None, compress_tol=0.0, compress_from_mib=0.0):
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
        self.store = FactorStore(n1, compress_tol, chunk=max(64, 8 * self.W1.shape[1]),
                                 plain_bytes=compress_from_mib * 2.0 ** 20)
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

    def take_block(self) -> list:
        """The primal columns produced since the last call, and the primal residual directions: a list of
        n1-row arrays (the caller stacks the blocks of both equations once: at n1 = 2e5 every fresh
        n1 x k array is page-faulted anew, ``docs/design/lradi.md``)."""
        cols = list(self.block)
        self.block = []
        # E^{-1}W (controllability) or its primal counterpart (observability): where the residual lives
        cols += [self.W1, self.proj(self.W2)[1]] if self.equation == "controllability" else \
            [self.proj(self.W1)[1], self.proj(self.W2)[1]]
        return cols

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

