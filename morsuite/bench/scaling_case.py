r"""One case of the ``scaling`` benchmark: a reduction or a full response, its time and memory.

:func:`run_case` runs one case in this process: ``model`` ("dsms" | "tcom" | "fem_block") at
``size`` (g, nc or n1), ``task`` ("irka" | "bt" | "freqresp" | "irka-projected"),
``r``, ``nfreq``, ``nfreq_measured``, ``options``, ``trace``, ``warm`` (the compiled kernels
loaded before the timer; default False: a fresh process's first call pays them). It records wall
and CPU time, the LU count, and the memory of :class:`~morsuite.bench.memory.MemoryProbe`
against the :math:`8 n_1^2` bytes of one dense :math:`n_1 \times n_1` array
(``peak_over_dense_square``), the process's lifetime peak RSS (``process_maxrss_mb``) and,
for a reduction, its ``time_breakdown`` and size-dependent choices (``compress_tol``,
``stage_stall``, ``update_switch_reasons``, ``factor_ranks``, where its info has them). A failure, or the memory guard of
``irka-projected`` refusing, is a result.

:func:`run_isolated` runs a case in a child process (``python -m morsuite.bench
--case JSON``) with a time limit and an RSS watchdog, so that one case cannot take
the machine's memory and its memory is measured from a clean state.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
import warnings

import numpy as np

from ..errors import MemoryBudgetError, OptionError
from ..utils import load_average
from .memory import MIB, MemoryProbe
from .output import code_state

__all__ = ["run_case", "run_isolated", "derive_row", "CASE_RESULT_TAG"]

#: the line of the child's stdout that carries its result
CASE_RESULT_TAG = "MORSUITE_CASE_RESULT "



def _maxrss_mb():
    try:
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux
    except ImportError:  # pragma: no cover - not on Linux
        return None


def _model(family: str, size: int):
    from .. import models

    if family == "dsms":
        return models.dsms(int(size))
    if family == "tcom":
        return models.tcom(int(size))
    if family == "fem_block":
        return models.fem_block(int(size))
    raise OptionError(f"scaling case: unknown 'model' {family!r}; expected 'dsms', 'tcom' or 'fem_block'")


def run_case(case: dict) -> dict:
    """Run one scaling case in this process; plain-data result.

    ``case``: ``model`` ("dsms" | "tcom" | "fem_block"), ``size`` (g, nc or n1), ``task``
    ("freqresp" or a reducer's name: "irka", "bt", "irka-projected", "irka-fo", ...), ``r``, ``nfreq`` (grid
    size of the response), ``nfreq_measured`` (frequencies actually solved,
    every k-th of the grid), ``options`` (reducer options), ``trace``
    (tracemalloc on), ``warm`` (the kernels loaded before the timer).
    """
    from .. import reducers
    from ..analysis import freq_grid

    t0 = time.perf_counter()
    fom = _model(case["model"], case["size"])
    build = time.perf_counter() - t0
    task, r = case["task"], int(case.get("r", 20))
    row = {"model": case["model"], "size": int(case["size"]), "n1": fom.n1, "n2": fom.n2, "task": task,
           "r": r, "model_build_s": build, "load_average": load_average(),
           "code_digest": code_state(git=False)["digest"],
           "dense_square_mb": 8.0 * fom.n1 ** 2 / MIB}
    opts = dict(case.get("options") or {})
    if case.get("warm"):  # the compiled kernels loaded (or compiled) before the timer, as a reducer's own time_s
        from ..linalg.warmup import warm_kernels
        warm_kernels()
    probe = MemoryProbe(trace=bool(case.get("trace", True)))
    status, info = "ok", {}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            if task == "freqresp":
                nfreq = int(case.get("nfreq", 200))
                omega = freq_grid(fom.band, nfreq)
                k = int(case.get("nfreq_measured") or nfreq)
                step = max(1, int(round(nfreq / k)))
                sub = omega[::step]
                with probe:
                    t1, c1 = time.perf_counter(), time.process_time()
                    H = fom.freqresp(sub)
                    elapsed, cpu = time.perf_counter() - t1, time.process_time() - c1
                row.update(nfreq=nfreq, nfreq_measured=int(sub.size), time_per_freq_s=elapsed / sub.size,
                           time_s=elapsed * nfreq / sub.size, time_measured_s=elapsed,
                           cpu_s=cpu * nfreq / sub.size,
                           scaled=bool(sub.size < nfreq), lu_count=int(nfreq),  # LUs that time_s stands for
                           finite=bool(np.all(np.isfinite(H))))
            else:
                red = reducers.make(task, fom, **opts)  # irka-projected's guard may refuse here
                with probe:
                    t1, c1 = time.perf_counter(), time.process_time()
                    res = red.reduce(r)
                    elapsed, cpu = time.perf_counter() - t1, time.process_time() - c1
                info = res.info
                row.update(time_s=elapsed, cpu_s=cpu, reducer_time_s=info["time_s"], lu_count=info.get("lu_count"),
                           iterations=info.get("iterations"), converged=info.get("converged"),
                           r_used=info.get("r"), states=info.get("states"), stable=info.get("stable"))
                # per-phase times and the size-dependent choices the reducer made (recorded in its info)
                row.update(time_breakdown=info.get("time_breakdown"),
                           **{k: info[k] for k in ("compress_tol", "stage_stall", "update_switch_reasons",
                                                   "factor_ranks") if k in info})
                if isinstance(info.get("adi"), dict):  # LR-ADI's columns made and compressions, per equation
                    row.update({f"adi_{k}": {eq: a.get(k) for eq, a in info["adi"].items()}
                                for k in ("columns", "compressions")})
        except MemoryBudgetError as exc:
            status = "refused by memory guard"
            row["message"] = str(exc)
        except Exception as exc:  # a failure is a result too
            status = f"error: {type(exc).__name__}"
            row["message"] = str(exc)[:500]
    row["process_maxrss_mb"] = _maxrss_mb()  # this process's lifetime peak RSS (the model build included)
    row["warnings"] = sorted({f"{w.category.__name__}: {str(w.message)[:160]}" for w in caught})[:8]
    row["status"] = status
    if status == "ok":
        row.update(probe.as_dict())
    derive_row(row)
    if task == "irka-projected":
        from ..reducers.irka.projected import memory_estimate

        row["memory_estimate_gib"] = memory_estimate(fom.n1, fom.n2)["peak_gib"]
    return row


def derive_row(row: dict) -> dict:
    """Quantities computed from a case's measurements (also re-derived by ``scaling.rewrite``)."""
    if row.get("status") != "ok":
        return row
    peak = np.nanmax([row.get("tracemalloc_peak_mb", np.nan), row.get("rss_delta_mb", np.nan)])
    row["peak_over_dense_square"] = float(peak / row["dense_square_mb"]) if row.get("dense_square_mb") else None
    lus = row.get("nfreq") if row.get("task") == "freqresp" else row.get("lu_count")
    if lus:
        row["lu_count"] = int(lus)
        row["time_per_lu_s"] = row["time_s"] / lus
        if row.get("cpu_s") is not None:
            row["cpu_per_lu_s"] = row["cpu_s"] / lus
    return row


