r"""What a reduction's ``info`` says about how it ended and what it cost.

Every reducer's ``info`` carries, besides its own records:

``status`` (one of :data:`STATUS`) and ``converged``
    ``converged`` is True only when the method's own optimality or fixed-point test
    passed on the full model (IRKA: the shift or response change below ``tol`` at a
    stable iterate; so-h2: the relative gradient norm at or below its tolerance; bt:
    both Lyapunov residuals below the LR-ADI tolerance). Every other ending is a
    ``status`` value with ``converged=False``: an iteration cap, a cycle, a stall, a
    skipped iteration. :data:`CONVERGED_STATUSES` are the values that go with
    ``converged=True``; :func:`check_outcome` enforces the pairing, and
    :meth:`Reducer.reduce <morsuite.reducers.Reducer.reduce>` applies it to every result
    (a reducer that sets only one of the two gets the other derived,
    :func:`complete_outcome`).
``status_reason``
    A sentence saying why, where a status other than ``converged``/``direct`` comes from
    something the method depends on rather than its own iteration (``partial``: how many modes
    ARPACK converged; ``detection-failed``: what the rigid-body detection said). A warning
    with the same text is issued and recorded in ``info["warnings"]``; the method's own
    status, when it said converged or direct, is kept as ``method_status``.
``lu_count``, ``lu_count_shared``, ``setup_reused``, ``setup_cost``
    ``lu_count`` is every LU this call paid (the LUs its ``time_s`` covers: sparse LUs of
    the saddle-point matrix, or dense LUs for ``irka-projected``, whatever they served:
    bases, Gramian factors, a start, scoring). ``lu_count_shared`` is the LUs of the work
    that does not depend on r and that the result relies on (Gramian factors, a start's
    LR-ADI, a projector), counted whoever paid them: this call, an earlier call of the
    same reducer, or the model's cache. ``setup_reused`` is True when this call did not
    pay that shared work (then ``lu_count`` leaves ``lu_count_shared`` out and ``time_s``
    leaves ``setup_cost`` out, by parts: ``setup_cost`` maps a part's name to its time,
    ``setup_paid`` -- or, where a reducer has none, ``time_breakdown`` -- holds what this
    call paid of each part). A reducer whose reusable pieces are many (so-h2's BT levels and
    surrogate models) keeps a :class:`SetupLedger`: each piece's cost when it was made,
    and which pieces a call used and made.

:func:`standalone_time` and :func:`standalone_lu_count` give the cost of reducing to
this r alone, on a fresh reducer and a fresh model: the one definition the studies
(``time_standalone_s``) and the benchmarks (``bench pareto``) use. Design note:
``docs/design/reducers.md`` (section "Status and cost accounting").
"""

from __future__ import annotations

from numbers import Integral, Real

import numpy as np

from ..errors import MorsuiteError

__all__ = ["STATUS", "CONVERGED_STATUSES", "SetupLedger", "check_outcome", "complete_outcome", "standalone_time",
           "standalone_lu_count"]

#: The values of ``info["status"]`` and what each means.
STATUS = {
    "converged": "the method's own optimality or fixed-point test passed on the full model",
    "direct": "a method that does not iterate on its result (bt): its inner solves met their "
              "tolerances and the result is not an iterate",
    "cap": "the iteration cap (the method's maxit, or an inner solver's maxiter) was reached "
           "before the test passed; the best iterate is returned",
    "cycle": "the iteration stopped on a detected cycle; the best iterate is returned",
    "stalled": "the iteration stopped because it made no more progress (e.g. a small decrease over a "
               "window of steps) before the test passed",
    "uncertified": "the iteration's own stopping rule held, but the method's test on the full model "
                   "failed or could not be made",
    "budget": "the method's budget ran out before its test passed (its LUs, max_lus, or the time of a "
              "tolerance search, Reducer.deadline); the best model within the budget is returned",
    "skipped": "the method did not iterate (e.g. its start is below the objective's resolution); "
               "its start is returned",
    "partial": "an inner eigensolver converged only some of what was asked (ARPACK within its restart cap: "
               "modal's modes); the result is built from what converged and may lack modes",
    "detection-failed": "the model's rigid-body-mode detection failed or converged only in part "
                        "(morsuite.models.rigid): it was reduced as having the rigid modes found (none if the "
                        "detection failed), which may be wrong",
    "stopped": "converged=False and the reducer did not say why (set by the base class)",
}

