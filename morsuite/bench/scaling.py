r"""Benchmark ``scaling``: run time and peak memory against :math:`n_1`, with fitted exponents.

Cases, on ``dsms(g)`` (:math:`n_1 = g`) and ``tcom(nc)`` (:math:`n_1 = 3 n_c + 1`)
at :math:`n_1 \approx 10^3 \ldots 10^6` (:data:`SIZES`):

- ``irka``, ``bt``: ``reduce(20)`` of a fresh reducer (default options);
- ``freqresp``: the full response on 200 log-spaced frequencies of the band,
  one LU each (at :math:`n_1 > 5 \cdot 10^5` measured on every 5th frequency
  and scaled to 200);
- ``irka-projected``: the dense baseline on small sizes, up to where its memory
  guard (4 GiB) refuses.

Each case (:mod:`~morsuite.bench.scaling_case`) runs in its own process with a
time limit (2700 s) and an RSS watchdog (8 GiB) and records wall and CPU time,
the LU count (exponents are also fitted to the time per LU, which a changing
iteration count does not affect), the tracemalloc peak and the peak-RSS delta. The exponent :math:`p` of
:math:`t \sim n_1^p` is fitted by least squares of :math:`\log t` against
:math:`\log n_1` (:func:`fit_exponent`); target :math:`p \le 1.15` for ``irka``,
``bt`` and ``freqresp``. A task stops at the first size that does not finish.
``quick``: two small sizes per model, r = 6, 10 frequencies, in-process: seconds.

Writes ``scaling.json`` (through :func:`morsuite.bench.run`), ``scaling.csv/.md``
(one row per case), ``scaling_fits.csv/.md``, ``scaling.png`` and, while running,
``scaling.partial.json``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from . import benchmark
from ..errors import ShapeError
from ..utils import atomic_write_text
from .memory import MIB
from .output import code_state, new_figure, resolve_out_dir, rewrite_derived, save_png, write_table
from .scaling_case import derive_row, run_case, run_isolated

__all__ = ["bench_scaling", "fit_exponent", "rewrite", "write_outputs", "SIZES"]

#: sizes per model family: dsms g, tcom nc (nearest even to 333, 3333, ...: n1 = 3 nc + 1)
SIZES = {"dsms": (1_000, 10_000, 100_000, 1_000_000),
         "tcom": (334, 3_334, 33_334, 333_334)}


def fit_exponent(n, t) -> dict:
    r"""Least-squares fit :math:`\log t = p \log n + c`: the exponent p of :math:`t \sim n^p`.

    Non-finite or non-positive points are left out. Returns ``exponent``,
    ``prefactor`` (:math:`e^c`), ``points``, ``local_exponent`` (slope between
    the two largest n) and ``n_range``; NaN where fewer than two points remain.
    """
    n, t = np.asarray(n, dtype=float).ravel(), np.asarray(t, dtype=float).ravel()
    if n.shape != t.shape:
        raise ShapeError(f"fit_exponent: 'n' and 't' must have the same length; got {n.size} and {t.size}")
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
    def derive(res):
        res["rows"] = [derive_row(dict(r)) for r in res["rows"]]
        res["fits"] = _fits(res["rows"])
        res["ratios"] = _ratios(res["fits"])

    return rewrite_derived(out_dir, "scaling", derive, write_outputs)


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
        sq = 8.0 * n_all ** 2 / MIB
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
            row = run_isolated(case, plan["timeout_s"], plan["rss_limit_gib"])
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
