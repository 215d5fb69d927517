"""Benchmark ``krylov``: second-order Krylov moment matching against one LU + solve of the saddle matrix.

``reducers.make("krylov", fom, **opts).reduce(20)`` on fem_block(20000) for three
settings: the default (one real point at the band's lower edge, one-sided), three
points in the band (``points="band"``) and two-sided at one point. Floor of a run
(:func:`~morsuite.bench.floor.bare_lu_floor`): one bare LU with a right and a
transposed solve at each of the run's expansion points, one BLAS thread, timed right
after the run; the ratio ``time_s / floor`` of the median of 3 alternating pairs is
printed, with no target: the run pays, besides its LUs, one saddle solve per basis
column and side (``info["solves"]``) and the orthogonalisation, which the ratio shows.
A second reduce(10) on the same reducer shows the reuse (``reuse_s``: no LU).

``quick``: fem_block(2000), once. Cost: 2 x ``lu_count`` LUs per pair. Writes
``krylov.json`` (through :func:`morsuite.bench.run`).
"""

from __future__ import annotations

import time
import warnings

from . import benchmark
from .floor import median_run, run_against_floor, upper_half

__all__ = ["bench_krylov", "SETTINGS", "PLANS"]

#: the settings timed: name -> reducer options
SETTINGS = {"one point, one-sided": {}, "band (3 points), one-sided": {"points": "band"},
            "one point, two-sided": {"sided": "two"}}


#: the plans: model, r, repeats and the settings timed
PLANS = {"full": {"spec": "fem_block:n1=20000", "r": 20, "repeats": 3, "settings": list(SETTINGS)},
         "quick": {"spec": "fem_block:n1=2000", "r": 10, "repeats": 1, "settings": list(SETTINGS)}}


@benchmark("krylov")
def bench_krylov(quick: bool, *, plan: dict | None = None) -> dict:
    """krylov at r = 20 on fem_block(20000) (three settings): wall time over one bare LU + solves per point.

    ``plan`` (keys of :data:`PLANS`' entries) replaces the plan ``quick`` picks, e.g.
    ``{"settings": ["one point, one-sided"], "repeats": 1}`` on a loaded machine, where one
    LU of fem_block(20000) took 178 s (2026-11-27).
    """
    from .. import models, reducers

    plan = {**PLANS["quick" if quick else "full"], **(plan or {})}
    spec, r, repeats = plan["spec"], plan["r"], plan["repeats"]
    fom = models.parse(spec)
    fom.new_solver()._ordering()  # the pattern and its column ordering (once per model): not the runs' time
    rows, ratios = [], {}
    for label in plan["settings"]:
        opts = SETTINGS[label]
        keep = {}

        def run():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                red = reducers.make("krylov", fom, **opts)
                info = red.reduce(r).info
            keep["reducer"] = red
            return info["time_s"], info

        runs = [run_against_floor(fom, run, lambda info: upper_half(info["points"])) for _ in range(repeats)]
        med = median_run(runs)
        info = med.info
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            again = keep["reducer"].reduce(r // 2).info
        reuse = time.perf_counter() - t0
        tb = info["time_breakdown"]
        rows.append({"model": spec, "setting": label, "options": opts, "r": info["r"], "r_requested": r,
                     "lu_count": info["lu_count"], "solves": info["solves"], "stable": info["stable"],
                     "moments": [m["moments"] for m in info["moments"]], "time_s": info["time_s"],
                     "floor_s": med.floor_s, "ratio": med.ratio,
                     "ratios_all": sorted(round(x.ratio, 4) for x in runs),
                     "reuse_s": reuse, "reuse_lu_count": again["lu_count"],
                     **{f"t_{k}": v for k, v in tb.items()}})
        ratios[f"{spec} r={r} {label}"] = {
            "value": med.ratio, "target": None,
            "what": f"krylov wall time / bare floor ({info['lu_count']} x (splu + 2 solves) at its expansion "
                    f"points); the run adds {info['solves']} saddle solves; median of {repeats} alternating pairs"}
    return {"rows": rows, "ratios": ratios}
