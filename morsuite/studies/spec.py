"""Study specifications: a TOML file -> a validated :class:`Study` (plain data).

A study names its models, frequency grids, reducers (with options) and a list of
scenes (figures and tables). Everything is checked before anything is computed:
an unknown key, model, reducer, option, grid, scene kind or an r the model cannot
support raises :class:`~morsuite.errors.SpecError` naming it and listing the valid
choices. Example::

    name = "demo"                        # output folder results/demo (default: file stem)
    title = "IRKA on the DSMS"
    root = ".."                          # base of relative paths, relative to this file

    [models]
    dsms = "dsms:g=600"                  # catalog string, or a path: .mat, .npz, a Matrix Market set

    [grids]
    fig = { band = [1e-2, 1.0], n = 200 }   # log-spaced, rad/s; band defaults to the model's

    [methods.irka]                       # alias; reducer defaults to the alias
    reducer = "irka"
    options = { tol = 1e-6 }
    label = "IRKA"

    [[scenes]]
    name = "dsms_r30_abs_error_irka"
    kind = "error"                       # see morsuite.studies.scenes.KINDS
    model = "dsms"
    grid = "fig"
    r = 30                               # int, list, or { from = 2, to = 40, step = 2 }
    # r_by_method = { irka_fo = 60 }     # other orders for some methods (first-order ROMs at 2r states)
    error = "abs"
    paper_csv = "studies/paper_figures/dsms_r30_abs_error_irka.csv"

Exact error norms (:mod:`morsuite.studies.norms`) are computed only where asked: the
top-level ``norms = ["h2", "hinf"]`` (every reduction of the study; summary columns),
a scene measure ``"h2"``, ``"h2_rel"``, ``"hinf"``, ``"hinf_rel"`` (``error_vs_r``,
``pareto``) or a table scene's ``norms = [...]``; their options in
``[norm_options]`` (``h2 = { rtol = 1e-8 }``, ``hinf = { max_lus = 190 }``).
Time-domain scenes (kind ``time``: input, horizon, step, ...) are described in
:mod:`morsuite.studies.timedomain`.
"""

from __future__ import annotations

import hashlib
import json
import tomllib
from dataclasses import dataclass, field
from numbers import Integral, Real
from pathlib import Path

import numpy as np

from ..utils import to_plain
from ..errors import FileFormatError, InputError, SpecError
from ..modelfiles import is_model_path, model_files
from .checks import Ctx as _Ctx, name_ok as _name_ok, r_by_method as _r_by_method, r_values as _r_values
from .checks import suggest as _suggest
from .kinds import COMMON_KEYS, KINDS, check_output_names as _check_output_names
from .norm_options import norms_of as _norms
from .time_options import resolve as _resolve_time

__all__ = ["Study", "ModelEntry", "GridEntry", "MethodEntry", "SceneEntry", "load_spec",
           "study_from_dict", "plain"]

TOP_KEYS = ("name", "title", "description", "root", "models", "grids", "methods", "scenes", "norms",
            "norm_options")
GRID_KEYS = ("band", "n")
METHOD_KEYS = ("reducer", "options", "label")
DEFAULT_GRID = "default"
DEFAULT_GRID_N = 200


@dataclass(frozen=True)
class ModelEntry:
    """One model of a study: ``spec`` as written, ``source`` as passed to tasks."""

    alias: str
    spec: str
    source: str          # catalog string or absolute file path
    model_id: str        # identity used in cache keys (canonical spec or file hash)
    name: str
    n1: int
    n2: int
    order: int           # n1 - n2: the largest admissible r
    band: tuple
    m: int = 0           # inputs and outputs (0: not known, an old memo entry)
    p: int = 0


@dataclass(frozen=True)
class GridEntry:
    """One frequency grid of a study: ``n`` log-spaced points on ``band`` (None: each model's default band)."""

    name: str
    band: tuple | None   # None: the model's default band
    n: int

    def omega_for(self, model: ModelEntry) -> np.ndarray:
        """The grid's ``n`` log-spaced frequencies (rad/s) on its band, or on the model's default band."""
        lo, hi = self.band or model.band
        return np.logspace(np.log10(lo), np.log10(hi), self.n)

    def bounds_for(self, model: ModelEntry) -> tuple:
        """``(lo, hi, n)`` of the grid on ``model``: what identifies it in cache keys."""
        lo, hi = self.band or model.band
        return float(lo), float(hi), int(self.n)


