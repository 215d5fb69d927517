r"""The exact H2 score of IRKA's shortlisted iterates when the iteration does not converge.

Without convergence the engine returns one of the stable iterates that its
:class:`~morsuite.reducers.irka.safeguards.Shortlist` kept (the ``shortlist`` of smallest convergence
measure). :class:`ExactH2Score` ranks them by their exact H2 error
:math:`\|T - T_r\|_{\mathcal H_2}` from the suite's one H2 evaluator,
:func:`morsuite.norms.h2.h2_error`: the value, floor and ``trusted`` flag the studies
report for the returned model are the ones the choice was made on.

Cost: the model's Gramian factors once per model (LR-ADI, shared with ``bt`` and the
norms through the model's cache), then per scored iterate dense work of order
:math:`k r^2` and, when the error is small against :math:`\|T\|`, one sparse LU per real
pole or conjugate pair of the iterate, for at most ``shortlist`` iterates (default 5),
against about ``r maxit`` LUs of the iteration (``docs/design/norms.md``).
"""

from __future__ import annotations

import warnings

import numpy as np

from ...errors import AccuracyWarning
from ...linalg.gramians import ADI_DEFAULTS, cached_gramian_factors
from ...norms.h2 import h2_error

__all__ = ["ExactH2Score", "iterate_scorer", "score_cost"]


class ExactH2Score:
    r"""Callable ``(fom, rom) -> ||T - T_r||_H2`` (smaller is better), by the suite's one H2 evaluator.

    Every score is :func:`morsuite.norms.h2.h2_error` with its floor: the same value,
    accuracy guarantee and ``trusted`` flag the studies report, so that the iterate
    IRKA returns is the one the tables rank best.

    Parameters
    ----------
    norm : {"cached", "compute"}
        Kept for compatibility: the evaluator needs the model's Gramian factors and
        computes them once per model when they are not cached (shared with ``bt`` and
        the studies' norms), whichever is given.
    adi : dict, optional
        LR-ADI options of the factors (default :data:`~morsuite.linalg.gramians.ADI_DEFAULTS`,
        those of ``bt`` and ``h2_error``, so that the cached factors are shared).

    Attributes
    ----------
    lu_count : int
        Sparse LUs of the evaluations made so far (their solves at mirrored poles).
    gramian_lu_count : int
        LR-ADI LUs of the Gramian factors made by this scorer (0 when they were cached).
    gramian_lu_relied, gramian_time_relied : int, float
        LUs and seconds of the Gramian factors the scores relied on, whoever paid them (this
        scorer or the model's cache): the same whatever ran before on the model (0 before any score).
    records : list of dict
        One per call: ``score`` (the H2 error), ``floor`` (its absolute error bound),
        ``h2_error``, ``trusted``, ``route``, ``lu_count``.
    """

    def __init__(self, norm: str = "cached", adi=None):
        self.norm, self.adi = norm, dict(ADI_DEFAULTS if adi is None else adi)
        self.lu_count = 0
        self.gramian_lu_count = 0
        self.gramian_lu_relied, self.gramian_time_relied = 0, 0.0
        self.records = []

    def __call__(self, fom, rom) -> float:
        if not rom.is_stable():
            self.records.append({"score": np.inf, "floor": 0.0, "h2_error": np.inf, "lu_count": 0,
                                 "trusted": True, "route": None})
            return np.inf
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", AccuracyWarning)  # the record carries trusted and the floor
            value, d = h2_error(fom, rom, adi=self.adi, details=True)
        gram = int(d.get("gramian", {}).get("gramian_lu_count", 0))
        self.gramian_lu_count += gram
        gf = cached_gramian_factors(fom, **self.adi)  # the factors the value came from (cached by now)
        if gf is not None:
            self.gramian_lu_relied, self.gramian_time_relied = int(gf.lu_count), float(gf.time_s)
        self.lu_count += int(d["lu_count"]) - gram
        self.records.append({"score": float(value), "floor": float(d["floor"]), "h2_error": float(value),
                             "trusted": bool(d["trusted"]), "route": d["method"],
                             "lu_count": int(d["lu_count"]) - gram})
        return float(value)


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
            "score_gramian_lu_relied": int(getattr(score, "gramian_lu_relied", 0)),
            "score_gramian_time_relied": float(getattr(score, "gramian_time_relied", 0.0)),
            "score_records": list(getattr(score, "records", []))}