def run_isolated(case: dict, timeout_s: float, rss_limit_gib: float) -> dict:
    """Run ``case`` in a child process with a time limit and an RSS watchdog."""
    cmd = [sys.executable, "-m", "morsuite.bench", "--case", json.dumps(case)]
    try:
        import psutil
    except ImportError:  # pragma: no cover
        psutil = None
    limit = rss_limit_gib * 2 ** 30
    t0 = time.perf_counter()
    peak_seen = 0
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen(cmd, stdout=out, stderr=err, text=True)
        killed = None
        handle = psutil.Process(proc.pid) if psutil else None
        while proc.poll() is None:
            time.sleep(0.25)
            if handle is not None:
                try:
                    rss = handle.memory_info().rss
                    peak_seen = max(peak_seen, rss)
                    if rss > limit:
                        killed = f"killed: RSS {rss / 2**30:.2f} GiB above the limit {rss_limit_gib:g} GiB"
                except psutil.Error:
                    pass
            if time.perf_counter() - t0 > timeout_s:
                killed = f"timeout: killed after {timeout_s:.0f} s"
            if killed:
                proc.kill()
                proc.wait()
                break
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read(), err.read()
    wall = time.perf_counter() - t0
    for line in stdout.splitlines()[::-1]:
        if line.startswith(CASE_RESULT_TAG):
            row = json.loads(line[len(CASE_RESULT_TAG):])
            row["process_wall_s"] = wall
            row["watchdog_peak_rss_mb"] = peak_seen / MIB
            return row
    row = {"model": case["model"], "size": case["size"], "task": case["task"], "r": case.get("r"),
           "status": killed or f"error: child exited with code {proc.returncode}",
           "message": stderr[-500:], "process_wall_s": wall, "watchdog_peak_rss_mb": peak_seen / MIB}
    return row
