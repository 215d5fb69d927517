"""Files of the ``pareto`` benchmark: its tables (CSV and Markdown) and figures (PNG).

:func:`write_outputs` writes, from the plain-data result of
:func:`~morsuite.bench.pareto.bench_pareto`, ``pareto.csv/.md`` (one row per
reduction), ``pareto_pairs.csv/.md`` and ``pareto_verdict.csv/.md`` (IRKA against
BT), ``pareto_soh2.csv/.md`` (so-h2 against second-order BT), ``pareto_floor.csv/.md``
and ``pareto_floor.png`` (each run against its LU floor, and where its time goes), and
``pareto_MODEL.png`` (time against error).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .output import new_figure, save_png, write_table

__all__ = ["write_outputs"]


_COLORS = {"irka": "C0", "bt": "C3", "bt-vv": "C1", "irka-projected": "C2", "irka-fo": "C4", "so-h2": "C5"}
_MARKERS = {"irka": "o", "bt": "s", "bt-vv": "v", "irka-projected": "D", "irka-fo": "^", "so-h2": "P"}


def _pareto_figure(spec, rows, summaries, methods, path):
    """``methods``: the result's ``{label: {"order": what r means, ...}}``, in drawing order."""
    fig, (ax,) = new_figure()
    for label in methods:
        pts = sorted(((x["time_standalone_s"], x["max_abs_error"], x["r_requested"], x["states_nominal"])
                      for x in rows if x["model"] == spec and x["method"] == label and x.get("status") == "ok"),
                     key=lambda p: p[3])
        if not pts:
            continue
        t = np.array([p[0] for p in pts])
        e = np.maximum(np.array([p[1] for p in pts]), 1e-300)
        ax.plot(t, e, "-", lw=0.7, marker=_MARKERS[label], ms=4, color=_COLORS[label],
                label=f"{label}: {methods[label].get('order', '')}")
        for p in pts[:: max(1, len(pts) // 5)]:
            ax.annotate(f"{p[3]}", (p[0], max(p[1], 1e-300)), fontsize=6, color=_COLORS[label],
                        xytext=(3, 2), textcoords="offset points")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time of the reduction from scratch [s] (BT: Gramians included)")
    ax.set_ylabel(r"$\max_\omega \sigma_{\max}(T - T_r)$ on the frequency grid")
    summ = [s for s in summaries if s["model"] == spec]
    rs = [x["r_requested"] for x in rows if x["model"] == spec and "r_requested" in x]
    title = (f"{spec}: time against error, r = {min(rs, default=0)}..{max(rs, default=0)} "
             f"(labels: first-order states asked for)")
    ax.set_title(title, fontsize=9)
    if summ:
        txt = "\n".join(f"vs {s['against']}: IRKA more accurate {s['irka_more_accurate']}/{s['pairs']}, "
                        f"faster {s['irka_faster']}/{s['pairs']}, both {s['claim_holds']}/{s['pairs']}"
                        for s in summ)
        ax.text(0.01, 0.01, txt, transform=ax.transAxes, fontsize=6.5, va="bottom")
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=6.5, loc="upper right")
    return save_png(fig, path)


def _floor_figure(floor_rows, path):
    from matplotlib import colormaps

    fig, (ax,) = new_figure(width=10.0, height=4.6)
    labels = [f"{x['model']}\n{x['method']}" for x in floor_rows]
    names = list(floor_rows[0]["profile"]["categories_s"]) if floor_rows else []
    cmap = colormaps["tab20"]
    bottom = np.zeros(len(floor_rows))
    for j, name in enumerate(names):
        frac = np.array([x["profile"]["categories_s"][name] / max(x["profile"]["total_s"], 1e-300)
                         for x in floor_rows])
        ax.bar(range(len(floor_rows)), frac, bottom=bottom, label=name if len(name) < 70 else name[:67] + "...",
               color=cmap(j % 20), width=0.7)
        bottom += frac
    for i, x in enumerate(floor_rows):
        ax.text(i, 1.01, f"ratio {x['ratio']:.2f}", ha="center", fontsize=7)
    ax.set_xticks(range(len(floor_rows)), labels, fontsize=7)
    ax.set_ylim(0, 1.1)
    ax.set_ylabel("share of the profiled run")
    ax.set_title("where the time goes; ratio = time / (LUs x one LU with its solves)", fontsize=9)
    fig.legend(loc="outside right upper", fontsize=6.5)
    return save_png(fig, path)


def _slug(spec: str) -> str:
    return spec.replace(":", "_").replace("=", "").replace(",", "_")


def write_outputs(result: dict, out_dir) -> list[Path]:
    """Every table and figure of a pareto result into ``out_dir``; returns the paths."""
    import pandas as pd

    out = Path(out_dir)
    files = []
    rows = pd.DataFrame(result["rows"])
    cols = ["model", "method", "r_requested", "r", "states", "states_nominal", "status", "converged",
            "reducer_status", "stable", "iterations", "lu_count", "lu_count_shared", "lu_count_standalone", "time_s",
            "time_standalone_s", "max_abs_error", "max_rel_error", "worse_than_zero", "error_bound", "warnings"]
    files += write_table(rows[[c for c in cols if c in rows]], out / "pareto",
                         title="pareto: wall time against max abs error",
                         note=result["note"], md_columns=cols)
    pairs = pd.DataFrame(result["pairs"])
    if not pairs.empty:
        files += write_table(pairs, out / "pareto_pairs", title="pareto: IRKA against BT at equal state counts",
                             note="times: standalone (BT with its Gramians); error: max abs over the grid")
    soh2 = pd.DataFrame(result.get("so_h2") or [])
    if not soh2.empty:
        files += write_table(soh2, out / "pareto_soh2",
                             title="pareto: so-h2 against second-order BT (bt-vv) at equal r",
                             note="times and LUs standalone (Gramians included; so-h2 also its starts: the BT "
                                  "levels and the paper's IRKA); error: max abs over the grid; so_h2_h2_error: its "
                                  "exact H2 error")
    summ = pd.DataFrame(result["verdicts"])
    files += write_table(summ, out / "pareto_verdict", title="pareto: the paper's claim, as measured",
                         md_columns=["model", "against", "matched_on", "pairs", "irka_more_accurate", "other_more_accurate",
                                     "accuracy_ties", "irka_faster", "other_faster", "claim_holds",
                                     "median_time_ratio", "median_error_ratio", "verdict"])
    if result["floor"]:
        flat = []
        for x in result["floor"]:
            rec = {k: v for k, v in x.items() if k not in ("time_breakdown", "floor", "profile")}
            tot = max(x["profile"]["total_s"], 1e-300)
            for g, v in x["profile"]["groups_s"].items():
                rec[f"share {g}"] = v / tot
            for c, v in x["profile"]["categories_s"].items():
                rec[f"cat {c}"] = v / tot
            flat.append(rec)
        fdf = pd.DataFrame(flat)
        md = ["model", "method", "r_used", "converged", "iterations", "lu_count", "time_s", "lu_floor_s",
              "ratio", "ratio_via_solver", "profile_overhead"] + [c for c in fdf if c.startswith("share ")]
        files += write_table(fdf, out / "pareto_floor", title="pareto: each run against its LU floor (r = 20)",
                             note="ratio = time_s / (lu_count x median(one splu + right solve + transposed solve "
                                  "at the run's shifts)); shares: fractions of the profiled repeat (StackProfiler: time "
                                  "charged to the first category with a function on the call stack)",
                             md_columns=md)
        files.append(_floor_figure(result["floor"], out / "pareto_floor.png"))
    for spec in dict.fromkeys(x["model"] for x in result["rows"]):
        # the methods travel in the result (pareto.json): this module does not import the benchmark
        methods = result.get("methods") or {m: {} for m in dict.fromkeys(x["method"] for x in result["rows"])}
        files.append(_pareto_figure(spec, result["rows"], result["verdicts"], methods,
                                    out / f"pareto_{_slug(spec)}.png"))
    return files
