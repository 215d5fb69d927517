"""Benchmark ``irka``: the projector-free IRKA against its floor (LUs made x time of one LU).

IRKA (``reducers.make("irka", fom).reduce(r)``, default options) on dsms(6000)
and tcom(nc=2000) at r = 10, 20, 30. Floor of a run
(:func:`~morsuite.bench.floor.bare_lu_floor`): one bare LU with a right and a
transposed solve at every shift at which the run factorized (one per real shift
or conjugate pair per iteration, from ``info["history"]``), one BLAS thread. Run
and floor are timed alternately 3 times; the ratio ``time_s / floor`` of the
median pair is the headline, target 1.5: what the run spends beyond its sparse
LUs (dense update, projection, orthogonalisation, equilibration, checks, Python).

``quick``: dsms(600) and tcom(200) at r = 10, once; not judged. Cost: 2 x
``lu_count`` LUs per pair. Writes ``irka.json`` (through :func:`morsuite.bench.run`).
"""

from __future__ import annotations

import warnings

from . import benchmark
from .floor import irka_lu_shifts, median_run, run_against_floor

__all__ = ["bench_irka"]


@benchmark("irka")
def bench_irka(quick: bool) -> dict:
    """IRKA on dsms(6000) and tcom(nc=2000), r = 10, 20, 30: wall time over the bare LU floor (target <= 1.5)."""
    from .. import models, reducers

    cases = [("dsms:g=6000", r) for r in (10, 20, 30)] + [("tcom:nc=2000", r) for r in (10, 20, 30)]
    repeats = 3
    if quick:
        cases, repeats = [("dsms:g=600", 10), ("tcom:nc=200", 10)], 1
    rows, ratios = [], {}
    for spec, r in cases:
        fom = models.parse(spec)

        def run():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                info = reducers.make("irka", fom).reduce(r).info
            return info["time_s"], info

        runs = [run_against_floor(fom, run, irka_lu_shifts) for _ in range(repeats)]
        med = median_run(runs)
        ratio, info, floor = med.ratio, med.info, med.floor_s
        tb = info["time_breakdown"]
        rows.append({"model": spec, "r": info["r"], "r_requested": r, "states": info["states"],
                     "converged": info["converged"], "iterations": info["iterations"],
                     "lu_count": info["lu_count"], "time_s": info["time_s"], "floor_s": floor,
                     "ratio": ratio, "ratios_all": sorted(round(x.ratio, 4) for x in runs),
                     **{f"t_{k}": v for k, v in tb.items()}})
        ratios[f"{spec} r={r}"] = {"value": ratio, "target": 1.5, "pass": None if quick else ratio <= 1.5,
                                   "what": f"irka wall time / bare floor ({info['lu_count']} x (splu + 2 solves) "
                                           f"at the run's own shifts), median of {repeats} alternating pairs"}
    return {"rows": rows, "ratios": ratios}
