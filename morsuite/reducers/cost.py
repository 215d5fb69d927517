"""The cost entries of a reduction's ``info``, written one way: :func:`cost_record`.

A reducer that does r-independent work once (Gramian factors, modes, samples, the LUs of its
expansion points) and reuses it across ``reduce`` calls reports, per call, what
:mod:`morsuite.reducers.outcome` defines: ``lu_count`` (the LUs this call paid), ``lu_count_shared``
(the shared work's LUs, whoever paid them), ``setup_reused`` (this call did not pay all of them),
``setup_cost`` (the shared work by parts, as a fresh reducer pays it), ``setup_paid`` (what this call
paid of each part) and ``time_breakdown``. :func:`cost_record` makes those entries from the counts
and times a reducer knows, so that the rule lives in one place; :class:`Stopwatch` times the parts of
a call. Cost: O(number of parts).
"""

from __future__ import annotations

import time
from contextlib import contextmanager

__all__ = ["cost_record", "Stopwatch"]


def cost_record(*, lus_shared: int, lus_paid: int, setup_cost: dict, paid: dict, breakdown: dict | None = None,
                own_lus: int = 0) -> dict:
    """The cost entries of one call's ``info``.

    Parameters
    ----------
    lus_shared : int
        Sparse LUs of the r-independent work the result relies on, whoever paid them.
    lus_paid : int
        Of those, the LUs this call paid (all of them on a fresh reducer and model, none when reused).
    setup_cost : dict
        Part -> seconds of the shared work as a fresh reducer pays it.
    paid : dict
        Part -> seconds this call paid of it (0 for a part reused).
    breakdown : dict, optional
        Further parts of this call's time (the projection, ...), added to ``time_breakdown``.
    own_lus : int
        LUs this call paid beyond the shared work.

    Returns
    -------
    dict
        ``lu_count`` (``own_lus + lus_paid``), ``lu_count_shared``, ``setup_reused``
        (``lus_paid < lus_shared``: this call did not pay all of the shared work's LUs), ``setup_cost``,
        ``setup_paid`` and ``time_breakdown`` (``paid`` and ``breakdown``), as
        :func:`~morsuite.reducers.outcome.standalone_time` and
        :func:`~morsuite.reducers.outcome.standalone_lu_count` read them.
    """
    return {"lu_count": int(own_lus + lus_paid), "lu_count_shared": int(lus_shared),
            "setup_reused": bool(lus_paid < lus_shared), "setup_cost": dict(setup_cost), "setup_paid": dict(paid),
            "time_breakdown": {**paid, **(breakdown or {})}}


class Stopwatch:
    """Seconds of named parts of a call: ``with clock("svd"): ...``; ``clock.times`` (part -> seconds, summed
    over repeats, in first-use order)."""

    def __init__(self):
        self.times: dict = {}

    @contextmanager
    def __call__(self, part: str):
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.times[part] = self.times.get(part, 0.0) + time.perf_counter() - t0
