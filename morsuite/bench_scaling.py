r"""Benchmark "scaling": run time and peak memory against :math:`n_1`, with fitted exponents.

For the DSMS (``dsms(g)``, :math:`n_1 = g`) and the TCOM (``tcom(nc)``,
:math:`n_1 = 3 n_c + 1`) at :math:`n_1 \approx 10^3 \ldots 10^6` it measures

``irka``
    the projector-free IRKA at r = 20 (default options: the iteration count is
    the model's, so it may change with the size);
``bt``
    low-rank-ADI balanced truncation at r = 20 (default form: 20 first-order
    states), Gramians included;
``freqresp``
    the full-order response on 200 log-spaced frequencies of the model's band
    (on a subset of every k-th of them at the largest sizes, scaled to 200:
    the exponent is fitted to the time per frequency, which the scaling does
    not change);
``irka-projected``
    the explicit :math:`\Pi`-projected dense baseline, on small sizes up to
    where its memory guard (:class:`~morsuite.errors.MemoryBudgetError`) refuses.

Each case runs in its own process (``python -m morsuite.bench_scaling --case
JSON``) with a time limit and an RSS watchdog, so that one case cannot take
the machine's memory and so that its memory is measured from a clean state:

* ``tracemalloc_peak_mb``: Python/NumPy allocations during the task (SuperLU's
  factor storage is malloc'd in C and is invisible to tracemalloc);
* ``rss_delta_mb``: peak resident set size during the task minus the RSS just
  before it (the kernel's high-water mark is reset through
  ``/proc/self/clear_refs`` where Linux allows it; otherwise the lifetime
  ``ru_maxrss`` is used, which can only overstate the delta).

A dense :math:`n_1 \times n_1` float64 array would need :math:`8 n_1^2` bytes;
``peak_over_dense_square`` is the measured peak over that, so a value far
below 1 at large :math:`n_1` (and a memory exponent near 1) shows that no
such array was formed.

The fit is least squares of :math:`\log t` against :math:`\log n_1`
(:func:`fit_exponent`); the goal for ``irka``, ``bt`` and ``freqresp`` is an
exponent of at most 1.15. ``local_exponent`` is the slope between the two
largest sizes (the asymptotic trend; at 1e3 fixed per-call costs flatten the
curve). ``time_per_lu`` exponents remove the effect of an iteration count that
changes with the model.

This module also holds the small output helpers of the ``bench_*`` modules
(:func:`resolve_out_dir`, :func:`write_table`, :func:`save_png`,
:class:`MemoryProbe`).
"""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
import tempfile
import time
import tracemalloc
import warnings
from pathlib import Path

import numpy as np

from .bench import benchmark
from .utils import atomic_path, atomic_write_text

__all__ = ["bench_scaling", "run_case", "fit_exponent", "resolve_out_dir", "write_table", "save_png",
           "MemoryProbe", "SIZES", "write_readme", "code_state"]

_MIB = 2.0 ** 20

#: sizes per model family: dsms g, tcom nc (nearest even to 333, 3333, ...: n1 = 3 nc + 1)
SIZES = {"dsms": (1_000, 10_000, 100_000, 1_000_000),
         "tcom": (334, 3_334, 33_334, 333_334)}


# ---------------------------------------------------------------------------
# shared helpers of the bench_* modules
# ---------------------------------------------------------------------------

def fit_exponent(n, t) -> dict:
    r"""Least-squares fit :math:`\log t = p \log n + c`: the exponent p of :math:`t \sim n^p`.

    Non-finite or non-positive points are left out. Returns ``exponent``,
    ``prefactor`` (:math:`e^c`), ``points``, ``local_exponent`` (slope between
    the two largest n) and ``n_range``; NaN where fewer than two points remain.
    """
    n, t = np.asarray(n, dtype=float).ravel(), np.asarray(t, dtype=float).ravel()
    if n.shape != t.shape:
        raise ValueError(f"n and t must have the same length; got {n.size} and {t.size}")
    ok = np.isfinite(n) & np.isfinite(t) & (n > 0) & (t > 0)
    n, t = n[ok], t[ok]
    out = {"exponent": float("nan"), "prefactor": float("nan"), "points": int(n.size),
           "local_exponent": float("nan"), "n_range": [float(n.min()), float(n.max())] if n.size else []}
    if np.unique(n).size < 2:
        return out
    p, c = np.polyfit(np.log(n), np.log(t), 1)
    order = np.argsort(n)
    n2, t2 = n[order[-2:]], t[order[-2:]]
    out.update(exponent=float(p), prefactor=float(np.exp(c)),
               local_exponent=float(np.log(t2[1] / t2[0]) / np.log(n2[1] / n2[0])) if n2[1] > n2[0] else float("nan"))
    return out


