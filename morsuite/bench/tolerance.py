"""Benchmark ``tolerance``: the smallest model within a tolerance, per method, and what the search cost.

The targets of issue 44 on the paper's models: for tcom(2000) and dsms(1000) at ``tol = 1e-3`` with
the exact H2 error (:class:`~morsuite.analysis.tolerance.ToleranceSearch`, ``measure="h2"``), every
returned model meets it (trusted H2 value) and the next smaller model, evaluated too, misses it;
and the continuation of the IRKA family: the method's LUs in the whole search against one fresh
run at the final order (a new reducer, ``reduce(r_final)``), target at most 1.5. Each method runs on
a fresh model (its Gramian factors paid in its search, as in a study's first run).

Rows: model, method, status, the chosen and next smaller states and errors, trusted, the search's
LUs (method, evaluations) and time, the orders evaluated; for ``irka`` and ``irka-fo`` the fresh run's
LUs, iterations and time and the ratio. ``quick``: tcom(nc=200) and dsms(g=200), bt and irka only.
Writes ``tolerance.json`` (through :func:`morsuite.bench.run`). Design note: ``docs/design/tolerance.md``.
"""

from __future__ import annotations

import time
import warnings

from . import benchmark

__all__ = ["bench_tolerance", "PLANS", "CONTINUATION_TARGET"]

#: the IRKA family's LUs in a search over one fresh run at the final order (issue 44)
CONTINUATION_TARGET = 1.5

PLANS = {"full": {"models": ["tcom:nc=2000", "dsms:g=1000"], "tol": 1e-3, "measure": "h2",
                  "methods": ["bt", "irka-fo", "irka", "krylov", "so-h2", "modal", "adaptive", "dominant"]},
         "quick": {"models": ["tcom:nc=200", "dsms:g=200"], "tol": 1e-3, "measure": "h2",
                   "methods": ["bt", "irka"]}}

#: the methods whose route continues in r (their LUs are compared with a fresh run at the final order)
CONTINUED = ("irka", "irka-fo")


def _fresh(spec, method, r):
    """One fresh run at order r on a fresh model: (LUs, iterations, seconds, status)."""
    from .. import models, reducers

    fom = models.parse(spec)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        info = reducers.make(method, fom).reduce(r).info
    return int(info["lu_count"]), int(info.get("iterations", 0)), time.perf_counter() - t0, info["status"]


@benchmark("tolerance")
def bench_tolerance(quick: bool, *, plan: dict | None = None) -> dict:
    """The smallest model within 1e-3 (H2) per method on tcom(2000) and dsms(1000); the IRKA family's search LUs
    over one fresh run at the final order (target <= 1.5)."""
    from .. import models
    from ..analysis.tolerance import ToleranceSearch

    plan = {**PLANS["quick" if quick else "full"], **(plan or {})}
    rows, ratios = [], {}
    for spec in plan["models"]:
        for method in plan["methods"]:
            fom = models.parse(spec)  # fresh: the search pays the model's Gramian factors where it needs them
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                s = ToleranceSearch(fom, method, measure=plan["measure"])
                o = s.run([plan["tol"]])[0]
            wall = time.perf_counter() - t0
            ch, sm = o.chosen, o.smaller
            row = {"model": spec, "method": method, "tol": plan["tol"], "measure": plan["measure"],
                   "status": o.status, "reason": o.reason, "states": ch.states if ch else None,
                   "error": ch.value if ch else None, "trusted": ch.trusted if ch else None,
                   "smaller_states": sm.states if sm else None, "smaller_error": sm.value if sm else None,
                   "smaller_misses": (not sm.meets(plan["tol"])) if sm else None,
                   "lu_count": o.lus, "eval_lu_count": o.eval_lus, "search_time_s": o.time_s, "wall_s": wall,
                   "reference_lus": s.reference_lus, "evaluated": [c.states for c in sorted(
                       s.candidates.values(), key=lambda c: c.index)]}
            if method in CONTINUED and o.status == "met":
                lus, its, t, status = _fresh(spec, method, ch.r)
                row.update(fresh_lu_count=lus, fresh_iterations=its, fresh_time_s=t, fresh_status=status,
                           continuation_ratio=o.lus / max(lus, 1))
                ratios[f"{spec} {method} search LUs / one fresh run at r = {ch.r}"] = {
                    "value": o.lus / max(lus, 1), "target": CONTINUATION_TARGET,
                    "what": "the method's sparse LUs over its whole tolerance search, over those of one fresh "
                            "reduction at the order it chose (Gramian factors included in both)"}
            rows.append(row)
    return {"plan": plan, "rows": rows, "ratios": ratios}
