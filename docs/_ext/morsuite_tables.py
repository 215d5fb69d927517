"""Sphinx extension: tables read from the code when the docs are built, so they cannot drift.

Directives (each renders reStructuredText; the page is re-read on every build):

``.. morsuite-reducer-options::`` [NAME]
    Every option of every registered reducer (or of reducer NAME): default,
    admissible values and description, from the class's ``OPTIONS`` table
    (:class:`morsuite.reducers.base.Option`). The same table is appended to
    each reducer class's docstring in the API reference, and the raw
    ``OPTIONS`` attribute is left out there.
``.. morsuite-reducer-table::``
    One row per registered reducer, from its description
    (:class:`morsuite.reducers.Description`): the reduced model (and the named
    variants), what it targets, its cost in sparse LUs, what to use it for, the
    options users set, its family folder and design page.
``.. morsuite-spec-keys::``
    The keys of a study spec (TOML), from the key tables of
    :mod:`morsuite.studies.spec` and the scene kinds of
    :mod:`morsuite.studies.scenes`. A key without a description here is a
    build warning: add it to ``SPEC_KEY_DOCS`` / ``SCENE_KEY_DOCS``.
``.. morsuite-cli::``
    ``morsuite --help`` and every subcommand's help, and a table of each
    subcommand's arguments with their defaults, from
    :func:`morsuite.cli.build_parser`.
``.. morsuite-refused-table::``
    Runs every row of :mod:`morsuite.stress.refused` (a few seconds) and shows
    the error class and the actual message; a row that is not refused as
    declared is a build warning.

Option tables of the older form ``name -> (default, admissible, description)``
(``morsuite.analysis.simulate.OPTIONS``) are appended to their data's
docstring in the API reference.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os

from docutils import nodes
from docutils.parsers.rst import Directive
from docutils.statemachine import StringList
from sphinx.util import logging
from sphinx.util.nodes import nested_parse_with_titles

from morsuite_api import _generated_docs

logger = logging.getLogger(__name__)

#: top-level, [grids.NAME] and [methods.ALIAS] keys of a study spec
SPEC_KEY_DOCS = {
    "name": "name of the study and of its output folder OUT/NAME (default: the file's stem)",
    "title": "title of the study's summary (default: the name)",
    "description": "free text kept in the manifest (default: empty)",
    "root": "base of the relative paths in the spec, relative to the spec file (default: the file's folder)",
    "models": "table alias = \"catalog spec\" (e.g. \"dsms:g=600\") or the path of a .mat/.npz file (required)",
    "grids": "table of frequency grids NAME = { band = [lo, hi], n = N }; a grid \"default\" always exists",
    "methods": "table of [methods.ALIAS] tables (required, not empty)",
    "scenes": "array of [[scenes]] tables: the figures and tables to make (required, not empty)",
    "grids.band": "[lo, hi] in rad/s, log-spaced (default: the model's band)",
    "grids.n": "number of frequencies, an integer >= 2 (default: {n})",
    "methods.reducer": "registered reducer name (default: the alias)",
    "methods.options": "reducer options (default: none given; every declared option with its default is recorded)",
    "methods.label": "legend label (default: the alias)",
    "norms": "exact error norms computed for every reduction of the study: a list from \"h2\", \"hinf\" "
             "(default: none; scenes may still ask for them)",
    "norm_options": "options of the exact norms, tables h2 = { ... } and hinf = { ... } with the keyword options "
                    "of morsuite.analysis.h2_error / hinf_error (default: their defaults)",
}

#: keys of a [[scenes]] table (common ones, and the kind-specific ones of morsuite.studies.scenes.KINDS)
SCENE_KEY_DOCS = {
    "name": "file-name-safe name of the scene's output files (required)",
    "kind": "scene kind, one of the table below (required)",
    "title": "figure title (default: empty)",
    "model": "model alias (required)",
    "methods": "method aliases (default: every method of the study)",
    "r": "reduced order: an int, a list, or { from = 2, to = 40, step = 2 } (required)",
    "grid": "grid name (default: \"default\", the model's band with 200 points)",
    "paper_csv": "reference curve(s) to overlay: a path, or a table { curve = path }",
    "error": "error scenes: absolute or relative error; tolerance scenes: the error the tolerance bounds, band (max "
             "over the grid over the band's peak), h2 (over ||T||_H2) or hinf (certified upper bound over ||T||_Hinf)",
    "tol": "tolerance scene: a relative tolerance in (0, 1) or a list of them (required)",
    "budget_lus": "tolerance scene: each method's sparse LUs in its search (default: no budget)",
    "budget_s": "tolerance scene: each method's seconds of search (default: no budget)",
    "max_states": "tolerance scene: the largest reduced model tried, in first-order states (default 400)",
    "save_roms": "tolerance scene: write each chosen model as .npz and .mat with a JSON provenance sidecar into "
                 "the study's roms/ folder (default: false)",
    "measure": "what is plotted against r: max absolute or relative error on the grid (max_abs, max_rel), or an "
               "exact norm of the error over the whole axis (h2, h2_rel, hinf, hinf_rel; no grid)",
    "norms": "table scene: exact error norms shown as columns, a list from \"h2\", \"hinf\"",
    "input": "time scene: the input, a string KIND[:key=value,...] (step, impulse, chirp, multisine, csv:PATH) "
             "or a table { kind = ..., ... }",
    "horizon": "time scene: simulated time in seconds (default: 2 pi / the band's lower end)",
    "step": "time scene: constant time step in seconds (default: 0.3 / the band's upper end)",
    "scheme": "time scene: integrator of the full model and, with rom_method = scheme, of the ROMs",
    "rom_method": "time scene: ROMs stepped by the same scheme or by python-control's forced_response",
    "direction": "time scene: input direction b (u(t) = b s(t)) for a model with several inputs (default: ones)",
    "channel": "time scene: output channel drawn (1-based; the errors use all channels)",
    "axis": "error_vs_r, time_vs_r: x axis, the reduced order r or the number of first-order states (2r for a "
            "second-order ROM); pareto: which of the two is written beside each point (default: r)",
    "r_by_method": "orders of their own for some of the scene's methods, a table { alias = r } with r as in "
                   "'r' (e.g. a first-order reducer at 2r states beside second-order ones at r; default: none)",
    "time": "reduction time at this r alone (standalone) or of the reduce(r) call with shared work reused",
    "count": "number of Hankel singular values shown (default: all)",
}


def _rst_cell(text) -> str:
    """Plain text as one table cell: inline markup characters escaped, empty as a dash."""
    text = " ".join(str(text).split())
    for ch in "\\`*|_":
        text = text.replace(ch, "\\" + ch)
    return text or "\\-"


def list_table(header: list[str], rows: list[list[str]], widths: str | None = None) -> list[str]:
    """A ``list-table`` with a header row; cells are reStructuredText (one line each)."""
    lines = [".. list-table::", "   :header-rows: 1", "   :width: 100%"]
    if widths:
        lines.append(f"   :widths: {widths}")
    lines.append("")
    for row in [header] + rows:
        lines.append(f"   * - {row[0]}")
        lines += [f"     - {cell}" for cell in row[1:]]
    return lines + [""]


def _literal(value) -> str:
    return f"``{value!r}``"


def _toml(value) -> str:
    """A default as it is written in TOML (None: the key is not set)."""
    if value is None:
        return "not set"
    if isinstance(value, bool):
        return f"``{str(value).lower()}``"
    return f"``{json.dumps(value)}``"


# -- reducer options ---------------------------------------------------------
def option_rows(options: dict) -> list[list[str]]:
    """Rows (name, default, admissible values, description) of an ``OPTIONS`` table of either form."""
    rows = []
    for name, opt in options.items():
        if hasattr(opt, "describe"):  # morsuite.reducers.base.Option
            allowed = opt.describe() + (" or None" if opt.nullable else "")
            rows.append([f"``{name}``", _literal(opt.default), _rst_cell(allowed), _rst_cell(opt.doc)])
        else:  # (default, admissible values or type, description)
            default, allowed, doc = opt
            if isinstance(allowed, type):
                allowed = f"a {allowed.__name__}" + (" or None" if default is None else "")
            else:
                allowed = "one of " + ", ".join(repr(a) for a in allowed)
            rows.append([f"``{name}``", _literal(default), _rst_cell(allowed), _rst_cell(doc)])
    return rows


def options_table(options: dict, groups: dict | None = None) -> list[str]:
    """The top-level options' table, then one table per group of advanced options
    (:class:`morsuite.reducers.options.Group`): each option by its name in the group, with the name it is
    recorded under (and may be given as) where that differs."""
    groups = groups or {}
    grouped = {m for g in groups.values() for m in g.members}
    top = {k: v for k, v in options.items() if k not in grouped}
    lines = list_table(["option", "default", "admissible", "description"], option_rows(top), "14 10 20 56")
    for name, grp in groups.items():
        doc = _rst_cell(grp.doc[:1].upper() + grp.doc[1:])
        lines += [f".. rubric:: Advanced: ``{name}``", "", f"{doc}. Given as ``{name}={{...}}``; recorded (and "
                  "accepted) under the names in brackets.", ""]
        rows = option_rows({m: options[m] for m in grp.members})
        for row, m in zip(rows, grp.members):
            short = grp.short(m)
            row[0] = f"``{short}``" + (f" (``{m}``)" if short != m else "")
        lines += list_table(["option", "default", "admissible", "description"], rows, "14 10 20 56")
    return lines


def reducer_options_rst(name: str | None = None) -> list[str]:
    from morsuite import reducers

    names = [name] if name else reducers.available()
    lines = []
    for n in names:
        cls = reducers.get_class(n)
        if name is None:
            title = f"``{n}``"
            lines += [title, "-" * len(title), ""]
        lines += [f"Class :class:`{cls.__module__}.{cls.__qualname__}`; "
                  f"``ms.reducers.make({n!r}, fom, **options)``.", ""]
        lines += options_table(cls.OPTIONS, getattr(cls, "GROUPS", {}))
    return lines


def reducer_table_rows() -> list[list[str]]:
    """Rows (method, reduced model, targets, cost, use it for, options) of every registered reducer,
    read from its :class:`morsuite.reducers.Description`, in the registry's order."""
    from morsuite import reducers

    rows = []
    for name, m in reducers.methods().items():
        if m.name != m.reducer:
            continue
        d = m.description
        variants = [v for v in reducers.methods().values() if v.reducer == name and v.name != name]
        model = _rst_cell(f"{m.result.replace('-', ' ')}, "
                          + ("r states" if m.states_per_order == 1 else "order r (2r states)"))
        if variants:
            model += "; " + ", ".join(f"``{v.name}``" for v in variants) + " (" + \
                ", ".join(sorted({v.result.replace("-", " ") for v in variants})) + ")"
        page = f":doc:`{d.page}`" if d.page else ""
        rows.append([f"``{name}`` (``reducers/{d.family}/``{'; ' + page if page else ''})", model,
                     _rst_cell(d.targets), _rst_cell(d.cost), _rst_cell(d.use_for),
                     ", ".join(f"``{o}``" for o in d.options) or "\\-"])
    return rows


