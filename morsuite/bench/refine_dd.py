"""Benchmark ``refine-dd``: the refinement's extended-precision residual, double-double against long double.

Iterative refinement (:mod:`morsuite.linalg.refine`) forms :math:`b - S(a)x` beyond double precision:
since 2026-11-28 in double-double by compiled kernels (:mod:`morsuite.linalg.dd_kernels`), before in
numpy's ``np.longdouble``. This bench runs both through :func:`~morsuite.linalg.refine.refine_columns`
at the three band shifts of :func:`~morsuite.bench.backends.band_shifts`, the two variants alternating
with the order swapped from shift to shift, one thread, the LU made before and not timed: per shift a
fresh :class:`~morsuite.linalg.refine.SaddleOperator` (its pattern structure, which IRKA's persistent
operator makes once, and the entries of :math:`S(a)` at the new shift), one refinement step of the
solve with :math:`[F b; 0]` and one of the transposed solve with :math:`[L^T c; 0]` (b, c all ones),
about what a refined IRKA shift pays beyond its LU and its two solves. Reported per model: median seconds of each variant, their ratio
measured in the same run, and the largest difference of the two refined solutions relative to the
solution (both are more accurate than double; the difference is the long double residual's error,
which the double-double one does not have). Models: the TCOM at :math:`n_1 = 10^6` (where IRKA
at r = 20 refines the solves of most iterations) and fem_block(4000), a 3D pattern (quick: tcom(2000),
fem_block(1000), not judged). Quoted in ``docs/design/irka.md`` (2026-11-28, seventh session).
"""

from __future__ import annotations

import time

import numpy as np

from . import benchmark
from .backends import _load, _versions, band_shifts

__all__ = ["bench_refine_dd", "refine_side_by_side"]

MODELS = ("tcom:nc=333334", "fem_block:n1=4000")
MODELS_QUICK = ("tcom:nc=2000", "fem_block:n1=1000")


def refine_side_by_side(spec: str, echo=None) -> dict:
    """One model's row: median seconds per shift of a refined right and left solve pair's refinement, in
    double-double (``t_dd``) and in long double (``t_ld``), their ratio ``dd_over_ld`` and the largest
    relative difference of the refined solutions (``max_rel_diff``)."""
    from .. import models
    from ..linalg.refine import SaddleOperator, refine_columns

    fom = models.parse(spec)
    solver = fom.new_solver(cache_size=1)
    b = np.asarray(fom.F @ np.ones(fom.m)).ravel().astype(complex)
    c = np.asarray(fom.L.T @ np.ones(fom.p)).ravel().astype(complex)
    times = {"dd": [], "ld": []}
    diff = 0.0
    for i, s in enumerate(band_shifts(fom)):
        lu = solver.factor(s)
        x, y = lu.solve(b, full=True), lu.solve(c, trans=True, full=True)
        out = {}
        for k in (("dd", "ld") if i % 2 == 0 else ("ld", "dd")):
            op = SaddleOperator(solver.pattern, double_double=(k == "dd"))
            t0 = time.perf_counter()
            xr, xi, _ = refine_columns(lu, b, x, False, s, op, steps=1)
            yr, yi, _ = refine_columns(lu, c, y, True, s, op, steps=1)
            times[k].append(time.perf_counter() - t0)
            out[k] = np.concatenate([xr + 1j * xi, yr + 1j * yi]).astype(complex)
            if echo:
                echo(f"  {spec} s = {s:.3g} {k}: {times[k][-1]:.3f} s")
        diff = max(diff, float(np.max(np.abs(out["dd"] - out["ld"])) / np.max(np.abs(out["ld"]))))
    med = {k: float(np.median(v)) for k, v in times.items()}
    return {"model": spec, "n1": fom.n1, "n2": fom.n2, "backend": solver.backend, "t_dd": med["dd"],
            "t_ld": med["ld"], "dd_over_ld": med["dd"] / med["ld"], "times": times, "max_rel_diff": diff}


@benchmark("refine-dd")
def bench_refine_dd(quick: bool) -> dict:
    """The refinement residual in double-double against long double, per refined shift, side by side."""
    from ..linalg.warmup import warm_kernels

    warm_kernels()  # the kernels compiled (or loaded) before anything is timed
    load0 = _load()
    rows = []
    for spec in (MODELS_QUICK if quick else MODELS):
        row = refine_side_by_side(spec, echo=print)
        print(f"{spec} ({row['backend']}): double-double {row['t_dd']:.3f} s, long double {row['t_ld']:.3f} s per "
              f"shift: {row['dd_over_ld']:.3f}; refined solutions differ by {row['max_rel_diff']:.1e}")
        rows.append(row)
    ratios = {f"{row['model']}: double-double / long double per refined shift": {
        "value": row["dd_over_ld"], "target": None if quick else 1.0,
        "what": "a fresh operator at the shift, one refinement step of the right solve and one of the left, median "
                "of three band shifts, the variants alternating (the LU and the solves before them not timed)"}
        for row in rows}
    return {"rows": rows, "ratios": ratios, "load_before": load0, "load_after": _load(), "versions": _versions(),
            "quick": quick}