@dataclass(frozen=True)
class MethodEntry:
    """One method of a study: a registered ``reducer`` with ``options``, shown as ``label``."""

    alias: str
    reducer: str
    options: dict        # the options as written (passed to the reducer)
    full_options: dict   # every declared option, defaults filled in (plain data)
    label: str

    @property
    def method_id(self) -> str:
        """``REDUCER:DIGEST``, the method's identity in cache keys: the first 16 hex digits of the SHA-256 of the reducer name and every option with defaults filled in (so an alias or a default written out does not change it)."""
        return self.reducer + ":" + _digest({"reducer": self.reducer, "options": self.full_options})[:16]


@dataclass
class SceneEntry:
    """One validated scene: a figure or table of ``kind`` on one model, for ``methods`` and orders ``rs``."""

    name: str
    kind: str
    model: str
    methods: tuple
    rs: tuple
    grid: str | None
    title: str
    params: dict = field(default_factory=dict)     # kind-specific settings, defaults filled
    paper: dict = field(default_factory=dict)      # curve name -> Path (may not exist)
    #: method alias -> its own orders (``r_by_method``), for methods whose r counts something else
    #: (a first-order ROM with 2r states beside second-order ROMs of order r); others use ``rs``
    r_by_method: dict = field(default_factory=dict)

    def rs_of(self, method) -> tuple:
        """The reduced orders of ``method`` in this scene."""
        return self.r_by_method.get(method, self.rs)


@dataclass
class Study:
    """A validated study. Models were built once to learn their band and order."""

    name: str
    title: str
    description: str
    path: Path | None
    root: Path
    models: dict
    grids: dict
    methods: dict
    scenes: list
    raw: dict
    #: norms computed for every reduction ("h2", "hinf"), and each kind's options (defaults filled in)
    norms: tuple = ()
    norm_options: dict = field(default_factory=dict)
    #: validated entries to keep in the cache once the study runs (:class:`~morsuite.studies.memo.SpecMemo`)
    memo: object = field(default=None, repr=False, compare=False)

    def canonical(self) -> dict:
        """Plain-data form of the validated spec (defaults filled in, models identified)."""
        return plain({
            "name": self.name, "title": self.title,
            "models": {a: {"spec": m.spec, "model_id": m.model_id} for a, m in self.models.items()},
            "grids": {g.name: {"band": g.band, "n": g.n} for g in self.grids.values()},
            "methods": {a: {"reducer": m.reducer, "options": m.full_options, "label": m.label}
                        for a, m in self.methods.items()},
            "scenes": [{"name": s.name, "kind": s.kind, "title": s.title, "model": s.model, "methods": s.methods,
                        "r": s.rs, "grid": s.grid, "params": s.params,
                        "paper": {k: str(v) for k, v in s.paper.items()},
                        # only when given: the canonical form (and hash) of other studies is unchanged
                        **({"r_by_method": s.r_by_method} if s.r_by_method else {})} for s in self.scenes],
            "norms": list(self.norms), "norm_options": self.norm_options,
        })

    @property
    def config_hash(self) -> str:
        """SHA-256 of :meth:`canonical`, the validated spec; recorded in ``manifest.json``."""
        return _digest(self.canonical())


# -- helpers ---------------------------------------------------------------
plain = to_plain  # one converter for info, manifests and cache keys


def _digest(obj) -> str:
    return hashlib.sha256(json.dumps(plain(obj), sort_keys=True).encode()).hexdigest()


# -- models ----------------------------------------------------------------
_MODEL_FIELDS = ("model_id", "name", "n1", "n2", "order", "m", "p", "band")


