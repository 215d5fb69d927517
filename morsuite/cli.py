"""Command line: ``morsuite run | compare | reduce | verify | simulate | list | info | bench``."""

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


def _options(args) -> dict:
    """The reducer options of ``--option KEY=VALUE`` (repeatable)."""
    opts = {}
    for item in args.option or []:
        key, eq, val = item.partition("=")
        if not eq:
            raise SystemExit(f"--option expects KEY=VALUE or GROUP.KEY=VALUE, got {item!r}")
        group, dot, sub = key.partition(".")
        if dot:  # an advanced option in its group (morsuite.reducers.options)
            opts.setdefault(group, {})[sub] = _option_value(val)
        else:
            opts[key] = _option_value(val)
    return opts


def _reduced(args):
    """(fom, Reduction) of ``--model``, ``--method``, ``--r``, ``--option``; the reducer's warnings are
    recorded in ``info["warnings"]`` (and not printed under ``--json``)."""
    from . import models, reducers

    fom = models.parse(args.model)
    opts = _options(args)
    with warnings.catch_warnings():
        if args.json:
            warnings.simplefilter("ignore")  # they are recorded in info["warnings"]
        res = reducers.make(args.method, fom, **opts).reduce(args.r)
    return fom, res


def _print(out: dict, as_json: bool):
    if as_json:
        from .utils import strict_json
        print(json.dumps(strict_json(out)))
    else:
        for k, v in out.items():
            print(f"{k:>20}: {v}")


def cmd_reduce(args) -> int:
    """Reduce one model with one method; print one JSON object (band errors and, unless --no-norms,
    the H2 errors and the Hinf error's lower and, where certified, upper bound; ``status``,
    ``lu_count_shared`` and ``worse_than_zero``, the norms in which the reduced model's error is at or
    above the full model's own norm, :func:`morsuite.analysis.worse_than_zero`; ``rigid_modes``, the
    model's rigid-body modes, 0 for a supported model: with k > 0 the reduced model carries them
    exactly and the norms are the flexible part's, :mod:`morsuite.models.rigid`)."""
    import numpy as np

    from . import analysis

    fom, res = _reduced(args)
    lo, hi, n = args.omega if args.omega else (*fom.band, 200)
    omega = np.logspace(np.log10(lo), np.log10(hi), n)
    df = analysis.errors(fom, res.rom, omega)
    info = res.info
    out = {"model": args.model, "method": args.method, "r": info["r"], "r_requested": info["r_requested"],
           "states": info["states"], "converged": info["converged"], "status": info.get("status"),
           "iterations": info["iterations"], "stable": info["stable"], "time_s": info["time_s"],
           "lu_count": info.get("lu_count"), "lu_count_shared": info.get("lu_count_shared"),
           "max_abs_error": float(df.abs_error.max()), "max_rel_error": float(df.rel_error.max()),
           "omega": [lo, hi, n], "rigid_modes": (info.get("rigid_modes") or {}).get("count", 0)}
    # hinf_error is the peak found (a lower bound); hinf_upper_bound / hinf_certified: its level-set certificate
    keys = ("h2_error", "h2_rel_error", "hinf_error", "hinf_rel_error", "h2_route", "h2_trusted", "hinf_route",
            "hinf_peak_frequency", "hinf_upper_bound", "hinf_certified", "h2_lu_count", "hinf_lu_count", "h2_time_s",
            "hinf_time_s")
    warned = list(info["warnings"])
    if args.no_norms:
        out.update(dict.fromkeys(keys))
    else:
        with warnings.catch_warnings():
            if args.json:
                warnings.simplefilter("ignore")  # recorded in norm_warnings
            norms = analysis.error_norms(fom, res.rom)
        out.update({k: norms.get(k) for k in keys})
        warned += norms["norm_warnings"]
    # the norms in which the reduced model is no better than T_r = 0 (utils.worse_than_zero)
    out["worse_than_zero"] = analysis.worse_than_zero(
        band=(out["max_abs_error"], float(df.sigma_full.max())),
        h2=(out["h2_rel_error"], 1.0), hinf=(out["hinf_rel_error"], 1.0))
    out["warnings"] = warned
    if args.save:
        out["saved"] = _save(args, fom, res, out, None if args.no_norms else norms, float(df.sigma_full.max()))
    _print(out, args.json)
    return 0


