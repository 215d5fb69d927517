"""docs/design/layout.md places every module of the package (issue 47, item 3): each module under
``morsuite/`` (private ones included; a package's ``__init__`` is its row) is named in its package's
row of the table, and every name listed there is a module of that package. A reducer family folder the
registry discovers needs no row: the generated reducer table (docs/design/reducers.md) places it."""

from __future__ import annotations

import re
from pathlib import Path

import morsuite

PKG = Path(morsuite.__file__).resolve().parent
LAYOUT = PKG.parent / "docs" / "design" / "layout.md"


def _table() -> dict:
    """package path (``morsuite/linalg``) -> the module names in its row's second cell."""
    rows = {}
    for line in LAYOUT.read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        m = re.fullmatch(r"`(morsuite(?:/[\w/]+)?)`", cells[0]) if len(cells) >= 3 else None
        if m:
            # a reducer's registered name follows its module in parentheses: (`irka-fo`); it is no module
            names = re.sub(r"\(`[^`]*`\)", "", cells[1])
            rows[m.group(1)] = set(re.findall(r"`([\w]+)`", names))
    return rows


def _modules() -> dict:
    """package path -> its modules (file stems, ``__init__`` left out)."""
    out = {}
    for path in PKG.rglob("*.py"):
        pkg = "morsuite" + ("/" + path.parent.relative_to(PKG).as_posix() if path.parent != PKG else "")
        out.setdefault(pkg, set())
        if path.stem != "__init__":
            out[pkg].add(path.stem)
    return out


def _families() -> set:
    """package paths of the reducer family folders the registry discovers: the generated reducer table of
    docs/design/reducers.md places them (a new method is one folder, its test and its page: nothing else edited)."""
    from morsuite.reducers.registry import families

    return {f"morsuite/reducers/{f}" for f in families()}


def test_every_module_is_placed_in_the_layout():
    table, modules = _table(), _modules()
    assert "morsuite/linalg" in table and "lradi" in table["morsuite/linalg"]  # the parser reads the table
    placed = _families() - set(table)  # a family without a row of its own here: placed by the reducer table
    missing = {pkg: sorted(mods - table.get(pkg, set())) for pkg, mods in modules.items() if pkg not in placed}
    missing = {k: v for k, v in missing.items() if v}
    assert not missing, f"modules not placed in docs/design/layout.md (add them to their package's row): {missing}"


def test_every_listed_module_exists():
    table, modules = _table(), _modules()
    stale = {pkg: sorted(names - modules.get(pkg, set())) for pkg, names in table.items()}
    stale = {k: v for k, v in stale.items() if v}
    assert not stale, f"docs/design/layout.md lists modules that do not exist: {stale}"
