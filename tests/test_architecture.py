"""The package's import graph follows its layers (``docs/design/architecture.md``).

The rule, checked on every ``import`` and ``from ... import`` of every module under
``morsuite/`` (function-local and ``TYPE_CHECKING`` imports included: a late import is
still a dependency), parsed with ``ast`` without importing anything:

- shared leaves (``errors``, ``utils``, ``rom``, ``romfiles``, ``modelfiles``) import only each other;
- ``linalg`` is the kernel layer below the models: it takes matrices or any object
  providing ``linalg.system.ConstrainedSystem``, and imports only the leaves;
- then ``models -> reducers -> analysis -> studies``: each imports the leaves and the
  layers before it (``models`` may build a ``linalg`` solver; ``linalg`` never sees a model);
- ``report`` renders plain data: it imports only the leaves ("reports never solve"),
  and ``studies``, which schedules the writing of artifacts, imports it;
- drivers (the package root, ``__main__``, ``cli``, ``bench*``, ``stress*``) may
  import anything; anyone may import ``__version__`` from the root.

So the data-flow diagram ``models -> linalg -> reducers -> analysis -> studies -> report``
reads, as imports: ``linalg < models < reducers < analysis < studies``, with ``report`` a
side leaf of ``studies``.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

import morsuite

PKG = Path(morsuite.__file__).resolve().parent
LEAVES = {"errors", "utils", "rom", "romfiles", "modelfiles"}
CHAIN = ["linalg", "models", "norms", "reducers", "analysis", "studies"]
ALLOWED = {"leaf": {"leaf"}, "report": {"leaf", "report"}}
for _i, _layer in enumerate(CHAIN):
    ALLOWED[_layer] = {"leaf", *CHAIN[: _i + 1]} | ({"report"} if _layer == "studies" else set())

#: known back-edges awaiting a fix elsewhere: (importer prefix, imported module, names). Each must
#: still exist (the test says when one can be deleted).
#: reducers/irka takes sigma_max from analysis; it now lives in linalg.dense (import it from there)
KNOWN_BACK_EDGES: set = set()


def layer(module: str) -> str:
    parts = module.split(".")
    if len(parts) == 1:
        return "driver"
    top = parts[1]
    if top in LEAVES:
        return "leaf"
    if top in CHAIN or top == "report":
        return top
    if top in ("__main__", "cli") or top.startswith(("bench", "stress")):
        return "driver"
    raise AssertionError(f"module {module} is in no layer: add it to tests/test_architecture.py and "
                         "docs/design/architecture.md")


def module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def is_module(name: str) -> bool:
    base = PKG.parent.joinpath(*name.split("."))
    return base.with_suffix(".py").is_file() or (base / "__init__.py").is_file()


def imports_in(source: str, name: str, is_package: bool):
    """(imported module, names) for every import of a morsuite module in the module ``name``."""
    package = name if is_package else name.rpartition(".")[0]
    for node in ast.walk(ast.parse(source, name)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "morsuite":
                    yield alias.name, frozenset()
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "morsuite":
                continue
            plain = set()
            for alias in node.names:  # `from pkg import submodule` imports the submodule
                if is_module(f"{target}.{alias.name}"):
                    yield f"{target}.{alias.name}", frozenset()
                else:
                    plain.add(alias.name)
            if plain:
                yield target, frozenset(plain)


def edges():
    for path in sorted(PKG.rglob("*.py")):
        importer = module_name(path)
        for target, names in imports_in(path.read_text(encoding="utf-8"), importer, path.name == "__init__.py"):
            yield importer, target, names


def violations():
    out = []
    for importer, target, names in edges():
        src = layer(importer)
        if src == "driver":
            continue
        if target == "morsuite" and names and names <= {"__version__"}:
            continue
        dst = layer(target)
        if dst not in ALLOWED[src]:
            out.append((importer, target, names))
    return out


def _known(edge, known):
    importer, target, names = edge
    return importer.startswith(known[0]) and target == known[1] and names <= known[2]


def test_import_graph_follows_the_layers():
    found = violations()
    unexpected = [e for e in found if not any(_known(e, k) for k in KNOWN_BACK_EDGES)]
    assert not unexpected, "imports against the layers:\n" + "\n".join(
        f"  {i} ({layer(i)}) imports {t} ({layer(t)}) {sorted(n) or ''}" for i, t, n in unexpected)
    stale = [k for k in KNOWN_BACK_EDGES if not any(_known(e, k) for e in found)]
    assert not stale, f"fixed back-edges still listed in KNOWN_BACK_EDGES (delete them): {stale}"


@pytest.mark.parametrize("forbidden", ["models", "reducers", "analysis", "studies", "report"])
def test_linalg_never_imports_downstream(forbidden):
    bad = [(i, t) for i, t, _ in edges()
           if i.startswith("morsuite.linalg") and t.startswith(f"morsuite.{forbidden}")]
    assert not bad, bad


def test_the_checker_sees_local_and_relative_imports():
    """The parser resolves relative and function-local imports (the kind the old back-edge was)."""
    src = ("def f():\n    from ..models.index3 import Index3Model\n    from .. import reducers\n"
           "from . import saddle\nimport morsuite.errors\nfrom .. import __version__\n")
    found = set(imports_in(src, "morsuite.linalg.probe", False))
    assert found == {("morsuite.models.index3", frozenset({"Index3Model"})), ("morsuite.reducers", frozenset()),
                     ("morsuite.linalg.saddle", frozenset()), ("morsuite.errors", frozenset()),
                     ("morsuite", frozenset({"__version__"}))}
    assert layer("morsuite.models.index3") not in ALLOWED["linalg"]
    assert "report" not in ALLOWED["analysis"] and "studies" not in ALLOWED["report"]


def test_no_module_is_over_500_lines():
    """Modules are split by responsibility before they grow past 500 lines (issue 17)."""
    root = Path(morsuite.__file__).resolve().parent
    long = {str(p.relative_to(root)): n for p in root.rglob("*.py")
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > 500}
    assert not long, f"modules over 500 lines: {long}"


def import_cycles(edge_list) -> list:
    """The import circles of a graph given as ``(importer, imported)`` pairs: each strongly
    connected component with more than one module, or a module importing itself (Tarjan,
    iterative). Importing a package counts as importing its ``__init__``; the implicit
    import of a parent package that every ``import a.b.c`` does is not an edge."""
    graph = {}
    for a, b in edge_list:
        graph.setdefault(a, set()).add(b)
        graph.setdefault(b, set())
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1 or v in graph[v]:
                    out.append(sorted(comp))
    return out


def test_no_import_circle_anywhere_in_the_package():
    """No module of morsuite reaches itself through imports, at module level or inside a
    function (issue 28: the studies package flows spec -> plan -> tasks -> execute ->
    outputs; bench/pareto and its report no longer import each other)."""
    cycles = import_cycles((i, t) for i, t, _ in edges())
    assert not cycles, "import circles (each a set of modules that import each other):\n" + "\n".join(
        "  " + " <-> ".join(c) for c in cycles)


def test_the_cycle_finder_finds_planted_circles():
    """A planted three-module circle, a self-import and a diamond (no circle) are told apart."""
    found = import_cycles([("a", "b"), ("b", "c"), ("c", "a"), ("c", "d"), ("e", "e"),
                           ("p", "q"), ("p", "r"), ("q", "s"), ("r", "s")])
    assert sorted(found) == [["a", "b", "c"], ["e"]]
    assert import_cycles([("x", "y"), ("y", "z")]) == []
    # the real graph's edges include function-local imports: the old studies circle went through them
    src = "def f():\n    from .plan import SUMMARY\n"
    assert ("morsuite.studies.plan", frozenset({"SUMMARY"})) in set(imports_in(src, "morsuite.studies.checks", False))


def test_the_study_modules_flow_one_way():
    """spec -> plan -> tasks -> execute -> outputs -> runner: no study module imports one
    downstream of it (validators sit below what they validate)."""
    # task_common (the model of a source, built once per process) imports no study module: the spec's
    # validation and the tasks share its model
    order = ["checks", "task_common", "norm_options", "time_options", "kinds", "spec", "cache", "memo", "plan",
             "tasks", "norms", "timedomain", "execute", "time_figures", "scenes", "results", "outputs",
             "manifest", "pages", "runner", "batch", "compare"]
    rank = {f"morsuite.studies.{m}": i for i, m in enumerate(order)}
    back = [(i, t) for i, t, _ in edges() if i in rank and t in rank and rank[t] > rank[i]]
    assert not back, f"study modules importing downstream: {back}"


def test_no_control_characters_in_sources_and_docs():
    """A backslash escape in a non-raw string or a paste can leave a control character (a vertical tab for
    \\v, a bell for \\a) in a docstring: Sphinx then fails on garbled math. Tabs, newlines and carriage
    returns aside, none may appear in the package, the tests or the docs."""
    root = Path(morsuite.__file__).resolve().parents[1]
    bad = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f]")
    files = [p for d in ("morsuite", "tests", "docs") for p in (root / d).rglob("*")
             if p.suffix in (".py", ".md", ".rst", ".toml") and "_build" not in p.parts]
    hits = [f"{p.relative_to(root)}:{n}" for p in files
            for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if bad.search(line)]
    assert not hits, f"control characters: {hits}"