def _save(args, fom, res, out, norms, peak) -> list[str]:
    """``reduce --save``: the reduced model's files and sidecar, with the errors as the command computed them."""
    from .romfiles import ERROR_KEYS, provenance_of, save_rom

    errs = {"max_abs_error": out["max_abs_error"], "max_rel_error": out["max_rel_error"], "band_peak": peak}
    if norms is None:
        errs["norms"] = "not computed (--no-norms)"
    else:
        errs.update({k: v for k, v in norms.items() if k in ERROR_KEYS})
    prov = provenance_of(fom, args.method, _options(args), res.info, errs, grid=tuple(out["omega"]), source=args.model)
    return [str(p) for p in save_rom(res.rom, args.save, provenance=prov)]


def cmd_verify(args) -> int:
    """``morsuite verify MODEL ROMFILE``: compute again the errors recorded in a saved reduced model's sidecar
    (:func:`morsuite.analysis.verify.verify_rom`); print a table (or one JSON object with ``--json``);
    exit 0 when every recorded value agrees within its stated accuracy, 1 when one does not (named)."""
    from . import models
    from .analysis.verify import table_lines, verify_rom
    from .romfiles import load_rom

    rom = load_rom(args.romfile)
    fom = models.parse(args.model)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = verify_rom(fom, rom, norms=not args.no_norms)
    result["warnings"] = [f"{w.category.__name__}: {w.message}" for w in caught] + result.pop("norm_warnings")
    result.update(model=args.model, romfile=args.romfile)
    if args.json:
        _print(result, True)
    else:
        for w in result["warnings"]:
            print(f"warning: {w}", file=sys.stderr)
        print("\n".join(table_lines(result)))
    if not result["agrees"]:
        print(f"morsuite verify: {', '.join(result['failed'])} disagree", file=sys.stderr)
        return 1
    return 0


def cmd_simulate(args) -> int:
    """Reduce, then simulate the full and the reduced model for one input; print the output errors
    (``worse_than_zero`` names ``max_output`` / ``l2_output`` when the output error is at or above
    the output itself)."""
    from .analysis import output_errors, worse_than_zero
    from .analysis.compare import time_input, time_response

    fom, res = _reduced(args)
    t, u, setup = time_input(fom.band, fom.m, args.input, horizon=args.horizon, step=args.step,
                             direction=args.direction)
    with warnings.catch_warnings():
        if args.json:
            warnings.simplefilter("ignore")  # recorded in warnings
        y, full = time_response(fom, t, u, scheme=args.scheme)
        y_r, red = time_response(res.rom, t, u, scheme=args.scheme, rom_method=args.rom_method)
    errs = output_errors(y, y_r, t)
    info = res.info
    out = {"model": args.model, "method": args.method, "r": info["r"], "r_requested": info["r_requested"],
           "states": info["states"], "converged": info["converged"], "status": info.get("status"),
           "stable": info["stable"], "input": args.input, "horizon": setup["horizon"], "step": setup["step"], "steps": setup["steps"],
           "scheme": args.scheme, "rom_method": args.rom_method, "direction": setup["direction"],
           **{k: errs[k] for k in ("max_output_error", "l2_output_error", "max_output_rel_error",
                                   "l2_output_rel_error", "max_output", "l2_output", "t_max_error")},
           "growth": red["growth"], "unstable_poles": red["unstable_poles"], "growth_factor": red["growth_factor"],
           "lu_count": full["lu_count"], "reduce_lu_count": info.get("lu_count"),
           "times": {"reduce_s": info["time_s"], "simulate_full_s": full["time_s"], "simulate_rom_s": red["time_s"]},
           "worse_than_zero": worse_than_zero(max_output=(errs["max_output_error"], errs["max_output"]),
                                              l2_output=(errs["l2_output_error"], errs["l2_output"])),
           "csv": args.csv, "warnings": list(info["warnings"]) + full["warnings"] + red["warnings"]}
    if args.csv:
        _write_curves(args.csv, t, y, y_r)
    _print(out, args.json)
    return 0


def _write_curves(path, t, y, y_r):
    import numpy as np

    from .utils import atomic_write_text

    p = y.shape[1]
    header = ",".join(["t"] + [f"y{j + 1}" for j in range(p)] + [f"y_r{j + 1}" for j in range(p)])
    rows = np.column_stack([t, y, y_r])
    atomic_write_text(path, header + "\n" + "\n".join(",".join(repr(float(v)) for v in row) for row in rows) + "\n")


