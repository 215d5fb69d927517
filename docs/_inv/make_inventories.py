"""Write the intersphinx inventories of numpy, scipy, python-control, matplotlib, pandas, Python.

The documentation is built without network access (CI reaches PyPI only), so
intersphinx cannot download ``objects.inv`` from the projects' sites. This
script writes small inventories instead, from the public API of the packages
installed here, with the URLs under which those projects publish each object
(the page layouts of their Sphinx sites, below). ``conf.py`` points
``intersphinx_mapping`` at the files it writes, ``docs/_inv/NAME.inv``.

Regenerate after upgrading one of the packages (the output is sorted, so an
unchanged API gives an unchanged file)::

    python docs/_inv/make_inventories.py

What is listed: the public functions and classes of the modules in
``PROJECTS`` (their ``__all__``, or their public names), each class's public
methods and attributes, the modules themselves, and each class once more under
the name of the module that defines it (autodoc writes evaluated annotations
that way, e.g. ``scipy.sparse._csc.csc_matrix``). The URL of an object
follows its project's layout: numpy and scipy put every function, class and
method on a page of its own (``reference/generated/NAME.html``; numpy's
random generators and scalar types have their own pages), python-control a page per function
and class with the methods on the class's page (``generated/NAME.html``),
matplotlib a page per pyplot function and per Axes and Figure method and a
page per class elsewhere (``api/_as_gen/NAME.html``), pandas a page per
object (``reference/api/NAME.html``), Python a page per standard-library
module and two for the builtins. Names those projects
document on irregular pages may point at a page that does not exist; every
name morsuite's docs refer to was checked by hand.
"""

from __future__ import annotations

import importlib
import inspect
import sys
import zlib
from pathlib import Path

HERE = Path(__file__).resolve().parent

#: project -> (package, documentation root, modules whose public names are listed)
PROJECTS = {
    "numpy": ("numpy", "https://numpy.org/doc/stable/", ["numpy", "numpy.linalg", "numpy.fft", "numpy.random"]),
    "scipy": ("scipy", "https://docs.scipy.org/doc/scipy/",
              ["scipy.linalg", "scipy.sparse", "scipy.sparse.linalg", "scipy.sparse.csgraph", "scipy.integrate",
               "scipy.interpolate", "scipy.io", "scipy.optimize", "scipy.signal", "scipy.fft", "scipy.special",
               "scipy.stats", "scipy.spatial"]),
    "control": ("control", "https://python-control.readthedocs.io/en/stable/", ["control"]),
    "matplotlib": ("matplotlib", "https://matplotlib.org/stable/",
                   ["matplotlib.pyplot", "matplotlib.figure", "matplotlib.axes", "matplotlib.lines",
                    "matplotlib.colors", "matplotlib.ticker", "matplotlib.collections", "matplotlib.patches",
                    "matplotlib.text", "matplotlib.legend", "matplotlib.gridspec", "matplotlib.image"]),
    "pandas": ("pandas", "https://pandas.pydata.org/docs/", ["pandas"]),
    "python": ("sys", "https://docs.python.org/3/",
               ["pathlib", "dataclasses", "typing", "warnings", "json", "tomllib", "contextlib", "argparse",
                "tempfile", "functools", "collections", "numbers"]),
}

#: pages of modules (the ``module-NAME`` anchor is added)
MODULE_PAGES = {
    "numpy": "reference/index.html", "numpy.linalg": "reference/routines.linalg.html",
    "numpy.fft": "reference/routines.fft.html", "numpy.random": "reference/random/index.html",
    "control": "index.html", "matplotlib.pyplot": "api/pyplot_summary.html", "pandas": "reference/index.html",
}

#: the projects' names as their own inventories spell them (shown in link titles)
TITLES = {"numpy": "NumPy", "scipy": "SciPy", "control": "Python Control Systems Library",
          "matplotlib": "Matplotlib", "pandas": "pandas", "python": "Python"}

#: numpy constants, documented on one page
NUMPY_CONSTANTS = ("e", "euler_gamma", "inf", "nan", "newaxis", "pi")


def _public(mod) -> list[str]:
    names = getattr(mod, "__all__", None)
    if names is None:
        names = [n for n in dir(mod) if not n.startswith("_")]
    return sorted(n for n in set(names) if not n.startswith("_"))


def _role(obj) -> str | None:
    if inspect.ismodule(obj):
        return None
    if inspect.isclass(obj):
        return "py:exception" if issubclass(obj, BaseException) else "py:class"
    if callable(obj):
        return "py:function"
    return None


def _members(cls) -> list[tuple[str, str]]:
    """Public methods and attributes of ``cls``, inherited ones included (the projects document
    those on the class's pages too), except what builtin types define."""
    if issubclass(cls, BaseException):
        return []
    out = []
    for name in dir(cls):
        if name.startswith("_"):
            continue
        owner = next((k for k in cls.__mro__ if name in vars(k)), None)
        if owner is None or owner.__module__ == "builtins":
            continue
        value = vars(owner)[name]
        if isinstance(value, property) or type(value).__name__ in ("getset_descriptor", "member_descriptor"):
            out.append((name, "py:attribute"))
        elif callable(value) or isinstance(value, (classmethod, staticmethod)):
            out.append((name, "py:method"))
    return out


