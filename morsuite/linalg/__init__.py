"""Linear algebra kernels: saddle-point solver, LR-ADI, small dense kernels."""

from .saddle import SaddleLU, SaddlePointSolver, SolverStats
from .lradi import LRADIResult, lradi, lradi_pair  # noqa: F401

__all__ = ["SaddlePointSolver", "SaddleLU", "SolverStats"]
