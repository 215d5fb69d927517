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
real double step, ibid. Algorithm 3); it counts as two iterations. The shifted
solves through the saddle-point matrix are in :mod:`morsuite.linalg.adi_iteration`,
the shift strategies in :mod:`morsuite.linalg.adi_shifts`.

Options (defaults): ``tol=1e-10``, ``maxiter=2000``, ``shifts="projection"``
(or ``"penzl"``, or explicit shifts used cyclically), ``num_shifts=16``,
``selection="residual"`` (or ``"gain"``), ``refine=0`` (long-double refinement
steps of each shifted solve, :mod:`morsuite.linalg.adi_iteration`; in
:func:`lradi_pair` of the controllability solves only; the shared Gramian
factors of :mod:`morsuite.linalg.gramians` use 1), ``solver=None`` (a fresh
solver of the system, without a cache), ``shift_reuse=0.5`` and
``lu_pool_mib=2048`` (:class:`~morsuite.linalg.adi_shifts.LUPool`: a projection shift within
ADI distance
:math:`|p - q|/|p + \bar q| \le 0.5` of a kept LU's shift q is served by that
LU), ``pool_full_reuse=0.8`` (once the pool has had to drop an LU: reuse within ADI distance
0.8, and drop the kept LU farthest from the current batch's shifts), ``compress_tol=0`` (no column compression;
:class:`~morsuite.linalg.factor_store.FactorStore`).

