"""Sphinx extension: the API reference of a morsuite package, generated at build time.

``.. morsuite-api:: morsuite.models`` renders, for a package,

1. its docstring (``automodule``) and the names it exports (``__all__``), each
   linked to the place where it is documented, with the first line of its
   docstring;
2. one section per public submodule (recursively, ``_private`` ones skipped):
   its docstring and ``automodule`` of the names *defined* there.

A name is documented once, in the module that defines it (the place the
docstrings' own cross references point to, e.g.
``:class:`~morsuite.linalg.saddle.SaddlePointSolver```); names a package
exports from a private module (``norms._fom``) or defines itself are
documented in the package section. For a plain module (``morsuite.rom``) only
step 2 is done. The module list is read from the package when the docs are
built, so a new module appears without editing the docs.

What a module documents (:func:`documented_names`): the names of its
``__all__`` that it defines; without ``__all__``, the public classes and
functions it defines and the data it assigns with a ``#:`` doc comment.
Imported names are never documented twice.

A reference by the name users type (``:func:`morsuite.reducers.make```,
``:class:`morsuite.models.Index3Model```) or by a name the current module
imports (``:class:`SingularShiftError```) resolves to the object's documented
entry, and ``np.``/``pd.`` in annotations to numpy and pandas. Pages that use the directive are re-read on every build (their content
depends on the code, not on the page's text).
"""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil

from docutils import nodes
from docutils.parsers.rst import Directive
from docutils.statemachine import StringList
from sphinx.pycode import ModuleAnalyzer
from sphinx.util.nodes import nested_parse_with_titles

#: section underline characters by depth (the page title uses "=")
_UNDERLINES = "-~^\""
#: data whose repr is longer than this is shown without its value
_MAX_VALUE = 80


def public_submodules(modname: str) -> list[str]:
    """Public submodules of package ``modname`` (depth first, sorted); [] for a module."""
    mod = importlib.import_module(modname)
    if not hasattr(mod, "__path__"):
        return []
    out = []
    for info in sorted(pkgutil.iter_modules(mod.__path__), key=lambda i: i.name):
        if info.name.startswith("_"):
            continue
        full = f"{modname}.{info.name}"
        out.append(full)
        out.extend(public_submodules(full))
    return out


def _assigned_names(mod) -> set[str]:
    """Names bound by top-level assignments in the module's source."""
    try:
        tree = ast.parse(inspect.getsource(mod))
    except (OSError, TypeError):
        return set()
    names = set()
    for node in tree.body:
        targets = []
        if isinstance(node, ast.Assign):
            targets = node.targets
        elif isinstance(node, (ast.AnnAssign, ast.AugAssign)):
            targets = [node.target]
        for t in targets:
            for n in ast.walk(t):
                if isinstance(n, ast.Name):
                    names.add(n.id)
    return names


def _defined_here(mod, name: str, assigned: set[str]) -> bool:
    obj = getattr(mod, name, None)
    if inspect.ismodule(obj):
        return False
    if inspect.isclass(obj) or inspect.isroutine(obj):
        return getattr(obj, "__module__", None) == mod.__name__
    return name in assigned


def _exported_by_parents(mod) -> list[str]:
    """Classes and functions defined in ``mod`` that a parent package exports (``models`` exports
    ``catalog.register`` although ``catalog.__all__`` leaves it out): documented here too."""
    parts = mod.__name__.split(".")
    out = []
    for i in range(1, len(parts)):
        parent = importlib.import_module(".".join(parts[:i]))
        for name in getattr(parent, "__all__", []):
            obj = getattr(parent, name, None)
            if ((inspect.isclass(obj) or inspect.isroutine(obj)) and getattr(obj, "__module__", None) == mod.__name__
                    and getattr(mod, obj.__name__, None) is obj and obj.__name__ not in out):
                out.append(obj.__name__)
    return out


def documented_names(modname: str) -> list[str]:
    """The names documented in module ``modname`` (see the module docstring)."""
    mod = importlib.import_module(modname)
    assigned = _assigned_names(mod)
    exported = getattr(mod, "__all__", None)
    if exported is not None:
        names = [n for n in exported if hasattr(mod, n) and _defined_here(mod, n, assigned)]
        return names + [n for n in _exported_by_parents(mod) if n not in names]
    try:
        attr_docs = {name for (_, name) in ModuleAnalyzer.for_module(modname).find_attr_docs()}
    except Exception:  # noqa: BLE001 - no source: document classes and functions only
        attr_docs = set()
    out = []
    for name, obj in vars(mod).items():
        if name.startswith("_") or not _defined_here(mod, name, assigned):
            continue
        if inspect.isclass(obj) or inspect.isroutine(obj) or name in attr_docs:
            out.append(name)
    return out