def _model_entry(ctx, alias, spec, root, memo=None):
    where = f"models.{alias}"
    ctx.string(where, spec)
    if is_model_path(spec):
        path = Path(spec).expanduser()
        path = path if path.is_absolute() else (root / path)
        path = path.resolve()
        try:
            files = model_files(path)
        except FileFormatError as exc:
            ctx.fail(where, str(exc))
        source = str(path)
        if len(files) == 1 and files[0] == path:
            digest = hashlib.sha256(path.read_bytes()).hexdigest()
        else:  # a Matrix Market set: its members' names and contents
            digest = hashlib.sha256(b"".join(f.name.encode() + b"\0" + hashlib.sha256(f.read_bytes()).digest()
                                             for f in files)).hexdigest()
        model_id = "file:" + path.name + ":" + digest[:16]
        material = {"model_id": model_id}
    else:
        source, material = spec, {"spec": spec}
    hit = memo.lookup("model", material, "morsuite.models") if memo is not None else None
    if hit is not None and all(k in hit for k in _MODEL_FIELDS):
        return ModelEntry(alias=alias, spec=spec, source=source, **{k: hit[k] for k in _MODEL_FIELDS[:-1]},
                          band=tuple(hit["band"]))

    from ..models import catalog

    if not is_model_path(spec):
        name = spec.partition(":")[0]
        if name not in catalog.CATALOG:
            ctx.fail(where, f"unknown model {name!r}{_suggest(name, catalog.available())}; catalog models: "
                            f"{', '.join(catalog.available())} (or a path: .mat, .npz, a Matrix Market set)")
        model_id = "catalog:" + catalog.canonical(spec)
    from .task_common import model_of

    try:
        fom = model_of(source)  # built once per process: the tasks and a second validation reuse it
    except InputError as exc:
        ctx.fail(where, f"model {spec!r} cannot be built: {exc}")
    entry = ModelEntry(alias=alias, spec=spec, source=source, model_id=model_id, name=fom.name,
                       n1=int(fom.n1), n2=int(fom.n2), order=int(fom.order), band=tuple(map(float, fom.band)),
                       m=int(fom.m), p=int(fom.p))
    if memo is not None:
        owner = "morsuite.models.io" if "model_id" in material else \
            getattr(catalog.CATALOG[spec.partition(":")[0]], "__module__", "")
        memo.store("model", material, {k: getattr(entry, k) for k in _MODEL_FIELDS}, owner)
    return entry


# -- methods ---------------------------------------------------------------
def _method_entry(ctx, alias, table, memo=None):
    where = f"methods.{alias}"
    if table is None:
        table = {}
    ctx.keys(where, table, METHOD_KEYS)
    name = table.get("reducer", alias)
    ctx.string(f"{where}.reducer", name)
    opts = table.get("options", {})
    material = {"reducer": name, "options": opts}
    hit = memo.lookup("method", material, "morsuite.reducers") if memo is not None else None
    if hit is not None and isinstance(opts, dict):
        label = table.get("label", alias)
        ctx.string(f"{where}.label", label)
        # stored as pairs: the declaration order of the options survives the JSON
        return MethodEntry(alias=alias, reducer=name, options=dict(opts), full_options=dict(hit["full_options"]),
                           label=label)

    from .. import reducers

    avail = reducers.available()
    if name not in avail:
        ctx.fail(f"{where}.reducer", f"unknown reducer {name!r}{_suggest(name, avail)}; registered reducers: "
                                     f"{', '.join(avail)}")
    cls = reducers.get_class(name)
    groups = getattr(cls, "GROUPS", {})
    ctx.keys(f"{where}.options", opts, tuple(cls.OPTIONS) + tuple(groups))
    full = {}
    from ..errors import OptionError
    from ..reducers.options import expand_options
    try:  # a group's table ([methods.ALIAS.options.GROUP]) to the options' own names, as they are recorded
        flat, given_as = expand_options(cls.__name__, cls.OPTIONS, groups, opts)
    except OptionError as exc:
        ctx.fail(f"{where}.options", str(exc))
    for key, opt in cls.OPTIONS.items():
        try:
            full[key] = opt.validate(cls.__name__, given_as.get(key, key), flat.get(key, opt.default))
        except OptionError as exc:
            ctx.fail(f"{where}.options.{given_as.get(key, key)}", str(exc))
    full = plain(full)
    if memo is not None:
        memo.store("method", material, {"full_options": list(full.items())}, getattr(cls, "__module__", ""))
    label = table.get("label", alias)
    ctx.string(f"{where}.label", label)
    return MethodEntry(alias=alias, reducer=name, options=dict(opts), full_options=full, label=label)


# -- grids and r -----------------------------------------------------------
def _grid_entry(ctx, name, table):
    where = f"grids.{name}"
    ctx.keys(where, table, GRID_KEYS)
    band = table.get("band")
    if band is not None:
        ok = (isinstance(band, list) and len(band) == 2 and all(isinstance(b, Real) and not isinstance(b, bool)
                                                                 for b in band))
        if not ok or not (0 < band[0] < band[1] < np.inf):
            ctx.fail(f"{where}.band", f"expected [lo, hi] with 0 < lo < hi (rad/s); got {band!r}")
        band = (float(band[0]), float(band[1]))
    n = table.get("n", DEFAULT_GRID_N)
    if isinstance(n, bool) or not isinstance(n, Integral) or n < 2:
        ctx.fail(f"{where}.n", f"expected an integer >= 2; got {n!r}")
    return GridEntry(name=name, band=band, n=int(n))


