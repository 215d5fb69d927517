r"""Benchmark ``bt-scaling``: balanced truncation's time per LU from dsms(2e4) to dsms(2e5), one fresh process per run.

``bt`` at r = 10 with its default options (``gramian_cache="reducer"``: a fresh LR-ADI per run) on
dsms(g) at the two sizes, each run in its own child process (:func:`~morsuite.bench.scaling_case.run_isolated`:
the model built there, the compiled kernels loaded before the timer), the sizes alternating so that a change
of load hits both alike: ``reps`` runs per size (5; ``quick``: dsms(2000) and dsms(20000), 2 runs, in
this process). The exponent :math:`p` of the time per LU, :math:`t/N_{LU} \sim n_1^p`, from the
medians of the two sizes: target :math:`p \le 1.10` (issue 47: 1.61 when the factors were compressed
from n1 = 2e5 on, whatever their size; ``docs/design/lradi.md``), for wall time and, reported beside
it, CPU time (less sensitive to other processes on a shared machine). The rows keep each run's time
breakdown (``compress``: the factors' column compression) and the factors' columns, ranks and
compressions.

Writes ``bt-scaling.json`` (through :func:`morsuite.bench.run`).
"""

from __future__ import annotations

import numpy as np

from . import benchmark
from .scaling_case import run_case, run_isolated

__all__ = ["bench_bt_scaling"]

#: the exponent of BT's time per LU from the smaller to the larger size, at most
TARGET = 1.10


def _row(case, isolate):
    row = run_isolated(case, 1800.0, 16.0) if isolate else run_case(case)
    return {k: row.get(k) for k in ("model", "size", "n1", "status", "time_s", "cpu_s", "lu_count", "time_per_lu_s",
                                    "cpu_per_lu_s", "iterations", "compress_tol", "factor_ranks", "adi_columns",
                                    "adi_compressions", "time_breakdown", "load_average", "message")}


@benchmark("bt-scaling")
def bench_bt_scaling(quick: bool = False) -> dict:
    """BT's time per LU from dsms(2e4) to dsms(2e5) (r = 10, fresh processes): exponent <= 1.10.

    Parameters
    ----------
    quick : bool
        dsms(2000) and dsms(20000), 2 runs each, in this process: a smoke run of seconds, not judged.

    Returns
    -------
    dict
        ``rows`` (one per run, in the order run), ``medians`` (per size) and ``ratios``
        (``bt time per LU exponent`` wall and CPU), the format of :mod:`morsuite.bench`.
    """
    sizes = (2_000, 20_000) if quick else (20_000, 200_000)
    reps = 2 if quick else 5
    rows = []
    if quick:  # in this process: its first reduction pays the imports and first calls
        run_case({"model": "dsms", "size": sizes[0], "task": "bt", "r": 10, "options": {"gramian_cache": "reducer"},
                  "trace": False})
    for _ in range(reps):
        for g in sizes:
            case = {"model": "dsms", "size": g, "task": "bt", "r": 10, "options": {"gramian_cache": "reducer"},
                    "trace": False, "warm": True}
            rows.append(_row(case, isolate=not quick))
            r = rows[-1]
            print(f"bt-scaling: dsms({g}) {r['status']}"
                  + (f", {r['time_s']:.3f} s wall, {r['cpu_s']:.3f} s CPU, {r['lu_count']} LUs, "
                     f"compress {r['time_breakdown'].get('compress', float('nan')):.3f} s, load "
                     f"{r['load_average']}" if r["status"] == "ok" else f": {r.get('message')}"), flush=True)
    medians = {}
    for g in sizes:
        ok = [r for r in rows if r["size"] == g and r["status"] == "ok"]
        medians[g] = {key: float(np.median([r[key] for r in ok])) if ok else float("nan")
                      for key in ("time_s", "cpu_s", "time_per_lu_s", "cpu_per_lu_s")}
        medians[g].update(n1=ok[0]["n1"] if ok else None, runs=len(ok))
    small, large = (medians[g] for g in sizes)
    ratios = {}
    for kind, key in (("wall", "time_per_lu_s"), ("cpu", "cpu_per_lu_s")):
        p = float(np.log(large[key] / small[key]) / np.log(large["n1"] / small["n1"])) if small["runs"] and \
            large["runs"] else float("nan")
        ratios[f"bt dsms time per LU exponent ({kind})"] = {
            "value": p, "target": TARGET if kind == "wall" else None,
            "pass": None if quick or kind == "cpu" else bool(p <= TARGET),
            "what": f"log(t/LU at n1 = {large['n1']} / t/LU at n1 = {small['n1']}) / log(n1 ratio), medians "
                    f"of {reps} {'runs in this process' if quick else 'fresh processes'} per size, {kind} time of reduce(10)"
                    + (" (quick: smoke run, not judged)" if quick else "")}
    for name, v in ratios.items():
        print(f"{name:45s} {v['value']:6.3f}  (target <= {v['target']})")
    return {"rows": rows, "medians": {str(g): m for g, m in medians.items()}, "ratios": ratios}
