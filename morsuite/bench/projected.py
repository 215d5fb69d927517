r"""Benchmark ``projected``: the explicit :math:`\Pi`-projected dense IRKA against the projector-free IRKA.

Both reducers start from the same r = 20 real shifts (log-spaced over the
band, ``init="given"``) and run exactly ``maxit`` iterations (``tol`` tiny,
cycle detection off), so they do the same IRKA work and return the same reduced
model (the relative difference of their transfer functions on 50 frequencies is
reported). What differs is the price of one basis: a sparse LU of the
:math:`(n_1+n_2)` saddle-point matrix for ``"irka"``, a dense LU of the projected
:math:`(n_1-n_2)` pencil for ``"irka-projected"``, plus its one-off setup (form
:math:`\Pi`, split it, project). DSMS g = 1000, 2000, 4000, 3 iterations; ratio
``irka_over_projected_gG`` = time of ``"irka"`` / time of ``"irka-projected"``,
target 1; the exponents of ratio and times against g are fitted
(:func:`~morsuite.bench.scaling.fit_exponent`).

``quick``: g = 250, 500, 1000, 2 iterations (seconds). Writes ``projected.json``
(through :func:`morsuite.bench.run`).
"""

from __future__ import annotations

import os
import time
import warnings

import numpy as np

from . import benchmark
from .output import THREAD_ENV_VARS
from .scaling import fit_exponent

__all__ = ["bench_projected"]

#: the thread variables recorded in ``settings``
_THREAD_VARS = THREAD_ENV_VARS[:3]


def _run(name, fom, r, opts):
    from .. import reducers

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # not converging is the point: maxit is fixed
        res = reducers.make(name, fom, **opts).reduce(r)
    return res