def canonical_target(pkgname: str, name: str):
    """``(role, target)`` of the place where ``pkgname.name`` is documented."""
    pkg = importlib.import_module(pkgname)
    obj = getattr(pkg, name)
    if inspect.ismodule(obj):
        return "mod", obj.__name__
    home = getattr(obj, "__module__", None) if (inspect.isclass(obj) or inspect.isroutine(obj)) else None
    if home and home != pkgname and not _is_private(home) and home.startswith("morsuite"):
        return "obj", f"{home}.{obj.__qualname__}"
    return "obj", f"{pkgname}.{name}"


def _is_private(modname: str) -> bool:
    return any(part.startswith("_") for part in modname.split("."))


def package_local_names(pkgname: str) -> list[str]:
    """Exported names documented in the package section (defined there or in a private module)."""
    pkg = importlib.import_module(pkgname)
    out = []
    for name in getattr(pkg, "__all__", []):
        if name.startswith("__"):
            continue
        role, target = canonical_target(pkgname, name)
        if role == "obj" and target == f"{pkgname}.{name}":
            out.append(name)
    return out


def first_line(obj) -> str:
    doc = inspect.getdoc(obj) if (inspect.isclass(obj) or inspect.isroutine(obj) or inspect.ismodule(obj)) else None
    if not doc:
        return ""
    line = doc.strip().split("\n\n")[0].replace("\n", " ").strip()
    return line


def _title(text: str, depth: int) -> list[str]:
    return [text, _UNDERLINES[depth] * len(text), ""]


def _object_directive(modname: str, name: str) -> list[str]:
    """``autoclass``/``autoexception``/``autofunction``/``autodata`` of one documented name.

    Classes list every public member, documented or not (a missing docstring
    shows as a bare signature; tests/test_docstrings.py asks for it), and the
    members they inherit from private bases (``rom._ROMBase``): those are
    documented nowhere else.
    """
    obj = getattr(importlib.import_module(modname), name)
    full = f"{modname}.{name}"
    if inspect.isclass(obj):
        kind = "autoexception" if issubclass(obj, BaseException) else "autoclass"
        lines = [f".. {kind}:: {full}", "   :members:", "   :undoc-members:"]
        if obj.__bases__ != (object,):
            lines.append("   :show-inheritance:")
        bases = obj.__mro__[1:]
        private = [b for b in bases if b.__module__.startswith("morsuite") and b.__name__.startswith("_")]
        if private:
            public = [b.__name__ for b in bases if b not in private]
            lines.append("   :inherited-members: " + ", ".join(public or ["object"]))
        return lines + [""]
    if inspect.isroutine(obj):
        return [f".. autofunction:: {full}", ""]
    # a long value (a table) is unreadable in a signature; option tables are
    # rendered as tables by morsuite_tables
    return [f".. autodata:: {full}"] + (["   :no-value:"] if len(repr(obj)) > _MAX_VALUE else []) + [""]


def _source_order(modname: str, names: list[str]) -> list[str]:
    mod = importlib.import_module(modname)
    if getattr(mod, "__all__", None) is not None:
        return names
    try:
        order = ModuleAnalyzer.for_module(modname).tagorder
    except Exception:  # noqa: BLE001 - no source: keep the given order
        return names
    return sorted(names, key=lambda n: order.get(n, len(order)))


def module_rst(modname: str, names: list[str]) -> list[str]:
    """The module's docstring and one directive per documented name."""
    lines = [f".. automodule:: {modname}", ""]
    for name in _source_order(modname, names):
        lines += _object_directive(modname, name)
    return lines