def resolve_out_dir(out_dir=None) -> Path:
    """Where a benchmark writes its CSV, Markdown and PNG files.

    ``out_dir`` if given; else the ``out`` directory of the calling
    :func:`morsuite.bench.run` (found on the call stack: ``bench.run`` does
    not pass it to the benchmark functions); else ``$MORSUITE_BENCH_OUT``;
    else ``results/bench``.
    """
    if out_dir is not None:
        return Path(out_dir)
    from . import bench

    frame = sys._getframe(1)
    while frame is not None:
        if frame.f_code is bench.run.__code__ and "out" in frame.f_locals:
            return Path(frame.f_locals["out"])
        frame = frame.f_back
    return Path(os.environ.get("MORSUITE_BENCH_OUT") or "results/bench")


def write_table(df, stem, *, title: str = "", note: str = "", md_columns=None) -> list[Path]:
    """``stem``.csv (every column, full precision) and ``stem``.md (``md_columns``, 6 digits), atomically."""
    from .report.tables import to_markdown

    csv, md = Path(f"{stem}.csv"), Path(f"{stem}.md")
    atomic_write_text(csv, df.to_csv(index=False))
    shown = df[[c for c in md_columns if c in df]] if md_columns is not None else df
    head = (f"## {title}\n\n" if title else "") + (f"{note}\n\n" if note else "")
    atomic_write_text(md, head + to_markdown(shown))
    return [csv, md]


def new_figure(ncols: int = 1, width: float = 6.0, height: float = 4.2):
    """A matplotlib Figure on the Agg canvas (no pyplot state) and its axes."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width * ncols, height), layout="constrained")
    axes = fig.subplots(1, ncols, squeeze=False)[0]
    return fig, list(axes)


def save_png(fig, path) -> Path:
    """Write ``fig`` to ``path`` (PNG) atomically."""
    path = Path(path)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=130)
    return path


def _rss_bytes() -> int | None:
    try:
        import psutil

        return int(psutil.Process().memory_info().rss)
    except ImportError:
        try:
            with open("/proc/self/statm") as fh:
                return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
        except (OSError, ValueError):
            return None


def _hwm_bytes() -> int | None:
    """The kernel's peak RSS of this process (VmHWM), or ru_maxrss."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        import resource

        return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024
    except ImportError:  # pragma: no cover - not on Linux
        return None


