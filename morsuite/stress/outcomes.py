r"""Outcome classes of a stress check, exception classification and known-bug attribution.

Classes (:data:`OUTCOMES`): ``pass``; ``not-converged`` (converged=False with a
ConvergenceWarning, every other invariant holding); ``refused`` (a documented
:class:`~morsuite.errors.MorsuiteError`); ``refused-spurious`` (a
SingularShiftError at a shift s where the Ruiz-equilibrated saddle-point matrix
has condition :math:`\kappa(s) <` :data:`SPURIOUS_KAPPA`: loud, documented, but
wrong); ``FAIL-undocumented`` (an exception that is not a MorsuiteError);
``FAIL-silent`` (NaN, a violated invariant, or a missing warning); ``skipped``
(the case needs a reducer that is not registered).

A ``FAIL-undocumented`` outcome is matched against :data:`KNOWN_BUGS` by
exception class and message; a ``FAIL-silent`` one is attributed to K1 (the
unequilibrated saddle solve) when the same check passes under
:class:`~morsuite.stress.reference.equilibrated_saddle` (:func:`attribute_silent`:
the check runs once more). Classifying a SingularShiftError costs one sparse LU
(the condition estimate at the failing shift).
"""

from __future__ import annotations

import re
import traceback
import warnings
from dataclasses import dataclass, field

from ..errors import MorsuiteError, SingularShiftError
from .reference import equilibrated_condition, equilibrated_saddle

__all__ = ["OUTCOMES", "SPURIOUS_KAPPA", "Outcome", "CheckFailed", "classify_exception", "KnownBug", "KNOWN_BUGS",
           "known_bug", "attribute_silent"]

OUTCOMES = ("pass", "not-converged", "refused", "refused-spurious", "FAIL-undocumented", "FAIL-silent", "skipped")
#: equilibrated condition number below which a SingularShiftError is spurious
SPURIOUS_KAPPA = 1e10


class CheckFailed(AssertionError):
    """An invariant was violated (silently wrong output)."""


@dataclass
class Outcome:
    """Result of one check (plain data)."""

    outcome: str
    detail: str = ""
    error_class: str = ""
    metrics: dict = field(default_factory=dict)


def _run_reducer(method, fom, r, options):
    """(Reduction or None, exception or None, list of warnings)."""
    from .. import reducers

    with warnings.catch_warnings(record=True) as W:
        warnings.simplefilter("always")
        try:
            res = reducers.make(method, fom, **options).reduce(r)
            return res, None, list(W)
        except Exception as exc:  # noqa: BLE001 - classified by the caller
            return None, exc, list(W)


_SHIFT_RE = re.compile(r"shift\(s\) \(?([-+0-9.e]+[-+][0-9.e]+j|[-+0-9.e]+)\)? hit a pole")
_COEFF_RE = re.compile(r"s-coefficients \(\(?([^,]+?)\)?, \(?([^,]+?)\)?, ")


def _failing_shift(exc, warns):
    """Best guess of the shift a SingularShiftError was raised at (None if unknown)."""
    s = getattr(exc, "shift", None)
    if s is not None:
        return complex(s)
    m = _COEFF_RE.search(str(exc))
    if m:
        try:
            return complex(m.group(2).replace(" ", ""))
        except ValueError:
            pass
    for w in reversed(warns):
        m = _SHIFT_RE.search(str(w.message))
        if m:
            try:
                return complex(m.group(1))
            except ValueError:
                pass
    return None


def classify_exception(fom, exc, warns) -> Outcome:
    """Documented (MorsuiteError) or not; a SingularShiftError at a well-conditioned shift is spurious."""
    name = type(exc).__name__
    if not isinstance(exc, MorsuiteError):
        tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__, limit=-3))
        where = re.findall(r'File "[^"]*?(morsuite/[^"]+)", line (\d+)', tb)
        loc = f" at {where[-1][0]}:{where[-1][1]}" if where else ""
        return Outcome("FAIL-undocumented", f"{name}: {str(exc)[:160]}{loc}", name)
    if isinstance(exc, SingularShiftError):
        s = _failing_shift(exc, warns)
        if s is not None:
            k = equilibrated_condition(fom, s)
            if k < SPURIOUS_KAPPA:
                return Outcome("refused-spurious", f"SingularShiftError at s = {s:.4g} where the equilibrated "
                               f"saddle matrix has condition {k:.1e}: {str(exc)[:120]}", name, {"kappa": k})
            return Outcome("refused", f"SingularShiftError at s = {s:.4g} (equilibrated condition {k:.1e})", name,
                           {"kappa": k})
    return Outcome("refused", f"{name}: {str(exc)[:200]}", name)


@dataclass(frozen=True)
class KnownBug:
    """A bug found by this suite in code it does not own, with its reproducer test."""

    key: str
    summary: str
    exc: str = ""          # exception class name for FAIL-undocumented signatures
    match: str = ""        # regex on the exception message
    test: str = ""


#: Bugs found by this suite and not yet fixed (none: K1-K7 are fixed, their reproducers are regression
#: tests in tests/stress/test_known_bugs.py; docs/design/stress.md)
KNOWN_BUGS: tuple = ()


def known_bug(outcome: Outcome):
    """The :class:`KnownBug` an undocumented exception matches (None if new or not an exception)."""
    if outcome.outcome != "FAIL-undocumented":
        return None
    for bug in KNOWN_BUGS:
        if bug.exc and bug.exc == outcome.error_class and re.search(bug.match, outcome.detail):
            return bug
    return None


def attribute_silent(recheck) -> str:
    """``"K1-saddle-accuracy"`` if ``recheck()`` (an Outcome) passes under :class:`equilibrated_saddle`."""
    with equilibrated_saddle():
        again = recheck()
    # the silent failure is gone (the recheck may still stop at a known crash further on)
    return "K1-saddle-accuracy" if again.outcome in ("pass", "not-converged", "refused") or known_bug(again) else ""
