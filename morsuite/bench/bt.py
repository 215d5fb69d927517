"""Benchmark ``bt``: balanced truncation against its floor, and a sweep over r against one r.

``bt`` (default options: first-order square-root BT; two LR-ADI runs in lock
step, the SVD, the projection) at r = 20, fresh reducer, on dsms(6000) and
tcom(2000). Floor (:func:`~morsuite.bench.floor.bare_lu_floor`): ``lu_count``
bare LUs with the right solve (all inputs) and transposed solve (all outputs) at
the run's ADI shifts (the LU of :math:`S(-p)` per shift :math:`p`). Ratios, each
the median over repetitions (5 on the DSMS, 3 on the TCOM) that time the run, its
floor and the sweep back to back:

- ``bt MODEL r=20 / floor``: wall time over the floor, target 1.5;
- ``bt MODEL sweep r=2..40 / single r`` (DSMS only): ``reduce(r)`` for
  r = 2, 4, ..., 40 on one reducer over one fresh ``reduce(20)``, target 1.5
  (the Gramians are computed once).

The DSMS wall time is also printed next to the 0.6 s of the independent
implementation quoted in ``models.md`` (reported, not a target).

``quick``: dsms(600) and tcom(200), 3 and 2 repetitions; not judged. Writes
``bt.json`` (through :func:`morsuite.bench.run`).
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from . import benchmark
from .floor import adi_lu_shifts, median_run, run_against_floor

__all__ = ["bench_bt"]


def _fresh_run(fom):
    """(wall time, info) of a fresh ``bt`` reducer at r = 20, construction included."""
    from .. import reducers

    t0 = time.perf_counter()
    info = reducers.make("bt", fom, gramian_cache="reducer").reduce(20).info
    return time.perf_counter() - t0, info


@benchmark("bt")
def bench_bt(quick: bool = False) -> dict:
    """``bt`` at r = 20 over its LU floor on dsms(6000) and tcom(2000), and a sweep r = 2..40 over one r.

    Parameters
    ----------
    quick : bool
        Use dsms(600): a smoke run of seconds. Its LUs take 2 ms, so Python and
        vector work weigh more and its ratios are not held to the targets.

    Returns
    -------
    dict
        ``rows`` (one per timed run) and ``ratios`` (name -> value, target,
        pass, what), the format of :mod:`morsuite.bench`.
    """
    from .. import models, reducers
    from ..reducers.base import BLAS_THREADS

    spec = "dsms:g=600" if quick else "dsms:g=6000"
    fom = models.parse(spec)
    rs = list(range(2, 41, 2))
    reps = 3 if quick else 5
    # the machine is shared: each repetition times the run, its floor and the sweep back to
    # back, and the ratios are the medians over repetitions
    r_floors, r_sweeps, t_singles, floors, t_sweeps = [], [], [], [], []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # RankWarnings of the sweep's large r are expected
        reducers.make("bt", fom, gramian_cache="reducer").reduce(20)  # warm-up: imports, first-call overheads
        for _ in range(reps):
            fr = run_against_floor(fom, lambda: _fresh_run(fom), adi_lu_shifts, threads=BLAS_THREADS)
            info, lus = fr.info, fr.info["lu_count"]
            red = reducers.make("bt", fom, gramian_cache="reducer")
            t0 = time.perf_counter()
            sweep = [red.reduce(r) for r in rs]
            t_sweep = time.perf_counter() - t0
            r_floors.append(fr.ratio)
            r_sweeps.append(t_sweep / fr.time_s)
            t_singles.append(fr.time_s)
            floors.append(fr.floor_s)
            t_sweeps.append(t_sweep)
    r_floor, r_sweep = float(np.median(r_floors)), float(np.median(r_sweeps))
    t_single, floor, t_sweep = (float(np.median(x)) for x in (t_singles, floors, t_sweeps))
    rows = [{"model": spec, "run": "single r=20", "time_s": t_single, "lu_count": lus, "floor_s": floor,
             "adi_iterations": info["adi_iterations"], "ratio": r_floor, "ratios": r_floors, "times_s": t_singles,
             **{f"t_{k}": v for k, v in info["time_breakdown"].items()}},
            {"model": spec, "run": f"sweep r={rs[0]}..{rs[-1]}", "time_s": t_sweep, "ratios": r_sweeps,
             "calls": len(rs), "r_used": [s.info["r"] for s in sweep], "ratio": r_sweep}]
    ratios = {
        f"bt {spec} r=20 / floor": {"value": r_floor, "target": 1.5, "pass": r_floor <= 1.5,
                                    "what": "bt wall time / bare floor (LUs x (splu + right and transposed solves) at the run's shifts)"},
        f"bt {spec} sweep r=2..40 / single r": {"value": r_sweep, "target": 1.5, "pass": r_sweep <= 1.5,
                                                "what": "20 reduce(r) calls on one reducer / one fresh reduce(20)"},
    }
    if quick:
        for v in ratios.values():
            v["pass"] = None
            v["what"] += " (quick: smoke run, not judged)"
    # the same floor ratio on the TCOM, whose ADI needs ~1200 iterations per Gramian (no sweep)
    tspec = "tcom:nc=200" if quick else "tcom:nc=2000"
    tfom = models.parse(tspec)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t_runs = [run_against_floor(tfom, lambda: _fresh_run(tfom), adi_lu_shifts, threads=BLAS_THREADS)
                  for _ in range(2 if quick else 3)]
    med = median_run(t_runs)
    tr, t_run, t_floor, tinfo = med.ratio, med.time_s, med.floor_s, med.info
    rows.append({"model": tspec, "run": "single r=20", "time_s": t_run, "lu_count": tinfo["lu_count"],
                 "floor_s": t_floor, "adi_iterations": tinfo["adi_iterations"], "ratio": tr,
                 "ratios": sorted(x.ratio for x in t_runs),
                 **{f"t_{k}": v for k, v in tinfo["time_breakdown"].items()}})
    ratios[f"bt {tspec} r=20 / floor"] = {"value": tr, "target": 1.5, "pass": None if quick else tr <= 1.5,
                                         "what": "bt wall time / bare floor (LUs x (splu + right and transposed "
                                                 "solves) at the run's shifts)"}
    for name, v in ratios.items():
        print(f"{name:45s} {v['value']:6.2f}  (target <= {v['target']}, "
              f"{'not judged' if v['pass'] is None else 'pass' if v['pass'] else 'FAIL'})")
    print(f"{'bt ' + spec + ' r=20 wall time':45s} {t_single:6.3f} s (median of {reps}; {lus} LUs, floor "
          f"{floor:.3f} s; the independent implementation: about 0.6 s at g = 6000)")
    return {"rows": rows, "ratios": ratios}

