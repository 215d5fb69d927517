"""HTML pages of a study's results: one ``index.html`` per study folder, and one linking them all.

The pages are rendered with Jinja2 from plain data (dicts, lists, numbers, strings) by the
templates shipped in ``morsuite/report/templates`` (package data); nothing here computes a
result. A page is self-contained: its style sheet is inline, it loads nothing from the
network, and it shows the study's own figure files (PNG, else SVG) by relative path. The
layout reflows from a phone's width to a desktop's (tables scroll sideways inside their
box, figures fill a grid of columns at least 26 rem wide).

Table cells carry the flags of the numbers they show, visibly (a phone has no hover):

- ``≈`` before a norm whose ``KIND_trusted`` column is False (not accurate to four digits);
- ``≥`` before an H-infinity error that is the peak found (a lower bound) unless a
  ``hinf_certified`` column says True, and ``✓`` after a certified value; both only on
  ``hinf_error``, the quantity the search and the certificate are about: ``hinf_rel_error``
  (a ratio of two peaks found) is neither a bound nor certified and carries no mark;
- ``converged``, ``stable``, ``*_trusted``, ``*_certified`` as ``yes`` / ``no`` (``no`` in
  red; ``growth`` and a ``status`` other than ``ok`` in red too); ``cached`` as ``cache``.

Cost: Jinja2's import (about 30 ms) and a render in milliseconds; the study runner renders
only when the page's data, these templates or Jinja2's version changed
(:mod:`morsuite.studies.pages`).
"""

from __future__ import annotations

import functools
import hashlib
import math
from numbers import Integral, Real
from pathlib import Path

__all__ = ["TEMPLATES", "template_digest", "cell", "table_view", "render_study", "render_index"]

#: the folder of the page templates (package data)
TEMPLATES = Path(__file__).resolve().parent / "templates"

_YES_NO = ("converged", "stable")
_BAD_WHEN_TRUE = ("growth",)


def template_digest() -> str:
    """SHA-256 of the templates' names and bytes (part of a page's key)."""
    h = hashlib.sha256()
    for f in sorted(TEMPLATES.glob("*.j2")):
        h.update(f.name.encode() + b"\0" + f.read_bytes())
    return h.hexdigest()


def _missing(value) -> bool:
    return value is None or (isinstance(value, float) and math.isnan(value))


def _number(value, column: str) -> str:
    if isinstance(value, Integral):
        return str(int(value))
    v = float(value)
    if math.isinf(v):
        return "∞" if v > 0 else "-∞"
    return format(v, ".3g" if column.startswith("time") or column.endswith("_s") else ".4g")


def cell(column: str, value, row: dict) -> dict:
    """One table cell as ``{"text", "cls", "title"}``: the value formatted (4 significant digits,
    times 3), with the visible marks of the module docstring and a class saying why."""
    if _missing(value):
        return {"text": "", "cls": "na", "title": "not computed"}
    if isinstance(value, bool):
        if column in _YES_NO or column.endswith(("_trusted", "_certified")):
            return {"text": "yes" if value else "no", "cls": "ok" if value else "bad",
                    "title": f"{column} = {value}"}
        if column in _BAD_WHEN_TRUE:
            return {"text": "yes" if value else "no", "cls": "bad" if value else "", "title": f"{column} = {value}"}
        if column == "cached":
            return {"text": "cache" if value else "", "cls": "muted", "title": "taken from the cache" if value
                    else "computed in the run that wrote this page"}
        return {"text": str(value), "cls": "", "title": ""}
    if column == "status":
        return {"text": str(value), "cls": "" if value == "ok" else "bad", "title": ""}
    if not isinstance(value, Real):
        return {"text": str(value), "cls": "", "title": ""}
    text, cls, title = _number(value, column), "num", ""
    kind = column.split("_", 1)[0]
    # h2_trusted covers the error and the norm (h2_rel_error too); the Hinf marks only hinf_error
    if column in ("h2_error", "h2_rel_error", "hinf_error"):
        certified = row.get(f"{kind}_certified")
        if row.get(f"{kind}_trusted") is False:
            text, cls = "≈" + text, "num untrusted"
            title = f"not accurate to four digits ({kind}_trusted = False)"
        elif certified is True:
            text, cls, title = text + " ✓", "num certified", f"certified ({kind}_certified = True)"
        elif kind == "hinf" and certified is not True:
            text, title = "≥" + text, "the peak of sigma_max found: a lower bound of the H-infinity error"
    return {"text": text, "cls": cls, "title": title}


def table_view(columns, rows) -> dict:
    """``{"columns": [...], "rows": [[cell, ...], ...]}`` of dict rows, each cell by :func:`cell`."""
    columns = list(columns)
    return {"columns": columns, "rows": [[cell(c, row.get(c), row) for c in columns] for row in rows]}


@functools.lru_cache(maxsize=1)
def _environment():
    import jinja2

    return jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)), autoescape=True,
                              undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True,
                              keep_trailing_newline=True)


def render_study(page: dict) -> str:
    """The HTML of one study's page from its plain data ``page`` (see
    :func:`morsuite.studies.pages.study_page` for the keys); tables are shown with
    :func:`table_view`."""
    tables = [{**t, "view": table_view(t["columns"], t["rows"])} for t in page["tables"]]
    return _environment().get_template("study.html.j2").render(page=page, tables=tables)


def render_index(index: dict) -> str:
    """The HTML of the page linking every study of a results folder: ``index["studies"]`` is a
    list of ``{"name", "href", "title", "description", "models", "methods", "reductions",
    "figures", "tables", "flags", "verdicts"}``."""
    return _environment().get_template("index.html.j2").render(index=index)
