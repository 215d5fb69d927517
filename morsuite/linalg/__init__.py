"""Linear algebra kernels: saddle-point solver, LR-ADI, small dense kernels.

They take matrices, or any object providing :class:`~morsuite.linalg.system.ConstrainedSystem`,
never the model class: :mod:`morsuite.models` builds on this package, not the reverse.
"""

from .saddle import SaddleLU, SaddlePointSolver, SolverStats
from .adi_result import LRADIResult  # noqa: F401
from .lradi import lradi, lradi_pair  # noqa: F401
from .system import ConstrainedSystem

__all__ = ["SaddlePointSolver", "SaddleLU", "SolverStats", "LRADIResult", "lradi", "lradi_pair",
           "ConstrainedSystem"]
