"""Command line: ``morsuite run | reduce | list | info | bench``."""

from __future__ import annotations

import argparse
import json
import sys
import warnings


def _omega_arg(text):
    try:
        lo, hi, n = text.split(":")
        return float(lo), float(hi), int(n)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--omega must be LO:HI:N, got {text!r}") from exc


def _option_value(text):
    from .models.catalog import _value
    return _value(text)


def cmd_reduce(args) -> int:
    """Reduce one model with one method; print one JSON object."""
    import numpy as np

    from . import analysis, models, reducers

    fom = models.parse(args.model)
    opts = {}
    for item in args.option or []:
        key, eq, val = item.partition("=")
        if not eq:
            raise SystemExit(f"--option expects KEY=VALUE, got {item!r}")
        opts[key] = _option_value(val)
    lo, hi, n = args.omega if args.omega else (*fom.band, 200)
    omega = np.logspace(np.log10(lo), np.log10(hi), n)
    with warnings.catch_warnings():
        if args.json:
            warnings.simplefilter("ignore")  # they are recorded in info["warnings"]
        res = reducers.make(args.method, fom, **opts).reduce(args.r)
    df = analysis.errors(fom, res.rom, omega)
    info = res.info
    out = {"model": args.model, "method": args.method, "r": info["r"], "r_requested": info["r_requested"],
           "states": info["states"], "converged": info["converged"], "iterations": info["iterations"],
           "stable": info["stable"], "time_s": info["time_s"], "lu_count": info.get("lu_count"),
           "max_abs_error": float(df.abs_error.max()), "max_rel_error": float(df.rel_error.max()),
           "omega": [lo, hi, n], "warnings": info["warnings"]}
    if args.json:
        print(json.dumps(out))
    else:
        for k, v in out.items():
            print(f"{k:>14}: {v}")
    return 0


def cmd_info(args) -> int:
    from . import models
    print(json.dumps(models.parse(args.model).summary(), indent=2))
    return 0


def cmd_list(args) -> int:
    from . import models, reducers
    print("models:   " + ", ".join(models.available()))
    print("reducers: " + ", ".join(reducers.available()))
    return 0


def _add_bench_parser(sub):
    """``morsuite bench [NAME ...] [--out DIR] [--quick] [--list]`` (see morsuite.bench)."""

    def cmd_bench(args) -> int:
        from . import bench
        if args.list:
            for name in bench.available():
                print(f"{name:<16} {bench.describe(name)}")
            return 0
        bench.run(args.names, out_dir=args.out, quick=args.quick)
        return 0

    p = sub.add_parser("bench", help="run benchmarks against their measured floor")
    p.add_argument("names", nargs="*", metavar="NAME", help="benchmarks to run (default: all)")
    p.add_argument("--out", default="results/bench", metavar="DIR",
                   help="output directory for NAME.json and manifest.json (default: results/bench)")
    p.add_argument("--quick", action="store_true", help="smaller grids, for a smoke test")
    p.add_argument("--list", action="store_true", help="list the benchmarks and exit")
    p.set_defaults(func=cmd_bench)
    return p


def _add_run_parser(sub):
    """``morsuite run SPEC [SPEC ...] [--out DIR] [--jobs N | --scheduler ADDR] [--cache DIR]
    [--no-cache] [--rerender] [--quiet] [--dry-run]`` (see morsuite.studies)."""

    def cmd_run(args) -> int:
        from pathlib import Path

        from .studies import build_plan, load_spec, run
        from .studies.cache import Cache
        from .studies.memo import SpecMemo

        cache = Cache(args.cache or Path(args.out) / ".cache", read=not args.no_cache)
        memo = SpecMemo(cache)  # validated models/methods: a cached study builds no model
        studies = [load_spec(path, memo=memo) for path in args.specs]  # every spec is valid before anything runs
        for study in studies:
            if args.dry_run:
                print(f"{study.name} ({study.path}): {len(study.scenes)} scenes; would compute")
                print("  " + "\n  ".join(build_plan(study).describe()))
                continue
            run(study, out=args.out, cache_dir=args.cache, use_cache=not args.no_cache, jobs=args.jobs,
                scheduler=args.scheduler, quiet=args.quiet, rerender=args.rerender)
        return 0

    p = sub.add_parser("run", help="run study specs (TOML): figures, tables, manifest in OUT/NAME/")
    p.add_argument("specs", nargs="+", metavar="SPEC", help="study spec files, e.g. studies/paper_*.toml")
    p.add_argument("--out", default="results", metavar="DIR", help="results root (default: results)")
    p.add_argument("--jobs", type=int, default=1, metavar="N",
                   help="local worker processes (default 1: Dask's synchronous scheduler, cleanest timings)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="dask.distributed scheduler, e.g. tcp://HOST:8786")
    p.add_argument("--cache", metavar="DIR", help="artifact cache (default: OUT/.cache)")
    p.add_argument("--no-cache", action="store_true", help="recompute everything (fresh entries replace the cache)")
    p.add_argument("--rerender", action="store_true",
                   help="draw every figure and write every table again, also those whose data did not change "
                        "(default: reuse them; files whose bytes come out the same are never rewritten)")
    p.add_argument("--quiet", action="store_true", help="no progress bars or log lines")
    p.add_argument("--dry-run", action="store_true", help="validate the specs and print what would be computed")
    p.set_defaults(func=cmd_run)
    return p


MODEL_HELP = "catalog spec (dsms:g=6000) or a path: .mat, .npz, a Matrix Market set (directory or stem)"


def build_parser():
    parser = argparse.ArgumentParser(prog="morsuite", description="Model reduction of second-order index-3 systems.")
    sub = parser.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("info", help="summary of a model")
    p.add_argument("model", help=MODEL_HELP)
    p.set_defaults(func=cmd_info)
    p = sub.add_parser("list", help="available models and reducers")
    p.set_defaults(func=cmd_list)
    p = sub.add_parser("reduce", help="reduce one model, print errors and timing")
    p.add_argument("--model", required=True, help=MODEL_HELP)
    p.add_argument("--method", required=True, help="reducer name (see `morsuite list`)")
    p.add_argument("--r", required=True, type=int, help="reduced order")
    p.add_argument("--omega", type=_omega_arg, help="frequency grid LO:HI:N (rad/s, log-spaced)")
    p.add_argument("--option", action="append", metavar="KEY=VALUE", help="reducer option (repeatable)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_reduce)
    _add_bench_parser(sub)
    _add_run_parser(sub)
    return parser, sub


def main(argv=None):
    parser, _ = build_parser()
    args = parser.parse_args(argv)
    from .errors import MorsuiteError
    try:
        return args.func(args)
    except MorsuiteError as exc:
        print(f"morsuite: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