Cost in sparse LUs: one per distinct shift that no kept LU serves (a complex pair: one complex LU),
plus one real LU of :math:`[[M, G^T], [G, 0]]` for the projector
(:class:`~morsuite.linalg.manifold.ManifoldProjector`; none without
constraints), plus one of K bordered for ``shifts="penzl"``. :func:`lradi_pair`
runs both equations in lock step on one shift sequence, so that each LU serves
the right and the transposed left solve (``design.md``). Measured iteration
counts are in ``docs/design/lradi.md``.
"""

from __future__ import annotations

import time
import warnings
from collections import deque
from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from ..errors import ModelError, ConvergenceWarning, InputError
from ..utils import blas_threads
from .adi_iteration import ADIIteration
from .adi_result import LRADIResult
from .adi_shifts import IMAG_TOL, LUPool, as_pairs, penzl_shifts, projection_shifts
from .manifold import ManifoldProjector
from .refine import SaddleOperator
from .system import check_system, new_solver

__all__ = ["lradi", "lradi_pair"]  # and LRADIResult (morsuite.linalg.adi_result), imported here

EQUATIONS = ("controllability", "observability")
#: defaults of the options that keep LUs and compress the factor (``lradi``, ``lradi_pair`` and
#: ``gramians.ADI_DEFAULTS`` alike; measurements in docs/design/lradi.md)
SHIFT_REUSE = 0.5
LU_POOL_MIB = 2048.0
POOL_FULL_REUSE = 0.8  # fem_block(4000) with a pool of 6 LUs: 94 LUs instead of 159
COMPRESS_TOL = 0.0  # the exact H2 error reads the factors' column layout (norms/error_gramian.py)
#: with compress_tol > 0 a factor is kept plain up to this many MiB (both blocks), then compressed: where it fits,
#: compression only costs time (dsms(2e5): 146 columns, 0.47 GB; BT's time per LU went as n1^1.6 from 2e4 to
#: 2e5 when it compressed them), while tcom at n1 = 1e6 (about 1300 columns, 21 GB per factor) starts compressing
#: after 64 columns, as the store did before this budget (docs/design/lradi.md)
COMPRESS_FROM_MIB = 1024.0
STRATEGIES = ("projection", "penzl")
SELECTIONS = ("residual", "gain")


# -- drivers ------------------------------------------------------------------------
def _is_symmetric(X) -> bool:
    """Exact symmetry of a sparse matrix."""
    return (X != X.T).nnz == 0


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
    reps = as_pairs(arr)
    up, down = reps[reps.imag > 0], arr[arr.imag < -IMAG_TOL * np.abs(arr)]
    if up.size != down.size or not np.allclose(np.sort_complex(up), np.sort_complex(np.conj(down)),
                                               rtol=1e-12, atol=0):
        raise InputError("shifts must be closed under complex conjugation")
    return reps


def _run(fom, equations, tol, maxiter, shifts, num_shifts, selection, solver, refine=0, refined=EQUATIONS,
         shift_reuse=SHIFT_REUSE, lu_pool_mib=LU_POOL_MIB, compress_tol=COMPRESS_TOL, pool_full_reuse=POOL_FULL_REUSE,
         compress_from_mib=COMPRESS_FROM_MIB):
    check_system(fom, "fom")
    tol = _unit_float("tol", tol, 0.0, open_low=True)
    maxiter = _positive_int("maxiter", maxiter)
    num_shifts = _positive_int("num_shifts", num_shifts)
    if selection not in SELECTIONS:
        raise InputError(f"selection must be one of {', '.join(map(repr, SELECTIONS))}; got {selection!r}")
    strategy = _check_shifts(shifts)
    if isinstance(refine, (bool, np.bool_)) or not isinstance(refine, (int, np.integer)) or refine < 0:
        raise InputError(f"refine must be a nonnegative integer; got {refine!r}")
    shift_reuse = _unit_float("shift_reuse", shift_reuse, 0.0)
    compress_tol = _unit_float("compress_tol", compress_tol, 0.0)
    pool_full_reuse = _unit_float("pool_full_reuse", pool_full_reuse, 0.0)
    if isinstance(lu_pool_mib, (bool, np.bool_)) or not isinstance(lu_pool_mib, (int, float, np.integer, np.floating)) \
            or not 0 <= float(lu_pool_mib) < np.inf:
        raise InputError(f"lu_pool_mib must be a finite number >= 0; got {lu_pool_mib!r}")
    if isinstance(compress_from_mib, (bool, np.bool_)) \
            or not isinstance(compress_from_mib, (int, float, np.integer, np.floating)) \
            or not 0 <= float(compress_from_mib) < np.inf:
        raise InputError(f"compress_from_mib must be a finite number >= 0; got {compress_from_mib!r}")
    with blas_threads(1):
        return _iterate(fom, equations, tol, maxiter, strategy, num_shifts, selection, solver, int(refine),
                        refined, shift_reuse, float(lu_pool_mib), compress_tol, pool_full_reuse,
                        float(compress_from_mib))


def _unit_float(name, value, low, open_low=False):
    """A float in [low, 1) (or (low, 1) with open_low), else InputError naming the argument."""
    ok = not isinstance(value, (bool, np.bool_)) and isinstance(value, (int, float, np.integer, np.floating))
    if ok:
        v = float(value)
        ok = (v > low if open_low else v >= low) and v < 1
    if not ok:
        raise InputError(f"{name} must be a float in {'(' if open_low else '['}{low:g}, 1); got {value!r}")
    return float(value)


def _iterate(fom, equations, tol, maxiter, strategy, num_shifts, selection, solver, refine, refined, shift_reuse,
             lu_pool_mib, compress_tol, pool_full_reuse, compress_from_mib):
    t_start = time.perf_counter()
    solver = new_solver(fom, cache_size=0) if solver is None else solver
    stats0 = solver.stats.copy()
    proj = ManifoldProjector(fom, solver)
    sym_m = _is_symmetric(fom.M)
    Mt = fom.M if sym_m else fom.M.T.tocsr()
    operators = {"controllability": (fom.M, sp.vstack([fom.M, fom.D], format="csr"), sym_m),
                 "observability": (Mt, sp.vstack([Mt, fom.D.T], format="csr"), sym_m)}
    saddle = SaddleOperator(solver.pattern) if refine else None
    its = [ADIIteration(fom, eq, proj, operators, refine if eq in refined else 0, saddle, compress_tol,
                        compress_from_mib) for eq in equations]
    given = not isinstance(strategy, str)
    label = "given" if given else strategy
    # a given or Penzl set is applied as it is: its LUs serve its cyclic repeats only
    projection = label == "projection"
    pool = LUPool(solver, shift_reuse if projection else 0.0, lu_pool_mib,
                  max(shift_reuse, pool_full_reuse) if projection else 0.0)
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
        pool.expect(first)
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
                basis = np.column_stack([c for it in active for c in it.take_block()])  # one n1 x k array
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
            pool.expect(new)
            batches.append(len(new))
            t_shift += time.perf_counter() - t0
        p, lu = pool.get(complex(queue.popleft()))  # a kept LU near p, or a new one
        for it in active:  # a complex pair is two iterations: never step past maxiter
            if it.iterations + (2 if p.imag else 1) > maxiter:
                it.done = True
        active = [it for it in active if not it.done]
        if not active:
            break
        used.append(p)
        for i, it in enumerate(active):
            # the first solve with an LU is checked (backward error, refinement); that
            # check probes the stability of the factors, which the second solve shares
            it.step(lu if i == 0 or lu.matrix is None else replace(lu, matrix=None), p)
            if it.residuals[-1] <= tol:
                it.done = it.converged = True
            elif it.iterations >= maxiter:
                it.done = True
    pool_peak, reused, dropped = pool.peak_bytes / 2.0 ** 20, pool.reused, pool.dropped
    pool.clear()
    t0 = time.perf_counter()
    for it in its:
        it.finish()
    t_compress = time.perf_counter() - t0
    total = time.perf_counter() - t_start
    st = solver.stats.since(stats0)
    out = []
    for it in its:
        if not it.converged:
            warnings.warn(f"LR-ADI ({it.equation}) did not converge: maxiter = {maxiter} iterations reached "
                          f"with relative residual {it.residuals[-1]:.2e} > tol = {tol:.1e}",
                          ConvergenceWarning, stacklevel=4)
        times = {"factor": st["factor_time_s"] + st["assemble_time_s"], "solve": it.t_solve,
                 "shifts": t_shift, "residual": it.t_res, "compress": it.t_compress + t_compress / len(its),
                 "total": total}
        Zp, Zv = it.factor()
        out.append(LRADIResult(position_unprojected=Zp, velocity=Zv, equation=it.equation,
                               residuals=np.array(it.residuals), shifts=np.array(it.shifts, dtype=complex),
                               iterations=it.iterations, converged=it.converged,
                               lu_count=int(st["factorizations"]), times=times, strategy=label,
                               selection=selection, tol=tol, maxiter=maxiter,
                               num_shifts=num_shifts, shift_batches=list(batches), refine=it.refine,
                               solve_rho=it.rho if it.refine else float("nan"),
                               shift_reuse=shift_reuse, lu_pool_mib=lu_pool_mib, lu_reused=reused,
                               pool_full_reuse=pool_full_reuse, lu_dropped=dropped,
                               lu_pool_peak_mib=pool_peak, compress_tol=compress_tol,
                               compress_from_mib=compress_from_mib, columns=it.columns,
                               compressions=it.compressions, residual_w1=it.W1, residual_w2=it.W2,
                               projector=proj if it.equation == "observability" and proj.lu is not None else None))
    return out


def lradi(fom, equation="controllability", *, tol=1e-10, maxiter=2000, shifts="projection", num_shifts=16,
          selection="residual", solver=None, refine=0, shift_reuse=SHIFT_REUSE, lu_pool_mib=LU_POOL_MIB,
          compress_tol=COMPRESS_TOL, pool_full_reuse=POOL_FULL_REUSE,
          compress_from_mib=COMPRESS_FROM_MIB) -> LRADIResult:
    r"""Low-rank ADI for one projected Lyapunov equation (see the module docstring).

    Parameters
    ----------
    fom : ConstrainedSystem
        Any object with M, D, K, G, F, L, n1, n2, m, p
        (:class:`~morsuite.linalg.system.ConstrainedSystem`), e.g. an
        ``Index3Model``.
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
        Default ``fom.new_solver(cache_size=0)``, or a new solver of M, D, K, G
        if ``fom`` has no ``new_solver``.
    refine : int
        Steps of iterative refinement of each shifted solve with a residual in
        ``np.longdouble`` (0: none). One step makes the factor accurate where
        the LU's solutions are not (shifts next to slow or lightly damped
        poles); it costs a long-double product with the saddle-point matrix and
        a pair of triangular solves per column, no LU.
    shift_reuse : float in [0, 1)
        A shift is served by the kept LU of a shift q with
        :func:`~morsuite.linalg.adi_shifts.adi_distance` (p, q) at most this
        (:class:`~morsuite.linalg.adi_shifts.LUPool`); 0 reuses exact
        repeats only, and so do given and Penzl shifts (a fixed set used
        cyclically: each of its shifts is factored once while its LU fits
        ``lu_pool_mib``). Default 0.5.
    lu_pool_mib : float >= 0
        Memory budget of the kept LUs in MiB (0: none kept). Default 2048.
    pool_full_reuse : float in [0, 1)
        Projection shifts, once the pool is full (it has dropped an LU to stay within
        ``lu_pool_mib``): a shift p is served by the kept LU of the shift q nearest to it
        if :math:`|p - q|/|p + \bar q| \le` ``pool_full_reuse`` (instead of
        ``shift_reuse``), and the LU dropped is the kept one whose shift is farthest in
        that distance from the current batch of shifts (instead of the least recently
        used). A small pool keeps too few LUs for a shift to find a neighbour within
        ``shift_reuse``; the wider radius trades an LU for a step that reduces the
        residual at p by at most that factor, i.e. some more ADI steps (solves). A run whose
        pool never fills is unchanged; a value at most ``shift_reuse`` (e.g. 0) keeps the
        plain rule (least recently used dropped, one radius). Default 0.8: on
        fem_block(4000) with a pool of about 6 LUs, 94 LUs and 568 / 408 iterations
        instead of 159 LUs and 442 / 312, 25% less time (``docs/design/lradi.md``).
    compress_tol : float in [0, 1)
        Column compression of the factor as it grows: new directions below
        ``compress_tol`` times its largest singular value are dropped
        (:class:`~morsuite.linalg.factor_store.FactorStore`); 0 (default) keeps
        every column in the order made, the layout that the exact H2 error's
        error-Gramian route replays (:mod:`morsuite.norms.error_gramian`).
    compress_from_mib : float >= 0
        With ``compress_tol`` > 0, the factor is kept plain (every column, in the order made)
        while it holds at most this many MiB, and compressed from there on; 0 compresses from
        the first columns. Default 1024: a factor that fits is not compressed (time only:
        dsms(2e5)'s 146 columns cost BT 37% more CPU time compressed, ``docs/design/lradi.md``).

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
    return _run(fom, (equation,), tol, maxiter, shifts, num_shifts, selection, solver, refine, EQUATIONS,
                shift_reuse, lu_pool_mib, compress_tol, pool_full_reuse, compress_from_mib)[0]


def lradi_pair(fom, *, tol=1e-10, maxiter=2000, shifts="projection", num_shifts=16, selection="residual",
               solver=None, refine=0, shift_reuse=SHIFT_REUSE, lu_pool_mib=LU_POOL_MIB, compress_tol=COMPRESS_TOL,
               pool_full_reuse=POOL_FULL_REUSE, compress_from_mib=COMPRESS_FROM_MIB):
    r"""Both projected Lyapunov equations in lock step: one shift sequence, one LU per shift.

    Each LU of :math:`[[S(-p), G^T], [G, 0]]` serves the controllability solve
    and the transposed observability solve; projection shifts are computed from
    the latest blocks and residuals of both iterations. An equation that has
    converged stops and the other goes on alone. Parameters as in :func:`lradi`,
    except that ``refine`` refines the controllability solves only: the
    factor :math:`Z` of :math:`\|T\|_{\mathcal H_2}^2 = \|LZ_p\|_F^2` needs
    them (``docs/design/norms.md``), while the observability factor enters
    that value only through the ADI tail correction (about ``tol`` of it) and
    balanced truncation through Hankel singular values that are themselves
    accurate to about ``tol``. Refining both costs twice the refinement time
    (tcom(2000): +110% of the LR-ADI time instead of +47%) for no accuracy that
    a caller uses.

    Returns
    -------
    (LRADIResult, LRADIResult)
        Controllability and observability; ``lu_count``, ``times["factor"]``,
        ``times["shifts"]`` and ``times["total"]`` are those of the shared run.
    """
    c, o = _run(fom, EQUATIONS, tol, maxiter, shifts, num_shifts, selection, solver, refine, ("controllability",),
                shift_reuse, lu_pool_mib, compress_tol, pool_full_reuse, compress_from_mib)
    return c, o
