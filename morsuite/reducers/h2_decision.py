r"""The H2 value on which ``so-h2`` and ``irka-fo`` decide: one function, so that every decision
(the start's ranking, "never worse than the start", the best iterate) uses the same evaluator.

:func:`decision_h2` returns :math:`\|T - T_r\|_{\mathcal H_2}`, an absolute bound of its error and
whether the value is resolved (its floor below ``RESOLVED`` of the value). Today it evaluates the
pole-residue formula from one saddle-point solve per real pole or conjugate pair of the reduced model,
refined in long double (:func:`~morsuite.linalg.h2_stationarity.full_stationarity`), or takes a value
the caller already tracked from such solves (irka-fo's iterates: unrefined); it is the single place
to route through a certified evaluator.
"""

from __future__ import annotations

import numpy as np

from ..linalg.h2 import norm_squared
from ..linalg.h2_gradient import FullTarget
from ..linalg.h2_stationarity import full_stationarity

__all__ = ["decision_h2", "RESOLVED"]

#: a value is trusted when its floor is at most this fraction of it
RESOLVED = 0.25


def _first_order(rom):
    """(A, B, C) with E = I of a reduced model (second-order: M^-1 applied; first-order: E^-1)."""
    if rom.kind == "second-order":
        from .so_h2_starts import standard_realization
        return standard_realization(rom)
    return np.linalg.solve(rom.E, rom.A), np.linalg.solve(rom.E, rom.B), rom.C


def decision_h2(fom, rom, *, full=None, tracked=None):
    r"""``(value, floor, trusted)`` of :math:`\|T - T_r\|_{\mathcal H_2}` for a decision.

    Parameters
    ----------
    fom : Index3Model
    rom : SecondOrderROM or FirstOrderROM (stable)
    full : FullTarget, optional
        The model as target, with its solver (made from the model's cached Gramian factors if not given).
    tracked : (J, floor of J), optional
        :math:`J = \|T - T_r\|^2` and its floor already computed from the same solves (no LU made).

    Returns
    -------
    value : float
        The H2 error (``inf`` for an unstable model).
    floor : float
        Absolute bound of its rounding: :math:`\min(\sqrt f, f/\hat e)` for a floor f of J.
    trusted : bool
        ``floor <= RESOLVED * value``.

    Cost: one LU per real pole or conjugate pair of the reduced model, unless ``tracked`` is given.
    """
    if tracked is None:
        if full is None:
            n2, f2, _, _ = norm_squared(fom, {})
            full = FullTarget(fom, n2, f2)
        A, B, C = _first_order(rom)
        if not np.all(np.linalg.eigvals(A).real < 0):
            return np.inf, 0.0, False
        st = full_stationarity(full, A, B, C)
        J, f = st["value"], st["floor"]
    else:
        J, f = tracked
    e = float(np.sqrt(max(J, 0.0)))
    floor = float(min(np.sqrt(max(f, 0.0)), f / e)) if e > 0 else float(np.sqrt(max(f, 0.0)))
    return e, floor, bool(J > 0 and floor <= RESOLVED * e)
