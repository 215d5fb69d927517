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


def build_parser():
    parser = argparse.ArgumentParser(prog="morsuite", description="Model reduction of second-order index-3 systems.")
    sub = parser.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("info", help="summary of a model")
    p.add_argument("model", help="catalog spec (dsms:g=6000) or .mat/.npz path")
    p.set_defaults(func=cmd_info)
    p = sub.add_parser("list", help="available models and reducers")
    p.set_defaults(func=cmd_list)
    p = sub.add_parser("reduce", help="reduce one model, print errors and timing")
    p.add_argument("--model", required=True, help="catalog spec (dsms:g=6000) or .mat/.npz path")
    p.add_argument("--method", required=True, help="reducer name (see `morsuite list`)")
    p.add_argument("--r", required=True, type=int, help="reduced order")
    p.add_argument("--omega", type=_omega_arg, help="frequency grid LO:HI:N (rad/s, log-spaced)")
    p.add_argument("--option", action="append", metavar="KEY=VALUE", help="reducer option (repeatable)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_reduce)
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