#: The statuses that go with ``converged=True``; every other one goes with ``converged=False``.
CONVERGED_STATUSES = ("converged", "direct")


def complete_outcome(info: dict) -> dict:
    """Fill what a reducer's ``info`` lacks of ``converged``, ``status`` and the LU counts (in place).

    Parameters
    ----------
    info : dict
        A reducer's ``info`` record.

    Returns
    -------
    dict
        ``info``: with only ``status``, ``converged = status in CONVERGED_STATUSES``;
        with only ``converged``, ``status = "converged"`` or ``"stopped"``; with neither,
        ``converged = True`` and ``status = "direct"`` (a method that does not say it
        iterates). ``lu_count`` defaults to 0 and ``lu_count_shared`` to the older
        ``lu_count_gramians``, else 0. Cost: none.
    """
    if isinstance(info.get("converged"), np.bool_):
        info["converged"] = bool(info["converged"])
    info.setdefault("lu_count", 0)
    info.setdefault("lu_count_shared", info.get("lu_count_gramians", 0))
    for key in ("lu_count", "lu_count_shared"):  # NumPy integers as int
        if isinstance(info[key], Integral) and not isinstance(info[key], (bool, np.bool_)):
            info[key] = int(info[key])
    if "status" in info and "converged" not in info:
        info["converged"] = info["status"] in CONVERGED_STATUSES
    elif "status" not in info:
        if "converged" not in info:
            info["converged"], info["status"] = True, "direct"
        else:
            info["status"] = "converged" if info["converged"] else "stopped"
    return info


def check_outcome(info: dict, who: str = "reducer") -> None:
    """Check a reducer's ``info``: ``status`` against ``converged``, and the LU counts.

    Parameters
    ----------
    info : dict
        A reducer's ``info`` record with ``status``, ``converged``, ``lu_count`` and
        ``lu_count_shared``.
    who : str
        The reducer's name, for the message.

    Raises
    ------
    MorsuiteError
        If ``status`` is not a :data:`STATUS` value, ``converged`` is not a bool, or
        ``converged`` is True with a status outside :data:`CONVERGED_STATUSES` (or False
        with one inside): a reducer that says "converged" for a capped, cycled, stalled or
        skipped run is a bug, never a result. Also if ``lu_count`` or ``lu_count_shared``
        is not a nonnegative int, or a call that paid its shared work (``setup_reused``
        False) reports fewer LUs than that work's. Cost: none.
    """
    status, conv = info.get("status"), info.get("converged")
    if status not in STATUS:
        raise MorsuiteError(f"{who}: info['status'] = {status!r} is not one of {', '.join(STATUS)}")
    if not isinstance(conv, bool):
        raise MorsuiteError(f"{who}: info['converged'] must be a bool; got {conv!r}")
    if conv != (status in CONVERGED_STATUSES):
        raise MorsuiteError(f"{who}: info['converged'] = {conv} contradicts info['status'] = {status!r} "
                            f"(converged=True goes with {' or '.join(CONVERGED_STATUSES)} only)")
    counts = {k: info.get(k) for k in ("lu_count", "lu_count_shared")}
    for key, n in counts.items():
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise MorsuiteError(f"{who}: info[{key!r}] must be a nonnegative int; got {n!r}")
    if not info.get("setup_reused") and counts["lu_count"] < counts["lu_count_shared"]:
        raise MorsuiteError(f"{who}: info['lu_count'] = {counts['lu_count']} leaves out shared LUs it paid "
                            f"(lu_count_shared = {counts['lu_count_shared']}, setup_reused False)")


