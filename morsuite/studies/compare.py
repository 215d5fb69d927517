"""``morsuite compare``: a method-comparison study of one model, built in memory and run.

:func:`compare_spec` writes the study a user would otherwise write by hand: the methods
compared at equal first-order states (a second-order reduced model of order r has 2r
states; a first-order one at N states runs at r = N), the frequency band of the model or,
for a model file, a decade beyond its undamped eigenfrequencies, the exact H2 and
H-infinity errors of every reduction, a verdict table per number of states, a Bode
magnitude figure (sigma_max of the full model and of every reduced model) and an error
figure per number of states, error and time against states when several are asked for,
and a time-domain scene when an input is given. :func:`compare` validates it (nothing
is written when an argument is wrong: the error names it), writes it as TOML into the
study's output folder (``OUT/NAME/NAME.toml``: edit it and ``morsuite run`` it again),
runs it with the cache, and returns the run and the verdict lines that the command prints.

The methods are read from the reducers' registry (:func:`morsuite.reducers.methods`: every
registered reducer and its named variants, with label and states per order): the defaults
are those whose description says so (the paper's IRKA, ``irka-fo``, ``so-h2``, second-order
BT at the velocity-velocity level ``bt-vv``, first-order ``bt``, ``modal``, ``krylov``);
``irka-projected`` (dense, n1 x n1), the other BT levels (``bt-pp``, ``bt-pv``, ``bt-vp``,
``bt-fv``), ``bt-fl`` and any reducer added later can be asked for. A reducer that takes a
band (``Description.band_option``) is given the comparison's band.

With ``tol`` (``morsuite compare MODEL --tol 0.01``) the study leads with a ``tolerance`` scene
(:mod:`morsuite.studies.tol_options`, :mod:`morsuite.analysis.tolerance`): each method's smallest
model within each tolerance, the next smaller one, the search's cost, the cheapest and the
smallest (:func:`tolerance_lines` prints them), and with ``save_roms`` the chosen models as files;
``states`` may then be left out.
"""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

from ..errors import InputError
from ..modelfiles import is_model_path
from ..utils import atomic_write_text
from .checks import suggest
from .task_common import model_of
from .tol_options import TOL_MEASURES

__all__ = ["all_methods", "default_methods", "INPUTS", "compare_spec", "compare", "to_toml", "verdict_lines", "verdict_row",
           "rigid_line"]

#: the H-infinity searches' ``skip_factor`` (:func:`morsuite.analysis.hinf_error`) in a comparison
SKIP_FACTOR = 0.5
#: the inputs of ``--input`` besides a CSV file (columns t, u1..um)
INPUTS = ("step", "impulse", "chirp")


def all_methods() -> dict:
    """The methods a comparison offers, by name: every registered reducer and every variant
    (:func:`morsuite.reducers.methods`, each a :class:`~morsuite.reducers.Method`: reducer, options,
    label, first-order states per order). Cost: the registry's discovery on first use."""
    from .. import reducers
    return reducers.methods()


def default_methods() -> tuple:
    """The methods compared when none are named: those whose reducer's description says so
    (:attr:`Description.default <morsuite.reducers.Description>`; today the paper's IRKA, irka-fo,
    so-h2, bt-vv, bt, modal and krylov), in the registry's order."""
    return tuple(name for name, m in all_methods().items() if m.default)


def _options(method, band) -> dict:
    """The method's options in a comparison on ``band``: its variant's, and the band for a reducer
    that takes one (``Description.band_option``: frequency-limited BT)."""
    opt = method.description.band_option
    return {**method.options, **({opt: list(band)} if opt else {})}


def _alias(name: str) -> str:
    return name.replace("-", "_")


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_.") or "model"


def _source(model) -> str:
    """The model's source as the study names it: a catalog spec as given, a file by its absolute path
    (the key of :func:`~morsuite.studies.task_common.model_of`, so that every step builds it once)."""
    source = str(model)
    return str(Path(source).expanduser().resolve()) if is_model_path(source) else source


