r"""One expansion point of the adaptive reducer: one sparse LU, moments in both directions, the true sample.

At a point :math:`s_0` (complex :math:`j\omega`, or real), with the one LU of
:math:`S(s_0) = [[s_0^2M + s_0D + K,\ G^T], [G,\ 0]]`, the second-order Arnoldi process
(:class:`~morsuite.reducers.krylov.soar.SOAR`) runs from the inputs :math:`F` (the right solves)
and from the outputs :math:`L^T` (the transposed solves, same LU); for a symmetric model, whose
:math:`S(s_0)^T = S(s_0)`, as one block recurrence started at :math:`[F, L^T]` (the same spaces
level by level, block solves). ``levels + extra`` levels of each are made, level by level; the first ``levels`` levels are the point's *primary*
columns (they enter the reduced model), the last ``extra`` its *enrichment* (they enter only the richer
space of the error estimate, :mod:`.estimate`). The first right solve also gives the full model's
transfer function at the point, :math:`T(s_0) = LX_0`: a true sample the reducer keeps (it validates the
estimate there, for free). The LU is released when the point is made: a point costs one LU whatever
happens later (at fem_block(1e5) an LU takes gigabytes; the reducer never holds two).

Cost: one sparse LU (complex for a complex point), ``(levels + extra)`` block solves per side with
``m`` (right) and ``p`` (left) columns, two sparse products per solve column and SOAR's
orthogonalisation, :math:`O(n_1 k^2)` for its k pairs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..krylov.soar import SOAR

__all__ = ["PointData", "make_point"]


@dataclass
class PointData:
    """What one expansion point left behind (its LU is released).

    Attributes
    ----------
    s : complex
        The point (one of a conjugate pair; the real basis serves both).
    primary, enrichment : list of ndarray
        Blocks of n1 rows, in the order made (level 0 right, level 0 left, level 1 right, ...):
        the reduced model's columns and the estimate's extra columns.
    T : ndarray (p, m)
        The full model's :math:`T(s_0)` from the first right solve (the LU's solution).
    levels : dict
        Levels made per side among the primary columns (``right`` and ``left``, or ``both`` for a
        symmetric model's block recurrence; a side whose Krylov space is exhausted stops early).
    lu_seconds, solve_seconds : float
        Time of the LU (with its assembly) and of the levels.
    solves : int
        Saddle solves (right-hand-side columns).
    """

    s: complex
    primary: list = field(default_factory=list)
    enrichment: list = field(default_factory=list)
    T: np.ndarray | None = None
    levels: dict = field(default_factory=dict)
    lu_seconds: float = 0.0
    solve_seconds: float = 0.0
    solves: int = 0

    @property
    def omega(self) -> float | None:
        """The frequency :math:`\\omega` of a point :math:`j\\omega` on the imaginary axis, else None."""
        return float(self.s.imag) if self.s.real == 0 and self.s.imag > 0 else None


def make_point(fom, solver, s, levels: int, extra: int, *, transposed, orth_tol: float, reorth: int,
               lu=None, symmetric: bool = False) -> PointData:
    r"""Factor :math:`S(s)` (or take ``lu``), run SOAR from :math:`F` and from :math:`L^T`, release the LU.

    Parameters
    ----------
    fom : Index3Model
    solver : SaddlePointSolver
        The reducer's solver (``cache_size=0``: nothing kept).
    s : complex
    levels, extra : int
        Primary and enrichment levels per side.
    transposed : (M, D, K)
        The transposes of M, D, K for the left side (the matrices themselves for a symmetric model).
    orth_tol, reorth : float, int
        SOAR's deflation tolerance and Gram-Schmidt passes.
    lu : SaddleLU, optional
        A factorization of :math:`S(s)` already made (a validation sample that becomes a point).
    symmetric : bool
        M, D, K symmetric: :math:`S(s)^T = S(s)`, so the left recurrence is the right one started at
        :math:`L^T`, and one block SOAR started at :math:`[F, L^T]` spans both sides level by level with
        block solves of m + p columns (fewer, larger triangular solves).

    Returns
    -------
    PointData
    """
    s = complex(s)
    t0 = time.perf_counter()
    if lu is None:
        lu = solver.factor(s.real if s.imag == 0 else s)
    t1 = time.perf_counter()
    out = PointData(s=s, lu_seconds=t1 - t0)
    captured = {}

    def right(rhs):
        x = lu.solve(rhs)
        captured.setdefault("X0", x)
        return x

    def left(rhs):
        return lu.solve(rhs, trans=True)

    Mt, Dt, Kt = transposed
    A1 = (2 * s) * fom.M + fom.D
    if symmetric:
        sides = {"both": SOAR(right, A1, fom.M, fom.K, fom.D, s, np.hstack([fom.F, fom.L.T]), orth_tol, reorth)}
    else:
        sides = {"right": SOAR(right, A1, fom.M, fom.K, fom.D, s, fom.F, orth_tol, reorth),
                 "left": SOAR(left, (2 * s) * Mt + Dt, Mt, Kt, Dt, s, fom.L.T, orth_tol, reorth)}
    made = {name: 0 for name in sides}
    for level in range(levels + extra):
        for name, soar in sides.items():
            if soar.exhausted:
                continue
            block = soar.step()
            if level < levels:
                out.primary.append(block)
                made[name] += 1  # a level whose columns deflated is in the span: its moment is matched too
            else:
                out.enrichment.append(block)
    X0 = captured["X0"][:, :fom.m]
    out.T = fom.L @ X0.real + 1j * (fom.L @ X0.imag) if np.iscomplexobj(X0) else fom.L @ X0
    out.levels = made
    out.solves = sum(so.solves for so in sides.values())
    out.solve_seconds = time.perf_counter() - t1
    del lu, sides  # the LU goes with the last reference to it
    return out
