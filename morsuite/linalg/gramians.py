r"""Low-rank Gramian factors of a model, computed once per model and ADI options.

Balanced truncation (:mod:`morsuite.reducers.bt.balanced`) and the exact H2 norm
(:func:`morsuite.analysis.h2_norm`) need the same pair of LR-ADI factors
:math:`P \approx ZZ^T`, :math:`Q \approx YY^T` of the projected Lyapunov
equations (:mod:`morsuite.linalg.lradi`). :func:`gramian_factors` is the one
place that computes them: one lock-step :func:`~morsuite.linalg.lradi.lradi_pair`
run (one sparse LU per shift for both equations), kept in the model's
``cache`` dict under the ADI options, so that BT followed by ``h2_norm`` (or
the reverse, or BT for several forms) in one process runs LR-ADI once.

Why the pair and not the controllability equation alone, when only
:math:`\|LZ_p\|_F` is asked for: the lock-step pair costs the LUs of the
longer of the two equations (measured at tol 1e-12: dsms(6000) 20 LUs for the
pair, 14 for the controllability equation alone; tcom(2000) 608 either way)
plus the transposed solves, a BT run afterwards then costs
nothing, and the observability factor corrects the ADI truncation of
:math:`\|T\|_{\mathcal H_2}^2` (:func:`h2_tail`), which is otherwise the
floor of every H2 error computed from it.

Accuracy: with ``refine=1`` (the default) each controllability solve is
refined once with an extended-precision residual (:mod:`morsuite.linalg.refine`), and the factor carries its
estimated forward error (``solve_error``), which :func:`morsuite.linalg.h2.norm_squared`
puts into the floor of :math:`\|T\|_{\mathcal H_2}^2` (``docs/design/norms.md``).

Memory: the factors stay with the model (``fom.cache.clear()`` drops them);
on tcom(2000) at tol 1e-12 they hold about 4 x 6001 x 1200 doubles (230 MB).

Across processes: :func:`use_store` gives this process a persistent store (the studies'
worker processes use :class:`morsuite.studies.gramian_store.GramianStore`, in the artifact
cache), which :func:`gramian_factors` reads after the model's cache and fills after an LR-ADI
run, so that a run's workers pay a model's factors once between them instead of once each.
:func:`factors_to_arrays` and :func:`factors_from_arrays` are the store's format: the factors'
arrays and their record as plain data, read back to the same bits.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, fields, replace

import numpy as np

from ..errors import ConvergenceWarning, InputError
from .adi_result import LRADIResult
from .lradi import COMPRESS_TOL, LU_POOL_MIB, POOL_FULL_REUSE, SHIFT_REUSE, lradi_pair
from .manifold import ManifoldProjector
from .system import new_solver

__all__ = ["ADI_DEFAULTS", "GramianFactors", "gramian_factors", "cached_gramian_factors", "residual_weights", "residual_selection",
           "residual_factor", "h2_tail", "use_store", "factors_to_arrays", "factors_from_arrays"]

#: LR-ADI options of the shared factors, with balanced truncation's defaults (``bt`` declares the same);
#: tol 1e-12 (not lradi's 1e-10): see morsuite.reducers.bt.balanced; refine 1 (not lradi's 0): one long-double
#: refinement step of every controllability solve, without which ||T||_H2^2 from the factor is off by the
#: solves' forward error (7.9e-12 relative on tcom(2000), docs/design/norms.md); it costs no LU, +25% (dsms(6000))
#: and +47% (tcom(2000)) of the LR-ADI time; shift_reuse, lu_pool_mib, pool_full_reuse and compress_tol as lradi's
#: (kept LUs serve nearby shifts, farther ones once the pool is full; no column compression, whose factors the exact
#: H2 error's error-Gramian route cannot replay)
ADI_DEFAULTS = {"tol": 1e-12, "maxiter": 3000, "shifts": "projection", "num_shifts": 16, "selection": "residual",
                "refine": 1, "shift_reuse": SHIFT_REUSE, "lu_pool_mib": LU_POOL_MIB, "compress_tol": COMPRESS_TOL,
                "pool_full_reuse": POOL_FULL_REUSE}


@dataclass
class GramianFactors:
    """Both LR-ADI factors of a model (plain data around two :class:`LRADIResult`).

    Attributes
    ----------
    controllability, observability : LRADIResult
    options : dict
        The ADI options they were computed with.
    time_s : float
        Seconds the lock-step run took when it was made.
    lu_count : int
        Sparse LUs of that run.
    computed : bool
        True if the call that returned this object ran LR-ADI; False if it
        came from the model's cache.
    """

    controllability: LRADIResult
    observability: LRADIResult
    options: dict
    time_s: float
    lu_count: int
    computed: bool = True

    @property
    def converged(self) -> bool:
        """True if both LR-ADI runs reached their tolerance (the Gramian factors are then trusted)."""
        return bool(self.controllability.converged and self.observability.converged)


def _key(options: dict):
    """A hashable cache key of the ADI options (explicit shift arrays as tuples)."""
    out = []
    for k in sorted(options):
        v = options[k]
        if not isinstance(v, (str, int, float)):
            v = tuple(complex(x) for x in np.asarray(v).ravel())
        out.append((k, v))
    return ("gramian_factors", tuple(out))


def _options(adi: dict) -> dict:
    unknown = sorted(set(adi) - set(ADI_DEFAULTS))
    if unknown:
        raise InputError(f"unknown LR-ADI option(s) {', '.join(map(repr, unknown))}; valid: "
                         f"{', '.join(sorted(ADI_DEFAULTS))}")
    return {**ADI_DEFAULTS, **adi}


#: the process's persistent store of factors (:func:`use_store`); None: the model's cache only
_STORE = None


def use_store(store):
    """Set this process's persistent store of Gramian factors; returns the one it replaces.

    Parameters
    ----------
    store : object or None
        With methods ``load(fom, options) -> GramianFactors | None`` and
        ``save(fom, options, factors)`` (e.g. :class:`morsuite.studies.gramian_store.GramianStore`);
        None (the default of a process) keeps the factors in the model's cache only.

    Returns
    -------
    object or None
        The store used before this call.
    """
    global _STORE
    previous, _STORE = _STORE, store
    return previous


#: the array fields of an LRADIResult in the store's format (the rest is plain data)
_ARRAY_FIELDS = ("position_unprojected", "velocity", "residuals", "shifts", "residual_w1", "residual_w2")
_SIDES = (("controllability", "c"), ("observability", "o"))


def factors_to_arrays(gf: GramianFactors):
    """``(arrays, meta)``: the factors' arrays (npz-ready) and everything else as plain data.

    The observability result's pending projector (an LU) is not stored; ``meta`` records that
    it was pending and :func:`factors_from_arrays` makes it again (one LU), so that the first
    read of ``position`` gives the same bits as in the process that ran LR-ADI.
    Cost: none (references to the arrays).
    """
    arrays, results = {}, {}
    for side, tag in _SIDES:
        res = getattr(gf, side)
        for name in _ARRAY_FIELDS:
            value = getattr(res, name)
            if value is not None:
                arrays[f"{tag}_{name}"] = value
        rec = {f.name: getattr(res, f.name) for f in fields(LRADIResult) if f.name not in _ARRAY_FIELDS + ("projector",)}
        rec["projector_pending"] = res.projector is not None
        results[side] = rec
    meta = {"options": dict(gf.options), "time_s": float(gf.time_s), "lu_count": int(gf.lu_count), "results": results}
    return arrays, meta


def factors_from_arrays(fom, arrays: dict, meta: dict) -> GramianFactors:
    """The :class:`GramianFactors` of :func:`factors_to_arrays`'s output, for model ``fom``
    (``computed=False``: read, not run). Cost: one sparse LU of the saddle matrix of M when the
    observability factor's projection was pending (none without constraints)."""
    out = {}
    for side, tag in _SIDES:
        rec = dict(meta["results"][side])
        pending = rec.pop("projector_pending")
        kw = {name: arrays.get(f"{tag}_{name}") for name in _ARRAY_FIELDS}
        projector = ManifoldProjector(fom, new_solver(fom, cache_size=0)) if pending else None
        out[side] = LRADIResult(**rec, **kw, projector=projector if projector is not None and projector.lu is not None
                                else None)
    return GramianFactors(out["controllability"], out["observability"], dict(meta["options"]), float(meta["time_s"]),
                          int(meta["lu_count"]), computed=False)


