"""Sphinx extension: tables of measured results read from the study CSVs when the docs are built.

A page that quotes a study's numbers in a hand-written table goes stale the moment
``results/`` is regenerated; this directive reads the CSV at build time instead, so the
table shows what the last run of the code wrote. The page is re-read whenever the CSV
changes (a build dependency).

``.. morsuite-results-table:: PATH``
    PATH is a CSV written by a study (``results/STUDY/summary.csv`` or a scene's table),
    relative to the page. Options:

    ``:where:``
        ``column=v1,v2; column=...``: keep the rows whose value (as written in the CSV)
        is one of the listed ones, for every column named; default: every row.
    ``:columns:``
        ``column=Header; column; ...``: the columns shown, in this order, with their
        header (default header: the column name); default: every column.
    ``:sort:``
        ``column; column``: row order. A column named in ``:where:`` sorts in the order
        its values are listed there, any other in its CSV order of first appearance;
        default: the CSV's order.
    ``:labels:``
        ``value=Label; ...``: cell values shown under another name (``bt=BT (vv)``).
    ``:digits:``
        significant digits of the error columns (default 3); columns whose name ends in
        ``_s`` (times) get 2.

    Booleans are shown as yes / **no** (bold), empty cells as a dash. ``h2_error`` and
    ``h2_rel_error`` of a row with ``h2_trusted`` False are shown in parentheses, and a
    note under the table says so; the note also names the CSV file.
"""

from __future__ import annotations

import csv
import math
import os

from docutils import nodes
from docutils.parsers.rst import directives
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

logger = logging.getLogger(__name__)

#: columns in parentheses when the row's ``h2_trusted`` is False
UNTRUSTED_COLUMNS = ("h2_error", "h2_rel_error")


def _pairs(text: str | None) -> list[tuple[str, str | None]]:
    """``a=b; c; d=e`` as [(a, b), (c, None), (d, e)]."""
    out = []
    for item in (text or "").split(";"):
        item = item.strip()
        if item:
            key, sep, value = item.partition("=")
            out.append((key.strip(), value.strip() if sep else None))
    return out


def number(value: float, digits: int = 3) -> str:
    """``digits`` significant digits, in exponent form (``1.36e-6``, ``1.05e3``) below 1e-3
    and wherever ``%g`` would use it."""
    if not math.isfinite(value):
        return str(value)
    text = f"{value:.{digits}g}"
    if value == 0 or (1e-3 <= abs(value) < 1e5 and "e" not in text):
        return text
    mantissa, exponent = f"{value:.{digits - 1}e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def cell(column: str, text: str, digits: int) -> str:
    """One CSV value as it is shown."""
    if text == "":
        return "-"
    if text in ("True", "False"):
        return "yes" if text == "True" else "no"
    try:
        return str(int(text))
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        return text
    return number(value, 2 if column.endswith("_s") else digits)


def results_table(path: str, where: str | None = None, columns: str | None = None, sort: str | None = None,
                  labels: str | None = None, digits: int = 3) -> tuple[list[str], list[list[str]], bool]:
    """Header, rows of shown cells, and whether a value was put in parentheses as untrusted
    (see the module docstring for the options)."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    header = list(rows[0]) if rows else []
    filters = {col: [v.strip() for v in (vals or "").split(",")] for col, vals in _pairs(where)}
    shown = _pairs(columns) or [(c, None) for c in header]
    missing = [c for c in list(filters) + [c for c, _ in shown] + [c for c, _ in _pairs(sort)] if c not in header]
    if missing:
        raise ValueError(f"no column {', '.join(map(repr, missing))} (columns: {header})")
    rows = [row for row in rows if all(row[c] in vals for c, vals in filters.items())]
    if not rows:
        raise ValueError(f"no row matches {where!r}")
    order = {}
    for col, _ in _pairs(sort):
        seen = filters.get(col) or list(dict.fromkeys(row[col] for row in rows))
        order[col] = {v: i for i, v in enumerate(seen)}
    rows.sort(key=lambda row: [order[c].get(row[c], len(order[c])) for c in order])
    names = dict(_pairs(labels))
    flagged = False
    body = []
    for row in rows:
        out = []
        for col, _ in shown:
            text = cell(col, names.get(row[col]) or row[col], digits)
            if col in UNTRUSTED_COLUMNS and row.get("h2_trusted") == "False" and text != "-":
                text, flagged = f"({text})", True
            out.append(text)
        body.append(out)
    return [head or col for col, head in shown], body, flagged


def _row(cells: list[str], kind=nodes.entry) -> nodes.row:
    row = nodes.row()
    for text in cells:
        # a method that did not converge stands out
        content = nodes.strong(text=text) if text == "no" else nodes.Text(text)
        row += kind("", nodes.paragraph("", "", content))
    return row


def table_nodes(header: list[str], body: list[list[str]], flagged: bool, shown_path: str) -> list[nodes.Node]:
    """A docutils table (independent of the page's markup language) and its source note."""
    table = nodes.table(classes=["morsuite-results"])
    group = nodes.tgroup(cols=len(header))
    table += group
    group += [nodes.colspec(colwidth=1) for _ in header]
    group += nodes.thead("", _row(header))
    group += nodes.tbody("", *[_row(r) for r in body])
    note = nodes.paragraph("", "From ", nodes.literal(text=shown_path))
    if flagged:
        note += nodes.Text("; in parentheses: an H2 value whose ")
        note += nodes.literal(text="h2_trusted")
        note += nodes.Text(" is False (its estimated accuracy is worse than four digits)")
    note += nodes.Text(".")
    return [table, note]


class ResultsTable(SphinxDirective):
    required_arguments = 1
    has_content = False
    option_spec = {"where": directives.unchanged, "columns": directives.unchanged, "sort": directives.unchanged,
                   "labels": directives.unchanged, "digits": directives.positive_int}

    def run(self):
        rel, path = self.env.relfn2path(self.arguments[0])
        self.env.note_dependency(rel)
        shown = os.path.relpath(path, os.path.dirname(self.env.srcdir))
        try:
            header, body, flagged = results_table(path, self.options.get("where"), self.options.get("columns"),
                                                  self.options.get("sort"), self.options.get("labels"),
                                                  self.options.get("digits", 3))
        except (OSError, ValueError) as exc:
            logger.warning("morsuite-results-table %s: %s", shown, exc, location=self.get_location())
            return []
        return table_nodes(header, body, flagged, shown)


def setup(app):
    app.add_directive("morsuite-results-table", ResultsTable)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