def _reset_hwm() -> bool:
    """Reset the peak-RSS counter (Linux >= 4.0: write 5 to /proc/self/clear_refs)."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


class MemoryProbe:
    """Context manager: tracemalloc peak and peak-RSS delta of the code it wraps.

    Attributes after exit: ``traced_peak_mb``, ``rss_before_mb``,
    ``rss_peak_mb``, ``rss_delta_mb``, ``hwm_reset`` (False: the peak is the
    process's lifetime peak, so the delta is an upper bound).
    """

    def __init__(self, trace: bool = True):
        self.trace = trace

    def __enter__(self):
        gc.collect()
        self.hwm_reset = _reset_hwm()
        rss = _rss_bytes()
        self.rss_before_mb = rss / _MIB if rss is not None else float("nan")
        if self.trace:
            tracemalloc.start()
        return self

    def __exit__(self, *exc):
        if self.trace:
            self.traced_peak_mb = tracemalloc.get_traced_memory()[1] / _MIB
            tracemalloc.stop()
        else:
            self.traced_peak_mb = float("nan")
        hwm = _hwm_bytes()
        self.rss_peak_mb = hwm / _MIB if hwm is not None else float("nan")
        self.rss_delta_mb = max(self.rss_peak_mb - self.rss_before_mb, 0.0)
        return False

    def as_dict(self) -> dict:
        return {"tracemalloc_peak_mb": self.traced_peak_mb, "rss_before_mb": self.rss_before_mb,
                "rss_peak_mb": self.rss_peak_mb, "rss_delta_mb": self.rss_delta_mb,
                "rss_peak_reset": self.hwm_reset}


#: modules whose content decides the timings; hashed into every result (colleagues edit the
#: tree while benchmarks run: a result must say which code it measured)
_KEY_MODULES = ("linalg/saddle.py", "linalg/lradi.py", "linalg/dense.py", "linalg/orthonormal.py",
                "linalg/refine.py", "reducers/irka.py", "reducers/irka_engine.py", "reducers/shift_update.py",
                "reducers/irka_safeguards.py", "reducers/bt.py", "reducers/irka_projected.py", "reducers/base.py", "models/index3.py", "rom.py")


def code_state(git: bool = True) -> dict:
    """The code a measurement ran: git HEAD and dirty files (read-only git), and short SHA-256
    hashes of the modules that decide the timings (``digest`` combines them)."""
    import hashlib

    pkg = Path(__file__).resolve().parent
    hashes = {}
    for rel in _KEY_MODULES:
        try:
            hashes[rel] = hashlib.sha256((pkg / rel).read_bytes()).hexdigest()[:12]
        except OSError:
            hashes[rel] = None
    state = {"modules": hashes,
             "digest": hashlib.sha256(json.dumps(hashes, sort_keys=True).encode()).hexdigest()[:12]}
    if git:
        def _git(*args):
            try:
                out = subprocess.run(["git", *args], cwd=pkg.parent, capture_output=True, text=True, timeout=20)
                return out.stdout.strip() if out.returncode == 0 else None
            except (OSError, subprocess.SubprocessError):
                return None
        state["git_head"] = _git("rev-parse", "HEAD")
        dirty = _git("status", "--porcelain", "--", "morsuite")
        state["git_dirty"] = dirty.splitlines() if dirty else []
    return state


def _load_average():
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except (AttributeError, OSError):  # pragma: no cover
        return None


# ---------------------------------------------------------------------------
# one case
# ---------------------------------------------------------------------------

def _model(family: str, size: int):
    from . import models

    if family == "dsms":
        return models.dsms(int(size))
    if family == "tcom":
        return models.tcom(int(size))
    raise ValueError(f"unknown model family {family!r}; expected 'dsms' or 'tcom'")


def run_case(case: dict) -> dict:
    """Run one scaling case in this process; plain-data result.

    ``case``: ``model`` ("dsms" | "tcom"), ``size`` (g or nc), ``task``
    ("irka" | "bt" | "freqresp" | "irka-projected"), ``r``, ``nfreq`` (grid
    size of the response), ``nfreq_measured`` (frequencies actually solved,
    every k-th of the grid), ``options`` (reducer options), ``trace``
    (tracemalloc on).
    """
    from . import reducers
    from .analysis import freq_grid
    from .errors import MemoryBudgetError

    t0 = time.perf_counter()
    fom = _model(case["model"], case["size"])
    build = time.perf_counter() - t0
    task, r = case["task"], int(case.get("r", 20))
    row = {"model": case["model"], "size": int(case["size"]), "n1": fom.n1, "n2": fom.n2, "task": task,
           "r": r, "model_build_s": build, "load_average": _load_average(),
           "code_digest": code_state(git=False)["digest"],
           "dense_square_mb": 8.0 * fom.n1 ** 2 / _MIB}
    opts = dict(case.get("options") or {})
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
        except MemoryBudgetError as exc:
            status = "refused by memory guard"
            row["message"] = str(exc)
        except Exception as exc:  # a failure is a result too
            status = f"error: {type(exc).__name__}"
            row["message"] = str(exc)[:500]
    row["warnings"] = sorted({f"{w.category.__name__}: {str(w.message)[:160]}" for w in caught})[:8]
    row["status"] = status
    if status == "ok":
        row.update(probe.as_dict())
    _derive_row(row)
    if task == "irka-projected":
        from .reducers.irka_projected import memory_estimate

        row["memory_estimate_gib"] = memory_estimate(fom.n1, fom.n2)["peak_gib"]
    return row


def _derive_row(row: dict) -> dict:
    """Quantities computed from a case's measurements (also re-derived by :func:`rewrite`)."""
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


def _run_isolated(case: dict, timeout_s: float, rss_limit_gib: float) -> dict:
    """Run ``case`` in a child process with a time limit and an RSS watchdog."""
    cmd = [sys.executable, "-m", "morsuite.bench_scaling", "--case", json.dumps(case)]
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
        if line.startswith("MORSUITE_CASE_RESULT "):
            row = json.loads(line[len("MORSUITE_CASE_RESULT "):])
            row["process_wall_s"] = wall
            row["watchdog_peak_rss_mb"] = peak_seen / _MIB
            return row
    row = {"model": case["model"], "size": case["size"], "task": case["task"], "r": case.get("r"),
           "status": killed or f"error: child exited with code {proc.returncode}",
           "message": stderr[-500:], "process_wall_s": wall, "watchdog_peak_rss_mb": peak_seen / _MIB}
    return row


# ---------------------------------------------------------------------------
# the benchmark
# ---------------------------------------------------------------------------

def _plan(quick: bool) -> dict:
    if quick:
        return {"sizes": {"dsms": (300, 1_200), "tcom": (10, 24)},
                "tasks": ("irka", "bt", "freqresp"), "r": 6, "nfreq": 10, "nfreq_large": 10,
                "large_n1": 10 ** 9,
                "projected": {"dsms": (100, 200, 2_000)}, "projected_budget_gib": 0.1,
                "isolate": False, "timeout_s": 120.0, "rss_limit_gib": 8.0}
    return {"sizes": SIZES, "tasks": ("irka", "bt", "freqresp"), "r": 20, "nfreq": 200, "nfreq_large": 40,
            "large_n1": 500_000,
            "projected": {"dsms": (1_000, 2_000, 4_000, 10_000), "tcom": (334, 666, 3_334)},
            "projected_budget_gib": 4.0,
            "isolate": True, "timeout_s": 2700.0, "rss_limit_gib": 8.0}


def _cases(plan) -> list[dict]:
    cases = []
    for family, sizes in plan["sizes"].items():
        for task in plan["tasks"]:
            for size in sizes:
                n1 = size if family == "dsms" else 3 * size + 1
                c = {"model": family, "size": int(size), "task": task, "r": plan["r"]}
                if task == "freqresp":
                    c["nfreq"] = plan["nfreq"]
                    c["nfreq_measured"] = plan["nfreq_large"] if n1 > plan["large_n1"] else plan["nfreq"]
                cases.append(c)
    for family, sizes in plan["projected"].items():
        for size in sizes:
            cases.append({"model": family, "size": int(size), "task": "irka-projected", "r": plan["r"],
                          "options": {"memory_budget_gib": plan["projected_budget_gib"]}})
    # smallest sizes first across all tasks (stable: per task still ascending), so that a long
    # case at the largest size cannot hold back the trends at the smaller ones
    rank = {}
    for c in cases:
        rank.setdefault((c["model"], c["task"]), []).append(c["size"])
    return sorted(cases, key=lambda c: sorted(rank[(c["model"], c["task"])]).index(c["size"]))


def _fits(rows) -> list[dict]:
    import pandas as pd

    df = pd.DataFrame([r for r in rows if r.get("status") == "ok"])
    fits = []
    if df.empty:
        return fits
    for (model, task), g in df.groupby(["model", "task"], sort=False):
        g = g.sort_values("n1")
        rec = {"model": model, "task": task, "sizes": int(len(g)), "n1_max": int(g["n1"].max())}
        for key, col in (("time", "time_s"), ("cpu", "cpu_s"), ("time_per_lu", "time_per_lu_s"),
                         ("cpu_per_lu", "cpu_per_lu_s"),
                         ("tracemalloc", "tracemalloc_peak_mb"), ("rss_delta", "rss_delta_mb")):
            if col in g:
                f = fit_exponent(g["n1"], g[col])
                rec[f"{key}_exponent"] = f["exponent"]
                rec[f"{key}_local_exponent"] = f["local_exponent"]
        big = g.iloc[-1]
        rec.update(time_at_max_s=float(big["time_s"]), cpu_at_max_s=float(big.get("cpu_s", np.nan)),
                   tracemalloc_at_max_mb=float(big["tracemalloc_peak_mb"]),
                   rss_delta_at_max_mb=float(big["rss_delta_mb"]))
        fits.append(rec)
    return fits


def _ratios(fits) -> dict:
    ratios = {}
    for f in fits:
        target = None if f["task"] == "irka-projected" else 1.15
        for kind, label in (("time", "wall time"), ("cpu", "CPU time")):
            v = f.get(f"{kind}_exponent")
            if v is None or not np.isfinite(v):
                continue
            ratios[f"exponent {f['model']} {f['task']} ({'wall' if kind == 'time' else 'cpu'})"] = {
                "value": v, "target": target,
                "what": f"least-squares exponent of {label} ~ n1^p over {f['sizes']} sizes up to n1 = "
                        f"{f['n1_max']} (slope between the two largest sizes {f[f'{kind}_local_exponent']:.2f}; "
                        f"per LU {f.get(f'{kind}_per_lu_exponent', float('nan')):.2f})"}
    return ratios


def rewrite(out_dir="results/bench") -> list[Path]:
    """Re-derive rows, fits and ratios of ``out_dir``/scaling.json with this code and rewrite it and
    the CSV, Markdown and PNG files (the measurements are not repeated)."""
    from .bench import _write_json

    out = Path(out_dir)
    res = json.loads((out / "scaling.json").read_text())
    res["rows"] = [_derive_row(dict(r)) for r in res["rows"]]
    res["fits"] = _fits(res["rows"])
    res["ratios"] = _ratios(res["fits"])
    files = write_outputs(res, out)
    res["files"] = [str(p) for p in files]
    _write_json(out / "scaling.json", res)
    return files


def _figure(rows, fits, path):
    fig, (ax_t, ax_m) = new_figure(ncols=2)
    ok = [r for r in rows if r.get("status") == "ok"]
    fitd = {(f["model"], f["task"]): f for f in fits}
    markers = {"irka": "o", "bt": "s", "freqresp": "^", "irka-projected": "D"}
    colors = {"dsms": "C0", "tcom": "C3"}
    for (model, task) in sorted({(r["model"], r["task"]) for r in ok}):
        pts = sorted((r["n1"], r["time_s"], r["tracemalloc_peak_mb"], r["rss_delta_mb"], r.get("cpu_s", np.nan))
                     for r in ok if r["model"] == model and r["task"] == task)
        n = np.array([p[0] for p in pts], float)
        f = fitd.get((model, task), {})
        ls = "--" if task == "irka-projected" else "-"
        lab = f"{model} {task}"
        if np.isfinite(f.get("cpu_exponent", np.nan)):
            lab += f" (p = {f['cpu_exponent']:.2f} CPU, {f['time_exponent']:.2f} wall)"
        ax_t.plot(n, [p[4] for p in pts], ls, marker=markers.get(task, "x"), color=colors.get(model), label=lab)
        ax_t.plot(n, [p[1] for p in pts], ":", marker=markers.get(task, "x"), color=colors.get(model), alpha=0.5,
                  markerfacecolor="none")
        lab_m = f"{model} {task}"
        if np.isfinite(f.get("tracemalloc_exponent", np.nan)):
            lab_m += f" (p = {f['tracemalloc_exponent']:.2f})"
        ax_m.plot(n, [p[2] for p in pts], ls, marker=markers.get(task, "x"), color=colors.get(model), label=lab_m)
        ax_m.plot(n, [max(p[3], 1e-3) for p in pts], ":", marker=markers.get(task, "x"), color=colors.get(model),
                  alpha=0.5, markerfacecolor="none")
    if ok:
        n_all = np.array(sorted({r["n1"] for r in ok}), float)
        for ax, ref in ((ax_t, np.nanmin([r.get("cpu_s", np.nan) for r in ok])),
                        (ax_m, min(max(r["tracemalloc_peak_mb"], 1e-3) for r in ok))):
            ax.plot(n_all, ref * n_all / n_all[0], color="0.6", lw=0.8, label="slope 1")
        sq = 8.0 * n_all ** 2 / _MIB
        ax_m.plot(n_all, sq, color="k", lw=0.8, ls="-.", label=r"one dense $n_1\times n_1$ array")
    for ax in (ax_t, ax_m):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(r"$n_1$")
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=6.5)
    ax_t.set_ylabel("time [s] (freqresp: 200 frequencies)")
    ax_m.set_ylabel("peak memory [MiB]")
    ax_t.set_title("CPU time (solid, p) and wall time (dotted) against size", fontsize=10)
    ax_m.set_title("peak memory: tracemalloc (solid, p), RSS delta (dotted)", fontsize=10)
    return save_png(fig, path)


