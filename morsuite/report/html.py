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

A study page opens with a scoreboard per size compared (:func:`scoreboard_view`: a row per
method, a column per measure, the best value marked and the others as ratios to it, at equal
states and above their floors only (:mod:`morsuite.report.ranking`), flags as the short marks
of :data:`MARKS`), and shows a modes section (:func:`modes_view`, :func:`pole_svg`)
when the study's data carry modes; :func:`headline` is the one-line summary on the results
folder's page. docs/design/reports.md describes them.

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

from .ranking import rank, tie_text

__all__ = ["TEMPLATES", "template_digest", "cell", "table_view", "MARKS", "SCOREBOARD_MEASURES", "scoreboard_view",
           "modes_glance", "HEADLINE_MEASURES",
           "headline", "modes_view", "pole_svg", "render_study", "render_index"]

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


#: the scoreboard's short marks and what each means (shown on hover and in the page's legend)
MARKS = {
    "nc": "not converged: the method's own optimality or fixed-point test failed; its best iterate is shown",
    "≈": "not trusted: the H2 value is not accurate to four digits (h2_trusted = False)",
    "≥": "lower bound: the peak of sigma_max(T - T_r) found; the H-infinity error is at least this",
    "✓": "certified: the H-infinity error lies between this value and the level-set test's upper bound",
    "unst": "unstable reduced model: its norms are infinite",
    "zero": "worse than zero: the error is at or above the full model's own norm, which the zero model T_r = 0 "
            "achieves",
    "fail": "the reduction failed: no values (the notes say why)",
    "tie": "at the rounding level (an H2 value below its floor, or a relative error at most 1e-10, "
           "morsuite.report.ranking): a tie with every value there, never ranked",
    "≠": "not compared: no other method has this number of states (values are compared at equal states only)",
}
#: the scoreboard's columns: (key, heading, what it is, the summary columns it reads, first present wins,
#: the name of the norm in ``worse_than_zero``)
SCOREBOARD_MEASURES = (
    ("band", "band max", "max over the band's grid of sigma_max(T - T_r) (max_abs_error)", ("max_abs_error",), "band"),
    ("h2", "H2", "||T - T_r||_H2, exact over the whole axis (h2_error)", ("h2_error",), "h2"),
    ("hinf", "H∞", "||T - T_r||_Hinf over the whole axis (hinf_error)", ("hinf_error",), "hinf"),
    ("output", "y(t) max", "max_t ||y(t) - y_r(t)||_2 of the time scene (max_output_error)", ("max_output_error",),
     "max_output"),
    ("time", "time (s)", "the reduction at this size alone (time_standalone_s; time_s if not recorded)",
     ("time_standalone_s", "time_s"), None),
    ("lus", "LUs", "sparse LUs of the reduction at this size alone (lu_count_standalone; lu_count if not recorded)",
     ("lu_count_standalone", "lu_count"), None),
)


def _value(row, columns):
    for c in columns:
        v = row.get(c)
        if not _missing(v) and not isinstance(v, bool) and isinstance(v, Real):
            return c, v
    return columns[0], None


def _ratio(q: float) -> str:
    """A ratio to the best: two decimals below 10 (1.004 reads 1.00, not 1), 3 significant digits below
    1000, whole numbers below 10^6 (1862, not 1.86e+03), else 2 digits and an exponent."""
    return f"{q:.2f}" if q < 10 else f"{q:.3g}" if q < 1000 else f"{q:.0f}" if q < 1e6 else f"{q:.1e}"


def _board_groups(rows, present) -> dict:
    """Per scoreboard column, the rows' ranking (:func:`morsuite.report.ranking.rank`, rows named by their
    index): ``{key: (groups, {row index: its group})}``. A row's value is its first present column of the
    measure, ranked under the measure's first column (whose floor rules apply)."""
    out = {}
    for key, _, _, cols, _ in present:
        proj = []
        for i, r in enumerate(rows):
            col, v = _value(r, cols)
            proj.append({**r, "_i": i, cols[0]: v})
        groups = rank(proj, cols[0], name=lambda row: row["_i"])
        where = {}
        for g in groups:
            for i in [n for _, n in g["ranked"]] + g["rounding"] + g["untrusted"] + g["infinite"]:
                where[i] = g
        out[key] = (groups, where)
    return out


