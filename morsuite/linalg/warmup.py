"""Compile the numba kernels before anything is timed (:func:`warm_kernels`)."""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from . import dd_kernels, kernels
from .refine import SaddleOperator
from .saddle import SaddlePointSolver

__all__ = ["warm_kernels"]


_WARM: dict = {}


def warm_kernels(first: int = 0) -> float:
    """Compile (or load from numba's on-disk cache) the compiled kernels before anything is timed.

    Runs the paths a reduction takes on a 40-position chain with a tie constraint: LUs at a complex
    and a real shift (banded backend: the band LU, the border's half-sweeps, the one-pass assembly,
    the scatter), solves and transposed solves with one and three right-hand sides, one
    Gram-Schmidt basis, the dense pencil, the refinement's double-double residual and the backward-error
    certificate's Dot2 residual. Idempotent (a flag per process); returns the seconds it took (0.0 after the first call, or where the kernels
    are off). Every kernel is a module-level function compiled with ``cache=True``, so only a fresh
    install's first process compiles (about 8.5 s, 2026-11-26); later processes load the machine
    code (0.37 s on a quiet machine, of which 0.33 s is numba's own start: its import and its
    registries; 2026-12-02, ``docs/design/backends.md``; ``tests/test_kernel_cache.py`` checks
    that nothing compiles again). Called by
    :meth:`morsuite.reducers.base.Reducer.reduce` before its timer starts and by the study runner's
    worker processes.

    ``first`` (default 0) picks which half is compiled first: 0 the complex kernels, 1 the real
    ones (then the other half). Two processes starting together with 0 and 1 (the study runner's
    workers) each compile one half and load the other from numba's on-disk cache, which the other
    process has written by then: about half the wall time of a cold start.
    """
    if _WARM.get("done") or not kernels.use_kernels():
        return 0.0
    t0 = time.perf_counter()
    from .orthonormal import gram_schmidt

    n = 40
    T = sp.diags([-np.ones(n - 1), 2.0 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csr")
    M = sp.identity(n, format="csr")
    G = sp.csr_matrix(([1.0, -1.0], ([0, 0], [0, n - 1])), shape=(1, n))  # a tie: x_0 = x_{n-1}
    solver = SaddlePointSolver(M, 0.01 * T, T, G, cache_size=0, backend="banded")
    rhs = np.linspace(1.0, 2.0, n)
    A = np.asfortranarray(T[:4, :4].toarray())

    def at(s):  # the banded backend's kernels, then the projected IRKA's dense pencil, in s's dtype
        lu = solver.factor(s)
        for b in (rhs, np.column_stack([rhs, rhs[::-1], np.ones(n)])):
            lu.solve(b)
            lu.solve(b, trans=True)
        kernels.dense_pencil(A, A, A, s, np.empty((4, 4), dtype=complex if s.imag else float, order="F"))
        ones = np.ones(np.asarray(solver.pattern["_rowptr"]).size - 1)  # refinement's double-double residual
        SaddleOperator(solver.pattern).at(s, False, True).residual(ones, None, ones.astype(np.longdouble))
        S = solver.matrix(s)  # the backward-error certificate's Dot2 residual (3D patterns take it)
        seg = (S.indptr.astype(np.int64), S.indices.astype(np.int64), np.arange(S.nnz, dtype=np.int64))
        for x in (ones, ones + 0.5j):
            dd_kernels.residual(seg, S.data, x, ones)

    steps = [lambda: at(0.3j), lambda: at(1.7),
             lambda: gram_schmidt(np.asfortranarray(np.vander(np.linspace(0.1, 1.0, n), 4)), 1e-12)]
    for step in steps if first % 2 == 0 else steps[1:] + steps[:1]:  # the complex half first, or the real one
        step()
    _WARM["done"] = True
    return time.perf_counter() - t0
