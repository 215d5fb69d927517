r"""The exact H2 score of IRKA's shortlisted iterates when the iteration does not converge.

Without convergence the engine returns one of the stable iterates that its
:class:`~.irka_safeguards.Shortlist` kept (the ``shortlist`` of smallest convergence
measure). :class:`ExactH2Score` ranks them by their exact H2 error,

.. math::

    \|T - T_r\|_{\mathcal H_2}^2 = \|T\|_{\mathcal H_2}^2 - 2\,\langle T, T_r\rangle
        + \|T_r\|_{\mathcal H_2}^2,

through its part that depends on the iterate, the score
:math:`J' = \|T_r\|^2 - 2\langle T, T_r\rangle = \|T - T_r\|^2 - \|T\|^2`
(:func:`morsuite.linalg.h2_gradient.h2_value` against
:class:`~morsuite.linalg.h2_gradient.FullTarget` with a zero norm): the cross term from
one saddle-point solve pair at each mirrored pole :math:`-\lambda_k` of the iterate,
:math:`\|T_r\|^2` from a 2r x 2r Lyapunov equation. The constant :math:`\|T\|^2` does not
change the ranking, so no Gramian factor is computed for it; when the model's cache holds
the factors (``bt`` or :func:`morsuite.analysis.h2_error` ran before, or ``norm="compute"``),
each record also carries the H2 error itself (:func:`morsuite.linalg.h2.norm_squared`).
The terms cancel to about :math:`\varepsilon\|T\|^2` (the record's ``floor``): iterates
closer than that are ranked by rounding, which cannot matter for the choice.

Cost: per scored iterate one sparse LU per real pole or conjugate pair of the 2r-state
reduced model (r LUs when all its poles are complex, at most 2r), for at most
``shortlist`` iterates (default 5): typically ``5 r`` LUs at the end, against about
``r maxit`` LUs of the iteration. ``norm="compute"`` adds the factors' LR-ADI once
per model (e.g. 131 LUs on ``tcom(nc=40)``).
"""

from __future__ import annotations

import numpy as np

from ..linalg.gramians import ADI_DEFAULTS, cached_gramian_factors
from ..linalg.h2 import norm_squared
from ..linalg.h2_gradient import EPS, FullTarget, h2_value
from .so_h2_starts import standard_realization

__all__ = ["ExactH2Score", "rom_realization", "iterate_scorer", "score_cost"]


def rom_realization(rom):
    """(A, B, C) with E = I of a reduced model: M (second-order) or E (first-order) applied as its inverse."""
    if rom.kind == "second-order":
        return standard_realization(rom)
    return np.linalg.solve(rom.E, rom.A), np.linalg.solve(rom.E, rom.B), rom.C


class ExactH2Score:
    r"""Callable ``(fom, rom) -> J'`` (the H2 error's square minus :math:`\|T\|^2`; smaller is better).

    Parameters
    ----------
    norm : {"cached", "compute"}
        :math:`\|T\|^2` for the records: only from Gramian factors already cached on the
        model (no work), or computed (LR-ADI once per model when not cached).
    adi : dict, optional
        LR-ADI options of the factors (default :data:`~morsuite.linalg.gramians.ADI_DEFAULTS`,
        those of ``bt`` and ``h2_error``, so that the cached factors are shared).

    Attributes
    ----------
    lu_count : int
        Sparse LUs of the cross terms made so far.
    gramian_lu_count : int
        LR-ADI LUs of the Gramian factors made by this scorer (0 unless ``norm="compute"``
        found no cached factors).
    records : list of dict
        One per call: ``score`` (J'), ``floor`` (its estimated absolute rounding),
        ``h2_error`` (None when the norm is not known), ``lu_count``.
    """

    def __init__(self, norm: str = "cached", adi=None):
        self.norm, self.adi = norm, dict(ADI_DEFAULTS if adi is None else adi)
        self.lu_count = 0
        self.gramian_lu_count = 0
        self.records = []
        self._fom = self._target = None
        self._norm2 = None

    def _setup(self, fom):
        if self._fom is fom:
            return
        self._fom, self._target, self._norm2 = fom, FullTarget(fom, 0.0), None
        if self.norm == "compute" or cached_gramian_factors(fom, **self.adi) is not None:
            norm2, _, rec, _ = norm_squared(fom, self.adi)
            self.gramian_lu_count += int(rec["gramian_lu_count"])
            self._norm2 = norm2

    def __call__(self, fom, rom) -> float:
        self._setup(fom)
        ev = h2_value(self._target, *rom_realization(rom)) if rom.is_stable() else None
        if ev is None or not ev.stable:
            self.records.append({"score": np.inf, "floor": 0.0, "h2_error": np.inf, "lu_count": 0})
            return np.inf
        self.lu_count += ev.lu_count
        # the rounding of the three-term form is eps times the size of its terms, ||T||^2 included
        floor = ev.floor + (8.0 * EPS * self._norm2 if self._norm2 is not None else 0.0)
        e = None if self._norm2 is None else float(np.sqrt(max(self._norm2 + ev.value, 0.0)))
        self.records.append({"score": float(ev.value), "floor": float(floor), "h2_error": e,
                             "lu_count": int(ev.lu_count)})
        return float(ev.value)


def iterate_scorer(reducer):
    """The scorer of an IRKA reducer's shortlist: its ``iterate_score`` if set, else by option
    ``shortlist_score`` an :class:`ExactH2Score` (``"h2"``) or None (``"measure"``)."""
    score = getattr(reducer, "iterate_score", None)
    if score is not None:
        return score
    return ExactH2Score() if reducer.options["shortlist_score"] == "h2" else None


def score_cost(score) -> dict:
    """The LUs a scorer made (0 for a scorer that does not count them), for ``info["safeguard"]``."""
    return {"score_lu_count": int(getattr(score, "lu_count", 0)),
            "score_gramian_lu_count": int(getattr(score, "gramian_lu_count", 0)),
            "score_records": list(getattr(score, "records", []))}