@benchmark("projected")
def bench_projected(quick: bool = False, *, sizes=None, r: int = 20, maxit: int | None = None,
                    irka_repeats: int = 5, verbose: bool = True) -> dict:
    r"""Time of ``"irka-projected"`` over ``"irka"`` on the DSMS, same shifts, same iteration count.

    Parameters
    ----------
    quick : bool
        Small sizes (g = 250, 500, 1000) and 2 iterations: seconds.
        Otherwise g = 1000, 2000, 4000 and 3 iterations: minutes.
    sizes : sequence of int, optional
        DSMS sizes g (n1 = g, n2 = 1) instead of the defaults.
    r : int
        Reduced order (number of shifts).
    maxit : int, optional
        Fixed number of IRKA iterations for both (default 2 quick, 3 full).
    irka_repeats : int
        ``"irka"`` is fast and noisy: the minimum over this many runs, half
        before and half after the projected one, is used (``"irka-projected"``
        runs once).

    Returns
    -------
    dict
        ``rows`` (one per g: total, setup and per-iteration times of both,
        LU counts, the ratios, the ROM agreement), ``fit`` (exponents p of
        ratio ~ g^p and of each time), ``ratios`` (morsuite.bench format),
        ``settings``.
    """
    from .. import models

    sizes = tuple(sizes) if sizes is not None else ((250, 500, 1000) if quick else (1000, 2000, 4000))
    maxit = int(maxit) if maxit is not None else (2 if quick else 3)
    rows = []
    if verbose:
        print(f"bench_projected: DSMS, r = {r}, {maxit} iterations each, same initial shifts; "
              f"threads {dict((v, os.environ.get(v)) for v in _THREAD_VARS)}", flush=True)
        print(f"{'g':>6} {'t_proj[s]':>10} {'setup':>8} {'per-it':>8} {'t_irka[s]':>10} {'per-it':>8} "
              f"{'ratio':>8} {'ratio/it':>8} {'LUs p/i':>8} {'rom diff':>9}", flush=True)
    for g in sizes:
        fom = models.dsms(g=int(g))
        lo, hi = fom.band
        opts = dict(init="given", init_shifts=np.logspace(np.log10(lo), np.log10(hi), r),
                    maxit=maxit, tol=1e-300, cycle_window=0)
        # "irka" runs before and after the projected one: a load spike on a
        # shared machine then cannot inflate all of its (short) timings
        n_rep = max(1, int(irka_repeats))
        irka_runs = [_run("irka", fom, r, opts) for _ in range((n_rep + 1) // 2)]
        t0 = time.perf_counter()
        proj = _run("irka-projected", fom, r, opts)
        wall_proj = time.perf_counter() - t0
        irka_runs += [_run("irka", fom, r, opts) for _ in range(n_rep // 2)]
        irka = min(irka_runs, key=lambda res: res.info["time_s"])
        pi, ii = proj.info, irka.info
        tb = pi["time_breakdown"]
        setup_p = tb["form_pi"] + tb["split"] + tb["project_model"]
        t_p, t_i = pi["time_s"], ii["time_s"]
        iter_p = (t_p - tb["setup"]) / pi["iterations"]
        iter_i = (t_i - ii["time_breakdown"]["setup"]) / ii["iterations"]
        omega = np.logspace(np.log10(lo), np.log10(hi), 50)
        Tp, Ti = proj.rom.freqresp(omega), irka.rom.freqresp(omega)
        diff = float(np.max(np.abs(Tp - Ti)) / np.max(np.abs(Ti)))
        row = {"g": int(g), "n1": fom.n1, "n2": fom.n2, "r": r, "iterations": pi["iterations"],
               "iterations_irka": ii["iterations"],
               "time_projected_s": t_p, "wall_projected_s": wall_proj,
               "setup_projected_s": setup_p, "form_pi_s": tb["form_pi"], "split_s": tb["split"],
               "project_model_s": tb["project_model"], "per_iteration_projected_s": iter_p,
               "dense_lu_s": tb["dense_lu"], "dense_lu_per_iteration_s": tb["dense_lu_per_iteration"],
               "lu_count_projected": pi["lu_count"], "peak_memory_gib_estimate": pi["memory"]["peak_gib"],
               "time_irka_s": t_i, "time_irka_all_runs_s": [x.info["time_s"] for x in irka_runs],
               "per_iteration_irka_s": iter_i, "lu_count_irka": ii["lu_count"],
               "ratio": t_p / t_i, "ratio_per_iteration": iter_p / iter_i,
               "rom_rel_difference": diff, "blas_threads": pi.get("blas_threads")}
        rows.append(row)
        if verbose:
            print(f"{g:>6} {t_p:>10.3f} {setup_p:>8.3f} {iter_p:>8.3f} {t_i:>10.4f} {iter_i:>8.4f} "
                  f"{row['ratio']:>8.1f} {row['ratio_per_iteration']:>8.1f} "
                  f"{pi['lu_count']:>4}/{ii['lu_count']:<3} {diff:>9.1e}", flush=True)
        del proj, irka, irka_runs, fom
    gs = [row["g"] for row in rows]
    fit = {key: fit_exponent(gs, [row[col] for row in rows])["exponent"]
           for key, col in (("ratio", "ratio"), ("ratio_per_iteration", "ratio_per_iteration"),
                            ("time_projected", "time_projected_s"), ("setup_projected", "setup_projected_s"),
                            ("per_iteration_projected", "per_iteration_projected_s"), ("time_irka", "time_irka_s"))}
    if verbose:
        print("fitted exponents (t ~ g^p): " + ", ".join(f"{k} {v:.2f}" for k, v in fit.items()), flush=True)
    ratios = {f"irka_over_projected_g{row['g']}": {
        "value": 1.0 / row["ratio"], "target": 1.0,
        "what": f"time of irka / time of irka-projected, DSMS g = {row['g']}, r = {r}, {maxit} iterations"}
        for row in rows}
    return {"rows": rows, "fit": fit, "ratios": ratios,
            "settings": {"model": "dsms", "sizes": list(sizes), "r": r, "maxit": maxit, "quick": bool(quick),
                         "irka_repeats": int(irka_repeats),
                         "threads": {v: os.environ.get(v) for v in _THREAD_VARS},
                         "blas_threads_in_reduce": rows[0]["blas_threads"] if rows else None}}

