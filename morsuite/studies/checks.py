"""The checks of a study spec: one failure format, and validators of the values scene keys take.

Every failure raises :class:`~morsuite.errors.SpecError` as
``study spec SOURCE: WHERE: what was wrong`` (with a close match suggested for a
misspelt name). Validators are plain functions ``check(ctx, where, value) -> value``
that the scene kinds (:mod:`morsuite.studies.kinds`) and the option tables (:mod:`morsuite.studies.norm_options`,
:mod:`morsuite.studies.time_options`) name. This module is the bottom of the study package:
it imports no other module of it (nor the numerical code); the checks that need the
scene kinds or the option tables live beside those (``kinds.check_output_names``,
``norm_options.norms_of``).
"""

from __future__ import annotations

import difflib
import math
from numbers import Integral, Real

from ..errors import SpecError

__all__ = ["Ctx", "suggest", "name_ok", "r_values", "positive_int", "nonnegative_int", "int_at_least",
           "positive_float", "float_in_01", "finite_list", "choice_of", "subset_of",
           "r_by_method"]


def suggest(word, choices) -> str:
    """' (did you mean X?)' for the closest of ``choices`` to ``word`` (difflib), or ''."""
    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


class Ctx:
    """Where a spec comes from (``source``), and its failure messages."""

    def __init__(self, source):
        self.source = source

    def fail(self, where, msg):
        """Raise :class:`~morsuite.errors.SpecError` ``study spec SOURCE: WHERE: msg``."""
        raise SpecError(f"study spec {self.source}: {where}: {msg}")

    def keys(self, where, table, allowed):
        """Check that ``table`` is a dict whose keys are all in ``allowed`` (a close match suggested)."""
        if not isinstance(table, dict):
            self.fail(where, f"expected a table; got {type(table).__name__}")
        for key in table:
            if key not in allowed:
                self.fail(where, f"unknown key {key!r}{suggest(key, allowed)}; valid keys: {', '.join(sorted(allowed))}")

    def string(self, where, value, *, empty=False):
        """``value`` if it is a string (non-empty unless ``empty``)."""
        if not isinstance(value, str) or (not empty and not value):
            self.fail(where, f"expected a non-empty string; got {value!r}")
        return value

    def choice(self, where, value, choices):
        """``value`` if it is one of ``choices``."""
        if value not in choices:
            self.fail(where, f"unknown value {value!r}{suggest(value, choices)}; valid choices: "
                             f"{', '.join(map(str, choices))}")
        return value

    def ref(self, where, value, table, what):
        """``value`` if it names an entry of ``table`` (a ``what``: model, grid, method...)."""
        self.string(where, value)
        if value not in table:
            self.fail(where, f"unknown {what} {value!r}{suggest(value, table)}; defined {what}s: "
                             f"{', '.join(sorted(table)) or '(none)'}")
        return value


def name_ok(text):
    """Whether ``text`` is usable as a file-name stem: letters, digits, '-', '_', '.', not hidden."""
    return bool(text) and all(c.isalnum() or c in "-_." for c in text) and not text.startswith(".")


def r_values(ctx, where, value):
    """The reduced orders of a scene: an int, a list, or ``{from, to, step}``; sorted, unique."""
    def bad():
        ctx.fail(where, f"expected a positive integer, a list of them, or {{ from = A, to = B, step = S }}; "
                        f"got {value!r}")
    if isinstance(value, bool):
        bad()
    if isinstance(value, Integral):
        rs = [int(value)]
    elif isinstance(value, list):
        if not value or any(isinstance(v, bool) or not isinstance(v, Integral) for v in value):
            bad()
        rs = [int(v) for v in value]
    elif isinstance(value, dict):
        ctx.keys(where, value, ("from", "to", "step"))
        lo, hi, step = value.get("from"), value.get("to"), value.get("step", 1)
        if any(isinstance(v, bool) or not isinstance(v, Integral) for v in (lo, hi, step)) or step < 1 or hi < lo:
            bad()
        rs = list(range(int(lo), int(hi) + 1, int(step)))
    else:
        bad()
    if any(r < 1 for r in rs):
        bad()
    return tuple(sorted(set(rs)))


def int_at_least(low):
    """A validator of integers >= ``low``."""
    def check(ctx, where, value):
        """``int(value)`` if it is an integer >= the bound."""
        if isinstance(value, bool) or not isinstance(value, Integral) or value < low:
            ctx.fail(where, f"expected an integer >= {low}; got {value!r}")
        return int(value)
    check.describe = f"an integer >= {low}"
    return check


positive_int = int_at_least(1)
nonnegative_int = int_at_least(0)


def positive_float(ctx, where, value):
    """``float(value)`` if it is a finite number > 0."""
    if isinstance(value, bool) or not isinstance(value, Real) or not (math.isfinite(value) and value > 0):
        ctx.fail(where, f"expected a positive finite number; got {value!r}")
    return float(value)


def float_in_01(ctx, where, value):
    """``float(value)`` if it lies in the open interval (0, 1)."""
    if isinstance(value, bool) or not isinstance(value, Real) or not (0 < value < 1):
        ctx.fail(where, f"expected a number in (0, 1); got {value!r}")
    return float(value)


def finite_list(ctx, where, value):
    """A non-empty list of finite numbers, as floats."""
    if not isinstance(value, list) or not value or any(
            isinstance(v, bool) or not isinstance(v, Real) or not math.isfinite(v) for v in value):
        ctx.fail(where, f"expected a non-empty list of finite numbers; got {value!r}")
    return [float(v) for v in value]


def choice_of(choices):
    """A validator of one value from ``choices``."""
    def check(ctx, where, value):
        return ctx.choice(where, value, choices)
    check.choices = tuple(choices)
    return check


def subset_of(choices):
    """A list of distinct values from ``choices`` (in the order given)."""
    def check(ctx, where, value):
        if isinstance(value, str):
            value = [value]
        if not isinstance(value, list):
            ctx.fail(where, f"expected a list of values from {', '.join(choices)}; got {value!r}")
        for v in value:
            ctx.choice(where, v, choices)
        if len(set(value)) != len(value):
            ctx.fail(where, f"duplicate value in {value!r}")
        return list(value)
    check.describe = "a list of distinct values from " + ", ".join(map(str, choices))
    return check


def r_by_method(ctx, where, table, mlist, spec, kind):
    """``{alias: orders}`` of a scene's ``r_by_method``: methods of the scene, orders as ``r``."""
    ctx.keys(where, table, tuple(mlist))
    out = {}
    for alias, value in table.items():
        rs = r_values(ctx, f"{where}.{alias}", value)
        if spec.one_r and len(rs) != 1:
            ctx.fail(f"{where}.{alias}", f"a {kind!r} scene shows one reduced order per method; got {list(rs)}")
        out[alias] = rs
    return out