def _direction_arg(text):
    try:
        return [float(v) for v in text.split(",")]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--direction must be numbers separated by commas, got {text!r}") from exc


def cmd_info(args) -> int:
    """``morsuite info MODEL``: print the model's summary (sizes, band, name) as JSON; returns 0.

    Builds the model (a catalog spec or a file) and analyses its sparsity pattern for
    the LU backend (``lu_backend``: one RCM ordering, no factorization). Detects
    rigid-body modes (``rigid_body_modes``; :mod:`morsuite.models.rigid`: one sparse LU unless K
    is positive definite by diagonal dominance) and says in one line on stderr what it found.
    """
    from . import models
    from .models.rigid import rigid_body_modes
    model = models.parse(args.model)
    rigid = rigid_body_modes(model)
    print(json.dumps({**model.summary(), "lu_backend": model.lu_analysis(), "rigid_body_modes": rigid.summary()},
                     indent=2, default=str))
    print(rigid.line(model.name), file=sys.stderr)
    return 0


def cmd_list(args) -> int:
    """``morsuite list``: print the catalog models, the registered reducers and the methods of
    ``morsuite compare`` (reducers and their variants; ``*``: compared by default); returns 0."""
    from . import models, reducers
    print("models:   " + ", ".join(models.available()))
    print("reducers: " + ", ".join(reducers.available()))
    print("methods (morsuite compare; * compared by default):")
    for name, m in reducers.methods().items():
        opts = ", ".join(f"{k}={v!r}" for k, v in m.options.items())
        print(f"  {'*' if m.default else ' '} {name:<16}{m.reducer + (f'({opts})' if opts else ''):<20}"
              f"{m.states_per_order} states/order  {m.label}")
    return 0


def _add_simulate_parser(sub):
    """``morsuite simulate --model M --method X --r R [--input SPEC] [--horizon T] [--step H] ...``."""
    p = sub.add_parser("simulate", help="reduce, simulate full and reduced model in time, print the output errors")
    p.add_argument("--model", required=True, help="catalog spec (dsms:g=6000) or .mat/.npz path")
    p.add_argument("--method", required=True, help="reducer name (see `morsuite list`)")
    p.add_argument("--r", required=True, type=int, help="reduced order")
    p.add_argument("--option", action="append", metavar="KEY=VALUE",
                   help="reducer option, GROUP.KEY=VALUE for an advanced one (repeatable)")
    p.add_argument("--input", default="step", metavar="SPEC",
                   help="step (default), impulse, chirp:omega0=0.01,omega1=1, multisine:omegas=0.1;0.5, csv:PATH")
    p.add_argument("--horizon", type=float, metavar="T", help="simulated time in s (default 2 pi / band low end)")
    p.add_argument("--step", type=float, metavar="H", help="time step in s (default 0.3 / band high end)")
    p.add_argument("--scheme", default="trapezoidal", choices=("trapezoidal", "backward-euler"))
    p.add_argument("--rom-method", default="scheme", choices=("scheme", "control"),
                   help="reduced model: the same scheme (default) or python-control's forced_response")
    p.add_argument("--direction", type=_direction_arg, metavar="B1,B2,...",
                   help="input direction of a MIMO model (default all ones)")
    p.add_argument("--csv", metavar="OUT", help="write t, y1..yp, y_r1..y_rp to this CSV file")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_simulate)
    return p


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
        from .studies.batch import shared_compute
        from .studies.cache import Cache
        from .studies.memo import SpecMemo
        from .studies.workers import default_jobs, sigterm_exits

        cache = Cache(args.cache or Path(args.out) / ".cache", read=not args.no_cache)
        memo = SpecMemo(cache)  # validated models/methods: a cached study builds no model
        studies = [load_spec(path, memo=memo) for path in args.specs]  # every spec is valid before anything runs
        rule = None
        if args.jobs is not None:
            jobs = args.jobs
        elif args.scheduler:
            jobs = 1
        else:  # the usable cores, bounded by memory (studies.workers.default_jobs)
            rule = default_jobs(max((m.n1 for s in studies for m in s.models.values()), default=0))
            jobs = rule["jobs"]
        if not args.dry_run and jobs > 1 and args.scheduler is None and not args.no_cache:
            # what any of the studies lacks computed once, then each study's report, on pinned workers
            memo.flush()
            with sigterm_exits():  # stopped, the run stops its workers (studies.workers)
                shared_compute(studies, cache, jobs, out=args.out, quiet=args.quiet,
                               run_kwargs={"out": args.out, "cache_dir": args.cache, "quiet": args.quiet,
                                           "rerender": args.rerender}, jobs_rule=rule)
            return 0
        for study in studies:
            if args.dry_run:
                print(f"{study.name} ({study.path}): {len(study.scenes)} scenes; would compute")
                print("  " + "\n  ".join(build_plan(study).describe()))
                continue
            with sigterm_exits():
                run(study, out=args.out, cache_dir=args.cache, use_cache=not args.no_cache, jobs=jobs,
                    scheduler=args.scheduler, quiet=args.quiet, rerender=args.rerender)
        return 0

    p = sub.add_parser("run", help="run study specs (TOML): figures, tables, manifest in OUT/NAME/")
    p.add_argument("specs", nargs="+", metavar="SPEC", help="study spec files, e.g. studies/paper_*.toml")
    p.add_argument("--out", default="results", metavar="DIR", help="results root (default: results)")
    p.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="worker processes, each pinned to a core (default: the usable cores, as many as the "
                        "available memory holds: morsuite.studies.workers.default_jobs); "
                        "with N > 1 what the studies lack is computed once, side by side, before their reports "
                        "(morsuite.studies.batch); 1: one study after the other on Dask's synchronous scheduler")
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


