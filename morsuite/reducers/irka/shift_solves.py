r"""The solves of one IRKA iteration, one shift at a time or concurrently.

The r shifts of an iteration give independent saddle-point problems: one LU of
:math:`S(\alpha_i)` per real shift or conjugate pair, a solve with :math:`F b_i` and
(two-sided) a transposed solve with :math:`L^T c_i`. :func:`raw_bases` forms the
jobs, has the reducer's ``_map_shifts`` run them (in order, or concurrently), and
makes the basis vectors in shift order, so the bases do not depend on how the
solves were scheduled.

Executors of :class:`~morsuite.reducers.irka.second_order.IRKA` (option ``executor``):

``"threads"`` (default)
    A thread pool of ``solver_threads`` workers (0: :func:`default_threads`, 2 on two
    or more cores). SciPy's SuperLU and LAPACK's banded LU release the GIL while they
    factor, the banded solves go through ctypes to release it too (measured:
    ``docs/design/backends.md``).
``"dask"``
    The current ``distributed`` client (``distributed.get_client()``): the model's
    solver is broadcast to the workers once per reduction and each job returns its
    solutions and LU counters; for clusters, where each worker has its own cores.

Each job is deterministic, so the reduced model is the same, to the bit, whatever
the executor and thread count.
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError, SingularShiftError
from ...linalg import accuracy
from ...linalg.refine import SaddleOperator, refined_solve
from ...utils import default_threads, map_threads  # noqa: F401 (re-exported: IRKA's executors)
from .shift_update import COMPLEX_TOL

__all__ = ["raw_bases", "default_threads", "map_threads", "map_dask", "remote_shift_solves"]


def raw_bases(red, alpha, bdir, cdir, left: bool):
    """The raw real bases (V, W) of the IRKA reducer ``red`` at shifts ``alpha`` (W None if not ``left``).

    One job per real shift or conjugate pair (the partner with negative imaginary part
    is skipped: its solution is the conjugate); ``red._map_shifts(red._shift_solves, jobs)``
    solves them; complex solutions give their real and imaginary parts, in shift order.
    """
    _, _, _, F, L = red._system()
    red._begin_bases()
    jobs = []
    for a, b, c in zip(alpha, bdir, cdir):
        cplx = abs(a.imag) > COMPLEX_TOL * abs(a)
        if cplx and a.imag < 0:
            continue  # its conjugate partner's LU and solve give both columns
        jobs.append((a if cplx else a.real, F @ (b if cplx else b.real),
                     (L.T @ (c if cplx else c.real)) if left else None, a))
    ncols = sum(2 if np.iscomplexobj(job[0]) else 1 for job in jobs)
    V = W = None
    j = 0
    for (x, w), (af, _, _, a) in zip(red._map_shifts(shift_solves(red), jobs), jobs):
        cplx = np.iscomplexobj(af)
        v = red._basis_vector(x, a, False)  # in shift order: a variant may record values here
        if V is None:  # Fortran order: each column written in one contiguous pass, no column_stack copy
            V = np.empty((v.shape[0], ncols), order="F")
            W = np.empty((v.shape[0], ncols), order="F") if left else None
        _put(V, j, v, cplx)
        if left:
            _put(W, j, red._basis_vector(w, a, True), cplx)
        j += 2 if cplx else 1
    return V, W


def _put(X, j, v, cplx):
    """Column j of X := Re v (and column j + 1 := Im v when ``cplx``)."""
    X[:, j] = v.real
    if cplx:
        X[:, j + 1] = v.imag


def shift_solves(red):
    """The job function of ``red``: (factor shift, F b, L^T c or None, shift) -> (x, w)."""
    def run(job):
        af, rhs_v, rhs_w, a = job
        lu = red._factor(af)
        x = red._solve(lu, rhs_v, False, a)
        w = None if rhs_w is None else red._solve(red._second(lu), rhs_w, True, a)
        return x, w  # the LU is freed here (a dense LU of the projected baseline is n1 x n1)
    return run


def remote_shift_solves(solver, job, steps: int, ext: bool, check_all: bool):
    """One job on a Dask worker: (x, w, counters) with the worker's copy of the model's solver.

    The same operations as the in-process job of :class:`~morsuite.reducers.irka.second_order.IRKA`: the LU at the
    shift, the solve (refined ``steps`` times with an ``ext``-precision residual), the
    transposed solve (checked when ``check_all``).
    """
    import copy
    from collections import OrderedDict
    from dataclasses import replace

    from ...linalg.saddle_lu import SolverStats
    af, rhs_v, rhs_w, a = job
    # own counters and cache: a worker may run several jobs at once on its copy of the solver
    solver = copy.copy(solver)
    solver.stats, solver._cache = SolverStats(), OrderedDict()
    try:
        lu = solver.factor(af)
    except SingularShiftError as exc:
        exc.shift = a
        raise
    op = SaddleOperator(solver.pattern) if steps else None

    def solve(f, rhs, trans):
        return f.solve(rhs, trans=trans) if not steps else refined_solve(f, rhs, trans, a, op, steps=steps, ext=ext)
    x = solve(lu, rhs_v, False)
    w = None
    if rhs_w is not None:
        w = solve(lu if check_all or lu.matrix is None else replace(lu, matrix=None), rhs_w, True)
    return x, w, solver.stats.as_dict()


def map_dask(red, jobs, steps: int, ext: bool, check_all: bool) -> list:
    """Run the jobs on the current ``distributed`` client; the counters are added to ``red``'s solver.

    Raises
    ------
    InputError
        If ``distributed`` is not installed or no client is running.
    """
    try:
        from distributed import get_client
        client = get_client()
    except (ImportError, ValueError) as exc:
        raise InputError("executor='dask' needs a running distributed.Client (e.g. on a LocalCluster)") from exc
    key = id(client)
    if getattr(red, "_dask_solver", (None, None))[0] != key:
        red._dask_solver = (key, client.scatter(red._solver, broadcast=True))
    futures = [client.submit(remote_shift_solves, red._dask_solver[1], job, steps, ext, check_all, pure=False)
               for job in jobs]
    out = []
    for fut in futures:
        x, w, counts = fut.result()
        red._solver.stats.add(**counts)
        accuracy.note_stats(counts)  # the worker's solves, in this run's record
        out.append((x, w))
    return out