def reducer_table_rst() -> list[str]:
    return list_table(["method", "reduced model", "what it targets", "cost in sparse LUs", "use it for",
                       "options users set"], reducer_table_rows(), "14 18 18 16 18 16")


def _is_option_table(obj) -> bool:
    return (isinstance(obj, dict) and bool(obj)
            and all(hasattr(v, "describe") or _is_option_tuple(v) for v in obj.values()))


def _is_option_tuple(v) -> bool:
    return (isinstance(v, tuple) and len(v) == 3 and isinstance(v[2], str)
            and (isinstance(v[1], type) or isinstance(v[1], (tuple, list))))


def _append_options(app, what, name, obj, options, lines):
    if what in ("class", "exception"):
        table = getattr(obj, "OPTIONS", None)
    else:
        table = obj if what == "data" and name.endswith(".OPTIONS") else None
    if table is None or not _is_option_table(table) or (what == "class" and "OPTIONS" not in vars(obj)):
        return
    groups = getattr(obj, "GROUPS", {}) if what in ("class", "exception") else {}
    lines += ["", ".. rubric:: Options", ""] + options_table(table, groups)


def _skip_options(app, what, name, obj, skip, options):
    if name == "OPTIONS" and _is_option_table(obj) and what in ("class", "exception"):
        return True
    return None