def _add_compare_parser(sub):
    """``morsuite compare MODEL [--states N ...] [--tol TOL ...] [--error band|h2|hinf] [--budget-lus N]
    [--budget-s S] [--save-roms] [--methods ...] [--band LO HI] [--input ...] [--out DIR] [--jobs N]``
    (see :mod:`morsuite.studies.compare`)."""

    def cmd_compare(args) -> int:
        from .studies.compare import compare, rigid_line, verdict_lines

        from .studies.workers import usable_cores

        line = rigid_line(args.model)
        if line:
            print(line)
        jobs = args.jobs if args.jobs is not None else min(2, len(usable_cores()))
        result, path = compare(args.model, args.states, args.methods, args.band, args.input, out=args.out,
                               name=args.name, quiet=args.quiet, jobs=jobs, tol=args.tol, error=args.error,
                               budget_lus=args.budget_lus, budget_s=args.budget_s, max_states=args.max_states,
                               save_roms=args.save_roms)
        print("\n".join(verdict_lines(result)))
        print(f"report: {result.outdir / 'index.html'}\nstudy:  {path} (morsuite run {path} --out {args.out})")
        roms = sorted(str(f) for f in result.files if f.parent.name == "roms")
        if roms:
            print("models: " + "\n        ".join(roms))
        status = result.summary["status"].astype(str)
        if len(status) and not (status == "ok").any():  # every reduction failed: say why, exit non-zero
            print(f"morsuite compare: every reduction failed; the first: {status.iloc[0]}", file=sys.stderr)
            return 1
        failed = [a for a in result.manifest["artifacts"] if a.get("kind") == "tolerance" and a.get("error")]
        if args.tol and len(failed) == sum(1 for a in result.manifest["artifacts"] if a.get("kind") == "tolerance"):
            print(f"morsuite compare: every tolerance search failed; the first: {failed[0]['error']}",
                  file=sys.stderr)
            return 1
        return 0

    from .studies.compare import INPUTS
    p = sub.add_parser("compare", help="compare reducers on one model at equal first-order states: a study, "
                                       "its HTML report and the verdict")
    p.add_argument("model", help=MODEL_HELP)
    p.add_argument("--states", nargs="+", type=int, metavar="N",
                   help="first-order states of the reduced models (even: a second-order ROM of order r has 2r)")
    p.add_argument("--tol", nargs="+", type=float, metavar="TOL",
                   help="relative tolerances in (0, 1): each method's smallest model within each, its cost, "
                        "the cheapest and the smallest (give --states, --tol or both)")
    p.add_argument("--error", default="band", choices=("band", "h2", "hinf"),
                   help="the error --tol bounds: band max error over the band's peak (default), H2 error over "
                        "||T||_H2, or the certified Hinf error bound over ||T||_Hinf")
    p.add_argument("--budget-lus", type=int, metavar="N", help="each method's budget of sparse LUs in the search")
    p.add_argument("--budget-s", type=float, metavar="S", help="each method's time budget of the search (s)")
    p.add_argument("--max-states", type=int, metavar="N", help="the largest model tried (default 400 states)")
    p.add_argument("--save-roms", action="store_true",
                   help="write each chosen model as .npz and .mat with a JSON provenance sidecar (OUT/NAME/roms/)")
    p.add_argument("--jobs", type=int, metavar="N",
                   help="worker processes, each pinned to a core (default: the usable cores, at most 2)")
    p.add_argument("--methods", nargs="+", metavar="NAME",
                   help="reducers or their variants (default: those marked * by `morsuite list`, which lists "
                        "every valid name)")
    p.add_argument("--band", nargs=2, type=float, metavar=("LO", "HI"),
                   help="frequency band in rad/s (default: the model's; a model file: from its eigenfrequencies)")
    p.add_argument("--input", metavar="|".join(INPUTS) + "|FILE.csv",
                   help="add a time-domain comparison for this input")
    p.add_argument("--out", default="results", metavar="DIR", help="results root (default: results)")
    p.add_argument("--name", help="study name (default: compare_MODEL)")
    p.add_argument("--quiet", action="store_true", help="no progress bars or log lines")
    p.set_defaults(func=cmd_compare)
    return p


