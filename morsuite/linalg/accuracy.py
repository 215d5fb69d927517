r"""The backward error that every checked saddle-point solve reaches, and the record of it per run.

**The quantity.** A solve of :math:`S x = b` (or :math:`S^T x = b`) with one LU of the
equilibrated matrix :math:`A = D_r S D_c` (:class:`~morsuite.linalg.saddle_lu.SaddleLU`; the
matrix as assembled in double and factored, renumbered or not) returns :math:`x`; with
:math:`x_e = D_c^{-1} x` and :math:`b_e = D_r b` its normwise backward error is

.. math::

    \eta(x) = \frac{\|b_e - A x_e\|_1}{\|A\|_1 \|x_e\|_1 + \|b_e\|_1}

(inf-norms for :math:`A^T`, whose inf-norm is :math:`\|A\|_1`), the worst over the
right-hand sides: the smallest :math:`\epsilon` for which :math:`x_e` solves a system
:math:`(A + \Delta A) x_e = b_e + \Delta b` with :math:`\|\Delta A\| \le \epsilon\|A\|` and
:math:`\|\Delta b\| \le \epsilon\|b_e\|`. Every checked solve reaches
:math:`\eta \le` ``backward_target`` (:data:`BACKWARD_TARGET` = 1e-15, about 9 units of
roundoff :math:`u = 2^{-53}`) or is flagged. "Reaches" is certified, not estimated:

- in double, when :math:`\hat\eta + \beta \le` target: :math:`\hat\eta` from the residual computed
  in double and :math:`\beta` the rigorous bound of that residual's rounding,
  :math:`\sum_i \gamma_{k_i+1}(|b_e| + |A||x_e|)_i` over the denominator (:math:`k_i` the entries of
  row i; :math:`\gamma_{k+3}` in complex arithmetic; :math:`\gamma_n = nu/(1-nu)`): the
  chains' few entries per row allow it;
- else with the residual formed in double-double (:mod:`morsuite.linalg.dd_kernels`; numpy's long
  double without numba), accurate far below the target (3D elements: 81 entries per row, where
  :math:`\beta` alone exceeds the target).

Above the target, iterative refinement with that extended residual and the same LU (at most
``refine_steps`` steps, stopped when a step does not halve :math:`\eta`); if it stagnates, one
fallback factorization (another LU of the same matrix: counted in ``stats.factorizations`` and
``stats.refactorizations``); if that does not reach it either, the solve is returned **flagged**:
counted in ``stats.above_target``, an :class:`~morsuite.errors.AccuracyWarning`, and recorded
where the run is recorded (below). Above ``backward_tol`` (1e-10) a solve is never returned:
:class:`~morsuite.errors.SingularShiftError`, as before.

The LU's matrix differs from the exact :math:`S(s)` by the rounding of its assembly (a few
units of roundoff of the terms :math:`|a||M| + |b||D| + |K|`); frequency responses refine
against the exact :math:`S(s)` in double-double beyond that
(:func:`morsuite.linalg.refine.refine_columns`).

**The record.** :func:`recording` opens a record; every checked solve made while it is open
(in this thread and in the threads of :func:`morsuite.utils.map_threads` it starts, and the
counters Dask workers send back) adds to it: the worst :math:`\eta`, how many solves (right-hand
sides) were checked and how many stayed above the target, refinement steps and fallback LUs.
:meth:`SolveAccuracy.as_info` is the plain data that reducers put into ``info["solve_accuracy"]``
(and the worst into ``info["solve_backward_error"]``), and the study tasks into their
manifest entries. Measurements: ``docs/design/backends.md`` (2026-11-29).
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import threading

import numpy as np

__all__ = ["BACKWARD_TARGET", "FORWARD_TOL", "FORWARD_MAX_STEPS", "SolveAccuracy", "recording", "note", "note_stats", "gamma",
           "target_off", "default_target", "forward_tol"]

#: default ``backward_target`` of :class:`~morsuite.linalg.saddle.SaddlePointSolver` (about 9 u)
BACKWARD_TARGET = 1e-15

#: frequency responses refine each solve against the exact S(s) until its estimated relative error is below this
FORWARD_TOL = 2.0 ** -52

#: most refinement steps of a frequency-response solve (one always, more while the estimate is above FORWARD_TOL)
FORWARD_MAX_STEPS = 6

#: unit roundoff of double precision
UNIT = 2.0 ** -53

_ACTIVE: contextvars.ContextVar = contextvars.ContextVar("morsuite_solve_accuracy", default=())
_LOCK = threading.Lock()


def target_off() -> bool:
    """True when the environment variable ``MORSUITE_SOLVE_TARGET`` is ``off``: solvers made then check
    ``backward_tol`` alone and frequency responses refine a fixed number of steps, as before 2026-11-29
    (for comparisons: ``morsuite bench solve-accuracy``)."""
    return os.environ.get("MORSUITE_SOLVE_TARGET", "").strip().lower() == "off"


def default_target() -> float:
    """The ``backward_target`` of a solver made now: :data:`BACKWARD_TARGET`, 0 when :func:`target_off`."""
    return 0.0 if target_off() else BACKWARD_TARGET


def forward_tol():
    """The ``tol`` of :func:`~morsuite.linalg.refine.refine_columns` for frequency responses:
    :data:`FORWARD_TOL`, None (fixed steps) when :func:`target_off`."""
    return None if target_off() else FORWARD_TOL


def gamma(n):
    r""":math:`\gamma_n = nu/(1 - nu)` (Higham's constant of n roundings), elementwise for an array ``n``."""
    nu = np.asarray(n, dtype=float) * UNIT
    return nu / (1.0 - nu)


class SolveAccuracy:
    """What the checked solves of one run reached (plain counters; thread-safe updates).

    Attributes
    ----------
    worst : float or None
        Largest certified backward error (:mod:`morsuite.linalg.accuracy`) of a checked solve; None
        when no solve was checked.
    target : float
        Largest ``backward_target`` of the solvers seen (0: no target was set).
    checked, above_target : int
        Right-hand sides checked; of them, those returned above their target (flagged).
    refinement_steps, fallback_lus : int
        Refinement steps (each one solve with the LU) and fallback LUs made on the way to the target.
    """

    def __init__(self):
        self.worst = None
        self.target = 0.0
        self.checked = 0
        self.above_target = 0
        self.refinement_steps = 0
        self.fallback_lus = 0

    def add(self, *, eta=None, target=0.0, checked=0, above_target=0, refinement_steps=0, fallback_lus=0):
        """Add one solve's (or a worker's) counters."""
        with _LOCK:
            if eta is not None and (self.worst is None or eta > self.worst):
                self.worst = float(eta)
            self.target = max(self.target, float(target))
            self.checked += int(checked)
            self.above_target += int(above_target)
            self.refinement_steps += int(refinement_steps)
            self.fallback_lus += int(fallback_lus)

    @property
    def met(self) -> bool:
        """True when every checked solve reached its target (also when none was checked)."""
        return self.above_target == 0

    def as_info(self) -> dict:
        """The record as plain data: ``backward_error`` (the worst, or None), ``target``, ``met``,
        ``checked``, ``above_target``, ``refinement_steps``, ``fallback_lus``."""
        return {"backward_error": self.worst, "target": self.target, "met": self.met, "checked": self.checked,
                "above_target": self.above_target, "refinement_steps": self.refinement_steps,
                "fallback_lus": self.fallback_lus}

    def message(self) -> str:
        """The warning text of a record that was not met."""
        return (f"{self.above_target} of {self.checked} saddle-point solves stayed above the backward-error target "
                f"{self.target:.0e} after refinement and a fallback LU (worst {self.worst:.1e}); their values may have "
                "lost digits (near a pole?)")


@contextlib.contextmanager
def recording():
    """Open a :class:`SolveAccuracy` record for the checked solves made inside the block (nested
    records all receive them). Yields the record."""
    rec = SolveAccuracy()
    token = _ACTIVE.set(_ACTIVE.get() + (rec,))
    try:
        yield rec
    finally:
        _ACTIVE.reset(token)


def note(**amounts) -> None:
    """Add one solve's counters (the keywords of :meth:`SolveAccuracy.add`) to every open record."""
    for rec in _ACTIVE.get():
        rec.add(**amounts)


def note_stats(counts: dict) -> None:
    """Add the accuracy counters of a :class:`~morsuite.linalg.saddle_lu.SolverStats` dict made elsewhere
    (a Dask worker's) to every open record."""
    if counts.get("checked_solves"):
        note(eta=counts.get("backward_error_max"), target=counts.get("backward_target", 0.0),
             checked=counts.get("checked_solves", 0), above_target=counts.get("above_target", 0),
             refinement_steps=counts.get("refinement_steps", 0), fallback_lus=counts.get("target_fallbacks", 0))
