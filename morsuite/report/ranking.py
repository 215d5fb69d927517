r"""Which values may be ranked: the one rule behind every headline, verdict and "best" mark.

A report ranks reductions by an error measure (smaller is better). Two rules decide what
may be ranked, for the study page's scoreboard and headline
(:mod:`morsuite.report.html`), the table scenes' verdicts (:mod:`morsuite.studies.scenes`)
and the lines ``morsuite compare`` prints (:mod:`morsuite.studies.compare`):

1. **Equal states only.** Rows are compared with rows whose reduced model has the same
   number of states (``states``: 2r for a second-order model of order r). A method that
   returned fewer states than asked (IRKA removing shifts, BT truncating at its rank) is
   compared with nobody at the size it was asked for, and the text says so.
2. **Only values above their floors.** Each value is classified by :func:`standing`:

   ``"ok"``
       finite and above its floor: ranked.
   ``"rounding"``
       at the rounding level: an H2 value that is not trusted (its floor, the stated
       accuracy, is not within four digits) and whose relative value is at most
       :data:`ROUNDING_REL`, or a value with no floor of its own (band maxima, the Hinf
       peak found, output errors) whose relative value is at most :data:`ROUNDING_REL`.
       Such values are a **tie at the rounding level** with each other, never ranked, and
       the text names them ("tie at the rounding level: irka, bt").
   ``"untrusted"``
       an H2 value not accurate to four digits and above the rounding level: not ranked
       (it may be right to a digit or two, or not at all).
   ``"infinite"``
       an unstable reduced model: infinite error, never best.
   ``"missing"``
       no value (a failed row, a measure not computed).

   A trusted H2 value is ranked whatever its size: its own floor is within four digits
   (:mod:`morsuite.norms.h2`). The other measures carry no floor in the summary: the full
   model's response comes from sparse solves whose relative accuracy is that of the
   solves (backward error times conditioning, e.g. 2.8e-8 at a resonance with damping
   ratio 1e-4 before refinement: issue 45), so a relative error below :data:`ROUNDING_REL`
   is read as rounding. This is a convention with a margin, not a proved bound.

:func:`rank` applies both rules to rows and returns, per number of states, the ranked
values (ascending), the rounding-level ties, the untrusted ones and the best (the smallest
ranked value when at least two were ranked and none is at the rounding level or untrusted:
a value at the rounding level is smaller than any ranked one, by an unknown factor, and an
untrusted one may be).
:func:`tie_text` and :func:`excluded_text` are the sentences every caller uses.
Cost: O(rows) per measure; nothing is computed but comparisons.
"""

from __future__ import annotations

import math
from numbers import Real

__all__ = ["ROUNDING_REL", "RELATIVE", "TRUSTED", "standing", "rank", "tie_text", "excluded_text"]

#: a relative error at or below this is at the rounding level of the full model's evaluation (no floor recorded)
ROUNDING_REL = 1e-10

#: the relative column that decides whether a measure's value is at the rounding level
RELATIVE = {
    "max_abs_error": "max_rel_error", "max_rel_error": "max_rel_error",
    "h2_error": "h2_rel_error", "h2_rel_error": "h2_rel_error",
    "hinf_error": "hinf_rel_error", "hinf_rel_error": "hinf_rel_error",
    "max_output_error": "max_output_rel_error", "max_output_rel_error": "max_output_rel_error",
    "l2_output_error": "l2_output_rel_error", "l2_output_rel_error": "l2_output_rel_error",
}
#: the trusted flag of a measure whose value carries its own floor (the value is above it when trusted)
TRUSTED = {"h2_error": "h2_trusted", "h2_rel_error": "h2_trusted"}


def _number(v):
    return v if isinstance(v, Real) and not isinstance(v, bool) and not (isinstance(v, float) and math.isnan(v)) \
        else None


