r"""What the linear-algebra kernels need of a constrained second-order system.

The kernels of :mod:`morsuite.linalg` work on

.. math::

    M \ddot x + D \dot x + K x + G^T z = F u, \qquad G x = 0, \qquad y = L x

through its matrices, never through the model class: :class:`ConstrainedSystem`
is the protocol they accept (``models.Index3Model`` provides it), and
:func:`check_system` validates an argument by its attributes. Nothing here
factors a matrix; the checks cost O(1).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
import scipy.sparse as sp

from ..errors import InputError, ShapeError
from .saddle import SaddlePointSolver

__all__ = ["ConstrainedSystem", "check_system", "new_solver", "SYSTEM_ATTRIBUTES"]

#: the attributes every kernel may read
SYSTEM_ATTRIBUTES = ("M", "D", "K", "G", "F", "L", "n1", "n2", "m", "p")


@runtime_checkable
class ConstrainedSystem(Protocol):
    """A constrained second-order system as the kernels read it.

    Attributes
    ----------
    M, D, K : sparse (n1, n1)
        Mass, damping and stiffness (physical sign convention).
    G : sparse (n2, n1)
        Constraint matrix of full row rank.
    F : ndarray (n1, m)
    L : ndarray (p, n1)
    n1, n2, m, p : int

    Optionally ``new_solver(**options)``, returning a fresh
    :class:`~morsuite.linalg.saddle.SaddlePointSolver` of the system (a model
    shares its sparsity pattern and column ordering this way); without it a
    solver is built from M, D, K, G (see :func:`new_solver`).
    """

    M: sp.spmatrix
    D: sp.spmatrix
    K: sp.spmatrix
    G: sp.spmatrix
    F: np.ndarray
    L: np.ndarray
    n1: int
    n2: int
    m: int
    p: int


def check_system(system, name: str = "fom"):
    """Return ``system`` if it provides :class:`ConstrainedSystem` with consistent shapes.

    Raises
    ------
    InputError
        An attribute is missing or a matrix has the wrong kind (the message
        names the argument and the attributes).
    ShapeError
        A matrix's shape disagrees with n1, n2, m, p.
    """
    missing = [a for a in SYSTEM_ATTRIBUTES if not hasattr(system, a)]
    if missing:
        raise InputError(f"{name} must provide the attributes {', '.join(SYSTEM_ATTRIBUTES)} of a constrained "
                         f"second-order system (linalg.system.ConstrainedSystem); {type(system).__name__} "
                         f"lacks {', '.join(missing)}")
    dims = {a: getattr(system, a) for a in ("n1", "n2", "m", "p")}
    for a, v in dims.items():
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or v < 0:
            raise InputError(f"{name}.{a} must be a non-negative integer; got {v!r}")
    n1, n2, m, p = (int(dims[a]) for a in ("n1", "n2", "m", "p"))
    expected = {"M": (n1, n1), "D": (n1, n1), "K": (n1, n1), "G": (n2, n1), "F": (n1, m), "L": (p, n1)}
    for a, shape in expected.items():
        X = getattr(system, a)
        if a in "MDKG" and not sp.issparse(X):
            raise InputError(f"{name}.{a} must be a scipy.sparse matrix; got {type(X).__name__}")
        if a in "FL" and not (isinstance(X, np.ndarray) and X.ndim == 2):
            raise InputError(f"{name}.{a} must be a 2-D ndarray; got {type(X).__name__}")
        if tuple(X.shape) != shape:
            raise ShapeError(f"{name}.{a} has shape {tuple(X.shape)}; expected {shape} from "
                             f"(n1, n2, m, p) = {(n1, n2, m, p)}")
    return system


def new_solver(system, **options):
    """A fresh saddle-point solver of ``system``: ``system.new_solver(**options)`` where provided
    (it shares the model's pattern and column ordering), else one built from M, D, K, G."""
    make = getattr(system, "new_solver", None)
    if make is not None:
        return make(**options)
    return SaddlePointSolver(system.M, system.D, system.K, system.G, **options)
