"""Every public name of the API has a docstring, and every public module has an API page.

The public names are those the API reference documents (docs/_ext/morsuite_api.py):
each package's ``__all__`` (or, without one, the classes and functions it defines),
the public methods and properties of each such class, including those inherited from
private bases, and every public module below ``morsuite``. ``KNOWN_MISSING`` is empty:
every public name has a docstring. A name may be listed there only for a while, with
the reason in a comment; a listed name that gained its docstring is simply deleted.
"""

from __future__ import annotations


import importlib
import inspect
import pkgutil
import re
from pathlib import Path

import pytest

import morsuite

DOCS_API = Path(__file__).resolve().parents[1] / "docs" / "api"

#: no docstring yet (emptied: every public name now has one; add a name here only with a reason)
KNOWN_MISSING: set[str] = set()


def public_modules() -> list[str]:
    """Every public module and package below ``morsuite`` (no ``_private`` part in its name)."""
    out = []
    for info in pkgutil.walk_packages(morsuite.__path__, "morsuite."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            out.append(info.name)
    return sorted(out)


def _exported(mod) -> list[str]:
    names = getattr(mod, "__all__", None)
    if names is not None:
        return [n for n in names if not n.startswith("__")]
    return [n for n, o in vars(mod).items() if not n.startswith("_") and (inspect.isclass(o) or inspect.isroutine(o))
            and getattr(o, "__module__", None) == mod.__name__]


def _canonical(obj, fallback: str) -> str:
    mod, qual = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    return f"{mod}.{qual}" if mod and qual and mod.startswith("morsuite") else fallback


def _member_function(value):
    if isinstance(value, property):
        return value.fget
    if isinstance(value, (classmethod, staticmethod)):
        return value.__func__
    return value if inspect.isfunction(value) else None


def _class_members(cls):
    """Public methods and properties of ``cls`` defined in morsuite: its own and its private bases'."""
    for klass in cls.__mro__:
        if not klass.__module__.startswith("morsuite") or (klass is not cls and not klass.__name__.startswith("_")):
            continue
        for name, value in vars(klass).items():
            fn = _member_function(value)
            if not name.startswith("_") and fn is not None:
                yield f"{_canonical(cls, cls.__name__)}.{name}", fn


def undocumented() -> set[str]:
    """Canonical names of public modules, classes, functions and members without a docstring."""
    missing = set()
    for modname in public_modules():
        mod = importlib.import_module(modname)
        if not (mod.__doc__ or "").strip():
            missing.add(modname)
        for name in _exported(mod):
            obj = getattr(mod, name, None)
            if not (inspect.isclass(obj) or inspect.isroutine(obj)):
                continue
            if not (obj.__doc__ or "").strip():
                missing.add(_canonical(obj, f"{modname}.{name}"))
            if inspect.isclass(obj):
                missing |= {full for full, fn in _class_members(obj) if not (fn.__doc__ or "").strip()}
    return missing


def test_every_public_name_has_a_docstring():
    new = sorted(undocumented() - KNOWN_MISSING)
    assert not new, "public names without a docstring:\n  " + "\n  ".join(new)


def test_every_public_module_is_in_the_api_reference():
    # docs/api/NAME.rst renders `.. morsuite-api:: PACKAGE`, which documents PACKAGE and every
    # public module below it; a module outside every such package is missing from the docs
    roots = set()
    for page in DOCS_API.glob("*.rst"):
        roots |= set(re.findall(r"^\.\. morsuite-api:: (\S+)\s*$", page.read_text(), flags=re.M))
    assert roots, f"no morsuite-api directive found in {DOCS_API}"
    uncovered = [m for m in public_modules() if not any(m == r or m.startswith(r + ".") for r in roots)]
    assert not uncovered, "modules without an API page (add docs/api/NAME.rst): " + ", ".join(uncovered)


def test_every_study_spec_key_is_described_for_the_docs(monkeypatch):
    """The docs' spec-key tables (docs/_ext/morsuite_tables.py) warn, and so fail the -W build,
    for a key without a description: catch it here, where a new key is added (where the
    docs' requirements are installed)."""
    # the extension imports docutils and sphinx.util: skip unless every module it imports loads
    # (sphinx alone can be there without a docutils it accepts)
    for name in ("docutils", "docutils.parsers.rst", "docutils.statemachine", "sphinx", "sphinx.util",
                 "sphinx.util.nodes"):
        pytest.importorskip(name)
    import importlib.util
    from pathlib import Path

    from morsuite.studies import scenes, spec

    path = Path(__file__).resolve().parents[1] / "docs" / "_ext" / "morsuite_tables.py"
    monkeypatch.syspath_prepend(str(path.parent))  # it imports its sibling extension
    mod_spec = importlib.util.spec_from_file_location("morsuite_tables_for_test", path)
    tables = importlib.util.module_from_spec(mod_spec)
    mod_spec.loader.exec_module(tables)
    missing = [k for k in spec.TOP_KEYS if k not in tables.SPEC_KEY_DOCS]
    missing += [f"grids.{k}" for k in spec.GRID_KEYS if f"grids.{k}" not in tables.SPEC_KEY_DOCS]
    missing += [f"methods.{k}" for k in spec.METHOD_KEYS if f"methods.{k}" not in tables.SPEC_KEY_DOCS]
    keys = set(scenes.COMMON_KEYS)
    for kind in scenes.KINDS.values():
        keys |= set(kind.keys)
        for key, (_default, choices) in kind.keys.items():
            assert tables._admissible(choices), f"scene key {key!r}: its validator describes nothing"
    missing += sorted(k for k in keys if k not in tables.SCENE_KEY_DOCS)
    assert not missing, f"spec keys without a description in docs/_ext/morsuite_tables.py: {missing}"