# -- study spec keys ---------------------------------------------------------
def _doc(table: dict, key: str, where: str, **fmt) -> str:
    if key not in table:
        logger.warning("study spec key %r (%s) has no description in docs/_ext/morsuite_tables.py", key, where)
        return ""
    text = table[key]
    for name, value in fmt.items():
        text = text.replace("{" + name + "}", str(value))
    return text


def _admissible(choices) -> str:
    """What a scene key admits: a list of choices, or a validator (its ``choices``, its
    ``describe`` text, or the first line of its docstring)."""
    if choices is None:
        return "a positive integer"
    if callable(choices):
        if getattr(choices, "choices", None) is not None:
            return ", ".join(json.dumps(c) for c in choices.choices)
        text = getattr(choices, "describe", None) or (choices.__doc__ or "").strip().splitlines()[0]
        if not text:
            logger.warning("scene key validator %r has neither choices, describe nor a docstring", choices)
        return text
    return ", ".join(json.dumps(c) for c in choices)


def spec_keys_rst() -> list[str]:
    from morsuite.studies import scenes, spec

    lines = ["Top level", "---------", ""]
    lines += list_table(["key", "meaning"], [[f"``{k}``", _rst_cell(_doc(SPEC_KEY_DOCS, k, "top level"))]
                                             for k in spec.TOP_KEYS], "20 80")
    lines += ["``[grids.NAME]``", "-----------------", ""]
    lines += list_table(["key", "meaning"],
                        [[f"``{k}``", _rst_cell(_doc(SPEC_KEY_DOCS, f"grids.{k}", "grids", n=spec.DEFAULT_GRID_N))]
                         for k in spec.GRID_KEYS], "20 80")
    lines += ["``[methods.ALIAS]``", "--------------------", ""]
    lines += list_table(["key", "meaning"], [[f"``{k}``", _rst_cell(_doc(SPEC_KEY_DOCS, f"methods.{k}", "methods"))]
                                             for k in spec.METHOD_KEYS], "20 80")
    lines += ["``[[scenes]]``", "--------------", ""]
    kind_keys = []
    for kind in scenes.KINDS.values():
        kind_keys += [k for k in kind.keys if k not in kind_keys]
    rows = []
    for key in list(scenes.COMMON_KEYS) + kind_keys:
        rows.append([f"``{key}``", _rst_cell(_doc(SCENE_KEY_DOCS, key, "scenes"))])
    lines += list_table(["key", "meaning"], rows, "20 80")
    lines += ["Scene kinds", "-----------", ""]
    rows = []
    for name, kind in scenes.KINDS.items():
        extra = []
        for key, (default, choices) in kind.keys.items():
            if key in ("r", "grid", "paper_csv"):
                continue
            allowed = _admissible(choices)
            extra.append(f"``{key}``: {_toml(default)} ({_rst_cell(allowed)})")
        needs = ["a grid" if kind.uses_grid else "no grid",
                 "no r" if not kind.needs_r else "one r" if kind.one_r else "any number of r"]
        if kind.min_methods > 1:
            needs.append(f"at least {kind.min_methods} methods")
        rows.append([f"``{name}``", _rst_cell(kind.doc), ", ".join(needs), "; ".join(extra) or "\\-"])
    lines += list_table(["kind", "shows", "needs", "own keys (default, admissible)"], rows, "12 38 20 30")
    return lines


