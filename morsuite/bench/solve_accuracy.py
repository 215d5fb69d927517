r"""Benchmark ``solve-accuracy``: the cost of solving to the backward-error target, against the rule before it.

Since 2026-12-02 every checked saddle-point solve reaches a backward error of 1e-15
(:mod:`morsuite.linalg.accuracy`: certified in double or measured in double-double, refined with the same
LU where above it) and frequency responses refine against the exact :math:`S(j\omega)` until their estimated
error is below double's rounding; before, solves were accepted up to 1e-10 and a band sample refined one
fixed step. This bench times one band sweep both ways in one process (``MORSUITE_SOLVE_TARGET=off``
restores the rule before, :func:`~morsuite.linalg.accuracy.target_off`): at ``n`` log-spaced frequencies
of the model's band, per frequency one sample as :func:`~morsuite.analysis.response.band_response` takes
it (:meth:`FomResponse.sample <morsuite.norms._fom.FomResponse.sample>`: the LU, the solve with
:math:`[F; 0]` and its refinement, the transposed solve with :math:`[L^T; 0]` of the derivative), the two
variants alternating with the order swapped from frequency to frequency, one thread, the patterns'
analyses made before and not timed. Reported per model: the sweep's seconds each way and their ratio,
the median of the per-frequency ratios, LUs, refinement steps and fallback LUs of the new rule, the
worst backward error each way (the rule before measures it in double) and the largest difference of the
two responses relative to the response. Models: fem_block(4000) (40 frequencies) and fem_block(20000)
(24; target: at most 1.15 times the time before); quick: fem_block(1000), 8 frequencies, not judged.

Accuracy rows (``accuracy``): issue 45's case, ``random_constrained(n1=1200, n2=10, m=2, p=2, seed=1,
extra_springs=3.0)`` at modal damping 1e-3, 1e-4 and 1e-5, :meth:`~morsuite.models.Index3Model.freqresp`
at its first undamped frequency by rslab (its LDL^T), KLU and SuperLU under both rules: the largest entry
of the difference from a reference relative to the largest of the reference (SuperLU's LU refined four
fixed steps against the exact :math:`S(j\omega)` in double-double), the worst backward error and the
refinement steps. Quoted in ``docs/design/backends.md`` (2026-12-02).
"""

from __future__ import annotations

import contextlib
import os
import time

import numpy as np

from . import benchmark
from .backends import _load, _versions

__all__ = ["bench_solve_accuracy", "sweep_side_by_side", "resonance_accuracy"]

MODELS = (("fem_block:n1=4000", 40, None), ("fem_block:n1=20000", 24, 1.15))
MODELS_QUICK = (("fem_block:n1=1000", 8, None),)


@contextlib.contextmanager
def _rule(variant: str):
    """``"before"``: the environment of the rule before 2026-12-02 inside the block; ``"target"``: today's."""
    old = os.environ.get("MORSUITE_SOLVE_TARGET")
    if variant == "before":
        os.environ["MORSUITE_SOLVE_TARGET"] = "off"
    else:
        os.environ.pop("MORSUITE_SOLVE_TARGET", None)
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("MORSUITE_SOLVE_TARGET", None)
        else:
            os.environ["MORSUITE_SOLVE_TARGET"] = old


def sweep_side_by_side(spec: str, n: int, echo=None) -> dict:
    """One model's row: seconds of a band sweep of ``n`` frequencies with the target (``t_target``) and
    with the rule before (``t_before``), their ratio, the per-frequency ratios' median and what each
    variant's solves did."""
    from .. import models
    from ..norms._fom import FomResponse
    from ..utils import blas_threads

    fom = models.parse(spec)
    omega = np.logspace(np.log10(fom.band[0]), np.log10(fom.band[1]), n)
    evs = {}
    for v in ("before", "target"):
        with _rule(v):
            evs[v] = FomResponse(fom, refine=1, cache_size=0)
    evs["before"].solver.factor(1j * omega[0])  # the analyses of the pattern (shared): once, not timed
    times = {v: [] for v in evs}
    values = {v: [] for v in evs}
    with blas_threads(1):
        for i, w in enumerate(omega):
            for v in (("before", "target") if i % 2 == 0 else ("target", "before")):
                with _rule(v):
                    t0 = time.perf_counter()
                    T0, T, _ = evs[v].sample(1j * w)
                    times[v].append(time.perf_counter() - t0)
                values[v].append(np.asarray(T if T is not None else T0, dtype=complex))
                if echo:
                    echo(f"  {spec} omega = {w:.4g} {v}: {times[v][-1]:.3f} s")
    st = {v: evs[v].solver.stats for v in evs}
    diff = max(float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))
               for a, b in zip(values["target"], values["before"]))
    t = {v: float(np.sum(times[v])) for v in times}
    per = np.asarray(times["target"]) / np.asarray(times["before"])
    return {"model": spec, "n1": fom.n1, "n2": fom.n2, "backend": evs["target"].solver.backend, "frequencies": n,
            "band": list(fom.band), "t_before": t["before"], "t_target": t["target"],
            "target_over_before": t["target"] / t["before"], "median_ratio": float(np.median(per)),
            "times": times, "lus": {v: int(st[v].factorizations) for v in st},
            "refactorizations": {v: int(st[v].refactorizations) for v in st},
            "factor_time_s": {v: float(st[v].factor_time_s) for v in st},
            "checked_solves": int(st["target"].checked_solves), "refinement_steps": int(st["target"].refinement_steps),
            "target_fallbacks": int(st["target"].target_fallbacks), "above_target": int(st["target"].above_target),
            "backward_error_max": {v: float(st[v].backward_error_max) for v in st},
            "max_rel_diff": diff}


