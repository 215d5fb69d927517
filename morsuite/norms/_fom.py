r"""The full model's transfer function at single shifts, to extended precision, counting LUs.

:math:`T(s)\,b = L x` with :math:`S(s)[x; z] = [Fb; 0]`, one sparse LU of
:math:`S(s)` per shift (a conjugate shift reuses it; its solves reach the backward-error target of
:mod:`morsuite.linalg.accuracy`), then ``refine`` steps of
iterative refinement whose residual :math:`[Fb; 0] - S(s)[x; z]` is formed beyond
double (double-double, :mod:`morsuite.linalg.refine`) with the same LU, and more (at most
:data:`~morsuite.linalg.accuracy.FORWARD_MAX_STEPS` in all) until the estimated relative error of the solution is below
:data:`~morsuite.linalg.accuracy.FORWARD_TOL` (near a lightly damped resonance, where the
condition of :math:`S(s)` multiplies the LU's rounding), the solution kept in long double and
:math:`Lx` summed in long double. Where :math:`T - T_r` is 1e-12 of :math:`T`,
a response rounded to double has lost all but four digits of the difference
(its error is :math:`\varepsilon|T|`); refined, the difference keeps
(measured) full double precision. The long-double product
:math:`S(s)x` is the one IRKA refines its solves with
(:class:`~morsuite.linalg.refine.SaddleOperator`), not a copy.
"""

from __future__ import annotations

import time

import numpy as np

from ..linalg.accuracy import FORWARD_MAX_STEPS, forward_tol
from ..linalg.refine import SaddleOperator, refine_columns, refined_unit
from ..linalg.warmup import warm_kernels

__all__ = ["FomResponse", "refined_unit"]

LD = np.longdouble
CLD = np.clongdouble
#: shifts whose T(s) a model's memo keeps (a few MB at most; emptied when full)
MEMO_SIZE = 20000