# -- command line ------------------------------------------------------------
def _parsers():
    from morsuite import cli

    built = cli.build_parser()
    parser = built[0] if isinstance(built, tuple) else built
    subs = {}
    for action in parser._actions:  # argparse keeps its subparsers only here
        if isinstance(action, argparse._SubParsersAction):
            subs.update(action.choices)
    return parser, subs


def _default(action) -> str:
    if action.required or action.default in (None, argparse.SUPPRESS):
        return "required" if action.required else "\\-"
    return _literal(action.default)


def cli_rst() -> list[str]:
    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"  # argparse wraps help to the terminal width: fix it
    try:
        parser, subs = _parsers()
        lines = ["``morsuite --help``", "-------------------", "", "::", ""]
        lines += ["   " + ln for ln in parser.format_help().splitlines()] + [""]
        for name, sub in subs.items():
            title = f"``morsuite {name}``"
            lines += [title, "-" * len(title), "", "::", ""]
            lines += ["   " + ln for ln in sub.format_help().splitlines()] + [""]
            rows = []
            for action in sub._actions:
                if isinstance(action, argparse._HelpAction):
                    continue
                flag = ", ".join(action.option_strings) or (action.metavar or action.dest)
                rows.append([f"``{flag}``", _default(action), _rst_cell(action.help or "")])
            if rows:
                lines += list_table(["argument", "default", "meaning"], rows, "22 18 60")
    finally:
        if old is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = old
    return lines