_TABLE_COLS = ["model", "task", "size", "n1", "status", "r", "r_used", "states", "converged", "iterations",
               "lu_count", "time_s", "cpu_s", "time_per_lu_s", "cpu_per_lu_s", "nfreq_measured", "scaled", "tracemalloc_peak_mb",
               "rss_delta_mb", "peak_over_dense_square", "model_build_s"]


def write_outputs(result: dict, out_dir) -> list[Path]:
    """scaling.csv/.md (one row per case), scaling_fits.csv/.md and scaling.png."""
    import pandas as pd

    out = Path(out_dir)
    rows = result["rows"]
    df = pd.DataFrame(rows)
    cols = [c for c in _TABLE_COLS if c in df] + [c for c in df if c not in _TABLE_COLS]
    files = write_table(df[cols] if not df.empty else df, out / "scaling",
                        title="scaling: time and peak memory against n1",
                        note=result.get("note", ""), md_columns=_TABLE_COLS)
    fits = pd.DataFrame(result["fits"])
    files += write_table(fits, out / "scaling_fits", title="scaling: fitted exponents (t ~ n1^p)",
                         note="least squares of log(y) against log(n1) over all sizes reached; "
                              "local = slope between the two largest sizes")
    files.append(_figure(rows, result["fits"], out / "scaling.png"))
    return files


