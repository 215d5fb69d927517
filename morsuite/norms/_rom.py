r"""The reduced model's side of the norms: validation, pole-residue form, accurate response.

Every reduced model is handled through its first-order realization
:math:`(E, A, B, C, D)` (``rom.first_order()`` for a
:class:`~morsuite.rom.SecondOrderROM`: :math:`E = \mathrm{blkdiag}(I, \hat M)`,
:math:`A = [[0, I], [-\hat K, -\hat D]]`), with :math:`E` nonsingular.

Pole-residue form: with the eigenvalues :math:`\lambda_k` and right
eigenvectors :math:`X` of :math:`(A, E)` (for a second-order model those of
``rom.eig()``, computed on the balanced pencil),

.. math::

    T_r(s) = \sum_k \frac{c_k b_k^T}{s - \lambda_k} + D,\qquad
    [c_1, \dots] = CX,\quad [b_1, \dots]^T = X^{-1}E^{-1}B,

valid when :math:`X` is well conditioned. Its rounding perturbs the reduced
model by about :math:`\varepsilon\,\kappa(X)` (:math:`\kappa` of the
column-normalised :math:`X`), which is reported and bounds the trust in
every quantity computed from it. The form itself (:class:`Modal`,
:func:`modal_form`) lives in :mod:`morsuite.linalg.h2`, where the reducers
that track H2 errors use it too.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError, ShapeError
from ..linalg.h2 import Modal, modal_form  # noqa: F401  (re-exported: the core moved to linalg)
from ._fom import refined_unit

__all__ = ["first_order_arrays", "Modal", "modal_form", "RomResponse"]

LD = np.longdouble
CLD = np.clongdouble

#: reciprocal condition of E below which a first-order reduced model counts as descriptor (refused)
E_RCOND_MIN = 1e-13


def first_order_arrays(fom, rom, name: str = "rom"):
    """Validated (E, A, B, C, D) of ``rom`` (float arrays), matched against ``fom``'s inputs and outputs.

    Raises
    ------
    InputError
        ``rom`` is not a reduced model, has non-finite matrices or a singular E.
    ShapeError
        Its numbers of inputs or outputs differ from the model's.
    """
    if not hasattr(rom, "to_first_order") or not hasattr(rom, "poles"):
        raise InputError(f"{name} must be a reduced model (SecondOrderROM or FirstOrderROM); got "
                         f"{type(rom).__name__}")
    if (rom.m, rom.p) != (fom.m, fom.p):
        raise ShapeError(f"{name} has {rom.m} inputs and {rom.p} outputs; the model has {fom.m} and {fom.p}")
    fields = ("M", "D", "K", "F", "L") if rom.kind == "second-order" else ("E", "A", "B", "C", "D")
    for f in fields:
        X = np.asarray(getattr(rom, f))
        if not np.all(np.isfinite(X)):
            raise InputError(f"{name}: matrix {f} has non-finite entries (NaN or inf)")
    if rom.kind == "second-order":
        E, A, B, C = rom.first_order()
        D = np.zeros((rom.p, rom.m))
    else:
        E, A, B, C, D = (np.asarray(getattr(rom, f), dtype=float) for f in ("E", "A", "B", "C", "D"))
    if E.size:
        rc = 1.0 / np.linalg.cond(E, 1) if np.all(np.isfinite(E)) else 0.0
        if not rc > E_RCOND_MIN:
            raise InputError(f"{name}: E (or the reduced mass matrix) is singular (reciprocal condition "
                             f"{rc:.1e}); descriptor reduced models with infinite poles are not supported")
    return E, A, B, C, D


class RomResponse:
    r"""Accurate :math:`T_r(s)`: a dense solve with :math:`sE - A` and ``refine`` steps of
    refinement with the residual in long double (clongdouble result)."""

    def __init__(self, E, A, B, C, D, *, refine: int = 1):
        self.E, self.A, self.B, self.C, self.D = E, A, B, C, D
        self.refine = int(refine)
        self._ld = tuple(np.asarray(X, dtype=LD) for X in (E, A, B, C, D))
        self.last_unit = refined_unit(0.0, self.refine)

    def transfer(self, s) -> np.ndarray:
        P = s * self.E - self.A
        x = np.linalg.solve(P, self.B.astype(complex))
        if self.refine == 0:
            return self.C @ x + self.D
        E, A, B, C, D = self._ld
        sl = CLD(s)
        Pl = sl * E - A
        X = x.astype(CLD)
        rho = 0.0
        for step in range(self.refine):
            R = B - Pl @ X
            d = np.linalg.solve(P, np.asarray(R, dtype=complex))
            if step == 0:
                size = np.max(np.abs(x))
                rho = float(np.max(np.abs(d)) / size) if size > 0 else 0.0
            X = X + d.astype(CLD)
        self.last_unit = refined_unit(rho, self.refine)
        return C @ X + D

    def derivative(self, s) -> np.ndarray:
        r""":math:`T_r'(s) = -C(sE-A)^{-1}E(sE-A)^{-1}B` (double precision)."""
        P = s * self.E - self.A
        return -self.C @ np.linalg.solve(P, self.E @ np.linalg.solve(P, self.B.astype(complex)))