MODEL_HELP = "catalog spec (dsms:g=6000) or a path: .mat, .npz, a Matrix Market set (directory or stem)"


def build_parser():
    """Build the ``morsuite`` argument parser.

    Subcommands: ``info MODEL`` (a model's summary as JSON), ``list`` (models and
    reducers), ``reduce`` (one reduction, its band errors and exact norms),
    ``simulate`` (time-domain output errors), ``bench`` (the benchmarks of
    :mod:`morsuite.bench`), ``run`` (study specs, :mod:`morsuite.studies`) and ``compare``
    (a comparison study of one model, :mod:`morsuite.studies.compare`). Each
    subparser stores its command function as ``func``.

    Returns
    -------
    parser : argparse.ArgumentParser
        The top-level parser.
    sub : argparse._SubParsersAction
        Its subparsers, so that a caller can add commands.
    """
    parser = argparse.ArgumentParser(prog="morsuite", description="Model reduction of second-order index-3 systems.")
    sub = parser.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("info", help="summary of a model")
    p.add_argument("model", help=MODEL_HELP)
    p.set_defaults(func=cmd_info)
    p = sub.add_parser("list", help="available models, reducers and the methods of compare")
    p.set_defaults(func=cmd_list)
    p = sub.add_parser("reduce", help="reduce one model, print errors and timing")
    p.add_argument("--model", required=True, help=MODEL_HELP)
    p.add_argument("--method", required=True, help="reducer name (see `morsuite list`)")
    p.add_argument("--r", required=True, type=int, help="reduced order")
    p.add_argument("--omega", type=_omega_arg, help="frequency grid LO:HI:N (rad/s, log-spaced)")
    p.add_argument("--option", action="append", metavar="KEY=VALUE",
                   help="reducer option, GROUP.KEY=VALUE for an advanced one (repeatable)")
    p.add_argument("--no-norms", action="store_true",
                   help="skip the H2 and Hinf errors (printed as null); they cost the model's Gramian "
                        "factors once and up to a few hundred sparse LUs")
    p.add_argument("--save", metavar="PATH",
                   help="write the reduced model as PATH.npz, PATH.mat and the sidecar PATH.json (morsuite.romfiles)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_reduce)
    p = sub.add_parser("verify", help="compute again the errors recorded with a saved reduced model; exit 1 "
                                      "when one disagrees")
    p.add_argument("model", help=MODEL_HELP)
    p.add_argument("romfile", help="the saved reduced model: STEM.npz, STEM.mat, STEM.json or STEM")
    p.add_argument("--no-norms", action="store_true", help="check the band errors only (the H2 and Hinf "
                                                             "errors cost the Gramian factors and up to a few hundred LUs)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_verify)
    _add_simulate_parser(sub)
    _add_bench_parser(sub)
    _add_run_parser(sub)
    _add_compare_parser(sub)
    return parser, sub


def main(argv=None):
    """Entry point of the ``morsuite`` script and of ``python -m morsuite``.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after the program name; default ``sys.argv[1:]``.

    Returns
    -------
    int
        The exit status: 0 on success, 2 when the input was refused (any
        :class:`~morsuite.errors.MorsuiteError`; its message, which names the
        argument at fault, is printed to stderr without a traceback). A usage error
        exits through argparse with status 2 as well.
    """
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
