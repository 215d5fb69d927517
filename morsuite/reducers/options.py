r"""Declared options: one :class:`Option` per name, advanced ones in named :class:`Group` s.

A reducer declares every option once in ``OPTIONS`` (name -> :class:`Option`: default, constraint,
a one-line description). The few that users set stay at the top level; the advanced ones are
gathered in ``GROUPS`` (group name -> :class:`Group`), documented apart as advanced, and given as a
table: ``make("irka", fom, tol=1e-8, safeguards={"window": 5})``, in a study
``[methods.x.options.safeguards]`` / ``window = 5``, on the command line
``--option safeguards.window=5``. Inside a group an option goes by its short name (the group's
``prefix`` removed: ``safeguard_window`` is ``window`` in ``safeguards``).

**Recorded flat.** Every option keeps its own name, the flat one, everywhere the values are
recorded: ``self.options``, ``info["options"]``, study manifests and the cache keys that digest
them (unchanged by the grouping, so cached results stay valid). The flat name is also accepted as
input (``safeguard_window=5``, as before the groups): a script or study written before keeps working.
Giving one option both ways is refused, as is an unknown name inside a group (the message lists the
group's options). Cost of the expansion: O(number of options).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any

import numpy as np

from ..errors import OptionError

__all__ = ["Option", "Group", "expand_options", "top_level"]


@dataclass(frozen=True)
class Option:
    """One declared option: default, constraint and a one-line description.

    ``kind`` is one of "int", "float", "bool", "choice", "array", "any".
    ``low``/``high`` bound numbers (``open_low``/``open_high`` make them strict);
    ``choices`` lists the admissible values of a "choice"; ``nullable`` admits None.
    """

    default: Any
    kind: str
    doc: str = ""
    low: float | None = None
    high: float | None = None
    open_low: bool = False
    open_high: bool = False
    choices: tuple = ()
    nullable: bool = False

    def describe(self) -> str:
        """The admissible values in words, as error messages and option tables show them.

        For example ``"a float in (0, 1)"``, ``"an int in [1, inf)"`` or
        ``"one of 'auto', 'bt', 'residue'"``.
        """
        if self.kind == "choice":
            return "one of " + ", ".join(repr(c) for c in self.choices)
        if self.kind in ("int", "float"):
            lo = "-inf" if self.low is None else f"{self.low:g}"
            hi = "inf" if self.high is None else f"{self.high:g}"
            lb = "(" if self.open_low or self.low is None else "["
            rb = ")" if self.open_high or self.high is None else "]"
            return f"{'an int' if self.kind == 'int' else 'a float'} in {lb}{lo}, {hi}{rb}"
        return {"bool": "a bool", "array": "an array of numbers", "any": "a value"}[self.kind]

    def validate(self, owner: str, name: str, value):
        """Check ``value`` against this option's constraint and return it normalised.

        Parameters
        ----------
        owner : str
            The reducer's class name, for the message.
        name : str
            The option's name, for the message.
        value
            The value given.

        Returns
        -------
        value
            The value as the reducer uses it: ``bool``, ``int`` or ``float`` for those kinds
            (NumPy scalars converted), an ndarray for ``"array"``, the value itself
            otherwise; None if ``nullable``.

        Raises
        ------
        OptionError
            If the value is outside the constraint, in the form
            ``The 'tol' parameter of IRKA must be a float in (0, 1). Got -1 instead.``
            A bool is never accepted as a number; non-finite numbers and arrays with
            non-finite or non-numeric entries are refused.
        """
        def fail():
            raise OptionError(f"The {name!r} parameter of {owner} must be {self.describe()}"
                              f"{' or None' if self.nullable else ''}. Got {value!r} instead.")
        if value is None:
            if self.nullable:
                return None
            fail()
        if self.kind == "bool":
            if not isinstance(value, (bool, np.bool_)):
                fail()
            return bool(value)
        if self.kind == "choice":
            if value not in self.choices:
                fail()
            return value
        if self.kind in ("int", "float"):
            if isinstance(value, (bool, np.bool_)):
                fail()
            if self.kind == "int" and not isinstance(value, Integral):
                fail()
            if not isinstance(value, Real) or not math.isfinite(float(value)):
                fail()
            v = int(value) if self.kind == "int" else float(value)
            if self.low is not None and (v < self.low or (self.open_low and v == self.low)):
                fail()
            if self.high is not None and (v > self.high or (self.open_high and v == self.high)):
                fail()
            return v
        if self.kind == "array":
            try:
                arr = np.asarray(value)
            except Exception:
                fail()
            if arr.dtype == object or not np.issubdtype(arr.dtype, np.number) or not np.all(np.isfinite(arr)):
                fail()
            return arr
        return value


@dataclass(frozen=True)
class Group:
    """A named group of advanced options: ``members`` (their names in ``OPTIONS``), one line of ``doc``,
    and the ``prefix`` removed from a member's name inside the group (``"safeguard_"``: the option
    ``safeguard_window`` is ``window`` in the group)."""

    doc: str
    members: tuple
    prefix: str = ""

    def short(self, name: str) -> str:
        """The name of option ``name`` inside the group."""
        return name[len(self.prefix):] if self.prefix and name.startswith(self.prefix) else name

    def names(self) -> dict:
        """Short name -> option name, in declaration order."""
        return {self.short(m): m for m in self.members}

    def extended(self, *members: str) -> "Group":
        """The group with ``members`` added (a subclass that declares more options of the same kind)."""
        return Group(self.doc, tuple(self.members) + tuple(members), self.prefix)


def top_level(options: dict, groups: dict) -> list:
    """The names of ``options`` that are in no group of ``groups``, in declaration order."""
    grouped = {m for g in groups.values() for m in g.members}
    return [k for k in options if k not in grouped]


def expand_options(owner: str, options: dict, groups: dict, given: dict) -> tuple:
    """``(flat, given_as)``: the options ``given`` (top-level names, flat names, or a table per group)
    under their flat names, and for each the name it was given as (``"safeguards.window"``), for the
    messages.

    Raises
    ------
    OptionError
        For an unknown name (the message lists the top-level options and the groups), a group given as
        something else than a table, an unknown name inside a group (the message lists the group's
        options), or one option given twice (flat and in its group).
    """
    flat, given_as = {}, {}
    for key, value in given.items():
        if key in groups:
            grp = groups[key]
            if not isinstance(value, dict):
                raise OptionError(f"The {key!r} options of {owner} are given as a table {{name: value}} of "
                                  f"{', '.join(grp.names())}; got {value!r}")
            names = grp.names()
            for sub, v in value.items():
                if sub not in names:
                    raise OptionError(f"The {key!r} options of {owner} have no {sub!r}; valid: "
                                      f"{', '.join(names)}")
                _put(owner, flat, given_as, names[sub], v, f"{key}.{sub}")
        elif key in options:
            _put(owner, flat, given_as, key, value, key)
        else:
            unknown = sorted(k for k in given if k not in options and k not in groups)
            raise OptionError(f"{owner} got unknown option(s) {', '.join(map(repr, unknown))}; valid options: "
                              f"{', '.join(sorted(top_level(options, groups)))}"
                              + ("; advanced, as tables: " + "; ".join(f"{g} ({', '.join(grp.names())})"
                                                                      for g, grp in groups.items()) if groups else ""))
    return flat, given_as


def _put(owner, flat, given_as, name, value, shown):
    if name in flat:
        raise OptionError(f"{owner}: option {name!r} is given twice, as {given_as[name]!r} and as {shown!r}")
    flat[name], given_as[name] = value, shown
