"""Exception and warning hierarchy of morsuite.

Every failure that morsuite raises on purpose is a :class:`MorsuiteError`.
Errors caused by the caller's input also derive from :class:`ValueError`, so
``except ValueError`` keeps working for code that does not know morsuite.
Messages name the offending argument and say what was wrong with it.
"""

from __future__ import annotations


class MorsuiteError(Exception):
    """Base class of every error raised by morsuite."""


class InputError(MorsuiteError, ValueError):
    """An argument has the wrong type, shape, value or content."""


class ShapeError(InputError):
    """A matrix has the wrong shape or does not match another one."""


class ModelError(InputError):
    """A model is structurally unusable (e.g. rank-deficient constraints)."""


class OptionError(InputError):
    """An option of a reducer, a study or a command is unknown or out of range."""


class FileFormatError(InputError):
    """A file is missing, unreadable, or lacks a required entry."""


class SpecError(InputError):
    """A study specification is invalid."""


class SingularShiftError(MorsuiteError, ArithmeticError):
    """A shifted saddle-point matrix is singular to working precision."""


class MemoryBudgetError(MorsuiteError, MemoryError):
    """An operation would need more memory than the configured budget."""


class MorsuiteWarning(UserWarning):
    """Base class of every warning issued by morsuite."""


class ConvergenceWarning(MorsuiteWarning):
    """An iteration stopped before reaching its tolerance."""


class RankWarning(MorsuiteWarning):
    """A projection basis lost numerical rank; the reduced order was capped."""


class StabilityWarning(MorsuiteWarning):
    """A reduced model has (or had) poles in the closed right half-plane."""


class AccuracyWarning(MorsuiteWarning):
    """A computed quantity is less accurate than asked for (it is flagged, not returned as exact)."""


class DtypeWarning(MorsuiteWarning):
    """An input was converted to real floating point."""
