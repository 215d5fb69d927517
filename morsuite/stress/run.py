"""Stress runner: random constrained models, invariant checks, outcome classes.

``python -m morsuite.stress --cases N --out DIR`` draws N seeded cases
(:func:`~morsuite.stress.cases.draw_case`), runs one invariant check per case
(:func:`check_case`) with BLAS limited to one thread, and writes
``DIR/summary.csv`` and ``DIR/summary.md`` atomically (the CSV also every
``--progress`` cases, so partial results survive a kill). Exit status 1 if
any case failed silently.

Options (defaults): ``--cases`` (200), ``--seed`` master seed (0), ``--out``
(``results/stress``), ``--families`` (all of
:data:`~morsuite.stress.cases.FAMILIES`), ``--case INDEX`` (run and print one
case only), ``--progress`` (100; 0: never), ``--refused-table`` (print the
Markdown table of refused inputs, :mod:`morsuite.stress.refused`, and exit)
with ``--data-dir`` (the directory of its .mat file; default: the checkout's
``tests/data``).

Cost: dominated by the reference responses (one sparse LU per frequency of a
60-point grid) and the reductions; 0.36 s per case on average over the
2000-case run (n1 <= 300, 2 shared cores).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections import Counter
from dataclasses import asdict
from pathlib import Path

import numpy as np

from .cases import FAMILIES, Case, draw_case, given_shifts, regime, runner_options
from .checks import check_bt_bound, check_nullspace, check_reduction
from .outcomes import Outcome, attribute_silent, known_bug
from .replay import check_agreement, check_g_invariance
from .report import csv_text, summary_markdown

__all__ = ["check_case", "run_case", "main"]


def check_case(case: Case, fom=None) -> Outcome:
    """The invariant check of one case (deterministic: its random state comes from ``case.seed``)."""
    from .. import reducers
    from ..models import random_constrained

    if case.method not in reducers.available():
        return Outcome("skipped", f"reducer {case.method!r} is not registered")
    rng = np.random.default_rng(case.seed)
    fom = random_constrained(**case.model) if fom is None else fom
    r = min(case.r, fom.order)
    if case.family == "reduce":
        return check_reduction(fom, case.method, r, runner_options(case.method))
    if case.family == "agreement":
        return check_agreement(fom, r, case.maxit, given_shifts(fom, r, rng))
    if case.family == "nullspace":
        lo, hi = fom.band
        ws = 10 ** rng.uniform(np.log10(lo), np.log10(hi), 3)
        return check_nullspace(fom, [1j * ws[0], complex(ws[1], ws[2]), complex(ws[2], 0.0)])
    if case.family == "g-invariance":
        return check_g_invariance(fom, r, rng, maxit=case.maxit)
    if case.family == "bt-bound":
        return check_bt_bound(fom, r)
    raise ValueError(f"unknown family {case.family!r}")


def run_case(case: Case) -> dict:
    """Run one case; a plain-data row for the CSV (with the known bug a failure is attributed to)."""
    from ..models import random_constrained

    t0 = time.perf_counter()
    row = {"index": case.index, "seed": case.seed, "family": case.family, "method": case.method, "r": case.r,
           "maxit": case.maxit, "regime": regime(case.model), "model": json.dumps(case.model, sort_keys=True)}
    bug = ""
    try:
        fom = random_constrained(**case.model)
        row["r"] = min(case.r, fom.order)
        out = check_case(case, fom)
        if out.outcome == "FAIL-silent":
            bug = attribute_silent(lambda: check_case(case))  # a fresh model: no cached LUs
        elif out.outcome == "FAIL-undocumented":
            kb = known_bug(out)
            bug = kb.key if kb else ""
    except Exception as exc:  # noqa: BLE001 - a crash of the check itself is a failure to report
        out = Outcome("FAIL-undocumented", f"check crashed: {type(exc).__name__}: {str(exc)[:200]}",
                      type(exc).__name__)
    row.update(outcome=out.outcome, error_class=out.error_class, known_bug=bug,
               detail=out.detail.replace("\n", " "),
               metrics=json.dumps(_finite_json(out.metrics), sort_keys=True), time_s=round(time.perf_counter() - t0, 4))
    return row


def _finite_json(d):
    """``d`` with numpy scalars as Python numbers and non-finite floats as strings (JSON-safe)."""
    out = {}
    for k, v in d.items():
        if isinstance(v, (float, np.floating)):
            v = float(v)
            out[k] = v if math.isfinite(v) else str(v)
        elif isinstance(v, (np.integer,)):
            out[k] = int(v)
        elif isinstance(v, (np.bool_,)):
            out[k] = bool(v)
        else:
            out[k] = v
    return out


def main(argv=None) -> int:
    """The command line (see the module docstring); returns the exit status."""
    p = argparse.ArgumentParser(prog="python -m morsuite.stress", description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", type=int, default=200, help="number of random cases")
    p.add_argument("--seed", type=int, default=0, help="master seed")
    p.add_argument("--out", default="results/stress", help="output directory (summary.md, summary.csv)")
    p.add_argument("--families", default=",".join(FAMILIES), help="comma-separated check families")
    p.add_argument("--case", type=int, default=None, help="run only this case index and print it")
    p.add_argument("--progress", type=int, default=100, help="print a progress line every N cases (0: never)")
    p.add_argument("--refused-table", action="store_true",
                   help="print the Markdown table of refused inputs (docs/design/refused.md) and exit")
    p.add_argument("--data-dir", default=None, help="with --refused-table: the directory of "
                   "mess_msd_ind3_g600.mat (default: the checkout's tests/data)")
    args = p.parse_args(argv)
    if args.refused_table:
        from .refused import markdown_table

        print(markdown_table(args.data_dir))
        return 0
    args.n1_min, args.n1_max = 20, 300
    fams = [f.strip() for f in args.families.split(",") if f.strip()]
    bad = [f for f in fams if f not in FAMILIES]
    if bad or args.cases < 1:
        p.error(f"unknown families {bad}; valid: {', '.join(FAMILIES)}" if bad else "--cases must be >= 1")
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        if args.case is not None:
            case = draw_case(args.case, args.seed, fams)
            print(json.dumps(asdict(case)))
            print(json.dumps(run_case(case), indent=1))
            return 0
        from ..utils import atomic_write_text

        out = Path(args.out)
        rows, t0 = [], time.perf_counter()
        for i in range(args.cases):
            rows.append(run_case(draw_case(i, args.seed, fams)))
            if args.progress and (i + 1) % args.progress == 0:
                c = Counter(r["outcome"] for r in rows)
                print(f"[{i + 1}/{args.cases}] {time.perf_counter() - t0:.0f} s {dict(c)}", flush=True)
                atomic_write_text(out / "summary.csv", csv_text(rows))  # partial results survive a kill
        elapsed = time.perf_counter() - t0
        atomic_write_text(out / "summary.csv", csv_text(rows))
        atomic_write_text(out / "summary.md", summary_markdown(rows, args=args, elapsed=elapsed))
    silent = sum(1 for r in rows if r["outcome"] == "FAIL-silent")
    print(f"{len(rows)} cases in {elapsed:.0f} s: {dict(Counter(r['outcome'] for r in rows))}")
    return 1 if silent else 0