# -- scenes ----------------------------------------------------------------
def _scene_entry(ctx, i, table, study_models, grids, methods, root):
    where = f"scenes[{i}]"
    if not isinstance(table, dict):
        ctx.fail(where, "expected a table ([[scenes]])")
    kind = table.get("kind")
    if kind is None:
        ctx.fail(where, f"missing key 'kind'; valid kinds: {', '.join(KINDS)}")
    ctx.choice(f"{where}.kind", kind, tuple(KINDS))
    spec = KINDS[kind]
    name = table.get("name")
    if name is None:
        ctx.fail(where, "missing key 'name' (used for the output file names)")
    ctx.string(f"{where}.name", name)
    if not _name_ok(name):
        ctx.fail(f"{where}.name", f"{name!r} is not a file-name-safe string (letters, digits, - _ .)")
    where = f"scenes[{i}] ({name!r})"
    ctx.keys(where, table, COMMON_KEYS + tuple(spec.keys))
    if "model" not in table:
        ctx.fail(where, f"missing key 'model'; defined models: {', '.join(sorted(study_models))}")
    model = ctx.ref(f"{where}.model", table["model"], study_models, "model")
    mlist = table.get("methods", list(methods))
    if isinstance(mlist, str):
        mlist = [mlist]
    if not isinstance(mlist, list) or not mlist:
        ctx.fail(f"{where}.methods", f"expected a non-empty list of method aliases; got {mlist!r}")
    for m in mlist:
        ctx.ref(f"{where}.methods", m, methods, "method")
    if len(set(mlist)) != len(mlist):
        ctx.fail(f"{where}.methods", f"duplicate method in {mlist!r}")
    if len(mlist) < spec.min_methods:
        ctx.fail(f"{where}.methods", f"a {kind!r} scene needs at least {spec.min_methods} methods; got {mlist!r}")
    if not spec.needs_r:
        for key in ("r", "r_by_method"):
            if key in table:
                ctx.fail(f"{where}.{key}", f"a {kind!r} scene finds its orders itself; remove {key!r}")
        if kind == "tolerance" and "tol" not in table:
            ctx.fail(where, "missing key 'tol' (a relative tolerance in (0, 1), or a list of them)")
        rs, by_method = (), {}
    else:
        if "r" not in table:
            ctx.fail(where, "missing key 'r'")
        rs = _r_values(ctx, f"{where}.r", table["r"])
        if spec.one_r and len(rs) != 1:
            ctx.fail(f"{where}.r", f"a {kind!r} scene shows one reduced order; got r = {list(rs)}")
        by_method = _r_by_method(ctx, f"{where}.r_by_method", table.get("r_by_method", {}), mlist, spec, kind)
    params = {}
    for key, (default, check) in spec.keys.items():
        if key in ("r", "grid", "paper_csv"):
            continue
        val = table.get(key, default)
        if key not in table and default is None:
            pass  # an optional setting left out
        elif callable(check):
            val = check(ctx, f"{where}.{key}", val)
        elif check is not None:
            ctx.choice(f"{where}.{key}", val, check)
        elif val is not None and (isinstance(val, bool) or not isinstance(val, Integral) or val < 1):
            ctx.fail(f"{where}.{key}", f"expected a positive integer; got {val!r}")
        params[key] = val
    grid = None
    if spec.grid_needed(params):
        grid = table.get("grid", DEFAULT_GRID)
        ctx.ref(f"{where}.grid", grid, grids, "grid")
    elif "grid" in table and spec.uses_grid:
        what = f"error {params.get('error')!r}" if kind == "tolerance" else f"measure {params.get('measure')!r}"
        ctx.fail(f"{where}.grid", f"{what} is a norm over the whole frequency axis and uses no grid; remove 'grid'")
    title = table.get("title", "")
    ctx.string(f"{where}.title", title, empty=True)
    paper = {}
    if "paper_csv" in table:
        pc = table["paper_csv"]
        curves = spec.curve_names(mlist)
        if isinstance(pc, str):
            reduced = [c for c in curves if c != "full"]
            if len(reduced) != 1:
                ctx.fail(f"{where}.paper_csv", "a single path needs a scene with one method; give a table "
                                               f"{{ curve = path }} with curves from: {', '.join(curves)}")
            pc = {reduced[0]: pc}
        ctx.keys(f"{where}.paper_csv", pc, tuple(curves))
        for curve, p in pc.items():
            ctx.string(f"{where}.paper_csv.{curve}", p)
            path = Path(p)
            paper[curve] = path if path.is_absolute() else (root / path)
    return SceneEntry(name=name, kind=kind, model=model, methods=tuple(mlist), rs=rs, grid=grid,
                      title=title, params=params, paper=paper, r_by_method=by_method)