# -- refused inputs ----------------------------------------------------------
def refused_rst() -> list[str]:
    refused = importlib.import_module("morsuite.stress.refused")
    rows, skipped = refused.table_rows()
    by_area: dict[str, list] = {}
    for area, what, got, msg, key in rows:
        if "expected" in got or "not refused" in got:
            logger.warning("refused-inputs row %r: %s (message: %s)", key, got, msg)
        by_area.setdefault(area, []).append([_rst_cell(what), f"``{got}``", _rst_cell(msg), f"``{key}``"])
    lines = []
    for area, out in by_area.items():
        title = area[:1].upper() + area[1:]
        lines += [title, "-" * len(title), ""]
        lines += list_table(["input", "error", "message", "test id"], out, "24 16 46 14")
    if skipped:
        lines += [f"Left out (no ``{refused.DATA_FILE}`` in the data directory): "
                  + ", ".join(f"``{k}``" for k in skipped) + ".", ""]
    return lines


class _Generated(Directive):
    optional_arguments = 1
    has_content = False
    make = None

    def run(self):
        env = self.state.document.settings.env
        _generated_docs(env).add(env.docname)
        text = type(self).make(*self.arguments)
        node = nodes.section()
        node.document = self.state.document
        nested_parse_with_titles(self.state, StringList(text, source=f"<{self.name}>"), node)
        return node.children


def _directive(fn):
    return type(fn.__name__, (_Generated,), {"make": staticmethod(fn)})


def setup(app):
    app.setup_extension("morsuite_api")
    app.add_directive("morsuite-reducer-options", _directive(reducer_options_rst))
    app.add_directive("morsuite-reducer-table", _directive(reducer_table_rst))
    app.add_directive("morsuite-spec-keys", _directive(spec_keys_rst))
    app.add_directive("morsuite-cli", _directive(cli_rst))
    app.add_directive("morsuite-refused-table", _directive(refused_rst))
    app.connect("autodoc-process-docstring", _append_options, priority=600)  # after numpydoc
    app.connect("autodoc-skip-member", _skip_options)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
