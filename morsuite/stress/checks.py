r"""Invariant checks of one reducer run and of the full-order transfer function.

Each check returns an :class:`~morsuite.stress.outcomes.Outcome`; a violated
invariant is ``FAIL-silent``, never an exception.

* :func:`check_reduction` (family ``reduce``): a finite ROM and a finite error
  :math:`\max_\omega \sigma_{\max}(T - T_r) / \max_\omega \sigma_{\max}(T)` on
  :data:`N_GRID` log-spaced points of the model's band, or a documented error;
  ``info`` consistent with the warnings (:func:`check_info_consistency`). A
  converged IRKA of full order must meet the Hermite bitangential conditions
  :math:`T(\sigma_i) b_i = T_r(\sigma_i) b_i`, :math:`c_i^T T(\sigma_i) = c_i^T
  T_r(\sigma_i)`, :math:`c_i^T T'(\sigma_i) b_i = c_i^T T_r'(\sigma_i) b_i`
  (:func:`hermite_error`, tolerance :data:`HERMITE_TOL` scaled by
  :func:`~morsuite.stress.reference.product_tol`). Cost: the reduction, plus one
  sparse LU per grid point and per shift for the references.
* :func:`check_nullspace` (family ``nullspace``): ``fom.transfer(s)`` against the
  dense null-space formula, relative to :math:`\max(|T|, \mathrm{CANCEL}\,|L|\,|X|)`
  with tolerance :data:`NULLSPACE_TOL` scaled by the equilibrated condition;
  where they disagree, the equilibrated sparse reference decides which one is
  off. Dense :math:`O(n_1^3)` per point.
* :func:`check_bt_bound` (family ``bt-bound``): first-order BT satisfies
  :math:`\max_\omega \sigma_{\max}(T - T_r) \le 2 \sum_{k > r} \sigma_k
  (1 + \mathrm{BT\_BOUND\_RTOL}) + 10^{-10} \max_\omega \sigma_{\max}(T)` when
  both LR-ADI runs converged (the bound holds for exact Gramians); a stopped
  ADI gives ``not-converged``.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np

from .cases import BT_MAXITER
from .outcomes import CheckFailed, Outcome, _run_reducer, classify_exception
from .reference import (nullspace_transfer, product_tol, reference_response, reference_transfer, scaled_tol,
                        sigma)

__all__ = ["HERMITE_TOL", "NULLSPACE_TOL", "BT_BOUND_RTOL", "N_GRID", "CANCEL", "check_info_consistency",
           "hermite_error", "check_reduction", "check_nullspace", "bt_bound_of", "check_bt_bound"]

HERMITE_TOL = 1e-6
NULLSPACE_TOL = 1e-8
BT_BOUND_RTOL = 1e-3  # documented tolerance of the BT bound check (ADI Gramians are approximate)
N_GRID = 60
#: outputs below this fraction of ``|L| |X|`` are compared in absolute terms (see check_nullspace)
CANCEL = 1e-4


def _warn_cats(warns):
    return Counter(w.category.__name__ for w in warns)


def check_info_consistency(res, warns, r):
    """The info record agrees with the warnings issued and with the ROM; raises CheckFailed."""
    info, rom = res.info, res.rom
    cats = _warn_cats(warns)
    problems = []
    if info["r"] != rom.order:
        problems.append(f"info r = {info['r']} but rom.order = {rom.order}")
    if info["r_requested"] != r:
        problems.append(f"info r_requested = {info['r_requested']} != {r}")
    conv = info.get("converged", True)
    if not conv and not cats.get("ConvergenceWarning"):
        problems.append("converged=False without a ConvergenceWarning")
    if conv and cats.get("ConvergenceWarning"):
        problems.append("converged=True but a ConvergenceWarning was issued")
    if rom.order < r and not cats.get("RankWarning"):
        problems.append(f"order capped {r} -> {rom.order} without a RankWarning")
    if rom.order < r and not info.get("rank_capped", True):
        problems.append("order capped but info['rank_capped'] is False")
    stable = bool(rom.is_stable())
    if "stable" in info and bool(info["stable"]) != stable:
        problems.append(f"info stable = {info['stable']} but rom.is_stable() = {stable}")
    if not stable and not cats.get("StabilityWarning"):
        problems.append("unstable ROM without a StabilityWarning")
    recorded = Counter(w.split(":", 1)[0] for w in info.get("warnings", []))
    for cat in ("ConvergenceWarning", "RankWarning", "StabilityWarning"):
        if cats.get(cat, 0) and not recorded.get(cat, 0):
            problems.append(f"a {cat} was issued but not recorded in info['warnings']")
    if problems:
        raise CheckFailed("; ".join(problems))


def hermite_error(fom, rom, shifts, bdirs, cdirs):
    """Largest relative mismatch of T b, c^T T, c^T T' b at the shifts, and the tolerance it must meet.

    Returns ``(err, tol)`` with ``tol = HERMITE_TOL * max(1, kappa / KAPPA_REF)`` over the
    equilibrated condition of the full saddle matrix and of the reduced pencil at each shift.
    """
    worst, tol = 0.0, HERMITE_TOL
    for a, b, c in zip(shifts, bdirs, cdirs):
        T, dT, k = reference_transfer(fom, a, derivative=True)
        if T is None:
            return math.inf, math.inf
        P = a * a * rom.M + a * rom.D + rom.K
        kr = np.linalg.cond(P)
        Tr, dTr = rom.transfer(a), rom.transfer_derivative(a)
        tol = max(tol, product_tol(HERMITE_TOL, k, kr))
        for x, y, scale in ((T @ b, Tr @ b, np.linalg.norm(T) * np.linalg.norm(b)),
                            (c @ T, c @ Tr, np.linalg.norm(T) * np.linalg.norm(c)),
                            (c @ dT @ b, c @ dTr @ b, np.linalg.norm(dT) * np.linalg.norm(b) * np.linalg.norm(c))):
            num = np.linalg.norm(np.atleast_1d(x - y))
            den = max(np.linalg.norm(np.atleast_1d(x)), 1e-8 * scale, np.finfo(float).tiny)
            worst = max(worst, num / den)
    return float(worst), float(tol)


def check_reduction(fom, method, r, options=None, *, omega=None, H_ref=None, hermite=True) -> Outcome:
    """The ``reduce`` family: see the module docstring."""
    from ..reducers.base import as_complex

    options = dict(options or {})
    omega = np.logspace(np.log10(fom.band[0]), np.log10(fom.band[1]), N_GRID) if omega is None else omega
    res, exc, warns = _run_reducer(method, fom, r, options)
    if exc is not None:
        return classify_exception(fom, exc, warns)
    info = res.info
    metrics = {"r": info["r"], "converged": info.get("converged"), "iterations": info.get("iterations"),
               "stable": info.get("stable")}
    try:
        check_info_consistency(res, warns, r)
        Hr = res.rom.freqresp(omega)
        if not np.all(np.isfinite(Hr)):
            raise CheckFailed("the ROM's frequency response on the band has NaN/inf entries")
        if H_ref is None:
            H_ref, _ = reference_response(fom, omega)
        fin = np.all(np.isfinite(H_ref), axis=(1, 2))
        err = sigma(H_ref[fin] - Hr[fin])
        if not np.all(np.isfinite(err)):
            raise CheckFailed("the error on the band is not finite")
        top = float(np.max(sigma(H_ref[fin]))) if fin.any() else 0.0
        metrics["max_rel_error"] = float(np.max(err)) / top if top > 0 else float(np.max(err))
        if (hermite and method in ("irka", "irka-projected") and info.get("converged")
                and info["r"] == info["r_requested"]):
            e, tol = hermite_error(fom, res.rom, as_complex(info["shifts"]), as_complex(info["b"]),
                                   as_complex(info["c"]))
            metrics.update(hermite_error=e, hermite_tol=tol)
            if not e <= tol:
                raise CheckFailed(f"converged IRKA violates the Hermite conditions: relative error {e:.2e} > "
                                  f"tol {tol:.1e}")
    except CheckFailed as f:
        return Outcome("FAIL-silent", str(f), "", metrics)
    if not info.get("converged", True):
        return Outcome("not-converged", f"iterations {info.get('iterations')}", "", metrics)
    return Outcome("pass", "", "", metrics)


def check_nullspace(fom, points) -> Outcome:
    """``fom.transfer`` equals the dense null-space formula at every point.

    The difference is measured against ``max(|T|, CANCEL * |L| |X|)``: an output
    that is many orders below the state it reads (cancellation in L X) is only
    determined to within ``eps |L| |X|`` by any backward stable solver.
    """
    worst, metrics = 0.0, {}
    for s in points:
        try:
            T = fom.transfer(s)
        except Exception as exc:  # noqa: BLE001 - classified
            return classify_exception(fom, exc, [])
        if not np.all(np.isfinite(T)):
            return Outcome("FAIL-silent", f"transfer({s:.3g}) has NaN/inf entries")
        Tn, X, kn = nullspace_transfer(fom, s)
        Tr, _, k = reference_transfer(fom, s)
        tol = scaled_tol(NULLSPACE_TOL, k)
        den = max(np.linalg.norm(Tn), CANCEL * np.linalg.norm(fom.L, 2) * np.linalg.norm(X, 2), np.finfo(float).tiny)
        d = float(np.linalg.norm(T - Tn) / den)
        metrics = {"rel_diff": max(worst, d), "tol": tol, "kappa": k, "kappa_nullspace": kn}
        if not d <= tol:
            # the dense null-space formula is itself accurate only to eps * cond(N^T P N) (kn,
            # unequilibrated): when the equilibrated sparse reference sides with the suite, the
            # null-space value is the outlier
            d_sr = float(np.linalg.norm(T - Tr) / den) if Tr is not None else math.inf
            d_nr = float(np.linalg.norm(Tn - Tr) / den) if Tr is not None else 0.0
            if d_sr <= tol and d_nr > tol:
                metrics["nullspace_reference_inaccurate"] = True
                d = d_sr
            else:
                return Outcome("FAIL-silent", f"saddle-point T({s:.4g}) differs from the null-space T by {d:.2e} "
                               f"> {tol:.1e} (and from an equilibrated sparse solve by {d_sr:.1e})", "", metrics)
        worst = max(worst, d)
    return Outcome("pass", "", "", metrics)


def bt_bound_of(info, states):
    """The a-priori bound 2 * sum of the discarded HSVs from a BT info record (None if absent)."""
    for key in ("error_bound", "bound", "hinf_bound"):
        if info.get(key) is not None:
            return float(info[key])
    hsv = info.get("hsv")
    if hsv is None:
        return None
    return 2.0 * float(np.sum(np.asarray(hsv, dtype=float)[states:]))


def check_bt_bound(fom, r, options=None) -> Outcome:
    """First-order BT: max over the band of sigma(T - T_r) <= bound * (1 + BT_BOUND_RTOL) + tiny.

    Checked when both ADIs converged (the bound is a statement about exact
    Gramians); otherwise the case is ``not-converged`` (with its warning).
    """
    omega = np.logspace(np.log10(fom.band[0]), np.log10(fom.band[1]), N_GRID)
    options = {"maxiter": BT_MAXITER, **dict(options or {})}
    res, exc, warns = _run_reducer("bt", fom, r, options)
    if exc is not None:
        return classify_exception(fom, exc, warns)
    H_ref, _ = reference_response(fom, omega)
    Hr = res.rom.freqresp(omega)
    if not np.all(np.isfinite(Hr)):
        return Outcome("FAIL-silent", "BT ROM response has NaN/inf entries")
    try:
        check_info_consistency(res, warns, r)
    except CheckFailed as f:
        return Outcome("FAIL-silent", str(f))
    err = float(np.max(sigma(H_ref - Hr)))
    bound = bt_bound_of(res.info, res.rom.states)
    m = {"error": err, "bound": bound}
    if not res.info.get("converged", True):
        # the bound holds for exact Gramians only: with a stopped ADI it is not a claim
        return Outcome("not-converged", "", "", m)
    if bound is None:
        return Outcome("FAIL-silent", "first-order BT returned no error bound", "", m)
    top = float(np.max(sigma(H_ref)))
    tol = bound * (1 + BT_BOUND_RTOL) + 1e-10 * top
    if not err <= tol:
        return Outcome("FAIL-silent", f"BT error {err:.3e} exceeds its bound {bound:.3e}", "", m)
    return Outcome("pass", "", "", m)