def resonance_accuracy(zeta: float, backends=("rslab", "klu", "superlu")) -> list:
    """Rows of the accuracy table at one damping (the module docstring): per backend and rule, the relative
    error of ``freqresp`` at the first undamped frequency, its worst backward error and refinement steps."""
    import scipy.linalg as sla

    from ..linalg.refine import SaddleOperator, refine_columns
    from ..models import random_constrained

    fom = random_constrained(n1=1200, n2=10, m=2, p=2, seed=1, zeta=zeta, extra_springs=3.0)
    Z = sla.null_space(fom.G.toarray())
    lam = sla.eigh(Z.T @ fom.K.toarray() @ Z, Z.T @ fom.M.toarray() @ Z, eigvals_only=True, subset_by_index=[0, 0])
    w = float(np.sqrt(lam[0]))
    solver = fom.new_solver(cache_size=0, backend="superlu")
    lu = solver.factor(1j * w)
    xr, xi, _ = refine_columns(lu, fom.F, lu.solve(fom.F, full=True), False, 1j * w, SaddleOperator(solver.pattern),
                               steps=4)
    ref = fom.L @ (xr[:fom.n1].astype(float) + 1j * xi[:fom.n1].astype(float))
    rows = []
    for backend in backends:
        for rule in ("before", "target"):
            with _rule(rule):
                fom.lu_backend = backend
                T = fom.freqresp([w])[0]
            st = fom.last_freqresp_stats
            rows.append({"zeta": zeta, "omega": w, "backend": backend, "rule": rule,
                         "factor": type(fom.new_solver().factor(1j * w).lu).__name__,
                         "rel_error": float(np.max(np.abs(T - ref)) / np.max(np.abs(ref))),
                         "backward_error_max": float(st["backward_error_max"]),
                         "refinement_steps": int(st["refinement_steps"]), "lus": int(st["factorizations"])})
    return rows


@benchmark("solve-accuracy")
def bench_solve_accuracy(quick: bool) -> dict:
    """A band sweep solved to the backward-error target against the rule before it (fem_block 4000, 20000)."""
    from ..linalg.warmup import warm_kernels

    warm_kernels()
    load0 = _load()
    rows = []
    for spec, n, _ in (MODELS_QUICK if quick else MODELS):
        row = sweep_side_by_side(spec, n, echo=print)
        print(f"{spec} ({row['backend']}), {n} frequencies: target {row['t_target']:.1f} s, before "
              f"{row['t_before']:.1f} s: {row['target_over_before']:.3f} (median per frequency "
              f"{row['median_ratio']:.3f}); refinement steps {row['refinement_steps']}, fallback LUs "
              f"{row['target_fallbacks']}; worst backward errors {row['backward_error_max']['target']:.1e} / "
              f"{row['backward_error_max']['before']:.1e}; responses differ by {row['max_rel_diff']:.1e}")
        rows.append(row)
    accuracy = [row for zeta in ((1e-4,) if quick else (1e-3, 1e-4, 1e-5)) for row in resonance_accuracy(zeta)]
    for row in accuracy:
        print(f"zeta = {row['zeta']:.0e}, {row['backend']} ({row['factor']}), rule {row['rule']}: relative error "
              f"{row['rel_error']:.1e}, backward error {row['backward_error_max']:.1e}, "
              f"{row['refinement_steps']} refinement steps")
    targets = {spec: target for spec, _, target in (MODELS_QUICK if quick else MODELS)}
    ratios = {}
    for row in rows:
        target = None if quick else targets[row["model"]]
        ratios[f"{row['model']}: band sweep, target / before"] = {
            "value": row["target_over_before"], "target": target,
            "pass": None if target is None else bool(row["target_over_before"] <= target),
            "what": f"{row['frequencies']} band samples (LU, solve and refinement, transposed solve), one thread, "
                    "the two rules alternating"}
    return {"rows": rows, "accuracy": accuracy, "ratios": ratios, "load_before": load0, "load_after": _load(),
            "versions": _versions(), "quick": quick}