def standing(row: dict, column: str) -> str:
    """How ``row[column]`` may be ranked: ``"ok"``, ``"rounding"``, ``"untrusted"``, ``"infinite"`` or
    ``"missing"`` (module docstring). A row whose ``status`` is set and not ``"ok"`` (a failed
    reduction) is missing. Columns outside :data:`RELATIVE` (time, LU counts) have no floor: finite
    values are ``"ok"``. Cost: O(1)."""
    if row.get("status") not in (None, "ok"):
        return "missing"
    v = _number(row.get(column))
    if v is None:
        return "missing"
    if math.isinf(v):
        return "infinite"
    rel_col = RELATIVE.get(column)
    rel = _number(row.get(rel_col)) if rel_col else None
    low = rel is not None and abs(rel) <= ROUNDING_REL or v == 0
    flag = TRUSTED.get(column)
    if flag is not None:
        if row.get(flag) is True:
            return "ok"
        return "rounding" if low else "untrusted"
    return "rounding" if rel_col and low else "ok"


def _states(row):
    s = row.get("states")
    return int(s) if isinstance(s, (int, float)) and not isinstance(s, bool) and s == s else None


def rank(rows, column: str, name=lambda row: row["method"]) -> list:
    """The rows' values of ``column`` grouped by states and classified (module docstring).

    Parameters
    ----------
    rows : sequence of dict
        Summary rows (``states``, ``status``, the column and its relative and trusted columns).
    column : str
        The measure (smaller is better).
    name : callable
        A row's name in the result (default its ``method``).

    Returns
    -------
    list of dict
        One per number of states that some row with a value has, ascending (rows without
        ``states`` form a group of states None, last): ``states``; ``ranked`` ([(value, name)]
        of the ``"ok"`` values, ascending); ``rounding``, ``untrusted``, ``infinite`` (names);
        ``best`` (the name of the smallest ranked value when at least two were ranked and
        none is at the rounding level or untrusted, either of which may be the smallest, else None); ``second`` (the next ranked (value, name),
        else None); ``ratio`` (second over best, when best is set and positive, else None);
        ``alone`` (True when only one row of the group has a value: nothing to compare).
        Cost: O(rows log rows).
    """
    groups = {}
    for row in rows:
        st = standing(row, column)
        if st == "missing":
            continue
        g = groups.setdefault(_states(row), {"ranked": [], "rounding": [], "untrusted": [], "infinite": []})
        if st == "ok":
            g["ranked"].append((float(row[column]), name(row)))
        else:
            g[st].append(name(row))
    out = []
    for states in sorted(groups, key=lambda s: (s is None, s or 0)):
        g = groups[states]
        g["ranked"].sort(key=lambda t: t[0])
        count = sum(len(g[k]) for k in ("ranked", "rounding", "untrusted", "infinite"))
        best = second = ratio = None
        if len(g["ranked"]) >= 2 and not g["rounding"] and not g["untrusted"]:
            (b, best), second = g["ranked"][0], g["ranked"][1]
            ratio = second[0] / b if b > 0 else None
        out.append({"states": states, **g, "best": best, "second": second, "ratio": ratio, "alone": count < 2})
    return out


def tie_text(names) -> str:
    """The sentence for values at the rounding level: ``"tie at the rounding level: a, b"`` (one name:
    ``"at the rounding level (not ranked): a"``); "" for none."""
    names = list(names)
    if not names:
        return ""
    return ("tie at the rounding level: " if len(names) > 1 else "at the rounding level (not ranked): ") + \
        ", ".join(names)


def excluded_text(group: dict) -> str:
    """What a group leaves out of its ranking, as one clause: the rounding-level tie (:func:`tie_text`),
    the untrusted values and the infinite ones; "" when nothing is left out."""
    parts = [tie_text(group["rounding"])]
    if group["untrusted"]:
        parts.append("not ranked, not accurate to four digits: " + ", ".join(group["untrusted"]))
    if group["infinite"]:
        parts.append("infinite (unstable): " + ", ".join(group["infinite"]))
    return "; ".join(p for p in parts if p)
