"""Benchmark ``lu-backends``: the sparse LU backends against scipy's splu, their scaling, shift-parallel IRKA.

Every ratio is measured side by side in one process, the variants interleaved
(one of each per round or shift, the order rotated each time) and the medians
compared, so that the load of a shared machine hits all alike. Parts
(``MORSUITE_LU_BENCH_PARTS``, comma-separated, runs some; default all):

1. ``lu``: one LU plus one solve per shift, at three shifts in the band
   (:func:`band_shifts`), through the model's solver (pattern analysed before; assembly,
   equilibration, factorization, solve with [F; 0], backward-error check timed) for every
   installed backend (SuperLU, banded on narrow bands, KLU, rslab, PARDISO where installed),
   against ``scipy.sparse.linalg.splu`` of the assembled matrix plus its solve (assembly not
   timed; ``MMD_AT_PLUS_A`` on fem_block, ``COLAMD`` on the chains), one thread, medians over
   the shifts, each variant's largest backward error: fem_block(4000, 20000) (target: auto /
   splu <= 1/5 at 20000) and DSMS, TCOM at n1 = 2e5 (target <= 1/3.5); auto within 1.2x of the
   fastest installed backend. On fem_block(20000) SuperLU runs at the middle shift only, KLU not
   at all (46-56 s per LU there in issue 33), nor the banded LU on the wide bands.
2. ``scaling``: the same automatic LU + solve, and one IRKA iteration (r = 10),
   at n1 = 2e4 and 2e5 on the DSMS, the two sizes interleaved: exponent
   log(t2 / t1) / log(10) (target 1.10).
3. ``parallel``: IRKA at n1 = 2e5 (DSMS, r = 10, fixed 3 iterations), solver_threads
   2 against 1 (target t2 / t1 <= 1/1.6); and the LU + solve of 6 shifts alone on 2
   threads against 1 (what the threads can gain without IRKA's serial dense work).
4. ``agree``: converged IRKA ROMs (r = 10) from every backend against SuperLU's, max
   relative transfer-function difference on 200 frequencies (target 1e-8), on the
   DSMS and the TCOM; the full model's transfer function on a small FEM block.

The result records the date, the load (``uptime`` before and after) and the versions of
SciPy, NumPy, rslab, nbklu and mkl. ``quick``: smaller models, one round; not judged.
Writes ``lu-backends.json`` (through :func:`morsuite.bench.run`); measurements quoted in
``docs/design/backends.md``.
"""

from __future__ import annotations

import contextlib
import math
import os
import time
import warnings

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..linalg.backends import choose
from ..linalg.backends_ext import available as extras_available
from ..utils import blas_threads
from ..reducers.irka.shift_solves import map_threads
from . import benchmark

__all__ = ["bench_lu_backends", "bench_lu_rule", "grid3d_elastic", "strip_model"]