def bench_scaling(quick: bool = False, out_dir=None, *, plan: dict | None = None, echo=print) -> dict:
    """Time and peak memory of irka, bt (r = 20) and the full response against n1 up to 1e6."""
    plan = dict(plan or _plan(quick))
    out = resolve_out_dir(out_dir)
    code_start = code_state()
    rows = []
    stopped = set()
    for case in _cases(plan):
        key = (case["model"], case["task"])
        if key in stopped:
            rows.append({**{k: case[k] for k in ("model", "size", "task", "r")},
                         "status": "skipped: a smaller size of this task did not finish"})
            continue
        if plan["isolate"]:
            row = _run_isolated(case, plan["timeout_s"], plan["rss_limit_gib"])
        else:
            row = run_case(case)
        rows.append(row)
        if row["status"] != "ok":
            stopped.add(key)
        if echo:
            echo(f"scaling: {case['model']:<5} {case['task']:<15} size {case['size']:>8} n1 "
                 f"{row.get('n1', '?'):>8}: {row['status']}"
                 + (f", {row['time_s']:.3g} s, traced {row['tracemalloc_peak_mb']:.1f} MiB, RSS +"
                    f"{row['rss_delta_mb']:.1f} MiB" if row["status"] == "ok" else ""), flush=True)
        # partial results survive an interrupted run
        atomic_write_text(out / "scaling.partial.json", json.dumps(rows, indent=1, default=str) + "\n")
    fits = _fits(rows)
    ratios = _ratios(fits)
    note = ("time_s: wall time of reduce(r) (reducers) or of the response on nfreq frequencies (freqresp: "
            "measured on nfreq_measured of them, every k-th of the grid, and scaled when 'scaled'); memory "
            "from the same run: tracemalloc peak (NumPy/Python; SuperLU is invisible to it) and peak RSS "
            "delta; peak_over_dense_square = max(tracemalloc, RSS delta) / (8 n1^2 bytes).")
    result = {"plan": {k: (v if not isinstance(v, dict) else {kk: list(vv) if isinstance(vv, tuple) else vv
                                                               for kk, vv in v.items()})
                       for k, v in plan.items()},
              "code": code_state(), "code_start": code_start,
              "code_digests_of_cases": sorted({r.get("code_digest") for r in rows if r.get("code_digest")}),
              "rows": rows, "fits": fits, "ratios": ratios, "note": note}
    files = write_outputs(result, out)
    result["files"] = [str(p) for p in files]
    try:
        (out / "scaling.partial.json").unlink()
    except OSError:
        pass
    return result


