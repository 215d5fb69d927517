"""Linear algebra kernels: saddle-point solver, LR-ADI, small dense kernels."""

from .saddle import SaddleLU, SaddlePointSolver, SolverStats

__all__ = ["SaddlePointSolver", "SaddleLU", "SolverStats"]
