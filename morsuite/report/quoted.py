r"""Figures quoted in prose, checked against the results files they come from.

A number in README.md or a docs page that comes from ``results/`` carries its source
right after it, in an HTML comment that renders as nothing:

.. code-block:: text

    the paper's IRKA 1024<!-- = csv("results/sweep/summary.csv", "h2_error",
        model="tcom(nc=2000)", method="irka", r=30) -->

The comment holds one expression in a small language: numbers, ``+ - * / ( )``,
``min``, ``max``, ``abs`` and two readers,

``csv(path, column, **where)``
    the one value of ``column`` in the row of the CSV file whose cells equal the
    ``where`` values (compared as the CSV's text, so ``r=30`` matches ``30``); a
    selection that matches no row or several rows is an error, not a guess;
``json(path, key, ...)``
    the value at the path of keys (list indices as ints) of a JSON file.

Paths are relative to the repository root. :func:`check_text` finds every quoted
figure, evaluates its source and compares: the quoted number must equal the
value rounded to the digits it shows (half a unit of the last digit shown, so
``2.9e-8`` admits [2.85e-8, 2.95e-8] and ``11`` admits [10.5, 11.5]); ``| rel=R``
after the expression states a looser relative rounding instead (for a figure that
says "about"). The test ``tests/test_quoted_figures.py`` runs it on README.md and
every page of docs/ on each CI run, so a regenerated ``results/`` that no longer
says what the prose says fails.

Cost: one read per file (memoised within a call).
"""

from __future__ import annotations

import ast
import json as _json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from ..errors import InputError

__all__ = ["Quote", "check_text", "evaluate", "find_quotes"]

#: a number (optionally signed, decimal or exponent form) followed by an optional unit mark,
#: then the source comment
QUOTE = re.compile(
    r"(?P<num>(?<![\w.])[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?)(?P<unit>\s?(?:x|%|s|ms)?)"
    r"<!-- = (?P<expr>.*?) -->", re.S)


@dataclass
class Quote:
    """One quoted figure: the text shown, the source expression, the value and the verdict."""

    text: str
    expr: str
    line: int
    value: float | None = None
    low: float | None = None
    high: float | None = None
    ok: bool | None = None
    error: str | None = None


def _half_unit(text: str) -> float:
    """Half a unit of the last digit shown in ``text`` (a decimal or exponent number)."""
    mant, _, exp = text.lower().lstrip("+-").partition("e")
    decimals = len(mant.partition(".")[2])
    return 0.5 * 10.0 ** (int(exp or 0) - decimals)


def find_quotes(text: str) -> list[Quote]:
    """Every quoted figure of ``text`` (markdown) with its source expression. Cost O(len(text))."""
    out = []
    for m in QUOTE.finditer(text):
        out.append(Quote(text=m["num"], expr=" ".join(m["expr"].split()), line=text.count("\n", 0, m.start()) + 1))
    return out


class _Reader:
    def __init__(self, root: Path):
        self.root = Path(root)
        self._frames: dict = {}
        self._json: dict = {}

    def _path(self, path: str) -> Path:
        p = (self.root / path).resolve()
        if not p.is_file():
            raise InputError(f"quoted figure: source file {path!r} does not exist")
        return p

    def csv(self, path, column, **where):
        p = self._path(path)
        if p not in self._frames:
            self._frames[p] = pd.read_csv(p, dtype=str, keep_default_na=False)
        frame = self._frames[p]
        if column not in frame.columns:
            raise InputError(f"quoted figure: {path} has no column {column!r}")
        sel = pd.Series(True, index=frame.index)
        for key, value in where.items():
            if key not in frame.columns:
                raise InputError(f"quoted figure: {path} has no column {key!r}")
            sel &= frame[key] == str(value)
        rows = frame.loc[sel, column]
        if len(rows) != 1:
            raise InputError(f"quoted figure: {path} where {where} selects {len(rows)} rows, not one")
        return float(rows.iloc[0])

    def json(self, path, *keys):
        p = self._path(path)
        if p not in self._json:
            self._json[p] = _json.loads(p.read_text(encoding="utf-8"))
        value = self._json[p]
        for k in keys:
            value = value[k]
        return float(value)


_ALLOWED = (ast.Expression, ast.BinOp, ast.UnaryOp, ast.Constant, ast.Call, ast.Name, ast.Load, ast.keyword,
            ast.Add, ast.Sub, ast.Mult, ast.Div, ast.USub, ast.UAdd, ast.Pow)


def evaluate(expr: str, root) -> float:
    """The value of a quote's source expression (see the module text), read under ``root``.

    Raises :class:`~morsuite.errors.InputError` for anything outside the small
    language (no attribute access, no other names), a missing file, column or row.
    """
    tree = ast.parse(expr, mode="eval")
    for node in ast.walk(tree):
        if not isinstance(node, _ALLOWED):
            raise InputError(f"quoted figure: {type(node).__name__} not allowed in {expr!r}")
        if isinstance(node, ast.Name) and node.id not in ("csv", "json", "min", "max", "abs"):
            raise InputError(f"quoted figure: unknown name {node.id!r} in {expr!r}")
    reader = root if isinstance(root, _Reader) else _Reader(root)
    names = {"csv": reader.csv, "json": reader.json, "min": min, "max": max, "abs": abs}
    return float(eval(compile(tree, "<quote>", "eval"), {"__builtins__": {}}, names))  # noqa: S307


def check_text(text: str, root) -> list[Quote]:
    """Evaluate and judge every quoted figure of ``text``; sources are read under ``root``.

    A quote is ``ok`` when the value lies within half a unit of the last digit the
    quote shows (or within ``rel`` of it when the comment says ``| rel=R``).
    Returns the quotes with ``value``, the admitted interval and ``ok`` or ``error``.
    """
    reader = _Reader(root)
    quotes = find_quotes(text)
    for q in quotes:
        expr, _, opt = q.expr.partition("|")
        try:
            q.value = evaluate(expr.strip(), reader)
        except (InputError, KeyError, IndexError, ValueError, SyntaxError, ZeroDivisionError) as exc:
            q.ok, q.error = False, f"{type(exc).__name__}: {exc}"
            continue
        shown = float(q.text)
        if opt.strip():
            m = re.fullmatch(r"\s*rel\s*=\s*([0-9.eE+-]+)\s*", opt)
            if not m:
                q.ok, q.error = False, f"unknown option {opt.strip()!r}"
                continue
            tol = float(m[1]) * abs(shown)
        else:
            tol = _half_unit(q.text) * (1 + 1e-9)
        q.low, q.high = shown - tol, shown + tol
        q.ok = bool(math.isfinite(q.value) and q.low <= q.value <= q.high)
    return quotes