def _number(x) -> float:
    return float(x) if isinstance(x, Real) and not isinstance(x, bool) else 0.0


def standalone_time(info: dict, wall: float | None = None) -> float:
    r"""Seconds of ``reduce(r)`` on a fresh reducer and model: this call plus the shared work it reused.

    .. math::

        t_\text{standalone} = t + [\text{setup\_reused}]
            \sum_k \max\bigl(0,\ \text{setup\_cost}_k - \text{time\_breakdown}_k\bigr),

    with :math:`t` = ``info["time_s"]`` (``wall`` when the record has no ``time_s``) and
    :math:`k` over the parts of the r-independent work (``setup_cost``: Gramian factors,
    their SVD, a projector, so-h2's BT levels and surrogate models); the subtraction leaves
    out what this call paid of a part itself (``setup_paid``, else ``time_breakdown``; e.g. a
    reused reducer that computes the SVD of a new level), so nothing is counted twice. Without ``setup_reused`` it is :math:`t`.

    Parameters
    ----------
    info : dict
        A reducer's ``info``.
    wall : float, optional
        The caller's timing of the call, used when ``info`` has no ``time_s``.

    Returns
    -------
    float
        Seconds. Cost: none.
    """
    t = _number(info.get("time_s", wall))
    if not info.get("setup_reused"):
        return t
    paid = info.get("setup_paid") or info.get("time_breakdown") or {}
    for key, cost in (info.get("setup_cost") or {}).items():
        t += max(0.0, _number(cost) - _number(paid.get(key, 0.0)))
    return t


def standalone_lu_count(info: dict) -> int:
    r"""LUs of ``reduce(r)`` on a fresh reducer and model: ``lu_count`` plus the shared LUs it reused.

    :math:`\text{lu\_count} + [\text{setup\_reused}]\,\text{lu\_count\_shared}`
    (``lu_count_shared`` falls back to the older ``lu_count_gramians``, then 0, for records
    written before it existed).

    Parameters
    ----------
    info : dict
        A reducer's ``info``.

    Returns
    -------
    int
        The count. Cost: none.
    """
    lus = int(info.get("lu_count") or 0)
    if info.get("setup_reused"):
        lus += int(info.get("lu_count_shared", info.get("lu_count_gramians")) or 0)
    return lus


class SetupLedger:
    """The r-independent pieces a reducer made once and reuses across calls: cost, use, making.

    A reducer calls :meth:`begin` at the start of each ``reduce``, :meth:`made` when it
    makes a piece (with the seconds it took) and :meth:`used` whenever a call relies on
    one (made now or earlier). :meth:`parts` then gives, for a group of pieces, the two
    numbers :func:`standalone_time` needs: the cost of every piece this call used (what a
    fresh reducer would pay for them) and of those it made itself (what it paid).
    Plain data; cost O(1) per record.
    """

    def __init__(self):
        self.cost: dict = {}
        self._used: set = set()
        self._made: set = set()

    def begin(self):
        """Start a call: forget which pieces the previous call used and made."""
        self._used, self._made = set(), set()

    def made(self, key, seconds: float):
        """Record that this call made piece ``key`` in ``seconds`` (and so uses it)."""
        self.cost[key] = float(seconds)
        self._made.add(key)
        self._used.add(key)

    def used(self, key):
        """Record that this call relies on piece ``key`` (made before or now)."""
        self._used.add(key)

    def parts(self, group) -> tuple[float, float]:
        """``(cost of the used pieces, cost of the pieces made by this call)`` over keys whose first
        element is ``group``."""
        used = [k for k in self._used if k[0] == group]
        return (float(sum(self.cost[k] for k in used)),
                float(sum(self.cost[k] for k in used if k in self._made)))
