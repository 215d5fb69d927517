r"""Exact norms of the full model and of reduced models' errors: the one H2 evaluator.

This layer sits between the models and the reducers (``linalg < models < norms <
reducers < analysis``), so that every H2 value the suite reports or decides on (the
studies, the CLI, and the reducers' best-iterate and never-worse choices) comes from
one implementation with one accuracy guarantee: :func:`~morsuite.norms.h2.h2_error`.
The public entry points are re-exported by :mod:`morsuite.analysis`.
"""

from .h2 import h2_error, h2_norm, h2_rel_error

__all__ = ["h2_error", "h2_norm", "h2_rel_error"]
