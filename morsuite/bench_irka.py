"""Benchmark of the projector-free IRKA against its floor (LUs made x time of one LU).

For each model and r the reducer runs once; then, in the same process, the
floor is measured: the median time of one factorization of the saddle-point
matrix at the run's final shifts plus its right and transposed solve. The
ratio ``time_s / (lu_count x floor)`` says how much of the run is not sparse
LU work (dense update, projection, orthogonalisation, Python).
"""

from __future__ import annotations

import time
import warnings

import numpy as np
from threadpoolctl import threadpool_limits

from .bench import benchmark


def _lu_floor(fom, shifts, repeat=3) -> float:
    """Median seconds of one LU + one right + one transposed solve at the given shifts."""
    solver = fom.new_solver(cache_size=0)
    times = []
    rhs_r, rhs_l = fom.F[:, :1].astype(complex), fom.L.T[:, :1].astype(complex)
    for a in list(shifts)[:8] * repeat:
        t0 = time.perf_counter()
        lu = solver.factor(a)
        lu.solve(rhs_r)
        lu.solve(rhs_l, trans=True)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


@benchmark("irka")
def bench_irka(quick: bool) -> dict:
    """IRKA on dsms(6000) and tcom(nc=2000), r = 10, 20, 30: wall time over the LU floor (target <= 1.5)."""
    from . import models, reducers
    from .reducers.base import as_complex

    cases = [("dsms:g=6000", r) for r in (10, 20, 30)] + [("tcom:nc=2000", r) for r in (10, 20, 30)]
    if quick:
        cases = [("dsms:g=600", 10), ("tcom:nc=200", 10)]
    rows, ratios = [], {}
    for spec, r in cases:
        fom = models.parse(spec)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = reducers.make("irka", fom).reduce(r)
        info = res.info
        shifts = [a for a in as_complex(info["shifts"]) if a.imag >= 0]
        with threadpool_limits(limits=1, user_api="blas"):
            floor = _lu_floor(fom, shifts)
        ratio = info["time_s"] / (info["lu_count"] * floor)
        tb = info["time_breakdown"]
        rows.append({"model": spec, "r": info["r"], "r_requested": r, "states": info["states"],
                     "converged": info["converged"], "iterations": info["iterations"],
                     "lu_count": info["lu_count"], "time_s": info["time_s"], "lu_floor_s": floor,
                     "ratio": ratio, **{f"t_{k}": v for k, v in tb.items()}})
        ratios[f"{spec} r={r}"] = {"value": ratio, "target": 1.5, "pass": ratio <= 1.5,
                                   "what": "irka wall time / (LUs x (LU + 2 solves))"}
    return {"rows": rows, "ratios": ratios}