def _file_band(fom) -> tuple:
    from ..models.random import default_band, eigenfrequency_range

    lo, hi = eigenfrequency_range(fom.M, fom.K)
    return default_band(lo, hi, 0.0)


def compare_spec(model: str, states=None, methods=None, band=None, input=None, name=None, *, tol=None,
                 error: str = "band", budget_lus=None, budget_s=None, max_states=None, save_roms: bool = False) -> dict:
    """The study (a dict, as its TOML reads) comparing ``methods`` on ``model`` at ``states`` and/or by the
    smallest model within each tolerance of ``tol``.

    Parameters
    ----------
    model : str
        A catalog spec (``dsms:g=600``) or a model file (.mat, .npz, a Matrix Market set).
    states : sequence of int
        First-order states of the reduced models (each even when a second-order method is
        compared: its order is r = N / 2); at most 2 (n1 - n2), and N / 2 <= n1 - n2 for
        second-order methods.
    methods : sequence of str, optional
        Names from :func:`all_methods` (registered reducers and their variants); default
        :func:`default_methods`.
    band : (float, float), optional
        Frequency band (rad/s) of the error figures and band errors; default the catalog
        model's band, or for a model file a decade beyond its undamped eigenfrequency range
        (:func:`morsuite.models.random.eigenfrequency_range`: one sparse LU of K).
    input : str, optional
        ``step``, ``impulse``, ``chirp`` or a CSV file (t, u1..um): adds a time scene per N.
    name : str, optional
        The study's name (its output folder); default ``compare_`` and the model's name.
    tol : sequence of float, optional
        Relative tolerances in (0, 1): a ``tolerance`` scene first (:mod:`morsuite.studies.tol_options`),
        each method's smallest model meeting each (``error``: ``band``, ``h2`` or ``hinf``), searched
        within ``budget_lus`` / ``budget_s`` per method and ``max_states``; ``save_roms`` writes the chosen
        models (.npz, .mat, .json) into the study's ``roms/`` folder. At least one of ``states`` and
        ``tol`` is needed.

    Raises
    ------
    InputError
        Naming the argument at fault: ``MODEL`` unreadable, ``--states`` out of range or odd,
        ``--methods`` unknown, ``--band`` not 0 < lo < hi, ``--input`` unknown or missing.

    Cost: building the model (once per process: :func:`~morsuite.studies.task_common.model_of`, which
    the study's validation and its tasks share) and, for a file without ``band``, one sparse LU of K.
    """
    offered = all_methods()
    methods = list(default_methods() if not methods else methods)
    for m in methods:
        if m not in offered:
            raise InputError(f"--methods: unknown method {m!r}{suggest(m, offered)}; valid: {', '.join(offered)}")
    if len(set(methods)) != len(methods):
        raise InputError(f"--methods: a method is named twice in {methods}")
    if not states and not tol:
        raise InputError("give --states N ... (a comparison at those sizes) or --tol TOL ... (the smallest model "
                         "within each tolerance), or both")
    if error not in TOL_MEASURES:
        raise InputError(f"--error: expected one of {', '.join(TOL_MEASURES)}; got {error!r}")
    tols = sorted({float(t) for t in (tol or [])}, reverse=True)
    if any(not (0 < t < 1) for t in tols):
        raise InputError(f"--tol: expected relative tolerances in (0, 1); got {tol}")
    for flag, v in (("--budget-lus", budget_lus), ("--budget-s", budget_s), ("--max-states", max_states)):
        if v is not None and not (v > 0):
            raise InputError(f"{flag}: expected a positive number; got {v}")
    try:
        fom = model_of(_source(model))
    except (InputError, OSError, ValueError) as exc:
        raise InputError(f"MODEL {str(model)!r} cannot be read: {exc}") from exc
    states = sorted(set(int(n) for n in (states or [])))
    second = [m for m in methods if offered[m].states_per_order == 2]
    for n in states:
        if n < (2 if second else 1):
            raise InputError(f"--states: {n} is too small (at least {2 if second else 1})")
        if second and n % 2:
            raise InputError(f"--states: {n} is odd; a second-order reduced model of order r has 2r states, so "
                             f"{', '.join(second)} need an even number")
        if n > 2 * fom.order or (second and n // 2 > fom.order):
            cap = 2 * fom.order
            raise InputError(f"--states: {n} exceeds what model {fom.name} allows: {cap} first-order states "
                             f"(n1 - n2 = {fom.order}; a second-order model of order r <= {fom.order})")
    if band is not None:
        lo, hi = (float(b) for b in band)
        if not (0 < lo < hi < float("inf")):
            raise InputError(f"--band: expected 0 < LO < HI (rad/s); got {lo:g} {hi:g}")
        band = [lo, hi]
    elif is_model_path(str(model)):
        band = [float(b) for b in _file_band(fom)]
    else:
        band = [float(b) for b in fom.band]
    source = _source(model)  # a file: absolute here; relative to the TOML file when written (to_toml)
    name = name or _slug("compare_" + fom.name.replace("(", "_").replace(")", "").replace("=", ""))

    asked = ([f"the smallest model within {', '.join(f'{t:g}' for t in tols)} ({error} error)"] if tols else []) + \
        ([", ".join(str(n) for n in states) + " states"] if states else [])
    spec = {"name": name, "title": f"{fom.name}: " + ", ".join(methods) + ": " + "; ".join(asked),
            "description": f"Written by morsuite compare: {len(methods)} methods on {fom.name} (n1 = {fom.n1}, "
                           f"n2 = {fom.n2}): " + "; ".join(asked) + f"; band [{band[0]:.3g}, {band[1]:.3g}] rad/s"
                           + ("; exact H2 and Hinf errors of every reduction at those sizes." if states else "."),
            "norms": ["h2", "hinf"] if states else [], "models": {"model": source},
            "grids": {"band": {"band": band, "n": 200}},
            # the H-infinity searches sample the band response's grid too: one memo of T(jw), no second LU
            # and refine only the maxima that may beat the best peak found, sample only the resonances
            # whose surrogate may (screen)
            "norm_options": {"hinf": {"band_grid": [band[0], band[1], 200], "skip_factor": SKIP_FACTOR,
                                      "screen": True}},
            "methods": {_alias(m): {"reducer": offered[m].reducer,
                                    **({"options": _options(offered[m], band)} if _options(offered[m], band) else {}),
                                    "label": offered[m].label} for m in methods},
            "scenes": []}

    def orders(ns):
        """``r`` of the scene and ``r_by_method`` for the methods whose order counts otherwise."""
        base = 2 if second else 1
        rs = [n // base for n in ns]
        spo = {m: offered[m].states_per_order for m in methods}
        other = {_alias(m): ([n // spo[m] for n in ns] if len(ns) > 1 else ns[0] // spo[m])
                 for m in methods if spo[m] != base}
        return (rs if len(rs) > 1 else rs[0]), other

    aliases = [_alias(m) for m in methods]
    if tols:
        extra = {k: v for k, v in (("budget_lus", budget_lus), ("budget_s", budget_s), ("max_states", max_states))
                 if v is not None}
        spec["scenes"].append({"name": "to_reach", "kind": "tolerance", "model": "model", "methods": aliases,
                               **({"grid": "band"} if error == "band" else {}), "tol": tols, "error": error,
                               **{k: (int(v) if k != "budget_s" else float(v)) for k, v in extra.items()},
                               **({"save_roms": True} if save_roms else {}),
                               "title": f"{fom.name}: the smallest model within "
                                        f"{', '.join(f'{t:g}' for t in tols)} ({error} error)"})
    for n in states:
        r, other = orders([n])
        extra = {"r_by_method": other} if other else {}
        spec["scenes"].append({"name": f"table_{n}", "kind": "table", "model": "model", "grid": "band",
                               "methods": aliases, "r": r, **extra, "norms": ["h2", "hinf"],
                               "title": f"{fom.name}: {n} states"})
        spec["scenes"].append({"name": f"bode_{n}", "kind": "sigma", "model": "model", "grid": "band",
                               "methods": aliases, "r": r, **extra,
                               "title": f"{fom.name}: sigma_max of the full and reduced models at {n} states"})
        spec["scenes"].append({"name": f"error_{n}", "kind": "error", "model": "model", "grid": "band",
                               "methods": aliases, "r": r, **extra,
                               "title": f"{fom.name}: absolute error at {n} states"})
        if input is not None:
            spec["scenes"].append({"name": f"time_{n}", "kind": "time", "model": "model", "methods": aliases, "r": r,
                                   **extra, "input": _input(input),
                                   "title": f"{fom.name}: {input if input in INPUTS else 'measured input'}, "
                                            f"{n} states"})
    if not states:
        return spec
    r, other = orders([states[-1]])
    spec["scenes"].append({"name": f"modes_{states[-1]}", "kind": "modes", "model": "model", "grid": "band",
                           "methods": aliases, "r": r, **({"r_by_method": other} if other else {}),
                           "title": f"{fom.name}: modes in the band at {states[-1]} states"})
    if len(states) > 1:
        r, other = orders(states)
        extra = {"r_by_method": other} if other else {}
        for measure in ("h2", "hinf", "max_abs"):
            spec["scenes"].append({"name": f"{measure}_vs_states", "kind": "error_vs_r", "model": "model",
                                   "methods": aliases, "r": r, **extra, "measure": measure, "axis": "states",
                                   **({"grid": "band"} if measure == "max_abs" else {})})
        spec["scenes"].append({"name": "pareto_h2", "kind": "pareto", "model": "model", "methods": aliases, "r": r,
                               **extra, "measure": "h2", "axis": "states"})
    return spec


def _input(value: str):
    if value in INPUTS:
        return value
    p = Path(value).expanduser()
    if p.suffix.lower() != ".csv":
        raise InputError(f"--input: expected one of {', '.join(INPUTS)} or a CSV file (t, u1..um); got {value!r}")
    if not p.is_file():
        raise InputError(f"--input: CSV file {value!r} does not exist")
    return "csv:" + str(p.resolve())


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + " }"
    raise InputError(f"cannot write {v!r} to TOML")


def to_toml(spec: dict, relative_to=None) -> str:
    """The study ``spec`` (as :func:`compare_spec` builds it) as TOML text; with ``relative_to`` (the
    folder of the file) the model file and a CSV input are written relative to it."""
    if relative_to is not None:
        base = Path(relative_to).resolve()

        def rel(p):
            return os.path.relpath(p, base) if os.path.isabs(p) else p
        spec = {**spec, "models": {k: rel(v) if is_model_path(v) else v for k, v in spec["models"].items()},
                "scenes": [{**sc, "input": "csv:" + rel(sc["input"][4:])}
                           if str(sc.get("input", "")).startswith("csv:") else sc for sc in spec["scenes"]]}
    lines = ["# Written by `morsuite compare`; edit it and run it again with `morsuite run THIS_FILE --out DIR`."]
    for k in ("name", "title", "description", "norms"):
        lines.append(f"{k} = {_toml_value(spec[k])}")
    for table in ("models", "grids"):
        lines += ["", f"[{table}]"] + [f"{k} = {_toml_value(v)}" for k, v in spec[table].items()]
    for kind, opts in spec.get("norm_options", {}).items():
        lines += ["", f"[norm_options.{kind}]"] + [f"{k} = {_toml_value(v)}" for k, v in opts.items()]
    for alias, m in spec["methods"].items():
        lines += ["", f"[methods.{alias}]"] + [f"{k} = {_toml_value(v)}" for k, v in m.items()]
    for s in spec["scenes"]:
        lines += ["", "[[scenes]]"] + [f"{k} = {_toml_value(v)}" for k, v in s.items()]
    return "\n".join(lines) + "\n"


def tolerance_lines(result) -> list:
    """What ``morsuite compare --tol`` prints: per tolerance scene, a row per tolerance and method (status,
    states, error, the next smaller model's states and error, LUs, time) and the headline."""
    from .tolerance_scene import headline, tolerance_rows

    out = []
    for scene in result.study.scenes:
        if scene.kind != "tolerance":
            continue
        rows = tolerance_rows(scene, result.study, result.results)
        out.append(f"== {scene.title or scene.name}")
        out.append(f"{'tol':>8} {'method':<16}{'status':>9} {'states':>7} {'error':>11} {'smaller':>8} "
                   f"{'its error':>11} {'LUs':>6} {'time (s)':>9}")
        for r in rows:
            def num(v, f):
                return "" if v is None else format(v, f)
            out.append(f"{r['tol']:>8.3g} {r['method']:<16}{r['status']:>9} {num(r['states'], 'd'):>7} "
                       f"{num(r['error'], '.4g'):>11} {num(r['smaller_states'], 'd'):>8} "
                       f"{num(r['smaller_error'], '.4g'):>11} {num(r['lu_count'], 'd'):>6} "
                       f"{num(r['time_s'], '.3g'):>9}")
        out.append(headline(rows, {m: m for m in scene.methods}))
        out.append("")
    return out


def verdict_lines(result) -> list:
    """What ``morsuite compare`` prints: the tolerance scenes' rows and headlines (:func:`tolerance_lines`),
    then per table a row per method (states, flags, errors, time) and the table's verdict."""
    out = tolerance_lines(result)
    if not any(scene.kind == "table" for scene in result.study.scenes):
        return out
    for scene in result.study.scenes:
        if scene.kind != "table":
            continue
        rows = {}
        for r in result.summary_table.rows:  # one row per reduction (a row per grid otherwise)
            if r["method"] in scene.methods and r["r_requested"] == scene.rs_of(r["method"])[0]:
                if (r["method"] not in rows) or (rows[r["method"]].get("max_abs_error") is None):
                    rows[r["method"]] = r
        rows = [rows[m] for m in scene.methods if m in rows]
        out.append(f"== {scene.title or scene.name}")
        out.append(f"{'method':<16}{'states':>7} {'conv':>5} {'H2 error':>12} {'Hinf error':>12} "
                   f"{'band max':>11} {'time (s)':>9}")
        out += [verdict_row(r) for r in rows]
        note = _table_note(result, scene.name)
        if note:
            out.append(note)
        out.append("")
    out.append("(~: H2 value not accurate to four digits; >=: the Hinf peak found, a lower bound; "
               "time: the reduction at this order alone)")
    return out


def verdict_row(r: dict) -> str:
    """One method's line of :func:`verdict_lines` from its summary row (``method``, ``states``,
    ``converged``, ``status``, ``h2_error``, ``h2_trusted``, ``hinf_error``, ``hinf_certified``,
    ``max_abs_error``, ``time_standalone_s``; a missing value is None): errors to 4 digits, time to 3,
    ``~`` before an H2 value not accurate to four digits, ``>=`` before a Hinf value that is a lower bound."""
    h2 = "" if r.get("h2_error") is None else \
        ("~" if r.get("h2_trusted") is False else "") + f"{r['h2_error']:.4g}"
    hinf = "" if r.get("hinf_error") is None else \
        ("" if r.get("hinf_certified") is True else ">=") + f"{r['hinf_error']:.4g}"
    band = "" if r.get("max_abs_error") is None else f"{r['max_abs_error']:.4g}"
    conv = "yes" if r.get("converged") else ("FAIL" if r.get("status") != "ok" else "no")
    t = r.get("time_standalone_s")
    return (f"{r['method']:<16}{r.get('states') or '':>7} {conv:>5} {h2:>12} {hinf:>12} {band:>11} "
            f"{'' if t is None else format(t, '.3g'):>9}")


def _table_note(result, name) -> str:
    """The table's verdict (its note, :func:`morsuite.studies.scenes._verdict`: ranked at equal states and
    above the floors only, ties at the rounding level said as ties), as its Markdown file holds it."""
    md = result.outdir / f"{name}.md"
    try:
        lines = md.read_text().splitlines()
    except OSError:
        return ""
    return next((ln for ln in lines if ln.strip() and not ln.startswith(("#", "|"))), "")


def rigid_line(model: str) -> str | None:
    """The one line saying that ``model`` (a spec or file) has rigid-body modes and how the
    comparison treats them (:mod:`morsuite.models.rigid`), or None if it has none (or cannot be
    read: :func:`compare` then says why). Cost: building the model (shared with the comparison:
    :func:`~morsuite.studies.task_common.model_of`) and its detection, kept on the model for the
    reducers (one sparse LU unless K is positive definite by diagonal dominance)."""
    from ..models.rigid import rigid_body_modes

    try:
        fom = model_of(_source(model))
    except (InputError, OSError, ValueError):
        return None
    rigid = rigid_body_modes(fom)
    return (rigid.line(fom.name) + f"; each reduced model carries the {2 * rigid.k} rigid states beyond those asked, "
            "errors and norms are the flexible part's") if rigid.k else None


def compare(model, states=None, methods=None, band=None, input=None, out="results", name=None, quiet=False, *,
            jobs: int = 1, **tolerance):
    """Build, write and run the comparison study (see :func:`compare_spec`; ``tolerance``: its keyword
    arguments ``tol``, ``error``, ``budget_lus``, ``budget_s``, ``max_states``, ``save_roms``); returns
    ``(RunResult, toml_path)``. ``jobs`` > 1 computes the study's units on that many pinned worker
    processes first (:func:`~morsuite.studies.batch.shared_compute`, as ``morsuite run`` does), then
    writes its report in this process.

    The spec is validated in full before anything is written, so a refused argument leaves
    nothing behind. The TOML goes to ``out/NAME/NAME.toml`` (atomically; file paths in it
    relative to it), where the run reads it (its manifest records the file). If the run
    fails (any exception, ``KeyboardInterrupt`` too), nothing of this call stays: a TOML
    that was there before is put back as it was (atomically), one this call created is
    removed, and so are the study folder and ``out`` if this call created them. (A process
    killed outright during the run leaves the new TOML in place.)
    """
    from .cache import Cache
    from .memo import SpecMemo
    from .runner import run
    import tomllib

    from .spec import study_from_dict

    spec = compare_spec(model, states, methods, band, input, name, **tolerance)
    study_from_dict(spec, source="morsuite compare")      # every check before anything is written
    out = Path(out)
    folder = out / spec["name"]
    path = folder / f"{spec['name']}.toml"
    old = path.read_text() if path.is_file() else None
    created = [d for d in (folder, out) if not d.exists()]  # the study folder first: it is inside out
    folder.mkdir(parents=True, exist_ok=True)
    text = to_toml(spec, relative_to=folder)
    atomic_write_text(path, text)
    try:
        cache = Cache(out / ".cache")
        memo = SpecMemo(cache)
        # the study as its file reads (paths relative to it), from the text written: no second read, and
        # its model is the one built above (model_of), not a new one
        study = study_from_dict(tomllib.loads(text), path=path, memo=memo)
        shared = None
        if jobs > 1:
            from .batch import shared_compute, split_claims
            memo.flush()
            shared = split_claims([study], shared_compute([study], cache, jobs, out=out, quiet=quiet))[0]
        result = run(study, out=out, quiet=quiet, shared=shared)
    except BaseException:
        if old is not None:
            atomic_write_text(path, old)
        else:
            path.unlink(missing_ok=True)
        for d in created:
            shutil.rmtree(d, ignore_errors=True)
        raise
    return result, path
