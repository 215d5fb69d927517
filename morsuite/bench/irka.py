"""Benchmark of the projector-free IRKA against its floor (LUs made x time of one LU).

The floor of a run is what its sparse LUs cost bare: for every shift at which
the run factorized (one per real shift or conjugate pair per iteration, read
from ``info["history"]``) one ``scipy.sparse.linalg.splu`` of the pre-assembled,
unscaled saddle-point matrix (the solver's ordering and pivot threshold) plus
one right and one transposed solve. Run and floor are timed alternately,
three times (once with ``quick``), so that the load of this shared machine
hits both alike; the ratio is the median over the pairs of
``time_s / floor``. It says how much of the run is not sparse LU work (dense
update, projection, orthogonalisation, equilibration, checks, Python).
"""

from __future__ import annotations

import time
import warnings

from . import bare_lu_floor, benchmark
from ..utils import blas_threads


def lu_shifts(info) -> list:
    """The shifts at which a run factorized: per iteration, one per real shift or conjugate pair."""
    from ..reducers.base import as_complex

    out = []
    for sh in info["history"]["shifts"]:
        out.extend(a for a in as_complex(sh) if a.imag >= 0)
    return out


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
        pairs = []
        for _ in range(repeats):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = reducers.make("irka", fom).reduce(r)
            info = res.info
            with blas_threads(1):
                floor = bare_lu_floor(fom, lu_shifts(info), info["lu_count"])
            pairs.append((info["time_s"] / floor, info, floor))
        pairs.sort(key=lambda x: x[0])
        ratio, info, floor = pairs[len(pairs) // 2]
        tb = info["time_breakdown"]
        rows.append({"model": spec, "r": info["r"], "r_requested": r, "states": info["states"],
                     "converged": info["converged"], "iterations": info["iterations"],
                     "lu_count": info["lu_count"], "time_s": info["time_s"], "floor_s": floor,
                     "ratio": ratio, "ratios_all": [round(p[0], 4) for p in pairs],
                     **{f"t_{k}": v for k, v in tb.items()}})
        ratios[f"{spec} r={r}"] = {"value": ratio, "target": 1.5, "pass": None if quick else ratio <= 1.5,
                                   "what": f"irka wall time / bare floor ({info['lu_count']} x (splu + 2 solves) "
                                           f"at the run's own shifts), median of {repeats} alternating pairs"}
    return {"rows": rows, "ratios": ratios}
