r"""Benchmark ``irka-fo-floor``: irka-fo's own work against its LU floor over the five-method study (studies/five.toml).

The orders of ``studies/five.toml`` for irka-fo: dsms(g=1000) at 4, 12, ..., 60 states and
tcom(nc=2000) at 12, 28, 44, 60, reduced in increasing r on ONE reducer per model, as the
study does (``studies.tasks.reduce_sweep``), with one solver thread (``SOLVER_THREADS``), as on
the study's workers, each pinned to one core (``studies.batch``). The start (the model's Gramian
factors by LR-ADI, shared with ``bt``, and the SVD of first-order BT) is paid by the first call
and shown apart (``start_s``, ``start_lu_count``); every row then reports

- ``own_first_s``: the first call's ``time_s`` less the start's part of it
  (``time_breakdown["start"]``): the surrogate (its BT projection ``surrogate_projection_s``
  included when this call built it: it is cached with headroom and serves later orders), the
  full model's iterations, the certification round; ``own_s``: the median of 3 more calls at
  the same order on the same reducer (interleaved with their floors);
- ``lu_count_own``: the LUs a call made beyond the shared factors;
- ``lu_s``: the median time of one LU at a typical shift, measured right after each call in
  the same process (:func:`~morsuite.bench.floor.lu_floor`: ``splu`` of the pre-assembled
  saddle matrix with a right and a transposed solve, at up to 4 of the call's own shifts, 3
  times each, one BLAS thread); ``lu_solver_s`` the same through the model's solver (assembly,
  checks);
- ``floor_s`` = ``lu_count_own * lu_s``; ``ratio``: the median over the repeated calls of own
  time over its floor (target 2); ``ratio_first`` the first call's,
  ``ratio_first_without_projection`` without the surrogate's projection, ``ratio_solver``
  against the solver's LU.

``quick``: tcom(nc=60) at 8 and 16 states and dsms(g=200) at 4 and 12. Cost: the sweep's
irka-fo runs 4 times per order (twice in ``quick``), plus 12 LUs per call for the floor.
Writes ``irka_fo_floor.json``;
measurements in ``docs/design/irka_fo.md`` (2026-11-26).
"""

from __future__ import annotations

import warnings

from . import benchmark
from .floor import irka_lu_shifts, lu_floor

__all__ = ["bench_irka_fo_floor", "CASES"]

#: (model, orders) of the full run: the orders of studies/five.toml for irka-fo
CASES = [("dsms:g=1000", list(range(4, 61, 8))), ("tcom:nc=2000", [12, 28, 44, 60])]
QUICK = [("tcom:nc=60", [8, 16]), ("dsms:g=200", [4, 12])]
#: irka-fo's solver threads in the benchmark: 1, as on the study's pinned workers (2026-11-26, third session)
SOLVER_THREADS = 1