@benchmark("scaling")
def _registered(quick: bool) -> dict:
    """Time and peak memory against n1 (1e3 ... 1e6) for irka, bt and the full response; fitted exponents."""
    return bench_scaling(quick, resolve_out_dir())


# ---------------------------------------------------------------------------
# results/bench/README.md: every benchmark JSON present, one compact table each
# ---------------------------------------------------------------------------

def _fmt(x, digits=3) -> str:
    if x is None:
        return ""
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (float, np.floating)):
        return "" if not np.isfinite(x) else f"{x:.{digits}g}"
    return str(x).replace("|", "\\|").replace("\n", " ")


def _md(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(_fmt(v) for v in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def _ratio_table(res) -> str:
    rat = res.get("ratios") or {}
    if not rat:
        return "_no ratios_\n"
    rows = []
    for k, r in rat.items():
        t = r.get("target")
        ok = None if t is None else bool(float(r["value"]) <= float(t))
        rows.append((k, r.get("value"), t, "" if ok is None else ("pass" if ok else "ABOVE TARGET"),
                     r.get("what", "")))
    return _md(("ratio", "value", "target", "verdict", "what"), rows)


def _section_pareto(res) -> str:
    out = ["Verdicts on the paper's claim (IRKA more accurate and faster than BT), standalone times, matched on "
           "equal first-order states or on equal r:\n\n",
           _md(("model", "against", "matched on", "pairs", "IRKA more accurate", "BT more accurate", "ties",
                "IRKA faster", "BT faster", "claim holds", "median time irka/bt", "median error irka/bt"),
               [(v["model"], v["against"], v.get("matched_on", "states"), v["pairs"], v["irka_more_accurate"],
                 v["other_more_accurate"],
                 v["accuracy_ties"], v["irka_faster"], v["other_faster"], v["claim_holds"],
                 v.get("median_time_ratio"), v.get("median_error_ratio")) for v in res.get("verdicts", [])])]
    fl = res.get("floor") or []
    if fl:
        groups = list(fl[0]["profile"]["groups_s"])
        out += ["\nFloor at r = 20 (ratio = time / (LUs x one LU with its solves)) and where the time goes "
                "(shares of the profiled run):\n\n",
                _md(("model", "method", "LUs", "time [s]", "one LU [ms]", "ratio", *groups),
                    [(x["model"], x["method"], x["lu_count"], x["time_s"], 1e3 * x["lu_floor_s"], x["ratio"],
                      *[x["profile"]["groups_s"][g] / max(x["profile"]["total_s"], 1e-300) for g in groups])
                     for x in fl])]
    return "".join(out)


def _section_scaling(res) -> str:
    fits = res.get("fits") or []
    out = ["Exponents p of t ~ n1^p (least squares over all sizes; 'top' = slope between the two largest "
           "sizes); CPU time is the robust one on a shared machine:\n\n",
           _md(("model", "task", "sizes", "largest n1", "p wall", "p CPU", "top p CPU", "p CPU per LU",
                "p tracemalloc", "p RSS delta", "wall at largest [s]", "CPU at largest [s]",
                "tracemalloc at largest [MiB]", "RSS delta at largest [MiB]"),
               [(f["model"], f["task"], f["sizes"], f["n1_max"], f.get("time_exponent"), f.get("cpu_exponent"),
                 f.get("cpu_local_exponent"), f.get("cpu_per_lu_exponent"), f.get("tracemalloc_exponent"),
                 f.get("rss_delta_exponent"), f.get("time_at_max_s"), f.get("cpu_at_max_s"),
                 f.get("tracemalloc_at_max_mb"), f.get("rss_delta_at_max_mb"))
                for f in fits])]
    bad = [r for r in res.get("rows", []) if r.get("status") != "ok"]
    if bad:
        out.append("\nCases that did not finish:\n\n" + _md(("model", "task", "size", "status"),
                                                              [(r["model"], r["task"], r["size"], r["status"])
                                                               for r in bad]))
    return "".join(out)


def _section_peers(res) -> str:
    if not (res.get("pymor") or {}).get("available", True):
        return f"pyMOR not run: {res['pymor'].get('reason')}\n"
    return f"pyMOR {res['pymor'].get('version')}; ratios ours/theirs (below 1: morsuite better):\n\n" + _md(("model", "r", "peer", "ours", "status", "time ours/theirs", "error ours/theirs",
                "their time [s]", "our time [s]", "their error", "our error"),
               [(x["model"], x["r"], x["peer"], x["ours"], x["status"], x.get("time_ratio"), x.get("error_ratio"),
                 x.get("peer_time_s"), x.get("ours_time_s"), x.get("peer_error"), x.get("ours_error"))
                for x in res.get("rows", [])])


def _section_rows(res, keys) -> str:
    rows = [r for r in res.get("rows", []) if isinstance(r, dict)]
    keys = [k for k in keys if any(k in r for r in rows)]
    if not rows or not keys:
        return ""
    return _md(keys, [[r.get(k) for k in keys] for r in rows])


_SECTIONS = {"pareto": _section_pareto, "scaling": _section_scaling, "peers": _section_peers,
             "irka": lambda res: _section_rows(res, ("model", "r_requested", "r", "converged", "iterations",
                                                     "lu_count", "time_s", "floor_s", "ratio", "ratios_all")),
             "projected": lambda res: _section_rows(res, ("g", "n1", "r", "iterations", "time_projected_s",
                                                          "time_irka_s", "ratio", "ratio_per_iteration")),
             "bt": lambda res: _section_rows(res, ("model", "run", "time_s", "lu_count", "floor_s", "ratio",
                                                   "ratios"))}


_OWN_TABLES = ("pareto", "scaling", "peers")


def write_readme(out_dir="results/bench") -> Path:
    """``out_dir``/README.md: one compact section per benchmark JSON found there (any author)."""
    out = Path(out_dir)
    manifest = {}
    if (out / "manifest.json").is_file():
        try:
            manifest = json.loads((out / "manifest.json").read_text())
        except ValueError:
            manifest = {}
    m = manifest.get("machine", {})
    lines = ["# Benchmark results\n",
             "Written by `python -m morsuite.bench_scaling --readme DIR` from the JSON files in this folder "
             "(`morsuite bench NAME --out DIR` writes them). Every figure is a ratio or a trend measured in "
             "one run on one machine; lower ratios are better, `value <= target` passes.\n",
             f"Machine (manifest of the last `morsuite bench` run): {m.get('cpu_count')} CPUs "
             f"({m.get('cpus_usable')} usable), {m.get('platform')}, Python {m.get('python')}, "
             f"versions {m.get('versions')}, load average then {m.get('load_average')}. The machine is shared: "
             f"timings carry the load of other processes; ratios measured within one process are the robust "
             f"figures.\n"]
    files = sorted(p for p in out.glob("*.json") if p.name != "manifest.json" and ".partial" not in p.name)
    for path in files:
        try:
            res = json.loads(path.read_text())
        except ValueError as exc:
            lines.append(f"## {path.stem}\n\nunreadable: {exc}\n")
            continue
        name = res.get("benchmark", path.stem)
        head = (f"## {name}\n\n`{path.name}`, finished {res.get('finished', '?')}, "
                f"{'quick' if res.get('quick') else 'full'} run, {_fmt(res.get('wall_time_s'))} s.")
        extra = sorted(p.name for p in out.glob(f"{path.stem}*") if p.suffix in (".csv", ".md", ".png"))
        if extra:
            head += " Files: " + ", ".join(f"`{e}`" for e in extra) + "."
        code = res.get("code")
        if code:
            head += (f" Code: git {str(code.get('git_head'))[:10]}, module digest {code.get('digest')}"
                     + (f", uncommitted: {', '.join(x.split()[-1] for x in code.get('git_dirty', []))}"
                        if code.get("git_dirty") else "") + ".")
            starts = {(res.get("code_start") or {}).get("digest"), code.get("digest"),
                      *res.get("code_digests_of_cases", [])} - {None}
            if len(starts) > 1:
                head += (f" **The timed modules changed during the run** (digests {', '.join(sorted(starts))}): "
                         f"colleagues edited the tree meanwhile.")
        else:
            head += " Code state not recorded."
        lines.append(head + "\n")
        if name not in _OWN_TABLES:  # the pareto, scaling and peers tables below hold their ratios
            lines.append(_ratio_table(res))
        else:
            rat = res.get("ratios") or {}
            bad = sum(1 for r in rat.values() if r.get("target") is not None
                      and not float(r["value"]) <= float(r["target"]))
            lines.append(f"{len(rat)} ratios in `{path.name}`, {bad} above their target.\n")
        section = _SECTIONS.get(name)
        if section is not None:
            try:
                body = section(res)
            except (KeyError, TypeError, ValueError) as exc:  # another author's layout changed
                body = f"_(details not summarised: {type(exc).__name__}: {exc})_\n"
            if body:
                lines.append("\n" + body)
        lines.append("")
    path = out / "README.md"
    atomic_write_text(path, "\n".join(lines))
    return path


def _main(argv=None):  # pragma: no cover - the child process of _run_isolated, and --readme
    import argparse

    ap = argparse.ArgumentParser(prog="python -m morsuite.bench_scaling")
    ap.add_argument("--case", help="JSON of one case (see run_case); prints its result")
    ap.add_argument("--readme", metavar="DIR", help="write DIR/README.md summarising the benchmark JSONs in DIR")
    args = ap.parse_args(argv)
    if args.readme:
        print(write_readme(args.readme))
    if args.case:
        row = run_case(json.loads(args.case))
        print("MORSUITE_CASE_RESULT " + json.dumps(row, default=str), flush=True)


if __name__ == "__main__":  # pragma: no cover
    _main()
