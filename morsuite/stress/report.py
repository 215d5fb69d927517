"""The stress run's summary: ``summary.csv`` (one row per case) and ``summary.md``.

``summary.md`` counts outcomes by check family, by method (reduce family) and
by model regime, groups the refusals and failures by a reason with numbers
blanked out, and lists the known bugs and a verdict. Plain text work, linear
in the number of cases.
"""

from __future__ import annotations

import csv
import io
import json
import re
from collections import Counter, defaultdict

from .cases import FAMILIES, RUNNER_MAXIT
from .outcomes import KNOWN_BUGS, OUTCOMES

__all__ = ["CSV_FIELDS", "csv_text", "summary_markdown"]


CSV_FIELDS = ["index", "seed", "family", "method", "r", "maxit", "regime", "outcome", "error_class", "known_bug", "detail",
              "metrics", "time_s", "model"]


def csv_text(rows) -> str:
    """The CSV text of the case rows (columns :data:`CSV_FIELDS`)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_FIELDS, extrasaction="ignore")
    w.writeheader()
    for row in rows:
        w.writerow(row)
    return buf.getvalue()


def _short_reason(row):
    d = row["detail"]
    if row["outcome"] == "refused-spurious":
        return "SingularShiftError at a well-conditioned shift (pivot test not scale-invariant)"
    if row["outcome"] == "refused":
        d = re.sub(r"s = [-+0-9.ej ]+", "s = ...", d)
        d = re.sub(r"\d+(\.\d+)?(e[-+]?\d+)?", "#", d)
        return d[:110]
    if row["outcome"].startswith("FAIL"):
        d = re.sub(r"\d+(\.\d+)?(e[-+]?\d+)?", "#", d)
        return d[:140]
    return ""


def _table(rows, key, title):
    lines = ["", f"## {title}", "", f"| {key} | cases | " + " | ".join(OUTCOMES) + " |",
             "|---|---:|" + "---:|" * len(OUTCOMES)]
    groups = defaultdict(Counter)
    for r in rows:
        groups[r[key]][r["outcome"]] += 1
    order = sorted(groups, key=lambda g: (FAMILIES.index(g) if g in FAMILIES else 99, g))
    for g in order:
        c = groups[g]
        lines.append(f"| {g} | {sum(c.values())} | " + " | ".join(str(c.get(o, 0)) for o in OUTCOMES) + " |")
    return lines


def summary_markdown(rows, *, args, elapsed) -> str:
    """The Markdown summary of the case rows; ``args`` are the runner's parsed options."""
    tot = Counter(r["outcome"] for r in rows)
    lines = ["# Stress run summary", "",
             f"`python -m morsuite.stress --cases {args.cases} --seed {args.seed} --out {args.out}`: "
             f"{len(rows)} random constrained models (`ms.models.random_constrained`, n1 in {args.n1_min}..{args.n1_max}, "
             f"r in 1..12), one invariant check each, IRKA capped at maxit = {RUNNER_MAXIT} in the reduce family; "
             f"{elapsed:.0f} s wall time on a shared 2-core machine. Per-case rows (model parameters, outcome, "
             "detail, metrics) are in `summary.csv`; any case reruns with "
             f"`python -m morsuite.stress --case INDEX --seed {args.seed}`.", "",
             "Outcome classes: **pass**; **not-converged** (converged=False with a ConvergenceWarning, every other "
             "invariant holding); **refused** (a documented MorsuiteError); **refused-spurious** (a "
             "SingularShiftError at a shift where the equilibrated saddle-point matrix is well conditioned: loud "
             "and documented, but wrong); **FAIL-undocumented** (an exception that is not a MorsuiteError); "
             "**FAIL-silent** (NaN, a violated invariant, or a missing warning); **skipped** (the case needs a reducer "
             "that is not registered). Tolerances are relative and "
             "scaled by the condition of the Ruiz-equilibrated saddle-point matrix (and of the reduced pencil "
             "for ROM comparisons); see `docs/design/stress.md`.", ""]
    lines += _table(rows, "family", "Outcomes by check family")
    lines.append(f"| **all** | {len(rows)} | " + " | ".join(str(tot.get(o, 0)) for o in OUTCOMES) + " |")
    lines += _table([r for r in rows if r["family"] == "reduce"], "method", "Reduce family by method")
    lines += _table(rows, "regime", "Outcomes by model regime (damping / conditioning)")
    div = [r for r in rows if r["family"] in ("agreement", "g-invariance") and r["outcome"] == "pass"]
    ndiv = 0
    for r in div:
        m = json.loads(r["metrics"] or "{}")
        td, tol = m.get("trajectory_diff"), m.get("tol")
        if isinstance(td, (int, float)) and isinstance(tol, (int, float)) and td > tol:
            ndiv += 1
    lines += ["", f"Of the {len(div)} passing agreement/g-invariance cases, {ndiv} had whole IRKA trajectories "
              "that drifted apart after the first shift update (the ROMs built from the same shifts agreed; "
              "the update's selection steps amplify roundoff): recorded, not a failure.", ""]
    refused = Counter((r["outcome"], r["error_class"], _short_reason(r)) for r in rows
                      if r["outcome"] in ("refused", "refused-spurious"))
    lines += ["## Why cases were refused", ""]
    if refused:
        lines += ["| outcome | class | reason | cases |", "|---|---|---|---:|"]
        for (o, cls, why), n in refused.most_common():
            lines.append(f"| {o} | {cls} | {why.replace('|', '/')} | {n} |")
    else:
        lines.append("No case was refused.")
    fails = [r for r in rows if r["outcome"].startswith("FAIL")]
    lines += ["", "## Failures", ""]
    if fails:
        groups = defaultdict(list)
        for r in fails:
            groups[(r["outcome"], r.get("known_bug", ""), r["error_class"], _short_reason(r))].append(int(r["index"]))
        lines += ["| outcome | known bug | class | reason | cases | first case |", "|---|---|---|---|---:|---:|"]
        for (o, kb, cls, why), idx in sorted(groups.items(), key=lambda kv: -len(kv[1])):
            lines.append(f"| {o} | {kb or 'NEW'} | {cls} | {why.replace('|', '/')} | {len(idx)} | {min(idx)} |")
    else:
        lines.append("None.")
    lines += ["", "## Known bugs (reproducers in tests/stress/test_known_bugs.py)", "",
              "| key | cases | what |", "|---|---:|---|"]
    kc = Counter(r.get("known_bug", "") for r in fails)
    for bug in KNOWN_BUGS:
        lines.append(f"| {bug.key} | {kc.get(bug.key, 0)} | {bug.summary} |")
    silent = [r for r in fails if r["outcome"] == "FAIL-silent"]
    new_silent = [r for r in silent if not r.get("known_bug")]
    undoc = [r for r in fails if r["outcome"] == "FAIL-undocumented"]
    lines += ["", "## Verdict", "",
              f"- silent failures (FAIL-silent): {len(silent)}, of which {len(silent) - len(new_silent)} pass when "
              f"the saddle-point matrix is equilibrated (known bug K1) and {len(new_silent)} are unexplained;",
              f"- undocumented exceptions (FAIL-undocumented): {len(undoc)}, of which "
              f"{sum(1 for r in undoc if r.get('known_bug'))} match known bugs K2-K6;",
              f"- spurious refusals: {tot.get('refused-spurious', 0)};",
              f"- every other case ({tot.get('pass', 0) + tot.get('not-converged', 0) + tot.get('refused', 0)}) passed "
              "its invariants, ended in a documented error, or returned converged=False with a ConvergenceWarning.",
              ""]
    return "\n".join(lines)
