"""Benchmark of time stepping the full model against its floor: one LU + one solve per step.

Floor: ``scipy.sparse.linalg.splu`` of the pre-assembled, unscaled step matrix
:math:`S(2/h)` (the solver's ordering and pivot threshold) plus ``steps`` solves
with that factorization and one fixed right-hand side. ``simulate`` and the floor
are timed alternately (five pairs, the order swapped every other pair; one pair with
``quick``) so that the load of this shared machine hits both alike; the ratio is
the median over the pairs, and the ratio of the fastest run to the fastest floor is
reported next to it (``ratio_of_minima``: the least disturbed pair of runs). A second
ratio divides by the solver's own kernel (``steps`` triangular solves with the
equilibrated, renumbered factorization that the stepper uses): what is left is the
per-step product, the vector updates and Python.

Memory: tracemalloc peaks of ``simulate`` (NumPy and Python allocations; SuperLU's
factors are malloc'd by SuperLU, not traced: their size is reported from the LU's
nnz) at n1 and 10 n1, and at 1/10 of the steps, to show that memory is linear in
n1 and, beyond the input and output samples, independent of the step count.
"""

from __future__ import annotations

import time
import tracemalloc

import numpy as np

from . import benchmark
from ..utils import blas_threads


def _floor(fom, h, steps, rhs) -> float:
    import scipy.sparse.linalg as spla

    solver = fom.new_solver(cache_size=0)
    A = solver.matrix(2.0 / h)
    t0 = time.perf_counter()
    lu = spla.splu(A, permc_spec=solver.permc_spec, diag_pivot_thresh=solver.diag_pivot_thresh)
    with blas_threads(1):
        for _ in range(steps):
            lu.solve(rhs)
    return time.perf_counter() - t0


def _own_kernel(fom, h, steps, rhs) -> float:
    from .analysis.timestep import _lu_view

    solve = _lu_view(fom.new_solver(cache_size=0).factor(2.0 / h))[0]
    t0 = time.perf_counter()
    with blas_threads(1):
        for _ in range(steps):
            solve(rhs)
    return time.perf_counter() - t0


def _peak(fom, t, u):
    from .analysis import simulate

    simulate(fom, t[:3], u[:3])  # the solver pattern and imports are not part of the run
    tracemalloc.start()
    try:
        _, info = simulate(fom, t, u, details=True)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    io = (t.size * (fom.p + 2 * fom.m) + t.size) * 8  # y, u and its step sums, t
    return {"n1": fom.n1, "steps": t.size - 1, "tracemalloc_peak_mb": peak / 2**20,
            "io_samples_mb": io / 2**20, "peak_minus_io_bytes_per_n1": (peak - io) / fom.n1,
            "lu_nnz": info.get("lu_nnz"), "lu_mb_estimate": (info.get("lu_nnz") or 0) * 12 / 2**20}


@benchmark("simulate")
def bench_simulate(quick: bool) -> dict:
    """Trapezoidal stepping of dsms(6000) and tcom(nc=2000), 10,000 steps: time over one LU + 10,000 solves (target 1.3)."""
    from . import models
    from .analysis import signals, simulate

    cases = [("dsms:g=6000", "dsms:g=60000", 0.5), ("tcom:nc=2000", "tcom:nc=20000", 0.01)]
    steps, repeats = 10_000, 5
    if quick:
        cases, steps, repeats = [("dsms:g=600", "dsms:g=6000", 0.5), ("tcom:nc=200", "tcom:nc=2000", 0.01)], 1000, 1
    rows, ratios = [], {}
    for spec, big, h in cases:
        fom = models.parse(spec)
        t = signals.time_grid(steps * h, h)
        u = signals.step(t, m=fom.m)
        rhs = np.random.default_rng(0).standard_normal(fom.n1 + fom.n2)
        simulate(fom, t[:3], u[:3])  # warm-up
        pairs = []
        for k in range(repeats):
            if k % 2:
                floor, kernel = _floor(fom, h, steps, rhs), _own_kernel(fom, h, steps, rhs)
            y, info = simulate(fom, t, u, details=True)
            if not k % 2:
                floor, kernel = _floor(fom, h, steps, rhs), _own_kernel(fom, h, steps, rhs)
            pairs.append((info["time_s"] / floor, info, floor, kernel))
        minima = min(p[1]["time_s"] for p in pairs) / min(p[2] for p in pairs)
        pairs.sort(key=lambda p: p[0])
        ratio, info, floor, kernel = pairs[len(pairs) // 2]
        mem = [_peak(fom, t[: steps // 10 + 1], u[: steps // 10 + 1]), _peak(fom, t, u)]
        fbig = models.parse(big)
        mem.append(_peak(fbig, t[: steps // 10 + 1], signals.step(t[: steps // 10 + 1], m=fbig.m)))
        per_step = {"simulate": info["time_s"] / steps, "floor": floor / steps, "own_kernel": kernel / steps}
        rows.append({"model": spec, "n1": fom.n1, "n2": fom.n2, "step": h, "steps": steps,
                     "time_s": info["time_s"], "march_time_s": info["march_time_s"],
                     "setup_time_s": info["setup_time_s"], "floor_s": floor, "own_kernel_s": kernel,
                     "ratio": ratio, "ratio_of_minima": minima, "ratio_to_own_kernel": info["time_s"] / kernel,
                     "ratios_all": [round(p[0], 4) for p in pairs],
                     "per_step_us": {k: 1e6 * v for k, v in per_step.items()},
                     "lu_count": info["lu_count"], "solves": info["solves"], "kernel": info["kernel"],
                     "constraint_residual": info["constraint_residual"], "max_abs_y": float(np.max(np.abs(y))),
                     "memory": mem})
        # at the quick sizes a solve costs 15 us and fixed per-step costs dominate: no verdict
        ratios[spec] = {"value": ratio, "target": None if quick else 1.3,
                        "what": f"simulate {info['time_s']:.2f} s / floor {floor:.2f} s (splu(S(2/h)) + {steps} "
                                f"solves), median of {repeats} alternating pairs (fastest/fastest {minima:.3f}); "
                                f"to the stepper's own kernel {info['time_s'] / kernel:.3f}"}
    return {"rows": rows, "ratios": ratios}