def _one(red, fom, r):
    """One call reduce(r): (info, own seconds, projection seconds paid, LU floor record)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        info = red.reduce(r).info
    tb = info["time_breakdown"]
    own = float(info["time_s"]) - float(tb.get("start", 0.0))
    lf = lu_floor(fom, irka_lu_shifts(info), samples=4, repeat=3)
    return info, own, float(tb.get("surrogate_projection", 0.0)), lf


def sweep_rows(spec: str, orders, repeat: int = 3, echo=None) -> list:
    """One row per order (module docstring) for model ``spec``, one reducer across the orders.

    Each order is reduced ``1 + repeat`` times in a row on the same reducer, each call followed by
    its own LU floor; the first call pays what is built for this order (the surrogate's projection
    when the cached one is too small: ``ratio_first``), the repetitions give the medians
    (``own_s``, ``lu_s``, ``ratio``: the median of the per-call ratios).
    """
    import numpy as np

    from .. import models, reducers

    fom = models.parse(spec)
    # one solver thread: the study's workers are pinned to a core each, where the automatic thread
    # count resolves to 1 (studies.batch); the floor's LU is single-threaded too
    red = reducers.make("irka-fo", fom, solver_threads=SOLVER_THREADS)
    rows = []
    for r in sorted(orders):
        info, own1, build, lf1 = _one(red, fom, r)
        start_s = float(info["time_breakdown"].get("start", 0.0))
        n = int(info["lu_count_own"])
        reps = [_one(red, fom, r) for _ in range(repeat)]
        own = float(np.median([x[1] for x in reps])) if reps else own1
        lu_s = float(np.median([x[3]["median_s"] for x in reps + [(None, None, None, lf1)]]))
        lu_solver = float(np.median([x[3]["solver_median_s"] for x in reps + [(None, None, None, lf1)]]))
        ratios = [x[1] / (int(x[0]["lu_count_own"]) * x[3]["median_s"]) for x in reps]
        sur = info.get("surrogate") or {}
        row = {"model": spec, "r": r, "states": info["states"], "converged": info["converged"],
               "solver_threads": info.get("solver_threads"),
               "status": info["status"], "iterations": info["iterations"], "time_s": float(info["time_s"]),
               "start_s": start_s, "start_lu_count": int(info.get("lu_count_start", 0)),
               "lu_count_shared": int(info.get("lu_count_shared", 0)), "lu_count_own": n,
               "own_first_s": own1, "own_s": own, "repeats": len(reps),
               "same_lu_count": all(int(x[0]["lu_count_own"]) == n for x in reps),
               "lu_s": lu_s, "lu_solver_s": lu_solver, "floor_s": n * lu_s,
               "ratio": float(np.median(ratios)) if ratios else own1 / (n * lu_s),
               "ratio_first": own1 / (n * lf1["median_s"]), "ratio_solver": own / (n * lu_solver),
               "surrogate_s": float(info["time_breakdown"].get("surrogate", 0.0)), "surrogate_projection_s": build,
               "ratio_first_without_projection": (own1 - build) / (n * lf1["median_s"]),
               "surrogate_states": sur.get("states"), "surrogate_evaluations": sur.get("evaluations"),
               "surrogate_iterations": sur.get("iterations"),
               "analytic_jacobians": sur.get("analytic_jacobians"),
               "newton": [(x["converged"], x["steps"]) for x in sur.get("newton", [])],
               "h2_tracked": info.get("h2_error"), "certificate": info["certificate"]["residual"],
               "time_breakdown_last": dict((reps[-1][0] if reps else info)["time_breakdown"])}
        rows.append(row)
        if echo is not None:
            echo(f"{spec} r={r}: own {own:.3f} s (median of {len(reps)}; first call {own1:.3f} s, of which the "
                 f"surrogate's projection {build:.3f} s), {n} LUs x {lu_s * 1e3:.2f} ms = {row['floor_s']:.3f} s: "
                 f"ratio {row['ratio']:.2f} (first call {row['ratio_first']:.2f}, without the projection "
                 f"{row['ratio_first_without_projection']:.2f}; against the solver's LU {row['ratio_solver']:.2f}); "
                 f"start {start_s:.2f} s")
    return rows


@benchmark("irka-fo-floor")
def bench_irka_fo_floor(quick: bool) -> dict:
    """irka-fo over the sweep's orders (one reducer per model): own time beyond the shared start / its LU floor."""
    rows = []
    for spec, orders in (QUICK if quick else CASES):
        rows.extend(sweep_rows(spec, orders, repeat=1 if quick else 3, echo=print))
    ratios = {f"{x['model']} r={x['r']} own/floor": {
        "value": x["ratio"], "target": 2.0,
        "what": f"irka-fo time beyond its start ({x['own_s']:.3g} s, median of repeated calls) / "
                f"({x['lu_count_own']} LUs x one bare LU with two solves at a typical shift of the run)"} for x in rows}
    return {"rows": rows, "ratios": ratios,
            "note": "one reducer per model across r, as in the study; the floor's LU is measured right after each "
                    "row; ratios are within-run"}