# -- entry points ----------------------------------------------------------
def study_from_dict(data: dict, *, path=None, source: str | None = None, memo=None) -> Study:
    """Validate a parsed TOML table. ``path`` (the spec file) anchors relative paths.

    ``memo`` (a :class:`~morsuite.studies.memo.SpecMemo`) serves model and method
    entries validated before, so that neither models nor reducers are imported.
    """
    path = Path(path) if path is not None else None
    ctx = _Ctx(source or (str(path) if path else "<dict>"))
    ctx.keys("top level", data, TOP_KEYS)
    base = path.parent if path is not None else Path.cwd()
    root_rel = data.get("root", ".")
    ctx.string("root", root_rel)
    root = (base / root_rel).resolve()
    if not root.is_dir():
        ctx.fail("root", f"{str(root)!r} is not a directory")
    name = data.get("name", path.stem if path is not None else None)
    if name is None:
        ctx.fail("top level", "missing key 'name'")
    ctx.string("name", name)
    if not _name_ok(name):
        ctx.fail("name", f"{name!r} is not a file-name-safe string (letters, digits, - _ .)")
    title = ctx.string("title", data.get("title", name), empty=True)
    description = ctx.string("description", data.get("description", ""), empty=True)

    for key in ("models", "methods", "scenes"):
        if key not in data:
            ctx.fail("top level", f"missing key {key!r}")
    if not isinstance(data["methods"], dict) or not data["methods"]:
        ctx.fail("methods", "expected a non-empty table of [methods.ALIAS] tables")
    methods = {a: _method_entry(ctx, a, t, memo) for a, t in data["methods"].items()}
    grids_raw = data.get("grids", {})
    if not isinstance(grids_raw, dict):
        ctx.fail("grids", "expected a table of NAME = { band = [lo, hi], n = N }")
    grids = {DEFAULT_GRID: GridEntry(DEFAULT_GRID, None, DEFAULT_GRID_N)}
    grids.update({g: _grid_entry(ctx, g, t) for g, t in grids_raw.items()})
    scenes_raw = data["scenes"]
    if not isinstance(scenes_raw, list) or not scenes_raw:
        ctx.fail("scenes", "expected a non-empty array of tables ([[scenes]])")
    if not isinstance(data["models"], dict) or not data["models"]:
        ctx.fail("models", "expected a non-empty table alias = \"spec\"")
    # every scene is checked structurally first, so that a typo is reported before any
    # model is built; then the models the scenes use are built (to learn band and order)
    aliases = {a: None for a in data["models"]}
    scenes = [_scene_entry(ctx, i, t, aliases, grids, methods, root) for i, t in enumerate(scenes_raw)]
    names = [s.name for s in scenes]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        ctx.fail("scenes", f"duplicate scene name(s) {', '.join(map(repr, dup))}")
    _check_output_names(ctx, scenes)
    norms, norm_options = _norms(ctx, data)
    used = {s.model for s in scenes}
    for alias, spec in data["models"].items():
        if alias not in used:
            ctx.string(f"models.{alias}", spec)  # defined but unused: never built
    models = {a: _model_entry(ctx, a, data["models"][a], root, memo) for a in data["models"] if a in used}
    for i, s in enumerate(scenes):
        order = models[s.model].order
        if s.rs and s.rs[-1] > order:
            ctx.fail(f"scenes[{i}] ({s.name!r}).r", f"r = {s.rs[-1]} exceeds the order n1 - n2 = {order} "
                                                    f"of model {s.model!r} ({models[s.model].name})")
        for alias, rs in s.r_by_method.items():
            # a first-order ROM has up to 2 (n1 - n2) states; which reducers build one is not known
            # here without importing them, so a second-order one above n1 - n2 fails when it runs
            if rs[-1] > 2 * order:
                ctx.fail(f"scenes[{i}] ({s.name!r}).r_by_method.{alias}",
                         f"r = {rs[-1]} exceeds 2 (n1 - n2) = {2 * order} first-order states of model "
                         f"{s.model!r} ({models[s.model].name})")
        if s.kind == "time":
            _resolve_time(ctx, f"scenes[{i}] ({s.name!r})", s.params, models[s.model], root, memo)
    return Study(name=name, title=title, description=description, path=path, root=root, models=models,
                 grids=grids, methods=methods, scenes=scenes, raw=data, norms=norms, norm_options=norm_options,
                 memo=memo)


def load_spec(path, *, memo=None) -> Study:
    """Read and validate a study TOML file (``memo``: see :func:`study_from_dict`)."""
    path = Path(path)
    if not path.is_file():
        raise SpecError(f"study spec {str(path)!r} does not exist")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"study spec {str(path)}: not valid TOML: {exc}") from exc
    return study_from_dict(data, path=path, memo=memo)