def grid3d_elastic(n: int):
    """An elasticity-like 3D model: n^3 nodes, 3 coupled displacements each, 27-point stencil, x = 0 clamped.

    K is the Kronecker sum of 1D stiffness/mass stencils with a full 3 x 3 coupling of
    the displacements, M the matching mass pattern, D = 1e-3 M + 1e-3 K (Rayleigh);
    the 3 n^2 displacements of the face x = 0 are held by G (one row each).
    """
    from ..models import Index3Model

    T = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
    Mm = sp.diags([np.ones(n - 1), 4 * np.ones(n), np.ones(n - 1)], [-1, 0, 1]) / 6
    k3 = sp.kron(sp.kron(T, Mm), Mm) + sp.kron(sp.kron(Mm, T), Mm) + sp.kron(sp.kron(Mm, Mm), T)  # 27-point
    m3 = sp.kron(sp.kron(Mm, Mm), Mm)
    C = np.array([[2.0, 0.5, 0.5], [0.5, 2.0, 0.5], [0.5, 0.5, 2.0]])  # couples the 3 displacements
    K = sp.kron(k3, C).tocsr()
    M = sp.kron(m3, sp.identity(3)).tocsr()
    n1 = K.shape[0]
    face = np.flatnonzero((np.arange(n1) // 3) // (n * n) == 0)
    G = sp.csr_matrix((np.ones(face.size), (np.arange(face.size), face)), shape=(face.size, n1))
    rng = np.random.default_rng(0)
    return Index3Model(M, 1e-3 * M + 1e-3 * K, K, G, rng.standard_normal((n1, 1)), rng.standard_normal((1, n1)),
                       name=f"grid3d(n={n})", band=(1e-2, 1.0), check_constraints=False)


def strip_model(w: int, n1: int = 40000, n2: int = 2):
    """A 2D strip of width ``w`` (5-point stencil, n1 positions), n2 positions held by constraints.

    Its RCM bandwidth is about 2 w: the family on which the rule of ``"auto"`` is
    checked (``morsuite bench lu-rule``).
    """
    from ..models import Index3Model

    length = n1 // w
    T = lambda n: sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])  # noqa: E731
    K = (sp.kron(T(length), sp.identity(w)) + sp.kron(sp.identity(length), T(w))
         + 0.01 * sp.identity(length * w)).tocsr()
    n = K.shape[0]
    M = sp.identity(n, format="csr")
    held = np.linspace(0, n - 1, n2).astype(int)
    G = sp.csr_matrix((np.ones(n2), (np.arange(n2), held)), shape=(n2, n))
    rng = np.random.default_rng(0)
    return Index3Model(M, 0.01 * K + 0.01 * M, K, G, rng.standard_normal((n, 1)), rng.standard_normal((1, n)),
                       name=f"strip(w={w}, n2={n2})", check_constraints=False)


def _lu_solve_variants(fom, s, backends):
    """Callables timing one LU + solve: splu of the assembled matrix, and the solver per backend."""
    rhs = np.vstack([fom.F, np.zeros((fom.n2, fom.m))])
    A = fom.new_solver(cache_size=0, backend="superlu").matrix(s)

    def splu():
        t0 = time.perf_counter()
        spla.splu(A, permc_spec="COLAMD", diag_pivot_thresh=0.1).solve(rhs.astype(complex))
        return time.perf_counter() - t0

    out = {"splu": splu}
    for name in backends:
        b, lapack_kernel = (name[:-len("-lapack")], True) if name.endswith("-lapack") else (name, False)
        solver = fom.new_solver(cache_size=0, backend=b)
        solver.factor(s)  # the analysis and orderings: once per model, not timed

        def run(solver=solver, lapack_kernel=lapack_kernel):
            with _band_kernel("lapack" if lapack_kernel else None):
                t0 = time.perf_counter()
                solver.factor(s).solve(fom.F)
                return time.perf_counter() - t0
        out[name] = run
    return out


@contextlib.contextmanager
def _band_kernel(value):
    """``MORSUITE_BAND_KERNEL`` set to ``value`` inside the block (unchanged for None)."""
    old = os.environ.get("MORSUITE_BAND_KERNEL")
    if value is not None:
        os.environ["MORSUITE_BAND_KERNEL"] = value
    try:
        yield
    finally:
        if value is not None:
            if old is None:
                os.environ.pop("MORSUITE_BAND_KERNEL")
            else:
                os.environ["MORSUITE_BAND_KERNEL"] = old


def _interleaved(variants: dict, rounds: int) -> dict:
    """Median seconds per variant, the variants run one after the other in each round, the order
    rotated by one from round to round (the first variant after splu, which frees hundreds of MB,
    measured 4-14 ms slower than the same backend later in the round: 2026-11-26)."""
    times = {k: [] for k in variants}
    names = list(variants)
    for i in range(rounds):
        for k in names[i % len(names):] + names[:i % len(names)]:
            times[k].append(variants[k]())
    return {k: float(np.median(v)) for k, v in times.items()}


