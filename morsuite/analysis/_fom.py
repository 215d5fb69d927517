"""Moved to :mod:`morsuite.norms._fom` (the norms layer below the reducers); re-exported here."""

from ..norms._fom import *  # noqa: F401,F403
from ..norms._fom import __all__  # noqa: F401
