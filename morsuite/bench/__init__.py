"""Benchmarks: timings judged against a floor measured in the same run.

A benchmark is a function ``f(quick: bool) -> dict`` of plain data registered
with :func:`benchmark`. Its result may hold ``"ratios"``, a mapping
``name -> {"value": float, "target": float, "what": str}`` (lower is better;
``value <= target`` passes); :func:`run` prints one line per ratio and writes
``<out_dir>/<name>.json`` and ``<out_dir>/manifest.json`` (machine, versions,
thread settings) atomically.

Timings are compared with a floor measured on the same machine in the same
process, never with a number from elsewhere: the floor of a frequency
response is one sparse LU of the saddle-point matrix plus one solve per
frequency (design.md, "Numerics that decide speed").
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
import tracemalloc
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from ..errors import OptionError
from ..utils import atomic_path

__all__ = ["BENCHMARKS", "benchmark", "run", "machine_info"]

#: name -> benchmark function ``f(quick: bool) -> dict``
BENCHMARKS: dict = {}

THREAD_ENV_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                   "BLIS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")


def benchmark(name: str):
    """Register ``f(quick: bool) -> dict`` under ``name``."""
    if not isinstance(name, str) or not name:
        raise OptionError(f"benchmark name must be a non-empty string; got {name!r}")

    def deco(fn):
        if name in BENCHMARKS and BENCHMARKS[name] is not fn:
            raise OptionError(f"benchmark {name!r} is already registered")
        BENCHMARKS[name] = fn
        fn.benchmark_name = name
        return fn

    return deco


def _discover():
    """Import the modules of this package: each benchmark module registers its benchmarks.

    A module that cannot be imported (e.g. a missing optional dependency) is
    skipped with a warning, so that the other benchmarks still run.
    """
    import importlib
    import pkgutil
    import warnings

    from . import __path__ as package_path
    from ..errors import MorsuiteWarning

    for mod in pkgutil.iter_modules(package_path):
        if not mod.name.startswith("_"):
            try:
                importlib.import_module(f"{__package__}.{mod.name}")
            except ImportError as exc:
                warnings.warn(f"benchmark module {__package__}.{mod.name} not loaded: {exc}",
                              MorsuiteWarning, stacklevel=3)


def available() -> list[str]:
    """Names of the registered benchmarks (every module of ``morsuite.bench`` imported)."""
    _discover()
    return sorted(BENCHMARKS)


def describe(name: str) -> str:
    """First line of the benchmark's docstring."""
    doc = (BENCHMARKS[name].__doc__ or "").strip()
    return doc.splitlines()[0] if doc else ""


# ---------------------------------------------------------------------------
# machine manifest
# ---------------------------------------------------------------------------

def _blas_info() -> dict:
    try:
        cfg = np.show_config(mode="dicts")
    except TypeError:  # numpy < 1.25: no mode argument
        return {"available": False}
    deps = (cfg or {}).get("Build Dependencies", {})
    return {k: deps[k] for k in ("blas", "lapack") if k in deps}


def machine_info() -> dict:
    """Plain data about the machine and the software that produced a timing."""
    import scipy

    from .. import __version__

    info = {
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "processor": platform.processor(),
        "python": sys.version.split()[0],
        "versions": {"morsuite": __version__, "numpy": np.__version__, "scipy": scipy.__version__},
        "threads_env": {k: os.environ.get(k) for k in THREAD_ENV_VARS},
        "blas": _blas_info(),
    }
    if hasattr(os, "sched_getaffinity"):
        info["cpus_usable"] = len(os.sched_getaffinity(0))
    try:
        info["load_average"] = list(os.getloadavg())
    except (AttributeError, OSError):
        pass
    return info


# ---------------------------------------------------------------------------
# running
# ---------------------------------------------------------------------------

def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, Path):
        return str(x)
    return str(x)


def _write_json(path: Path, data):
    text = json.dumps(data, indent=2, default=_json_default)
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text + "\n")


def _ratio_line(name, key, r) -> str:
    value, target = float(r["value"]), r.get("target")
    line = f"{name}: {key} = {value:.3f}"
    if target is not None:
        line += f" (target <= {target}) " + ("ok" if value <= target else "ABOVE TARGET")
    if r.get("what"):
        line += f"  [{r['what']}]"
    return line


