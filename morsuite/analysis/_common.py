"""Moved to :mod:`morsuite.norms._common` (the norms layer below the reducers); re-exported here."""

from ..norms._common import *  # noqa: F401,F403
from ..norms._common import __all__  # noqa: F401