def package_rst(pkgname: str) -> list[str]:
    """reStructuredText of the API reference of ``pkgname`` (a package or a module)."""
    mod = importlib.import_module(pkgname)
    lines: list[str] = []
    subs = public_submodules(pkgname)
    if not subs:
        return module_rst(pkgname, documented_names(pkgname))
    lines += module_rst(pkgname, package_local_names(pkgname))
    exported = [n for n in getattr(mod, "__all__", []) if not n.startswith("__")]
    if exported:
        lines += [".. rubric:: Exported names", "", ".. list-table::", "   :widths: 30 70", ""]
        for name in exported:
            role, target = canonical_target(pkgname, name)
            summary = first_line(getattr(mod, name)).replace("|", "\\|")
            lines += [f"   * - :py:{role}:`{name} <{target}>`", f"     - {summary}" if summary else "     -"]
        lines.append("")
    base_depth = pkgname.count(".")
    for sub in subs:
        depth = sub.count(".") - base_depth - 1
        lines += _title(f"``{sub}``", min(depth, len(_UNDERLINES) - 1))
        lines += module_rst(sub, documented_names(sub))
    return lines


class MorsuiteAPI(Directive):
    """``.. morsuite-api:: PACKAGE``: see the module docstring."""

    required_arguments = 1
    has_content = False

    def run(self):
        pkgname = self.arguments[0]
        env = self.state.document.settings.env
        _generated_docs(env).add(env.docname)
        try:
            text = package_rst(pkgname)
        except ImportError as exc:
            return [self.state.document.reporter.warning(f"morsuite-api: cannot import {pkgname}: {exc}",
                                                         line=self.lineno)]
        node = nodes.section()
        node.document = self.state.document
        nested_parse_with_titles(self.state, StringList(text, source=f"<morsuite-api {pkgname}>"), node)
        return node.children


# -- references by public name, by short name, and through np./pd. -----------
#: abbreviations of annotations (``np.ndarray``) -> the package intersphinx knows
_ABBREVIATIONS = {"np.": "numpy.", "pd.": "pandas.", "sp.": "scipy.sparse.", "sla.": "scipy.linalg.",
                  "spla.": "scipy.sparse.linalg."}


def canonical_name(target: str) -> str | None:
    """Where the morsuite object ``target`` is documented: the defining module's name of it
    (``morsuite.analysis.h2_norm`` -> ``morsuite.norms.h2.h2_norm``), or None."""
    if not target.startswith("morsuite."):
        return None
    parts = target.split(".")
    for i in range(len(parts) - 1, 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        try:
            for attr in parts[i:]:
                obj = getattr(obj, attr)
        except AttributeError:
            return None
        break
    else:
        return None
    if inspect.ismodule(obj):
        return obj.__name__
    mod, qual = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    if not (inspect.isclass(obj) or inspect.isroutine(obj)) or not mod or not qual:
        return None
    return f"{mod}.{qual}"


def _resolve_public_name(app, env, node, contnode):
    """Resolve what the Python domain could not: a morsuite object by the name users type
    (``morsuite.reducers.make``), a short name imported into the current module
    (``SingularShiftError`` in ``morsuite.reducers.irka.second_order``), ``np.``/``pd.`` abbreviations."""
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "")
    for short, full in _ABBREVIATIONS.items():
        if target.startswith(short):
            from sphinx.ext.intersphinx import missing_reference

            expanded = node.deepcopy()
            expanded["reftarget"] = full + target[len(short):]
            return missing_reference(app, env, expanded, contnode)
    modname, clsname = node.get("py:module"), node.get("py:class")
    candidates = [target]
    if modname and not target.startswith("morsuite."):
        candidates = ([f"{modname}.{clsname}.{target}"] if clsname else []) + [f"{modname}.{target}"]
    domain = env.domains["py"]
    for candidate in candidates:
        try:
            canonical = canonical_name(candidate)
        except Exception:  # noqa: BLE001 - an import failing here only means: not resolvable
            canonical = None
        if canonical is not None:
            found = domain.resolve_xref(env, node["refdoc"], app.builder, node["reftype"], canonical, node,
                                        contnode)
            if found is not None:
                return found
    return None


# -- pages with generated content are read again on every build ------------
def _generated_docs(env) -> set:
    if not hasattr(env, "morsuite_generated_docs"):
        env.morsuite_generated_docs = set()
    return env.morsuite_generated_docs


def _purge(app, env, docname):
    _generated_docs(env).discard(docname)


def _merge(app, env, docnames, other):
    _generated_docs(env).update(_generated_docs(other) & set(docnames))


def _outdated(app, env, added, changed, removed):
    return sorted(_generated_docs(env) - set(removed))


def setup(app):
    app.add_directive("morsuite-api", MorsuiteAPI)
    app.connect("env-purge-doc", _purge)
    app.connect("env-merge-info", _merge)
    app.connect("env-get-outdated", _outdated)
    app.connect("missing-reference", _resolve_public_name)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
