"""The result of one LR-ADI run (:func:`morsuite.linalg.lradi.lradi`): the factor and its record.

Plain data: the Gramian factor's position and velocity blocks, the residual history, the
shifts, the LU and reuse counts and the options the run was made with
(:mod:`morsuite.linalg.lradi` has the iteration; :mod:`morsuite.linalg.gramians` stores two
of these per model). Cost of every property: none, except the observability factor's
position block, projected once on first read (two products with n2 columns).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import adi_shifts
from .refine import refined_unit

__all__ = ["LRADIResult"]


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
    refine : int
        Long-double refinement steps of each shifted solve.
    solve_rho : float
        With ``refine`` > 0: the largest first correction of a solve, relative
        to the solution (max-norm per column), i.e. the largest forward error
        of the unrefined solves; NaN without refinement (not measured).
    shift_reuse, lu_pool_mib, pool_full_reuse : float
        What was asked for (:class:`~morsuite.linalg.adi_shifts.LUPool`).
    lu_dropped : int
        Kept LUs dropped to stay within ``lu_pool_mib`` (0: the pool never filled, and
        ``pool_full_reuse`` changed nothing).
    lu_reused : int
        Steps served by a kept LU instead of a new one (shared by both results of :func:`lradi_pair`).
    lu_pool_peak_mib : float
        Largest estimated memory of the kept LUs.
    compress_tol : float
        Column compression tolerance (0: none; :class:`~morsuite.linalg.factor_store.FactorStore`).
    compress_from_mib : float
        With ``compress_tol`` > 0: the factor was kept plain up to this many MiB (``compressions`` 0: it stayed so).
    columns : int
        Columns the iteration produced; ``rank`` is the number kept.
    compressions : int
        Blocks of new columns compressed into the factor.
    residual_w1, residual_w2 : ndarray, (n1, m) or (n1, p)
        The final residual factor :math:`W = [W_1; W_2]` as iterated (the observability
        :math:`W_1` modulo :math:`\operatorname{range}(G^T)`): the Lyapunov residual is
        :math:`WW^T` (projected), whatever the factor's column layout.
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
    refine: int = 0
    solve_rho: float = float("nan")
    shift_reuse: float = 0.0
    lu_pool_mib: float = 0.0
    pool_full_reuse: float = 0.0
    lu_dropped: int = 0
    lu_reused: int = 0
    lu_pool_peak_mib: float = 0.0
    compress_tol: float = 0.0
    compress_from_mib: float = 0.0
    columns: int = 0
    compressions: int = 0
    residual_w1: np.ndarray = field(default=None, repr=False, compare=False)
    residual_w2: np.ndarray = field(default=None, repr=False, compare=False)
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

    @property
    def solve_error(self) -> float:
        """Estimated largest relative forward error of the refined solves
        (:func:`~morsuite.linalg.refine.refined_unit` of ``solve_rho``); NaN without refinement."""
        return refined_unit(self.solve_rho, self.refine) if self.refine else float("nan")

    def summary(self, history: bool = True) -> dict:
        """Everything but the factor (and, with ``history=False``, the residual history) as plain data."""
        out = {"equation": self.equation, "iterations": self.iterations, "converged": self.converged,
               "residual": self.residual, "rank": self.rank,
               "lu_count": self.lu_count, "strategy": self.strategy, "selection": self.selection,
               "num_shifts": self.num_shifts, "shifts": self.shifts.tolist(),
               "shift_batches": list(self.shift_batches), "times": dict(self.times),
               "refine": self.refine, "solve_rho": self.solve_rho, "solve_error": self.solve_error,
               "shift_reuse": self.shift_reuse, "lu_pool_mib": self.lu_pool_mib,
               "pool_full_reuse": self.pool_full_reuse, "lu_dropped": self.lu_dropped, "lu_reused": self.lu_reused,
               "lu_pool_peak_mib": self.lu_pool_peak_mib, "compress_tol": self.compress_tol,
               "compress_from_mib": self.compress_from_mib, "columns": self.columns, "compressions": self.compressions,
               "ritz_standard_rcond": adi_shifts.STANDARD_RCOND if self.strategy == "projection" else None}
        if history:
            out["residuals"] = self.residuals.tolist()
        return out