# -- URL layouts ---------------------------------------------------------------
def numpy_uri(name: str, role: str, cls: str | None) -> str:
    if role == "py:module":
        return MODULE_PAGES[name] + f"#module-{name}"
    if name.startswith("numpy.random."):
        leaf = name.split(".")[2]
        if leaf in ("Generator", "default_rng") and cls is None:
            return f"reference/random/generator.html#{name}"
        if leaf == "RandomState" and cls is None:
            return f"reference/random/legacy.html#{name}"
        return f"reference/random/generated/{name}.html#{name}"
    return f"reference/generated/{name}.html#{name}"


def scipy_uri(name: str, role: str, cls: str | None) -> str:
    if role == "py:module":
        return f"reference/{name.removeprefix('scipy.')}.html#module-{name}"
    return f"reference/generated/{name}.html#{name}"


def control_uri(name: str, role: str, cls: str | None) -> str:
    if role == "py:module":
        return MODULE_PAGES[name]
    return f"generated/{cls or name}.html#{name}"


def matplotlib_uri(name: str, role: str, cls: str | None) -> str:
    if role == "py:module":
        short = name.removeprefix("matplotlib.")
        return MODULE_PAGES.get(name, f"api/{short}_api.html") + f"#module-{name}"
    if cls in ("matplotlib.axes.Axes", "matplotlib.figure.Figure") or name.startswith("matplotlib.pyplot."):
        return f"api/_as_gen/{name}.html#{name}"
    return f"api/_as_gen/{cls or name}.html#{name}"


def pandas_uri(name: str, role: str, cls: str | None) -> str:
    if role == "py:module":
        return MODULE_PAGES[name] + f"#module-{name}"
    return f"reference/api/{name}.html#{name}"


def python_uri(name: str, role: str, cls: str | None) -> str:
    """The standard library: one page per module, ``library/MODULE.html``."""
    if role == "py:module":
        return f"library/{name}.html#module-{name}"
    return f"library/{name.split('.')[0]}.html#{name}"


def python_builtins() -> dict:
    """Built-in functions, types and exceptions (two pages of the Python docs)."""
    import builtins

    out = {}
    for name in dir(builtins):
        obj = getattr(builtins, name)
        if name.startswith("_") or not callable(obj):
            continue
        if inspect.isclass(obj) and issubclass(obj, BaseException):
            out[name] = ("py:exception", f"library/exceptions.html#{name}")
        elif inspect.isclass(obj):
            out[name] = ("py:class", f"library/functions.html#{name}")
        else:
            out[name] = ("py:function", f"library/functions.html#{name}")
    return out


URIS = {"numpy": numpy_uri, "scipy": scipy_uri, "control": control_uri, "matplotlib": matplotlib_uri,
        "pandas": pandas_uri, "python": python_uri}


def entries(project: str) -> list[tuple[str, str, str]]:
    """``(name, role, uri)`` of every object listed for ``project``."""
    _, _, modules = PROJECTS[project]
    uri = URIS[project]
    seen, aliases = {}, {}
    for modname in modules:
        mod = importlib.import_module(modname)
        seen.setdefault(modname, ("py:module", uri(modname, "py:module", None)))
        for name in _public(mod):
            obj = getattr(mod, name, None)
            role = _role(obj)
            full = f"{modname}.{name}"
            if role is None or full in seen:
                continue
            # pyplot and friends re-export other modules' classes: list them where they live
            if project in ("matplotlib", "python") and not getattr(obj, "__module__", "").startswith(modname):
                continue
            if project == "numpy" and inspect.isclass(obj) and issubclass(obj, sys.modules["numpy"].generic):
                # scalar types share one page and have no pages for their methods
                seen[full] = (role, f"reference/arrays.scalars.html#{full}")
                continue
            seen[full] = (role, uri(full, role, None))
            if inspect.isclass(obj):
                # evaluated annotations name a class where it is defined
                # (scipy.sparse._csc.csc_matrix): the same page under that name too
                home = f"{obj.__module__}.{obj.__qualname__}"
                if home != full:
                    aliases.setdefault(home, seen[full])
                for member, mrole in _members(obj):
                    mfull = f"{full}.{member}"
                    seen.setdefault(mfull, (mrole, uri(mfull, mrole, full)))
    for name, value in aliases.items():
        seen.setdefault(name, value)
    if project == "python":
        seen.update(python_builtins())
    if project == "numpy":
        for const in NUMPY_CONSTANTS:
            seen[f"numpy.{const}"] = ("py:data", f"reference/constants.html#numpy.{const}")
    return sorted((name, role, u) for name, (role, u) in seen.items())


def write_inventory(path: Path, project: str, version: str, rows) -> None:
    """Sphinx inventory format version 2: a text header, then zlib-compressed lines."""
    header = (f"# Sphinx inventory version 2\n# Project: {project}\n# Version: {version}\n"
              "# The remainder of this file is compressed using zlib.\n")
    # "$" at the end of a location stands for the object's name (the format's shorthand)
    body = "".join(f"{name} {role} 1 {uri[:-len(name)] + '$' if uri.endswith('#' + name) else uri} -\n"
                   for name, role, uri in rows)
    path.write_bytes(header.encode() + zlib.compress(body.encode(), 9))


def main(argv=None) -> int:
    out = HERE
    for project, (package, _, _) in PROJECTS.items():
        version = (f"{sys.version_info.major}.{sys.version_info.minor}" if project == "python"
                   else importlib.import_module(package).__version__)
        rows = entries(project)
        write_inventory(out / f"{project}.inv", TITLES[project], version, rows)
        print(f"{project} {version}: {len(rows)} objects -> {out / (project + '.inv')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