def run(names=None, out_dir="results/bench", quick: bool = False, echo=print) -> dict:
    """Run benchmarks ``names`` (all when empty), write their JSON and a manifest.

    Returns ``{name: result}``. Unknown names raise :class:`OptionError`
    before anything runs.
    """
    avail = available()
    names = list(names or avail)
    unknown = [n for n in names if n not in BENCHMARKS]
    if unknown:
        raise OptionError(f"unknown benchmark {', '.join(map(repr, unknown))}; available: {', '.join(avail)}")
    out = Path(out_dir)
    results = {}
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")
    for name in names:
        t0 = time.perf_counter()
        res = dict(BENCHMARKS[name](bool(quick)))
        res.setdefault("benchmark", name)
        res["quick"] = bool(quick)
        res["wall_time_s"] = time.perf_counter() - t0
        res["finished"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
        for key, r in (res.get("ratios") or {}).items():
            if r.get("target") is not None:
                r["pass"] = bool(float(r["value"]) <= float(r["target"]))
            if echo:
                echo(_ratio_line(name, key, r))
        _write_json(out / f"{name}.json", res)
        results[name] = res
    manifest_path = out / "manifest.json"
    manifest = {}
    if manifest_path.is_file():  # keep entries of benchmarks not run this time
        try:
            manifest = json.loads(manifest_path.read_text())
        except (OSError, ValueError):
            manifest = {}
    entries = manifest.get("benchmarks", {}) if isinstance(manifest.get("benchmarks"), dict) else {}
    for name, res in results.items():
        entries[name] = {"file": f"{name}.json", "quick": res["quick"], "finished": res["finished"],
                         "wall_time_s": res["wall_time_s"],
                         "ratios": {k: {"value": r["value"], "target": r.get("target"), "pass": r.get("pass")}
                                    for k, r in (res.get("ratios") or {}).items()}}
    manifest = {"machine": machine_info(), "started": started, "benchmarks": entries}
    _write_json(manifest_path, manifest)
    return results


# ---------------------------------------------------------------------------
# benchmarks
# ---------------------------------------------------------------------------

def bare_lu_floor(fom, shifts, n_lu: int) -> float:
    """Seconds of ``n_lu`` bare LUs + 2 solves, measured at ``shifts`` (assembly not timed).

    If the shifts are fewer or more than ``n_lu`` (a perturbed or refactored shift),
    the mean per shift is scaled to ``n_lu``.
    """
    import scipy.sparse.linalg as spla

    solver = fom.new_solver(cache_size=0)
    rhs_r = np.vstack([fom.F, np.zeros((fom.n2, fom.m))])
    rhs_l = np.vstack([fom.L.T, np.zeros((fom.n2, fom.p))])
    total = 0.0
    for a in shifts:
        A = solver.matrix(a)
        t0 = time.perf_counter()
        lu = spla.splu(A, permc_spec=solver.permc_spec, diag_pivot_thresh=solver.diag_pivot_thresh)
        lu.solve(rhs_r.astype(A.dtype, copy=False))
        lu.solve(rhs_l.astype(A.dtype, copy=False), trans="T")
        total += time.perf_counter() - t0
    return total / max(len(shifts), 1) * n_lu


@benchmark("freqresp")
def bench_freqresp(quick: bool) -> dict:
    """Full-order frequency response of DSMS g = 6000 against the one-LU-per-frequency floor.

    The floor of a frequency is one ``scipy.sparse.linalg.splu`` of the
    pre-assembled (unscaled) saddle-point matrix with the solver's column
    ordering and pivot threshold, plus one solve with [F; 0]. The grid (500
    log-spaced frequencies in [1e-2, 1], 100 with ``quick``) is cut into chunks
    of 10; for each chunk the floor of its frequencies is timed and then
    ``fom.freqresp(chunk)``, so that load changes on this shared machine hit
    both alike (measured: timing the whole response and then the whole floor
    gave ratios anywhere from 1.1 to 1.7 in consecutive runs; interleaved
    chunks repeat to +-0.01). The per-call overhead of ``freqresp`` is thereby
    paid 50 times instead of once, against us. The block is repeated 3 times
    (once with ``quick``); the headline is the median.
    """
    from ..analysis import sigma_max
    from ..models import dsms
    import scipy.sparse.linalg as spla

    g, nfreq, repeats, chunk = 6000, (100 if quick else 500), (1 if quick else 3), 10
    fom = dsms(g)
    omega = np.logspace(-2, 0, nfreq)
    solver = fom.new_solver(cache_size=0)
    rhs = np.vstack([fom.F, np.zeros((fom.n2, fom.m))]).astype(complex)
    chunks = [omega[i:i + chunk] for i in range(0, nfreq, chunk)]
    pc = time.perf_counter

    fom.freqresp(omega[:3])  # warm-up: imports, first-call overheads
    blocks = []
    for _ in range(repeats):
        t_ours = t_floor = t_kernel = 0.0
        nnz = []
        agg = {"factorizations": 0, "solves": 0, "factor_time_s": 0.0, "solve_time_s": 0.0,
               "assemble_time_s": 0.0}
        for w in chunks:
            mats = [solver.matrix(1j * x) for x in w]  # assembly is not part of the floor
            t0 = pc()
            for A in mats:
                lu = spla.splu(A, permc_spec=solver.permc_spec, diag_pivot_thresh=solver.diag_pivot_thresh)
                lu.solve(rhs)
            t_floor += pc() - t0
            nnz.append(int(lu.nnz))
            # the solver's own kernel: the equilibrated, renumbered matrix with the reused
            # ordering (NATURAL), pre-assembled: what remains above it is overhead proper
            perm = solver._ordering()
            kmats = [solver._assemble_scaled(-x * x, 1j * x, 1.0, perm)[2] for x in w]
            t0 = pc()
            for A in kmats:
                lu = spla.splu(A, permc_spec="NATURAL" if perm else solver.permc_spec,
                               diag_pivot_thresh=solver.diag_pivot_thresh)
                lu.solve(rhs)
            t_kernel += pc() - t0
            t0 = pc()
            fom.freqresp(w)
            t_ours += pc() - t0
            for k in agg:
                agg[k] += fom.last_freqresp_stats[k]
        blocks.append({"freqresp_time_s": t_ours, "floor_time_s": t_floor, "ratio": t_ours / t_floor,
                       "kernel_floor_time_s": t_kernel, "ratio_to_kernel": t_ours / t_kernel,
                       "solver_stats": agg, "lu_nnz_median": int(np.median(nnz))})
    ratios = [b["ratio"] for b in blocks]
    best = blocks[int(np.argsort(ratios)[len(ratios) // 2])]  # the median block

    # memory in a separate pass: tracemalloc slows allocation-heavy code down
    tracemalloc.start()
    try:
        H = fom.freqresp(omega)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    try:
        import resource
        maxrss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    except ImportError:  # not on Windows
        maxrss_mb = None

    stats = best["solver_stats"]
    t_freqresp, t_floor = best["freqresp_time_s"], best["floor_time_s"]
    accounted = stats["factor_time_s"] + stats["solve_time_s"] + stats["assemble_time_s"]
    ratio = best["ratio"]
    return {
        "benchmark": "freqresp",
        "model": fom.name, "n1": fom.n1, "n2": fom.n2, "m": fom.m, "p": fom.p,
        "omega": {"lo": float(omega[0]), "hi": float(omega[-1]), "n": int(nfreq), "spacing": "log"},
        "floor_definition": (f"sum over the grid of scipy.sparse.linalg.splu(S(j w)) (permc_spec "
                             f"{solver.permc_spec}, diag_pivot_thresh {solver.diag_pivot_thresh}) + one solve "
                             f"with [F; 0]; S pre-assembled, unscaled; timed in chunks of {chunk} "
                             "frequencies interleaved with freqresp on the same chunk"),
        "repeats": repeats,
        "freqresp_time_s": t_freqresp,
        "floor_time_s": t_floor,
        "lu_nnz_median": best["lu_nnz_median"],
        "per_frequency_ms": {"freqresp": 1e3 * t_freqresp / nfreq, "floor splu+solve": 1e3 * t_floor / nfreq,
                             "solver factor (assembly + equilibration + LU)":
                                 1e3 * (stats["factor_time_s"] + stats["assemble_time_s"]) / nfreq,
                             "solver solve (incl. backward-error check)": 1e3 * stats["solve_time_s"] / nfreq},
        "freqresp_breakdown_s": {"factor": stats["factor_time_s"], "solve (incl. check)": stats["solve_time_s"],
                                 "assembly + equilibration": stats["assemble_time_s"],
                                 "other (L @ X, Python)": t_freqresp - accounted},
        "solver_stats": stats,
        "blocks": [{k: b[k] for k in ("freqresp_time_s", "floor_time_s", "ratio", "kernel_floor_time_s",
                                      "ratio_to_kernel")} for b in blocks],
        "memory": {"tracemalloc_peak_mb": peak / 2**20, "frequencies": int(nfreq),
                   "note": "tracemalloc sees Python and NumPy allocations; SuperLU's own factor "
                           "storage is malloc'd by SuperLU and not traced",
                   "process_max_rss_mb": maxrss_mb},
        "sigma_max_range": [float(np.min(sigma_max(H))), float(np.max(sigma_max(H)))],
        "ratios": {
            "freqresp_vs_lu_floor": {
                "value": ratio, "target": 1.3,
                "what": f"freqresp {t_freqresp:.2f} s / floor {t_floor:.2f} s ({nfreq} x splu + solve, "
                        f"interleaved), median of {repeats} blocks "
                        f"(all: {', '.join(f'{r:.3f}' for r in ratios)})"},
            "freqresp_vs_own_kernel": {
                "value": best["ratio_to_kernel"], "target": None,
                "what": f"same block, floor = the solver's own kernel: splu of the pre-assembled equilibrated "
                        f"matrix in the reused ordering (NATURAL) + solve ({best['kernel_floor_time_s']:.2f} s); "
                        "the rest is assembly, equilibration, the backward-error check and Python"},
        },
    }
