"""Benchmark ``rslab-ldlt``: rslab's LDL^T against its LU at the shifts of 3D solids, side by side.

At a complex shift of a model with symmetric M, D and K the ``rslab`` backend factors :math:`S(s)`
by rslab's Bunch-Kaufman LDL^T (:class:`~morsuite.linalg.backends_rslab.RslabLDLT`, pivots perturbed
and solves refined), where it used rslab's LU until 2026-11-28; at real shifts it keeps the LU. This
bench runs both, the LDL^T forced at the real shifts,
through the model's solver (assembly, equilibration, factorization, backward-error check timed;
the patterns' analyses made before and not timed) at the three band shifts of
:func:`~morsuite.bench.backends.band_shifts` and at their moduli (real shifts), the two variants alternating with the order swapped
from shift to shift, one thread: per shift one factorization, the solve with :math:`[F; 0]` and the
transposed solve with :math:`[L^T; 0]` (what one sample of the transfer function and its
derivative costs). Reported per model: median seconds of each, the ratio LDL^T / LU measured in the
same run, the factors' entries and the largest backward error (of the unscaled matrix). Models:
fem_block(4000) and fem_block(20000) (quick: fem_block(1500), not judged). Records the date, the
load and the versions (through :func:`morsuite.bench.run`). Quoted in ``docs/design/backends.md``
(2026-11-28).
"""

from __future__ import annotations

import contextlib
import time

import numpy as np

from . import benchmark
from .backends import _backward_error, _load, _versions, band_shifts

__all__ = ["bench_rslab_ldlt", "ldlt_against_lu"]

MODELS = ("fem_block:n1=4000", "fem_block:n1=20000")
MODELS_QUICK = ("fem_block:n1=1500",)


@contextlib.contextmanager
def _rslab_as(kind: str):
    """The ``rslab`` backend with one factorization at every shift inside the block: ``"lu"`` its LU (the rule
    before 2026-11-28), ``"ldlt"`` its LDL^T at real shifts too (where M, D, K are symmetric: the variant the
    real-shift rows compare with the LU, which the backend keeps there)."""
    from ..linalg import saddle
    from ..linalg.backends_rslab import RslabLDLT, RslabLU, rslab_ldlt_symbolic
    make = {"lu": RslabLU, "ldlt": lambda As, pattern: RslabLDLT(As, pattern, rslab_ldlt_symbolic(pattern))}[kind]
    old = saddle._LIBRARY_LU["rslab"]
    saddle._LIBRARY_LU["rslab"] = make
    try:
        yield
    finally:
        saddle._LIBRARY_LU["rslab"] = old


def ldlt_against_lu(spec: str, echo=None) -> dict:
    """One model's row: median seconds per shift of LDL^T and LU (factor, solve, transposed solve) and their
    ratio, at the three complex band shifts (``t_ldlt``, ``t_lu``, ``ldlt_over_lu``) and at their moduli,
    real shifts (the same keys with ``_real``)."""
    from .. import models
    fom = models.parse(spec)
    shifts = band_shifts(fom)
    solvers = {"ldlt": fom.new_solver(cache_size=0, backend="rslab"), "lu": fom.new_solver(cache_size=0, backend="rslab")}
    for k, solver in solvers.items():
        with _rslab_as(k):
            solver.factor(shifts[1])  # the analyses: once per pattern, not timed
    B = np.vstack([fom.F, np.zeros((fom.n2, fom.m))]).astype(complex)
    C = np.vstack([fom.L.T.toarray() if hasattr(fom.L, "toarray") else fom.L.T, np.zeros((fom.n2, fom.p))]).astype(complex)
    row = {"model": spec, "n1": fom.n1, "n2": fom.n2, "shifts": [complex(s) for s in shifts]}
    for suffix, points in (("", shifts), ("_real", np.abs(shifts))):
        times = {k: [] for k in solvers}
        berr = {k: 0.0 for k in solvers}
        kinds, nnz = {}, {}
        for i, s in enumerate(points):
            A = solvers["lu"].matrix(s)
            for k in (("ldlt", "lu") if i % 2 == 0 else ("lu", "ldlt")):
                with _rslab_as(k):
                    t0 = time.perf_counter()
                    f = solvers[k].factor(s)
                    x = f.solve(fom.F, full=True)
                    y = f.solve(C, trans=True, full=True)
                    t = time.perf_counter() - t0
                times[k].append(t)
                berr[k] = max(berr[k], _backward_error(A, x, B), _backward_error(A.T.tocsc(), y, C))
                kinds[k], nnz[k] = type(f.lu).__name__, int(getattr(f.lu, "nnz", 0))
                if echo:
                    echo(f"  {spec} s = {s:.3g} {k} ({kinds[k]}): {t:.3f} s")
        med = {k: float(np.median(v)) for k, v in times.items()}
        row.update({f"t_ldlt{suffix}": med["ldlt"], f"t_lu{suffix}": med["lu"],
                    f"ldlt_over_lu{suffix}": med["ldlt"] / med["lu"], f"times{suffix}": times,
                    f"factor{suffix}": kinds, f"factor_nnz{suffix}": nnz, f"berr{suffix}": berr})
    row["refactorizations"] = {k: solvers[k].stats.refactorizations for k in solvers}
    return row


@benchmark("rslab-ldlt")
def bench_rslab_ldlt(quick: bool) -> dict:
    """rslab's LDL^T against its LU at complex and real shifts of fem_block (4000, 20000), side by side."""
    load0 = _load()
    rows = []
    for spec in (MODELS_QUICK if quick else MODELS):
        row = ldlt_against_lu(spec, echo=print)
        for suffix, what in (("", "complex"), ("_real", "real")):
            print(f"{spec}, {what} shifts: LDL^T {row['t_ldlt' + suffix]:.3f} s, LU {row['t_lu' + suffix]:.3f} s per "
                  f"shift: {row['ldlt_over_lu' + suffix]:.3f}; factors {row['factor_nnz' + suffix]['ldlt']:.3g} / "
                  f"{row['factor_nnz' + suffix]['lu']:.3g} entries; backward errors {row['berr' + suffix]['ldlt']:.1e} / "
                  f"{row['berr' + suffix]['lu']:.1e}")
        rows.append(row)
    ratios = {f"{row['model']}: LDL^T / LU per {what} shift": {
        "value": row["ldlt_over_lu" + suffix], "target": None if quick else 1.0,
        "what": "factorization, solve with [F; 0] and transposed solve with [L^T; 0] through the solver, median of "
                f"three {what} shifts (the band's, or their moduli), the variants alternating"}
        for row in rows for suffix, what in (("", "complex"), ("_real", "real"))}
    return {"rows": rows, "ratios": ratios, "load_before": load0, "load_after": _load(), "versions": _versions(),
            "quick": quick}
