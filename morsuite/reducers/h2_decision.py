r"""The H2 value on which ``so-h2`` and ``irka-fo`` decide: the suite's one H2 evaluator.

:func:`decision_h2` returns :math:`\|T - T_r\|_{\mathcal H_2}`, the bound of its error and whether
it is trusted, from :func:`morsuite.norms.h2.h2_error` (the function the studies and the CLI report
with), at relative accuracy :data:`DECISION_RTOL`: every decision (the start's ranking, "never worse
than the start", the best iterate) is made on the value, floor and flag the tables then show.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import AccuracyWarning
from ..norms.h2 import h2_error

__all__ = ["decision_h2", "DECISION_RTOL"]

#: relative accuracy asked of the evaluator for a decision (a ranking needs no more; the evaluator
#: stops escalating, and making LUs, once it is met)
DECISION_RTOL = 1e-6


def decision_h2(fom, rom, *, counter=None):
    r"""``(value, floor, trusted)`` of :math:`\|T - T_r\|_{\mathcal H_2}` for a decision.

    Parameters
    ----------
    fom : Index3Model
    rom : SecondOrderROM or FirstOrderROM

    Returns
    -------
    value : float
        The H2 error (``inf`` for an unstable model).
    floor : float
        Bound of its absolute error (``details["floor"]`` of :func:`~morsuite.norms.h2.h2_error`).
    trusted : bool
        The evaluator's ``trusted``.

    Notes
    -----
    Cost: that of :func:`~morsuite.norms.h2.h2_error` at ``rtol`` :data:`DECISION_RTOL`: the model's
    Gramian factors once per model (cached), then no LU or one LU per real pole or conjugate pair.
    """
    if not np.all(rom.poles().real < 0):
        return np.inf, 0.0, False
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", AccuracyWarning)  # the flag is returned
        value, d = h2_error(fom, rom, rtol=DECISION_RTOL, details=True)
    if counter is not None:
        counter["lu"] = counter.get("lu", 0) + int(d["lu_count"])
    return float(value), float(d["floor"]), bool(d["trusted"])
