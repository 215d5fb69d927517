"""``results/bench/README.md``: one compact section per benchmark JSON found in a folder.

:func:`write_readme` reads every ``NAME.json`` (any author; ``manifest.json`` and
partial files excepted) and writes, per benchmark, when and from which code it ran,
its ratios against their targets and a short table of its rows (pareto, scaling,
peers, irka, projected, bt have their own). Command line:
``python -m morsuite.bench --readme DIR``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..utils import atomic_write_text

__all__ = ["write_readme"]


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
                                                   "ratios")),
             "rslab-ldlt": lambda res: _section_rows(res, ("model", "n1", "t_ldlt", "t_lu", "ldlt_over_lu",
                                                           "factor_nnz", "berr")),
             "solve-accuracy": lambda res: _section_rows(res, ("model", "n1", "frequencies", "t_target", "t_before",
                                                               "target_over_before", "median_ratio",
                                                               "refinement_steps", "backward_error_max"))}


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
             "Written by `python -m morsuite.bench --readme DIR` from the JSON files in this folder "
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