def scoreboard_view(board: dict) -> dict:
    """The view of one scoreboard: ``board`` is ``{"title", "where", "rows"}`` with summary rows (dicts of
    the summary's columns and ``label``, the method's label), as :func:`morsuite.studies.pages.study_page`
    gathers them.

    Returns ``{"title", "where", "columns": [{"key", "heading", "title"}], "rows": [{"method", "label",
    "size", "marks": [(mark, meaning)], "cells": [{"text", "ratio", "best", "marks", "title"}]}]}``: a
    column per measure of :data:`SCOREBOARD_MEASURES` that some row has. Values are compared by the rules of
    :mod:`morsuite.report.ranking`: only with rows of the same number of states, and only values above their
    floors. Per column and number of states the best (``best`` True, ties all best) is the smallest ranked
    value when two or more were ranked and none is at the rounding level or untrusted; every other ranked
    value carries its ratio to the smallest ranked one (``×1.34``; none when that is 0). Marks of
    :data:`MARKS` on the row (``nc``, ``unst``, ``fail``) and on values (``≈``, ``≥``, ``✓``, ``zero``,
    ``tie``: at the rounding level, ``≠``: no other row at its number of states). Nothing is computed but
    the ratios.
    """
    rows = board["rows"]
    present = [m for m in SCOREBOARD_MEASURES if any(_value(r, m[3])[1] is not None for r in rows)]
    ranking = _board_groups(rows, present)
    out = []
    for i, r in enumerate(rows):
        failed = r.get("status") not in (None, "ok")
        marks = [m for m, bad in (("fail", failed), ("nc", not failed and r.get("converged") is False),
                                  ("unst", not failed and r.get("stable") is False)) if bad]
        zero = set(filter(None, str(r.get("worse_than_zero") or "").split(",")))
        cells = []
        for key, _, _, cols, norm in present:
            col, v = _value(r, cols)
            if v is None or failed:
                cells.append({"text": "", "ratio": "", "best": False, "marks": [], "title": "not computed"})
                continue
            text = _number(v, col)
            vmarks = []
            if key == "h2" and r.get("h2_trusted") is False:
                vmarks.append("≈")
            if key == "hinf":
                vmarks.append("✓" if r.get("hinf_certified") is True else "≥")
            if norm in zero:
                vmarks.append("zero")
            g = ranking[key][1].get(i)
            ranked = dict((n, val) for val, n in g["ranked"]) if g else {}
            if g is not None and i in g["rounding"]:
                vmarks.append("tie")
            if g is not None and g["alone"] and len(ranking[key][0]) > 1:
                vmarks.append("≠")
            low = g["ranked"][0][0] if g and len(g["ranked"]) >= 2 else None
            is_best = g is not None and g["best"] is not None and i in ranked and ranked[i] == low
            ratio = "best" if is_best else (f"×{_ratio(v / low)}" if low and i in ranked and v != low else "")
            title = f"{col} = {v!r}" + "".join(f"; {m}: {MARKS[m]}" for m in vmarks)
            cells.append({"text": text, "ratio": ratio, "best": is_best,
                          "marks": [(m, MARKS[m]) for m in vmarks], "title": title})
        size = f"r = {r.get('r') if r.get('r') is not None else r.get('r_requested')}" + (
            f", {r['states']} states" if r.get("states") is not None else "")
        out.append({"method": r["method"], "label": r.get("label") or r["method"], "size": size,
                    "marks": [(m, MARKS[m]) for m in marks], "cells": cells})
    return {"title": board["title"], "where": board["where"],
            "columns": [{"key": k, "heading": h, "title": t} for k, h, t, _, _ in present], "rows": out}


#: the measures a headline may be about, in preference: (name in the sentence, summary column)
HEADLINE_MEASURES = (("H2 error", "h2_error"), ("band max error", "max_abs_error"), ("H∞ error found", "hinf_error"))


