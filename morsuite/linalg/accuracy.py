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
  row i; :math:`\gamma_{k_i+4}` in complex arithmetic, whose products round by at most
  :math:`\sqrt 2\gamma_2`; :math:`\gamma_n = nu/(1-nu)`): the chains' few entries per row allow it;
- else with the residual formed by Dot2 (:func:`morsuite.linalg.dd_kernels.residual`: as if in twice
  the working precision; numpy's long double without numba), accurate far below the target (3D
  elements: 81 entries per row, where :math:`\beta` alone exceeds the target).

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

:class:`TargetRefinement` is that code (a base of :class:`~morsuite.linalg.saddle_lu.SaddleLU`).
Cost per checked solve: one product with :math:`|A|` beside the residual's (certificate in double), or one
Dot2 residual (about three double products' work); a refinement step one solve and one Dot2 residual;
a fallback one LU.

**The record.** :func:`recording` opens a record; every checked solve made while it is open
(in this thread and in the threads of :func:`morsuite.utils.map_threads` it starts, and the
counters Dask workers send back) adds to it: the worst :math:`\eta`, how many solves (right-hand
sides) were checked and how many stayed above the target, refinement steps and fallback LUs.
:meth:`SolveAccuracy.as_info` is the plain data that reducers put into ``info["solve_accuracy"]``
(and the worst into ``info["solve_backward_error"]``), and the study tasks into their
manifest entries. Measurements: ``docs/design/backends.md`` (2026-12-02).
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import threading
import time

import numpy as np
import scipy.sparse as sp

from ..errors import InputError, SingularShiftError
from . import dd_kernels, kernels

__all__ = ["BACKWARD_TARGET", "FORWARD_TOL", "FORWARD_MAX_STEPS", "SolveAccuracy", "TargetRefinement", "recording",
           "note", "note_stats", "gamma", "target_off", "default_target", "forward_tol", "check_options",
           "without_check_caches"]

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
    ``backward_tol`` alone and frequency responses refine a fixed number of steps, as before 2026-12-02
    (for comparisons: ``morsuite bench solve-accuracy``)."""
    return os.environ.get("MORSUITE_SOLVE_TARGET", "").strip().lower() == "off"


def default_target() -> float:
    """The ``backward_target`` of a solver made now: :data:`BACKWARD_TARGET`, 0 when :func:`target_off`."""
    return 0.0 if target_off() else BACKWARD_TARGET


def forward_tol():
    """The ``tol`` of :func:`~morsuite.linalg.refine.refine_columns` for frequency responses:
    :data:`FORWARD_TOL`, None (fixed steps) when :func:`target_off`."""
    return None if target_off() else FORWARD_TOL


def check_options(backward_target, refine_steps) -> tuple:
    """``(backward_target, refine_steps)`` of a solver validated: a number >= 0 (None: :func:`default_target`)
    and an int >= 0; :class:`~morsuite.errors.InputError` naming the argument otherwise."""
    try:
        target = default_target() if backward_target is None else float(backward_target)
    except (TypeError, ValueError):
        target = float("nan")
    if isinstance(backward_target, bool) or not target >= 0:
        raise InputError(f"backward_target must be a number >= 0 or None; got {backward_target!r}")
    if isinstance(refine_steps, bool) or not isinstance(refine_steps, (int, np.integer)) or refine_steps < 0:
        raise InputError(f"refine_steps must be an integer >= 0; got {refine_steps!r}")
    return target, int(refine_steps)


def without_check_caches(pattern: dict) -> dict:
    """A solver's ``pattern`` (and the renumbered patterns it holds) without the structures
    :class:`TargetRefinement` keeps there (made again where needed: a pickled solver leaves them behind)."""
    def keep(key):
        return not (isinstance(key, tuple) and key and key[0] in ("_segments", "_gammas"))
    return {k: (without_check_caches(v) if isinstance(v, dict) else v) for k, v in pattern.items() if keep(k)}


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


class TargetRefinement:
    """The backward-error certificate and the refinement to ``target`` of
    :class:`~morsuite.linalg.saddle_lu.SaddleLU` (its fields: ``matrix``, ``target``, ``refine_steps``,
    ``structure``, ``norms``, ``fallback``, ``stats``, ...; its ``_etas``, ``_lu_solve``): the module's
    definitions made code. Cost: see the module docstring."""

    def _measure(self, b, x, trans):
        """``(eta, r, ext)`` of each column: with a target, its backward error certified (this module),
        from the extended residual (``ext`` True) where the rounding bound of a double residual is above the target
        on most rows (3D elements), else the one computed in double plus that bound; without, the one computed in
        double. ``r`` the residual it was computed from."""
        cplx = np.iscomplexobj(x) or np.iscomplexobj(b) or np.iscomplexobj(self.matrix.data)
        gam = self._gammas(trans, cplx) if self.target > 0 else None
        if self.target > 0 and gam is None:
            eta, r, _ = self._etas(b, x, trans, self._ext_residual(b, x, trans))
            return eta, r, True
        eta, r, den = self._etas(b, x, trans)
        if gam is not None:  # the rigorous bound of the double residual's rounding
            ax = (self._abs_matrix().T if trans else self._abs_matrix()) @ np.abs(x)
            red = np.max if trans else np.sum
            with np.errstate(invalid="ignore", divide="ignore"):
                eta = eta + np.where(den > 0, red(gam[:, None] * (np.abs(b) + ax), axis=0)
                                     / np.where(den > 0, den, 1.0), 0.0)
        return eta, r, False

    def _to_target(self, b, x, trans, eta, r, ext):
        """``(x, eta, steps, fallback_lus)``: each column at or below ``target`` (``eta``, ``r``, ``ext`` as
        :meth:`_measure` gave them for ``x``) or refined towards it (:meth:`_refine`), one fallback LU where
        refinement stagnates above it; ``eta`` the certified backward error of each column."""
        todo = eta > self.target
        if not todo.any():
            return x, eta, 0, 0
        x = np.array(x, dtype=np.result_type(x, b))
        x[:, todo], eta[todo], steps = self._refine(b[:, todo], x[:, todo], trans, r[:, todo] if ext else None)
        fell = 0
        if (eta > self.target).any() and self.fallback and not self.target_fallback:
            # refinement stagnated above the target: the next LU of the fallback list, once per factorization,
            # kept only where it does better (it costs an LU: counted)
            self.target_fallback, fell = True, 1
            t0 = time.perf_counter()
            old = self.lu
            try:
                self.lu = self.fallback[0]()
            except (RuntimeError, SingularShiftError):
                self.lu = None
            self.stats.add(factorizations=1, refactorizations=1, factor_time_s=time.perf_counter() - t0)
            if self.lu is not None:
                x2 = self._lu_solve(b, trans)
                e2, r2, ext2 = self._measure(b, x2, trans)
                if np.max(e2) <= self.backward_tol:
                    x2 = np.array(x2, dtype=np.result_type(x2, b))
                    sel = e2 > self.target
                    if sel.any():
                        x2[:, sel], e2[sel], s2 = self._refine(b[:, sel], x2[:, sel], trans, r2[:, sel] if ext2 else None)
                        steps += s2
                    if np.max(e2) < np.max(eta):
                        self.fallback, self.refactored = self.fallback[1:], True
                        return x2, e2, steps, fell
            self.lu = old
        return x, eta, steps, fell

    def _gammas(self, trans, cplx):
        r""":math:`\gamma_{k_i+1}` (:math:`\gamma_{k_i+4}` complex: a complex product rounds by at most
        :math:`\sqrt 2\gamma_2`) per row of the product (rows of A, or of :math:`A^T`), the bound of a
        residual's rounding; None where its median is above the target (then no certificate in double).
        Kept with the pattern (``structure``)."""
        key = ("_gammas", bool(trans), bool(cplx))
        cache = self.structure if self.structure is not None else self.norms
        if key not in cache:
            A = self.matrix
            k = np.diff(A.indptr) if trans else np.bincount(A.indices, minlength=A.shape[0])
            g = gamma(k + (4 if cplx else 1))
            cache[key] = (g, float(np.median(g)) if g.size else np.inf)
        g, median = cache[key]
        return g if median <= self.target else None

    def _abs_matrix(self):
        """|A| of the factorized matrix (real, the same structure), made once."""
        if "abs" not in self.norms:
            A = self.matrix
            self.norms["abs"] = sp.csc_matrix((np.abs(A.data), A.indices, A.indptr), shape=A.shape)
        return self.norms["abs"]

    def _refine(self, b, x, trans, r=None):
        """Refine the columns of x towards ``target`` with the same LU and an extended-precision residual
        (``r``: x's, if known): ``(x, eta, steps)``, ``eta`` measured from that residual (accurate far below
        the target); a column stops when a step does not halve its backward error (the better iterate is
        kept), after ``refine_steps`` steps at most."""
        eta, r, _ = self._etas(b, x, trans, self._ext_residual(b, x, trans) if r is None else r)
        active = eta > self.target
        steps = 0
        while active.any() and steps < self.refine_steps:
            cols = np.flatnonzero(active)
            xn = x[:, cols] + self._lu_solve(r[:, cols], trans)
            en, rn, _ = self._etas(b[:, cols], xn, trans, self._ext_residual(b[:, cols], xn, trans))
            steps += 1
            with np.errstate(invalid="ignore", divide="ignore"):
                ratio = np.where(eta[cols] > 0, en / np.where(eta[cols] > 0, eta[cols], 1.0), 0.0)
            self.contraction = max(self.contraction, float(np.max(ratio)))
            better = en < eta[cols]
            keep = cols[better]
            x[:, keep], eta[keep], r[:, keep] = xn[:, better], en[better], rn[:, better]
            active[cols] = (en > self.target) & (ratio <= 0.5)
        return x, eta, steps

    def _ext_residual(self, b, x, trans):
        """``b - A x`` (``A^T x``) of the factorized matrix, formed by Dot2 (:func:`~morsuite.linalg.dd_kernels.residual`:
        as in twice the working precision; without numba in numpy's long double) and rounded to double once;
        2-D ``b``, ``x`` in the LU's space."""
        if self.conjugate:  # b - conj(A) x = conj(conj(b) - A conj(x))
            return np.conj(self._ext_residual_plain(np.conj(b), np.conj(x), trans))
        return self._ext_residual_plain(b, x, trans)

    def _ext_residual_plain(self, b, x, trans):
        structure = _segments(self.matrix, self.structure, trans)
        A = self.matrix
        cplx = np.iscomplexobj(b) or np.iscomplexobj(x) or np.iscomplexobj(A.data)
        out = np.empty(b.shape, dtype=complex if cplx else float)
        if kernels.available():  # Dot2: twice the working precision, rounded once
            if "parts" not in self.norms:  # the entries' real and imaginary parts, contiguous: once per LU
                d = A.data
                self.norms["parts"] = (np.ascontiguousarray(d.real, dtype=float),
                                       np.ascontiguousarray(d.imag, dtype=float) if np.iscomplexobj(d) else None)
            for j in range(b.shape[1]):
                out[:, j] = dd_kernels.residual(structure, self.norms["parts"], x[:, j], b[:, j])
            return out
        ptr, idx, order = structure  # numpy's long double: a gather, a product and a segmented sum
        vals = A.data[order]
        nonempty = np.flatnonzero(np.diff(ptr) > 0)
        for j in range(b.shape[1]):
            parts = []
            for part in ((vals.real, x[:, j].real), (vals.imag, x[:, j].imag), (vals.real, x[:, j].imag),
                         (vals.imag, x[:, j].real)):
                y = np.zeros(b.shape[0], dtype=np.longdouble)
                y[nonempty] = np.add.reduceat(part[0].astype(np.longdouble) * part[1].astype(np.longdouble)[idx],
                                              ptr[nonempty])
                parts.append(y)
            re = b[:, j].real.astype(np.longdouble) - (parts[0] - parts[1])
            out[:, j] = re.astype(float)
            if cplx:
                out[:, j] += 1j * (np.imag(b[:, j]).astype(np.longdouble) - (parts[2] + parts[3])).astype(float)
        return out


def _segments(A, structure, trans):
    """``(ptr, idx, order)`` (int64) of the rows of ``A`` (``trans``: of its columns) for
    :func:`~morsuite.linalg.dd_kernels.residual`: row i's terms are ``u`` in ``ptr[i]:ptr[i+1]``, entry
    ``order[u]`` of ``A.data``, column ``idx[u]``. Kept in ``structure`` (the pattern dict of A: shared by
    every LU of the pattern) when given."""
    key = ("_segments", bool(trans))
    if structure is not None and key in structure:
        return structure[key]
    indptr, indices = np.asarray(A.indptr, dtype=np.int64), np.asarray(A.indices, dtype=np.int64)
    if trans:
        seg = (indptr, indices, np.arange(indices.size, dtype=np.int64))
    else:  # the CSR order of the CSC entries: by row, columns ascending within a row (a stable sort)
        order = np.argsort(indices, kind="stable").astype(np.int64)
        cols = np.repeat(np.arange(A.shape[1], dtype=np.int64), np.diff(indptr))
        ptr = np.concatenate([[0], np.cumsum(np.bincount(indices, minlength=A.shape[0]))]).astype(np.int64)
        seg = (ptr, cols[order], order)
    if structure is not None:
        structure[key] = seg
    return seg
