r"""The hidden-manifold projector :math:`\Pi` applied without forming it.

For the constraint :math:`Gx = 0` of a system with mass matrix M,

.. math::

    \Pi = I - G^T (G M^{-1} G^T)^{-1} G M^{-1},

and :math:`\Pi b = Mx` with

.. math:: \begin{bmatrix} M & G^T \\ G & 0 \end{bmatrix}
          \begin{bmatrix} x \\ l \end{bmatrix} = \begin{bmatrix} b \\ 0 \end{bmatrix},

:math:`x = M^{-1}\Pi b \in \ker G`. Where only :math:`\Pi b` is needed, the
range-space form :math:`\Pi b = b - G^T X^T b`,
:math:`X = M^{-T}G^T(GM^{-T}G^T)^{-1}` (n1 x n2), costs two products with n2
columns. Cost: one real sparse LU of the matrix above per projector (none
without constraints), one checked solve with n2 columns for X.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ManifoldProjector"]


class ManifoldProjector:
    r"""Apply :math:`\Pi` through one LU of the saddle-point matrix of M (module docstring).

    ``proj(b)`` returns ``(Pi b, x)``; :math:`x = M^{-1}\Pi b \in \ker G` is
    the primal vector the shift strategies use. ``proj.project(b)`` returns
    :math:`\Pi b` alone, in range-space form for at most ``RANGE_FORM_MAX_N2``
    (64) constraints. Without constraints both are ``b``.

    The matrix does not depend on the shift, so its LU
    (``solver.factor(coeffs=(1, 0, 0))``) is checked once, by the backward
    error of one solve (at most ``BACKWARD_TOL`` = 1e-12), and later solves
    are unchecked; an LU that fails the check keeps the solver's checked solves.

    Parameters
    ----------
    fom : ConstrainedSystem
        Reads M, G, n1, n2.
    solver : SaddlePointSolver
        Makes the one LU (counted in its ``stats``).
    """

    #: largest normwise backward error accepted from the one-time check
    BACKWARD_TOL = 1e-12
    #: most constraints for which ``project`` keeps the dense n1 x n2 matrix X (above: solves)
    RANGE_FORM_MAX_N2 = 64

    def __init__(self, fom, solver):
        self.fom = fom
        self.lu = None
        self._raw = None  # the SuperLU object, used directly once the LU has passed the check
        self._X = None  # M^{-T} G^T (G M^{-T} G^T)^{-1}, for project()
        if fom.n2:
            lu = solver.factor(coeffs=(1.0, 0.0, 0.0))
            self.lu = lu
            # one check of the fixed LU (the solver's own measure), then unchecked solves
            ok = lu.matrix is None or lu.backward_error(np.cos(np.arange(fom.n1))) <= self.BACKWARD_TOL
            if ok and not lu.conjugate and not lu.complex_lu:
                self._raw = lu.lu
            if fom.n2 <= self.RANGE_FORM_MAX_N2:
                rhs = np.vstack([np.zeros((fom.n1, fom.n2)), np.eye(fom.n2)])
                self._X = np.ascontiguousarray(lu.solve(rhs, trans=True))  # checked (and refined) solve
                self._GT = fom.G.T.tocsr()

    def project(self, b):
        r""":math:`\Pi b` alone: :math:`b - G^T X^T b` (range-space form) for at most
        ``RANGE_FORM_MAX_N2`` constraints, else the solve of ``__call__``."""
        if self._X is None:
            return self(b)[0]
        return b - self._GT @ (self._X.T @ b)

    def __call__(self, b):
        if self.lu is None:
            return b, b
        if self._raw is None:  # an LU that failed the check: the solver's checked, refined solves
            x = self.lu.solve(b)
        else:  # real LU, zero constraint block; complex right-hand sides as 2k real columns
            if b.ndim == 1:
                Pb, x = self(b[:, None])
                return Pb[:, 0], x[:, 0]
            n1, k = self.fom.n1, b.shape[1]
            cplx = np.iscomplexobj(b)
            buf = np.zeros((n1 + self.fom.n2, 2 * k if cplx else k), order="F")
            if cplx:
                buf[:n1, :k], buf[:n1, k:] = b.real, b.imag
            else:
                buf[:n1] = b
            y = self.lu._raw_solve(buf, False)[:n1]  # unchecked, but with the equilibration
            x = y[:, :k] + 1j * y[:, k:] if cplx else y
        return self.fom.M @ x, x
