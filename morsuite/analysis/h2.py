"""Exact H2 norms: re-exported from :mod:`morsuite.norms.h2`, the one H2 evaluator (see there)."""

from ..norms.h2 import *  # noqa: F401,F403
from ..norms.h2 import __all__, breakpoints, resonances  # noqa: F401