def _irka_iteration(fom, r, threads, iters=3):
    """Seconds per iteration of IRKA with a fixed number of iterations (tol 0: no early stop)."""
    from .. import reducers
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        info = reducers.make("irka", fom, solver_threads=threads, maxit=iters, tol=1e-300,
                             safeguard="off").reduce(r).info
    return info["time_s"] / max(info["iterations"], 1), info


#: the patterns of part ``lu``: (spec, splu's ordering), full and quick
LU_PATTERNS = (("fem_block:n1=4000", "MMD_AT_PLUS_A"), ("fem_block:n1=20000", "MMD_AT_PLUS_A"),
               ("dsms:g=200000", "COLAMD"), ("tcom:nc=66666", "COLAMD"))
LU_PATTERNS_QUICK = (("fem_block:n1=1500", "MMD_AT_PLUS_A"), ("dsms:g=20000", "COLAMD"),
                     ("tcom:nc=6666", "COLAMD"))
#: the parts of ``lu-backends`` (``MORSUITE_LU_BENCH_PARTS``, comma-separated, picks some)
PARTS = ("lu", "scaling", "parallel", "agree")


def band_shifts(fom, k: int = 3) -> np.ndarray:
    """``k`` shifts :math:`i\\omega` in the model's band, at the quartiles of log(omega) (k = 3)."""
    lo, hi = np.log10(fom.band[0]), np.log10(fom.band[1])
    return 1j * np.logspace(lo, hi, k + 2)[1:-1]


def _backward_error(A, x, b) -> float:
    """Normwise backward error ||b - A x||_1 / (||A||_1 ||x||_1 + ||b||_1) of one solve."""
    r = b - A @ x
    return float(np.abs(r).sum() / (abs(A).sum(axis=0).max() * np.abs(x).sum() + np.abs(b).sum()))


def lu_side_by_side(spec: str, splu_order: str, backends, slow=(), echo=None) -> dict:
    """One LU + solve per shift (three in the band) by splu and every backend, side by side.

    splu (``splu_order``, threshold 0.1) of the assembled matrix plus its solve with [F; 0]
    (assembly not timed) against the model's solver per backend (pattern analysed before, not
    timed; then per shift assembly, scaling, factorization, solve, backward-error check), one
    thread. Per shift every variant runs once, the order rotated from shift to shift; the median
    over the shifts is reported, with each variant's largest backward error (of the unscaled
    matrix). Backends in ``slow`` are run at the middle shift only.
    """
    from .. import models
    fom = models.parse(spec)
    shifts = band_shifts(fom)
    rhs = np.vstack([fom.F, np.zeros((fom.n2, fom.m))]).astype(complex)
    solvers = {}
    for b in backends:
        solvers[b] = fom.new_solver(cache_size=0, backend=b)
        solvers[b].factor(shifts[1])  # the analysis and orderings: once per model, not timed
    times = {k: [] for k in ("splu", *backends)}
    berr = {k: 0.0 for k in times}
    names = list(times)
    for i, s in enumerate(shifts):
        A = solvers[backends[0]].matrix(s)
        for k in names[i % len(names):] + names[:i % len(names)]:
            if k in slow and i != 1:
                continue
            if k == "splu":
                t0 = time.perf_counter()
                x = spla.splu(A, permc_spec=splu_order, diag_pivot_thresh=0.1).solve(rhs)
                t = time.perf_counter() - t0
            else:
                t0 = time.perf_counter()
                x = solvers[k].factor(s).solve(fom.F, full=True)
                t = time.perf_counter() - t0
            times[k].append(t)
            berr[k] = max(berr[k], _backward_error(A, x, rhs))
            if echo:
                echo(f"  {spec} s = {s:.3g} {k}: {t:.3f} s")
    a = fom.lu_analysis()
    med = {k: float(np.median(v)) for k, v in times.items()}
    row = {"part": "lu", "model": spec, "n1": fom.n1, "n2": fom.n2, "kl_ku": a["kl"] + a["ku"], "auto": a["backend"],
           "reason": a["reason"], "splu_ordering": splu_order, "shifts": [complex(s) for s in shifts],
           **{f"t_{k}": v for k, v in med.items()}, **{f"n_shifts_{k}": len(v) for k, v in times.items()},
           **{f"{k}_over_splu": v / med["splu"] for k, v in med.items() if k != "splu"},
           **{f"berr_{k}": v for k, v in berr.items()},
           "refactorizations": {b: solvers[b].stats.refactorizations for b in backends}}
    fast = [b for b in backends if b not in slow]
    row["best"] = min(fast, key=lambda b: med[b])
    row["auto_over_best"] = med[a["backend"]] / med[row["best"]] if a["backend"] in med else None
    return row


