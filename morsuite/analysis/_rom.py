"""Moved to :mod:`morsuite.norms._rom` (the norms layer below the reducers); re-exported here."""

from ..norms._rom import *  # noqa: F401,F403
from ..norms._rom import __all__  # noqa: F401
