"""Moved to :mod:`morsuite.norms._quad` (the norms layer below the reducers); re-exported here."""

from ..norms._quad import *  # noqa: F401,F403
from ..norms._quad import __all__  # noqa: F401