def headline(board: dict) -> str:
    """One sentence from a scoreboard, by the rules of :mod:`morsuite.report.ranking`: who has the smallest
    H2 error (else band max, else H-infinity) among the rows of equal states whose values are above their
    floors, and by how much below the next, e.g. ``"60 states: irka_fo has the smallest H2 error, 1.34x below
    so_h2"`` (``"r = 30, 60 states: ..."`` when the board's rows differ in states; rows at other states are
    named as not compared). Without such a ranking, a tie at the rounding level of two or more rows
    (``"r = 40, 48 states, H2 error: tie at the rounding level: irka, bt"``); "" when there is neither.
    Methods by their aliases, as the scoreboard's rows name them."""
    rows = board["rows"]
    mixed = len({r.get("states") for r in rows}) > 1
    tie = ""
    for name, col in HEADLINE_MEASURES:
        groups = rank(rows, col)
        ranked = [g for g in groups if g["best"] is not None]
        if ranked:
            g = max(ranked, key=lambda g: (len(g["ranked"]), g["states"] or 0))
            at = f"{board['where']}, {g['states']} states" if mixed and g["states"] is not None else board["where"]
            (b, who), (second, nxt) = g["ranked"][0], g["second"]
            by = f"tied with {nxt}" if second == b else f"{_ratio(g['ratio'])}x below {nxt}"
            others = [f"{n} ({h['states']} states)" for h in groups if h is not g
                      for n in [n for _, n in h["ranked"]] + h["rounding"] + h["untrusted"] + h["infinite"]]
            return f"{at}: {who} has the smallest {name}, {by}" + (
                f"; not compared, at other states: {', '.join(others)}" if others else "")
        if not tie:
            g = next((h for h in groups if len(h["rounding"]) >= 2), None)
            if g is not None:
                at = f"{board['where']}, {g['states']} states" if mixed and g["states"] is not None else \
                    board["where"]
                tie = f"{at}, {name}: {tie_text(g['rounding'])}"
    return tie


#: the modes table's columns (see docs/design/reports.md, "Modes and poles")
MODES_COLUMNS = ("model", "method", "mode", "full_frequency", "reduced_frequency", "rel_frequency_error",
                 "damping_error", "mac")


def modes_view(modes) -> dict | None:
    """The modes table of a page (None when the study has no modes data): ``modes["rows"]`` are dicts
    with the keys of :data:`MODES_COLUMNS` (``mac`` None: the method has no lift, shown as "no lift";
    ``reduced_frequency`` None: the mode is missing from the reduced model)."""
    if not modes or not modes.get("rows"):
        return None
    view = table_view([c for c in MODES_COLUMNS if any(c in r for r in modes["rows"])], modes["rows"])
    for row, raw in zip(view["rows"], modes["rows"]):
        for c, name in zip(row, view["columns"]):
            if name == "mac" and raw.get("method") and _missing(raw.get("mac")):
                c.update(text="no lift", cls="na", title="the method has no lift V q: no mode shapes to compare")
            elif name == "reduced_frequency" and _missing(raw.get(name)):
                c.update(text="missing", cls="bad", title="no mode of the reduced model matches this one")
    return view


_BROKEN = {"M_spd": "M_r not SPD", "K_spd": "K_r not SPD", "D_psd": "D_r not PSD", "stable": "unstable"}


def modes_glance(modes) -> str:
    """One line for the first screen of a page, under the scoreboard: how many of the full model's modes in
    the band each reduced model keeps (matched in frequency, and with MAC at or above ``glance_mac`` where
    it has a lift) and which keep the structure (symmetric positive definite mass and stiffness,
    semidefinite damping, stable; first-order models: stable). Read from ``modes["structure"]`` and
    ``modes["info"]`` (:func:`morsuite.studies.modes.compute_modes`: ``modes_in_band``, ``glance_mac``);
    "" without them."""
    rows = (modes or {}).get("structure") or []
    info = (modes or {}).get("info") or {}
    n, level = info.get("modes_in_band"), info.get("glance_mac", 0.9)
    if not rows or not n:
        return ""
    kept, phys, broke = [], [], []
    for r in rows:
        shape = "no lift, no MAC" if r.get("mac_kept") is None else f"MAC ≥ {level:g} on {r['mac_kept']}"
        kept.append(f"{r['method']} (r = {r['r']}): {r['matched']} matched, {shape}, {r['spurious']} spurious")
        checks = ("M_spd", "K_spd", "D_psd", "stable") if r.get("kind") == "second-order" else ("stable",)
        bad = [_BROKEN[c] for c in checks if r.get(c) is False]
        (broke if bad else phys).append(r["method"] + (f" ({', '.join(bad)})" if bad else ""))
    text = f"Modes: of the full model's {n} in the band, " + "; ".join(kept) + "."
    if phys:
        text += " Structure kept: " + ", ".join(phys) + "."
    if broke:
        text += " Not kept: " + ", ".join(broke) + "."
    return text


_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22")