class FomResponse:
    """Transfer function (and derivative) of an :class:`~morsuite.models.Index3Model`, shift by shift.

    Parameters
    ----------
    fom : Index3Model
    refine : int
        Steps of extended-precision iterative refinement of each solve (0: the
        LU's solution, rounded to double); more, up to :data:`~morsuite.linalg.accuracy.FORWARD_MAX_STEPS`, while the estimated
        error is above :data:`~morsuite.linalg.accuracy.FORWARD_TOL`.
    cache_size : int
        LUs kept by the solver (2: a shift and its conjugate, or the value and
        the derivative at one shift, share one LU).
    memo : bool
        Keep :math:`T(s)` (the whole matrix, with its unit and whether it was refined; and
        :math:`T'(s)` for :meth:`transfer_and_derivative`, with the seconds it took) per exact shift in
        ``fom.cache``, at most :data:`MEMO_SIZE` shifts, and serve :meth:`transfer`
        from it (default False): the H2 quadrature's nodes recur across the reduced models of one
        model, as do the H-infinity search's start grids (``docs/design/norms.md``, 2026-11-26
        third session). Each call returns what a
        fresh response would (the unrefined value where ``need`` declines refinement, else the
        refined one, computed when not kept yet), so the values do not depend on earlier calls.

    Notes
    -----
    ``lu_count`` is the number of sparse LUs made so far (the cost floor);
    ``last_unit`` the estimated relative error of the last solve
    (:func:`refined_unit`).
    """

    def __init__(self, fom, *, refine: int = 1, cache_size: int = 2, memo: bool = False):
        self.fom = fom
        self.refine = int(refine)
        cache = getattr(fom, "cache", None)
        # T(s) (and T'(s)) by exact shift, kept in the model's cache for later calls of this process (memo=True)
        on = memo and cache is not None
        self._memo = cache.setdefault(("fom_response", self.refine), {}) if on else None
        self._memo_d = cache.setdefault(("fom_response_derivative", self.refine), {}) if on else None
        # the seconds each kept sample of :meth:`sample` took (its LU, solves and refinement), so that a user of
        # samples another computation paid can still state their cost
        self._seconds = cache.setdefault(("fom_response_seconds", self.refine), {}) if on else None
        self.solver = fom.new_solver(cache_size=cache_size)
        self._op = None  # the long-double S(s) x on the solver's pattern, made on the first refinement
        self.last_unit = refined_unit(0.0, self.refine)
        #: the shifts at which an LU was made, in order (benchmarks time bare LUs at them)
        self.shifts = []

    @property
    def lu_count(self) -> int:
        return int(self.solver.stats.factorizations)

    def _first(self, s, rhs):
        before = self.solver.stats.factorizations
        lu = self.solver.factor(s)
        if self.solver.stats.factorizations > before:
            self.shifts.append(complex(s))
        return lu, lu.solve(rhs, full=True)

    def _refined(self, s, lu, rhs, x) -> np.ndarray:
        """``refine`` steps from the LU solution ``x`` (n1 + n2 rows): the primal block in clongdouble."""
        if self._op is None:
            self._op = SaddleOperator(self.solver.pattern)
        taken = {}
        xr, xi, rho = refine_columns(lu, rhs, x, False, s, self._op, steps=self.refine, tol=forward_tol(),
                                     max_steps=FORWARD_MAX_STEPS, record=taken)
        n1 = self.fom.n1
        self.last_unit = max(refined_unit(rho, taken["steps"]), 4.0 * taken["estimate"])
        out = xr[:n1].astype(CLD)
        if xi is not None:
            out = out + 1j * xi[:n1].astype(CLD)
        return out

    def solve(self, s, rhs) -> np.ndarray:
        """Primal block :math:`x` (n1, k) of :math:`S(s)[x; z] = [\\mathrm{rhs}; 0]`, refined: clongdouble
        (complex128 with ``refine=0``)."""
        rhs = np.asarray(rhs).reshape(self.fom.n1, -1)
        lu, x = self._first(s, rhs)
        if self.refine == 0:
            self.last_unit = refined_unit(0.0, 0)
            return np.asarray(x[: self.fom.n1], dtype=complex)
        return self._refined(s, lu, rhs, x)

    def transfer(self, s, b=None, need=None) -> np.ndarray:
        r""":math:`T(s)` (p, m), or :math:`T(s)b` (p, k) for a (m, k) or (m,) ``b``.

        Refined (clongdouble) unless ``refine=0`` or ``need``, a callable given
        the unrefined value (complex128), returns False: refinement costs about
        as much as the solve and the LU's assembly together, and only matters
        where the value is about to be subtracted from a nearly equal one.
        """
        fom = self.fom
        memo = self._memo if b is None else None
        hit = self._recall(memo, s, need)
        if hit is not None:
            return hit[0]
        B = fom.F if b is None else fom.F @ np.asarray(b).reshape(fom.m, -1)
        lu, x = self._first(s, B)
        T0, T = self._values(s, lu, B, x, need)
        self._keep(memo, s, T0, T)
        return T0 if T is None else T

    def _values(self, s, lu, B, x, need):
        """``(T0, T)``: the LU's value of :math:`LX` and the refined one (None where ``refine`` is 0 or
        ``need`` declines it); sets ``last_unit``."""
        fom = self.fom
        X = x[: fom.n1]
        T0 = fom.L @ X.real + 1j * (fom.L @ X.imag)
        if self.refine == 0 or (need is not None and not need(T0)):
            self.last_unit = refined_unit(0.0, 0)
            return T0, None
        Xr = self._refined(s, lu, B, x)
        L = fom.L.astype(LD)
        return T0, (L @ Xr.real) + 1j * (L @ Xr.imag).astype(CLD)

    def _recall(self, memo, s, need):
        """The kept entry's answer as a fresh call would give it (the unrefined value where ``need``
        declines refinement, else the refined one), as ``(value, *rest)``; None when not kept."""
        hit = memo.get(complex(s)) if memo is not None else None
        if hit is None:
            return None
        T0, T, unit, *rest = hit
        if self.refine == 0 or (need is not None and not need(T0)):
            self.last_unit = refined_unit(0.0, 0)
            return (T0, *rest)
        if T is None:  # kept unrefined, asked refined: computed again
            return None
        self.last_unit = unit
        return (T, *rest)

    def _keep(self, memo, s, T0, T, *rest):
        if memo is not None:
            if len(memo) >= MEMO_SIZE:
                memo.clear()
            memo[complex(s)] = (T0, T, self.last_unit, *rest)

    def sample(self, s):
        r"""``(T0, T, dT)`` at ``s``: the LU's :math:`T(s)` (complex128), the refined one (as
        :meth:`transfer`; None with ``refine=0``) and :math:`T'(s)`, as
        :meth:`transfer_and_derivative` computes them, always refined: kept in the model's memo, such
        an entry serves every later call at ``s`` whatever its ``need`` (the band response of a
        comparison and the H-infinity searches of its reduced models share one memo). One LU per
        shift not kept yet; a shift kept unrefined is computed again."""
        hit = self._memo_d.get(complex(s)) if self._memo_d is not None else None
        if hit is None or (self.refine and hit[1] is None):
            self.transfer_and_derivative(s)
            hit = self._memo_d.get(complex(s)) if self._memo_d is not None else self._last
        self.last_unit = hit[2]
        return hit[0], hit[1], hit[3]

    def transfer_and_derivative(self, s, need=None):
        r""":math:`T(s)` (refined as :meth:`transfer`, with ``need``) and
        :math:`T'(s) = -Y^T(2sM + D)X` (:math:`S(s)^TY = [L^T; 0]`, double precision):
        one LU, one plain and one transposed solve (plus the refinement)."""
        fom = self.fom
        hit = self._recall(self._memo_d, s, need)
        if hit is not None:
            return hit
        warm_kernels()  # a sample's seconds are its LU and solves, not the process's first compile of the kernels
        t0 = time.perf_counter()
        lu, x = self._first(s, fom.F)
        T0, T = self._values(s, lu, fom.F, x, need)
        X = x[: fom.n1]
        Y = lu.solve(fom.L.T.astype(complex), trans=True)
        dT = -(Y.T @ ((2 * s) * (fom.M @ X) + fom.D @ X))
        self._keep(self._memo_d, s, T0, T, dT)
        if self._seconds is not None:
            if len(self._seconds) >= MEMO_SIZE:
                self._seconds.clear()
            self._seconds[complex(s)] = time.perf_counter() - t0
        self._last = (T0, T, self.last_unit, dT)
        return (T0 if T is None else T), dT