def _side_by_side_line(row: dict, names) -> str:
    """One printed line of part ``lu``: per variant the median seconds, the ratio to splu, the backward error."""
    cells = [f"{k} {row[f't_{k}']:.3g} s ({row[f't_{k}'] / row['t_splu']:.3f}, berr {row[f'berr_{k}']:.0e})"
             for k in names if f"t_{k}" in row]
    return f"{row['model']} (auto {row['auto']}): " + " | ".join(cells)


def _load() -> dict:
    """The load averages (1, 5, 15 min) and ``uptime``'s line, for the record."""
    import subprocess
    try:
        line = subprocess.run(["uptime"], capture_output=True, text=True, timeout=5).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        line = ""
    return {"loadavg": list(os.getloadavg()), "uptime": line}


def _versions() -> dict:
    from importlib.metadata import PackageNotFoundError, version
    out = {}
    for pkg in ("scipy", "numpy", "rslab", "nbklu", "mkl"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = None
    return out


@benchmark("lu-backends")
def bench_lu_backends(quick: bool) -> dict:
    """LU backends side by side against splu on 3D solids and chains, n1-scaling, shift-parallel IRKA, ROM agreement."""
    from .. import models, reducers
    from datetime import datetime, timezone

    big, small, rounds = (20000, 2000, 1) if quick else (200000, 20000, 5)
    parts = tuple(p for p in os.environ.get("MORSUITE_LU_BENCH_PARTS", ",".join(PARTS)).split(",") if p)
    rows, ratios = [], {}
    installed = [b for b, ok in extras_available().items() if ok]
    record = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "load_before": _load(),
              "versions": _versions(), "installed": installed, "parts": parts}

    def judge(name, value, target, what):
        ratios[name] = {"value": value, "target": target,
                        "pass": None if quick or target is None else bool(value <= target), "what": what}

    with blas_threads(1):
        # 1. one LU + solve per shift, every installed backend side by side with splu
        for spec, order in (LU_PATTERNS_QUICK if quick else LU_PATTERNS) if "lu" in parts else ():
            wide = spec.startswith("fem_block")
            large = wide and int(spec.split("=")[1]) > 10000
            # not run: the banded LU on wide bands (n1 (kl + ku)^2 work), KLU on the large 3D solids (no
            # supernodes: 46-56 s per LU at fem_block(20000) in issue 33, 9x SuperLU at fem_block(4000) here)
            names = ("superlu", *(() if wide else ("banded",)), *(b for b in installed if not (large and b == "klu")))
            slow = ("superlu",) if large else ()  # SuperLU (COLAMD) on the large 3D solids: the middle shift
            row = lu_side_by_side(spec, order, names, slow, echo=print)
            rows.append(row)
            print(_side_by_side_line(row, ("splu", *names)))
            judge(f"lu {spec}: auto ({row['auto']}) / splu {order}", row[f"{row['auto']}_over_splu"],
                  (1 / 5 if wide else 1 / 3.5) if not spec.endswith("=4000") else None,
                  f"one LU + solve through the solver (assembly, scaling, check included) over splu {order} + "
                  "solve, median over three shifts in the band, one thread, variants rotated per shift")
            if row["auto_over_best"] is not None:
                judge(f"lu {spec}: auto / best installed ({row['best']})", row["auto_over_best"], 1.2,
                      "the automatic choice over the fastest backend measured at all three shifts")
        # 2. growth with n1 (DSMS): both sizes in every round
        if "scaling" in parts:
            foms = {g: models.parse(f"dsms:g={g}") for g in (small, big)}
            lu_runs = {g: _lu_solve_variants(f, 1j * math.sqrt(f.band[0] * f.band[1]), ("auto",))["auto"]
                       for g, f in foms.items()}
            t_lu = _interleaved(lu_runs, rounds)
            t_it = _interleaved({g: (lambda f=f: _irka_iteration(f, 10, 1)[0]) for g, f in foms.items()},
                                max(1, rounds // 2))
            for g, f in foms.items():
                rows.append({"part": "scaling", "model": f"dsms:g={g}", "n1": f.n1, "t_lu_solve": t_lu[g],
                             "t_irka_iteration": t_it[g]})
            dec = math.log10(big / small)
            judge("scaling: LU + solve exponent", math.log10(t_lu[big] / t_lu[small]) / dec, 1.10,
                  f"time per LU + solve (auto) from n1 = {small} to {big} on the DSMS, as n1^x, sizes interleaved")
            judge("scaling: IRKA iteration exponent", math.log10(t_it[big] / t_it[small]) / dec, 1.10,
                  f"IRKA (r = 10) time per iteration from n1 = {small} to {big} on the DSMS, as n1^x, sizes interleaved")
    if "parallel" in parts:
        # 4. shift-parallel IRKA (BLAS single-threaded inside reduce), and its LUs + solves alone
        fom = models.parse(f"dsms:g={big}")
        med = _interleaved({1: lambda: _irka_iteration(fom, 10, 1)[0], 2: lambda: _irka_iteration(fom, 10, 2)[0]},
                           max(1, rounds // 2))
        solver = fom.new_solver(cache_size=0)
        shifts = 1j * np.geomspace(fom.band[0], fom.band[1], 6) + 0.05

        def lus(threads):
            t0 = time.perf_counter()
            map_threads(lambda a: solver.factor(a).solve(fom.F), list(shifts), threads)
            return time.perf_counter() - t0
        with blas_threads(1):
            med_lu = _interleaved({1: lambda: lus(1), 2: lambda: lus(2)}, rounds)
        rows.append({"part": "parallel", "model": f"dsms:g={big}", "t_serial": med[1], "t_threads2": med[2],
                     "t_6lu_serial": med_lu[1], "t_6lu_threads2": med_lu[2]})
        judge("parallel: IRKA iteration 2 threads / 1", med[2] / med[1], 1 / 1.6,
              f"IRKA r = 10 per iteration on dsms(g={big}), solver_threads 2 over 1, interleaved medians")
        judge("parallel: 6 LUs + solves 2 threads / 1", med_lu[2] / med_lu[1], 1 / 1.6,
              "the same shifts' LU + solve on 2 threads over 1 (no IRKA dense work), interleaved medians")
    if "agree" in parts:
        # 5. converged ROMs of every backend against SuperLU's (chains); the FOM's transfer function (FEM block,
        # on which IRKA does not converge in 100 iterations at r = 2..10 and its iterates are ill-conditioned)
        for spec in (("dsms:g=600", "tcom:nc=200") if quick else ("dsms:g=6000", "tcom:nc=2000")):
            roms = {}
            for b in ("superlu", "banded", *installed):
                fom = models.parse(spec)
                fom.lu_backend = b
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    res = reducers.make("irka", fom).reduce(10)
                roms[b] = (res.rom, res.info["converged"])
            omega = np.logspace(np.log10(fom.band[0]), np.log10(fom.band[1]), 200)
            Href = roms["superlu"][0].freqresp(omega)
            diffs = {b: float(np.max(np.abs(r[0].freqresp(omega) - Href)) / np.max(np.abs(Href)))
                     for b, r in roms.items() if b != "superlu"}
            rows.append({"part": "agree", "model": spec, "converged": {b: v[1] for b, v in roms.items()},
                         **{f"rel_diff_{b}": d for b, d in diffs.items()}})
            for b, d in diffs.items():
                judge(f"agree {spec}: {b} vs superlu ROM", d, 1e-8,
                      f"max |T_{b} - T_superlu| / max |T_superlu| of the converged IRKA ROMs (r = 10), 200 frequencies")
        spec = "fem_block:n1=600" if quick else "fem_block:n1=2000"
        H = {}
        for b in ("superlu", *installed):
            fom = models.parse(spec)
            fom.lu_backend = b
            omega = np.logspace(np.log10(fom.band[0]), np.log10(fom.band[1]), 40)
            H[b] = fom.freqresp(omega)
        for b in installed:
            d = float(np.max(np.abs(H[b] - H["superlu"])) / np.max(np.abs(H["superlu"])))
            rows.append({"part": "agree", "model": spec, f"rel_diff_fom_{b}": d})
            judge(f"agree {spec}: {b} vs superlu FOM transfer", d, 1e-8,
                  f"max |T_{b} - T_superlu| / max |T_superlu| of the full model at 40 frequencies")
    record["load_after"] = _load()
    return {"rows": rows, "ratios": ratios, **record}


@benchmark("lu-rule")
def bench_lu_rule(quick: bool) -> dict:
    """The rule of the automatic LU backend: every backend on 2D strips of growing width and border, 3D solids."""
    from .. import models
    from ..linalg.backends import BAND_RULE

    n1, rounds = (4000, 1) if quick else (40000, 3)
    extras = [b for b, ok in extras_available().items() if ok]
    cases = [(f"strip w={w} n2={n2}", lambda w=w, n2=n2: strip_model(w, n1=n1, n2=n2))
             for w, n2 in [(w, 2) for w in (1, 2, 4, 8, 16, 24, 32, 48)] + [(1, n2) for n2 in (4, 8, 16, 32, 64)]]
    cases += [(f"grid3d n={n}", lambda n=n: grid3d_elastic(n)) for n in ((4, 6) if quick else (6, 9))]
    cases += [(f"fem_block n1={n}", lambda n=n: models.parse(f"fem_block:n1={n}"))
              for n in ((600,) if quick else (1500, 4000))]
    rows, agree = [], 0
    with blas_threads(1):
        for name, make in cases:
            fom = make()
            a = fom.lu_analysis()
            names = ("superlu", *(("banded",) if a["kl"] + a["ku"] <= 100 else ()), *extras)
            med = _interleaved(_lu_solve_variants(fom, 0.3j, names), rounds)
            faster = min(names, key=lambda b: med[b])
            agree += faster == a["backend"]
            rows.append({"case": name, "n": fom.n1 + fom.n2, "n2": fom.n2, "kl_ku": a["kl"] + a["ku"],
                         "auto": a["backend"], "faster": faster, **{f"t_{b}": med[b] for b in names},
                         "auto_over_best": med[a["backend"]] / med[faster]})
    share = agree / len(cases)
    worst = max(r["auto_over_best"] for r in rows)
    return {"rows": rows, "rule": dict(BAND_RULE), "extras": extras,
            "ratios": {"rule misses": {"value": 1 - share, "target": 0.25, "pass": None if quick else 1 - share <= 0.25,
                                       "what": f"share of the {len(cases)} cases on which auto did not pick the "
                                               f"fastest backend (strips n1 = {n1}, 3D solids; medians of {rounds} "
                                               f"interleaved rounds; extras: {extras})"},
                       "rule worst auto / best": {"value": worst, "target": 1.5,
                                                  "pass": None if quick else worst <= 1.5,
                                                  "what": "largest time of the automatic choice over the fastest "
                                                          "backend among the cases"}}}