def pole_svg(poles) -> dict | None:
    """The pole figure as inline SVG (no file, no drawing library: microseconds per pole) and its legend.

    ``poles``: a list of ``{"label", "real": [...], "imag": [...]}`` (the full model's first, drawn as
    black crosses; each reduced model's as coloured rings), the poles of the upper half plane.
    Axes: real part (horizontal) and imaginary part, rad/s (vertical), linear, from the data's range.
    Returns ``{"svg", "legend": [(label, colour)]}``, or None without poles.
    """
    pts = [(float(x), float(y)) for p in poles or [] for x, y in zip(p["real"], p["imag"])
           if math.isfinite(float(x)) and math.isfinite(float(y))]
    if not pts:
        return None
    w, h, left, bottom, pad = 640, 400, 70, 40, 12
    x0, x1 = min(min(x for x, _ in pts), 0.0), max(max(x for x, _ in pts), 0.0)
    y0, y1 = min(min(y for _, y in pts), 0.0), max(y for _, y in pts)
    x0, x1 = (x0 - 0.05 * (x1 - x0 or 1), x1 + 0.05 * (x1 - x0 or 1))
    y1 = y1 + 0.05 * (y1 - y0 or 1)

    def sx(x):
        return left + (x - x0) / (x1 - x0) * (w - left - pad)

    def sy(y):
        return h - bottom - (y - y0) / (y1 - y0) * (h - bottom - pad)

    parts = [f'<svg class="poles" viewBox="0 0 {w} {h}" role="img" aria-label="poles">',
             f'<rect x="{left}" y="{pad}" width="{w - left - pad}" height="{h - bottom - pad}" fill="#fff" '
             f'stroke="#999"/>',
             f'<line x1="{sx(0):.1f}" y1="{pad}" x2="{sx(0):.1f}" y2="{h - bottom}" stroke="#bbb" '
             f'stroke-dasharray="4 3"/>']
    for t in range(5):
        xv, yv = x0 + (x1 - x0) * t / 4, y0 + (y1 - y0) * t / 4
        anchor = ("start", "middle", "middle", "middle", "end")[t]
        parts.append(f'<text x="{sx(xv):.1f}" y="{h - bottom + 16}" font-size="12" text-anchor="{anchor}">'
                     f'{xv:.3g}</text>')
        parts.append(f'<text x="{left - 6}" y="{sy(yv) + 4:.1f}" font-size="12" text-anchor="end">{yv:.3g}</text>')
    parts.append(f'<text x="{(left + w) / 2:.0f}" y="{h - 6}" font-size="13" text-anchor="middle">real part '
                 f'(1/s)</text>')
    parts.append(f'<text x="14" y="{(h - bottom) / 2:.0f}" font-size="13" text-anchor="middle" '
                 f'transform="rotate(-90 14 {(h - bottom) / 2:.0f})">imaginary part (rad/s)</text>')
    legend = []
    for i, p in enumerate(poles):
        full = i == 0
        colour = "#000" if full else _COLOURS[(i - 1) % len(_COLOURS)]
        legend.append((p["label"], colour))
        for x, y in zip(p["real"], p["imag"]):
            x, y = float(x), float(y)
            if not (math.isfinite(x) and math.isfinite(y)):
                continue
            if full:
                parts.append(f'<path d="M{sx(x) - 5:.1f},{sy(y) - 5:.1f}l10,10m0,-10l-10,10" stroke="{colour}" '
                             f'stroke-width="1.5"/>')
            else:
                parts.append(f'<circle cx="{sx(x):.1f}" cy="{sy(y):.1f}" r="{3 + 1.5 * ((i - 1) % 4)}" fill="none" '
                             f'stroke="{colour}" stroke-width="1.3"/>')
    parts.append("</svg>")
    return {"svg": "".join(parts), "legend": legend}


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
    import markupsafe

    tables = [{**t, "view": table_view(t["columns"], t["rows"])} for t in page["tables"]]
    reach = [{**t, "view": table_view(t["columns"], t["rows"])} for t in page.get("tolerance") or []]
    boards = []  # per table: its open scoreboards and its folded ones, in page order
    for b in page.get("scoreboards") or []:
        if not boards or boards[-1]["table"] != b["table"]:
            boards.append({"table": b["table"], "open": [], "folded": []})
        boards[-1]["folded" if b.get("folded") else "open"].append(scoreboard_view(b))
    modes = page.get("modes") or {}
    poles = pole_svg(modes.get("poles"))
    if poles is not None:
        poles["svg"] = markupsafe.Markup(poles["svg"])  # built here from numbers and escaped labels only
    return _environment().get_template("study.html.j2").render(
        page=page, tables=tables, reach=reach, boards=boards, marks=MARKS, modes=modes_view(modes), poles=poles,
        modes_note=modes.get("note") or "", glance=modes_glance(modes))


def render_index(index: dict) -> str:
    """The HTML of the page linking every study of a results folder: ``index["studies"]`` is a
    list of ``{"name", "href", "title", "description", "models", "methods", "reductions",
    "figures", "tables", "flags", "verdicts"}``."""
    return _environment().get_template("index.html.j2").render(index=index)