def cached_gramian_factors(fom, **adi) -> GramianFactors | None:
    """The factors for these ADI options if the model's cache or the process's store (:func:`use_store`)
    holds them, else None. No LR-ADI; a read from the store costs a file read and, for a constrained
    model, one LU (:func:`factors_from_arrays`), and puts them into the model's cache."""
    cache = getattr(fom, "cache", None)
    if cache is None:
        return None
    options = _options(adi)
    hit = cache.get(_key(options))
    if hit is None and _STORE is not None:
        hit = _STORE.load(fom, options)
        if hit is not None:
            cache[_key(options)] = hit
    return None if hit is None else replace(hit, computed=False)


def gramian_factors(fom, *, use_cache: bool = True, **adi) -> GramianFactors:
    """Both Gramian factors of ``fom``, from the model's cache or one :func:`lradi_pair` run.

    Parameters
    ----------
    fom : Index3Model
    use_cache : bool
        Read and fill ``fom.cache`` (default) and the process's store, if one is set
        (:func:`use_store`). False runs LR-ADI and keeps nothing (benchmarks that time whole runs).
    **adi
        LR-ADI options (``tol``, ``maxiter``, ``shifts``, ``num_shifts``,
        ``selection``, ``refine``); missing ones take :data:`ADI_DEFAULTS`, the
        defaults of ``bt``. Factors are shared only between calls with equal options.

    Returns
    -------
    GramianFactors
        ``computed`` says whether this call ran LR-ADI (cost: ``lu_count`` LUs).

    Notes
    -----
    LR-ADI's :class:`ConvergenceWarning` is not re-issued here: the results
    carry ``converged`` and their callers say what an unconverged factor
    means for them.
    """
    options = _options(adi)
    hit = cached_gramian_factors(fom, **options) if use_cache else None
    if hit is not None:
        return hit
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConvergenceWarning)
        c, o = lradi_pair(fom, **options)
    for w in caught:
        if not issubclass(w.category, ConvergenceWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    out = GramianFactors(c, o, dict(options), time.perf_counter() - t0, int(c.lu_count), True)
    cache = getattr(fom, "cache", None)
    if use_cache and cache is not None:
        cache[_key(options)] = replace(out, computed=False)
    if use_cache and _STORE is not None:
        _STORE.save(fom, options, out)
    return out


def residual_weights(result: LRADIResult, width: int) -> np.ndarray:
    r"""Weights :math:`\gamma` with :math:`W_k = W_0 + E Z_k S`, :math:`S_{j, j \bmod w} = \gamma_j`.

    The G-LR-ADI update (:mod:`morsuite.linalg.lradi`) appends, for a real
    shift :math:`p`, the block :math:`\sqrt{-2p}\,V` to the factor and adds
    :math:`-2p\,EV` to the residual factor; for a complex pair it appends
    :math:`gR` and :math:`c\,\mathrm{Im}\,V` (:math:`g = 2\sqrt{-\mathrm{Re}\,p}`)
    and adds :math:`g^2 ER`. So the residual factor after the run is
    :math:`W_0` plus :math:`E` times the factor's columns weighted by
    :math:`\sqrt{-2p}`, :math:`g` and 0. This reads the column layout of
    :func:`lradi_pair`'s factors (blocks of ``width`` columns, one per step or
    two per complex step), tested against the dense residual. A compressed factor
    (``compress_tol`` > 0) has no such layout: its residual factor is
    ``result.residual_w1, residual_w2`` (:func:`residual_factor`).
    """
    if result.rank != result.columns:
        raise InputError(f"the factor was compressed ({result.columns} columns to {result.rank}): its columns "
                         "carry no residual weights; use residual_factor")
    gam = []
    shifts = np.asarray(result.shifts, dtype=complex)
    i = 0
    while i < shifts.size:
        p = shifts[i]
        if p.imag != 0:
            gam += [2.0 * np.sqrt(-p.real)] * width + [0.0] * width
            i += 2
        else:
            gam += [np.sqrt(-2.0 * p.real)] * width
            i += 1
    gam = np.asarray(gam)
    if gam.size != result.rank:
        raise InputError(f"the factor has {result.rank} columns but its shifts account for {gam.size}: "
                         "not a factor of lradi_pair")
    return gam


def residual_selection(result: LRADIResult, width: int) -> np.ndarray:
    r""":math:`S` (k x ``width``) with :math:`W = W_0 + EZS`: the weights of :func:`residual_weights`
    placed so that column :math:`j` of the factor feeds column :math:`j \bmod` ``width`` of :math:`W`."""
    gam = residual_weights(result, width)
    k = result.rank
    S = np.zeros((k, width))
    S[np.arange(k), np.arange(k) % width] = gam
    return S


def residual_factor(result: LRADIResult, fom):
    r"""The final residual factor :math:`W = [W_1; W_2]` of a controllability run, as iterated.

    :math:`W_2` is :math:`\Pi F` plus E times factor columns; products with vectors of
    :math:`\ker G` see it as :math:`W_0 = [0; F]` plus those (``residual_selection``).
    Runs without the stored residual (older results) rebuild it from the column layout.
    """
    if result.residual_w1 is not None:
        return result.residual_w1, result.residual_w2
    S = residual_selection(result, fom.m)
    return result.position @ S, np.asarray(fom.F, dtype=float) + fom.M @ (result.velocity @ S)


def h2_tail(factors: GramianFactors, fom) -> float:
    r"""Estimate of :math:`\|T\|_{\mathcal H_2}^2 - \|LZ_p\|_F^2`, the part the ADI factor misses.

    With the residual factor :math:`W` of the controllability run,
    :math:`P - ZZ^T` solves the Lyapunov equation with right-hand side
    :math:`WW^T`, so the missing part is :math:`\mathrm{tr}(W^TQW)`
    (:math:`Q` the observability Gramian), estimated by
    :math:`\|Y^TW\|_F^2` with
    :math:`Y^TW = Y_p^TW_1 + Y_v^TW_2` (:func:`residual_factor`; :math:`W_1 \in \ker G`,
    so the unprojected :math:`Y_p` will do, and :math:`Y_v \in \ker G`). Its own error is of
    the order of the estimate times the observability residual. Cost: products
    of the factors with m columns, no solve.
    """
    c, o = factors.controllability, factors.observability
    W1, W2 = residual_factor(c, fom)
    YW = o.position_unprojected.T @ W1 + o.velocity.T @ W2
    return float(np.sum(YW * YW))
