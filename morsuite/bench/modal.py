r"""Benchmark ``modal``: constrained modal truncation against one LU and solve of the saddle matrix.

``modal`` (20 modes, ``static_correction=False``, shift 0, a fresh reducer and a fresh model
solver) on fem_block(20000), against the floor: one LU of the same saddle matrix
:math:`[[K, G^T], [G, 0]]` (the shift 0) through the model's solver with its default backend,
plus one solve with :math:`[F; 0]`. Run and floor alternate ``repeat`` times (the load of a
shared machine hits both alike); the ratio is of the medians, target 5 (issue 34). The
run with ``static_correction=True`` (20 modes plus the static column, same LU) is reported
beside it, and the load average (``os.getloadavg``) before and after.

``quick``: fem_block(3000), one repetition; not judged. Writes ``modal.json``. Measurements
in ``docs/design/modal.md``.
"""

from __future__ import annotations

import os
import time
import warnings

import numpy as np

from ..utils import blas_threads
from . import benchmark

__all__ = ["bench_modal"]

#: (n1 of fem_block, modes, repetitions) of the full and the quick run
FULL, QUICK = (20000, 20, 2), (3000, 20, 1)


def _floor(fom) -> float:
    """Seconds of one LU of [[K, G^T], [G, 0]] and one solve with [F; 0] through a fresh solver."""
    solver = fom.new_solver(cache_size=0)
    with blas_threads(1):
        t0 = time.perf_counter()
        solver.factor(coeffs=(0.0, 0.0, 1.0)).solve(fom.F)
        return time.perf_counter() - t0


def _run(fom, k, static):
    from .. import reducers

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        res = reducers.make("modal", fom, static_correction=static).reduce(k + (fom.m if static else 0))
        wall = time.perf_counter() - t0
    return wall, res.info


@benchmark("modal")
def bench_modal(quick: bool) -> dict:
    """modal (20 modes) on fem_block(20000) against one LU + solve of the saddle matrix (target 5x)."""
    from ..models import fem_block

    n1, k, repeat = QUICK if quick else FULL
    load_before = os.getloadavg()
    fom = fem_block(n1)
    _floor(fom)  # the pattern, its ordering and the compiled kernels: not part of either timing
    runs, floors, static_runs, info = [], [], [], None
    for _ in range(repeat):
        wall, info = _run(fom, k, False)
        runs.append(wall)
        floors.append(_floor(fom))
        static_runs.append(_run(fom, k, True)[0])
    run_s, floor_s = float(np.median(runs)), float(np.median(floors))
    row = {"model": fom.name, "n1": fom.n1, "n2": fom.n2, "modes": k, "lu_backend": fom.lu_analysis()["backend"],
           "run_s": run_s, "floor_s": floor_s, "static_run_s": float(np.median(static_runs)),
           "runs_s": runs, "floors_s": floors, "lu_count": info["lu_count"],
           "time_breakdown": info["time_breakdown"], "max_residual": info["max_residual"],
           "omega": list(map(float, info["omega"])), "load_before": list(load_before),
           "load_after": list(os.getloadavg())}
    ratio = run_s / floor_s
    return {"rows": [row], "ratios": {
        f"modal {fom.name} {k} modes / (LU + solve)": {
            "value": ratio, "target": None if quick else 5.0,
            "what": "median wall time of modal (fresh reducer) over one LU + solve of the saddle matrix at the "
                    "same shift, default backend"},
        f"modal+static {fom.name} {k} modes / (LU + solve)": {
            "value": row["static_run_s"] / floor_s, "target": None,
            "what": "the same with static_correction=True (reported)"}}}
