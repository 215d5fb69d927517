r"""Invariants that compare two IRKA runs built from the same shifts.

IRKA's ROM is a function of the shifts :math:`\sigma_i` and tangential
directions :math:`b_i, c_i` it was built from. Replaying the shifts and
directions one run returned, for one iteration, through another
implementation or an equivalent model must give the same reduced order and
the same reduced transfer function: :math:`\max_\omega \sigma_{\max}(T_a - T_b)
/ \max_\omega \sigma_{\max}(T_a) \le` ``AGREE_TOL`` scaled by
:func:`~morsuite.stress.reference.product_tol` of the equilibrated saddle-point
condition at the shifts times the condition of the projection, and the
condition of the reduced pencils. Different orders are accepted only when a
deciding singular value lies within a factor 1e3 of ``rank_tol`` or
``oblique_tol``. Whether the whole trajectories stay together is recorded
(``metrics["trajectory_diff"]``), not asserted: the shift update selects among
near-ties, a discontinuous step that amplifies roundoff.

* :func:`check_agreement` (family ``agreement``): ``irka`` against
  ``irka-projected`` from the same given shifts, ``maxit`` iterations.
* :func:`check_g_invariance` (family ``g-invariance``): permuting G's rows and
  scaling them by :math:`10^{U(-3, 3)}` changes neither T(s) at three points of
  the band nor IRKA's ROM.

Cost: the two reductions, two one-iteration replays, and one sparse LU per
shift (at most six) for the condition estimates.
"""

from __future__ import annotations

import math

import numpy as np

from .cases import given_shifts, transformed_g
from .checks import CANCEL, N_GRID, NULLSPACE_TOL, check_info_consistency
from .outcomes import CheckFailed, Outcome, _run_reducer, classify_exception
from .reference import _EqLU, equilibrated_condition, product_tol, scaled_tol, sigma

__all__ = ["AGREE_TOL", "check_agreement", "check_g_invariance"]

AGREE_TOL = 1e-6


def _rom_diff(rom_a, rom_b, omega):
    """max_w sigma(H_a - H_b) / max_w sigma(H_a) on the grid (inf if a response is not finite)."""
    Ha, Hb = rom_a.freqresp(omega), rom_b.freqresp(omega)
    if not (np.all(np.isfinite(Ha)) and np.all(np.isfinite(Hb))):
        return math.inf
    top = float(np.max(sigma(Ha)))
    diff = float(np.max(sigma(Ha - Hb)))
    return diff / top if top > 0 else diff


def _replay(method, fom, res, r):
    """Run ``method`` on ``fom`` for one iteration from the shifts and directions ``res`` returned.

    IRKA's ROM is a function of the shifts and tangential directions it was
    built from; replaying them through another implementation (or another
    but equivalent model) must give the same ROM. This separates that
    invariant from the shift update, whose selection steps (which r of 2r
    poles, which iterate is "best") are discontinuous in the data.
    """
    from ..reducers.base import as_complex

    info = res.info
    opts = dict(init="given", init_shifts=as_complex(info["shifts"]), init_b=as_complex(info["b"]),
                init_c=as_complex(info["c"]), maxit=1)
    return _run_reducer(method, fom, r, opts)


def _projection_diagnostics(method, fom, info):
    """Conditioning of IRKA's projection step for the shifts/directions in ``info`` (None if unavailable).

    Rebuilds the raw bases with the reducer's own ``_bases`` hook and returns
    ``kappa``, the product of the condition numbers of the kept parts of the
    normalised V and W and of W^T V, and ``near_threshold``: whether a singular
    value that decides the reduced order lies within a factor 1e3 of
    ``rank_tol`` or ``oblique_tol`` (then two correct computations may keep
    different orders).
    """
    from ..linalg.dense import orth
    from ..reducers.base import as_complex

    try:
        red = _make_given(method, fom, info)
        red._setup()
        o = red.options
        V, W = red._bases(as_complex(info["shifts"]), as_complex(info["b"]), as_complex(info["c"]), True)
        Vo, sv = orth(V, o["rank_tol"], method="householder")
        Wo, sw = orth(W, o["rank_tol"], method="householder")
        k = min(Vo.shape[1], Wo.shape[1])
        if k == 0:
            return None
        s_ = np.linalg.svd(Wo[:, :k].T @ Vo[:, :k], compute_uv=False)
        kk = max(1, int(np.sum(s_ > o["oblique_tol"] * s_[0])))
        rel = [sv / sv[0], sw / sw[0]]
        near = any(np.any((x > o["rank_tol"] / 1e3) & (x < o["rank_tol"] * 1e3)) for x in rel) or bool(
            np.any((s_ / s_[0] > o["oblique_tol"] / 1e3) & (s_ / s_[0] < o["oblique_tol"] * 1e3)))
        kappa = float(sv[0] / sv[kk - 1] * sw[0] / sw[kk - 1] * s_[0] / s_[kk - 1])
        return {"kappa": kappa, "near_threshold": near}
    except Exception:  # noqa: BLE001 - a diagnostic only; internal hooks may change
        return None


def _make_given(method, fom, info):
    from .. import reducers
    from ..reducers.base import as_complex

    return reducers.make(method, fom, init="given", init_shifts=as_complex(info["shifts"]),
                         init_b=as_complex(info["b"]), init_c=as_complex(info["c"]), maxit=1)


def _compare_replay(fom_ref, res_ref, fom_new, method_new, r, omega, what):
    """Outcome of replaying res_ref's shifts through (fom_new, method_new); None if they agree.

    Tolerance: ``AGREE_TOL`` scaled by the product of the condition of the full
    saddle matrix at the shifts, of the reduced pencil, and of the projection
    (kept parts of V, W and W^T V). Different reduced orders are accepted only
    when a deciding singular value sits within a factor 1e3 of its threshold.
    """
    from ..reducers.base import as_complex

    rep, exc, W = _replay(method_new, fom_new, res_ref, r)
    if exc is not None:
        o = classify_exception(fom_new, exc, W)
        if o.outcome == "refused":
            o = Outcome("refused-spurious", f"{what}: the replay refused shifts the other run used: {o.detail}",
                        o.error_class)
        return o, {}
    diag = _projection_diagnostics(method_new, fom_new, res_ref.info) or {"kappa": 1.0, "near_threshold": False}
    if rep.info["r"] != res_ref.info["r"]:
        if diag["near_threshold"]:
            return None, {"order_differs_near_threshold": True}
        return Outcome("FAIL-silent", f"{what}: the same shifts give order {rep.info['r']} vs {res_ref.info['r']}"), {}
    used = as_complex(res_ref.info["shifts"])
    kap = max(equilibrated_condition(fom_new, a) for a in used[:6])
    kr = max(_rom_cond(res_ref.rom, used, omega), _rom_cond(rep.rom, used, omega))
    tol = product_tol(AGREE_TOL, kap * diag["kappa"], kr)
    d = _rom_diff(res_ref.rom, rep.rom, omega)
    m = {"rel_diff": d, "tol": tol, "kappa": kap, "kappa_rom": kr, "kappa_projection": diag["kappa"]}
    if not d <= tol:
        return Outcome("FAIL-silent", f"{what}: the same shifts give ROMs that differ by {d:.2e} > {tol:.1e}",
                       "", m), m
    return None, m


def check_agreement(fom, r, maxit, shifts=None) -> Outcome:
    """``irka`` and ``irka-projected`` from the same given shifts, ``maxit`` iterations.

    Invariants: both run or both refuse with documented errors; info records
    are consistent; the shifts and directions each run returned, replayed for
    one iteration through the other implementation, give the same ROM
    (condition-scaled tolerance). Whether the two whole trajectories stay
    together is recorded (``metrics["trajectory_diff"]``), not asserted: the
    shift update selects among near-ties (see :func:`_replay`).
    """
    shifts = given_shifts(fom, r) if shifts is None else shifts
    opts = dict(init="given", init_shifts=shifts, maxit=maxit)
    (ra, ea, wa), (rb, eb, wb) = (_run_reducer(m, fom, r, opts) for m in ("irka", "irka-projected"))
    if ea is not None or eb is not None:
        oa = classify_exception(fom, ea, wa) if ea is not None else None
        ob = classify_exception(fom, eb, wb) if eb is not None else None
        for o in (oa, ob):
            if o is not None and o.outcome.startswith("FAIL"):
                return o
        worst = oa or ob
        if (ea is None) != (eb is None) and worst.outcome == "refused":
            worst = Outcome("refused", f"only one of the two refused: {worst.detail}", worst.error_class)
        return worst
    for res, W in ((ra, wa), (rb, wb)):
        try:
            check_info_consistency(res, W, r)
        except CheckFailed as f:
            return Outcome("FAIL-silent", f"{res.info['method']}: {f}")
    omega = np.logspace(np.log10(fom.band[0]), np.log10(fom.band[1]), N_GRID)
    metrics = {"r_irka": ra.info["r"], "r_projected": rb.info["r"], "trajectory_diff": _rom_diff(ra.rom, rb.rom, omega)}
    worst = {}
    for ref, new, what in ((rb, "irka", "irka replaying irka-projected"),
                           (ra, "irka-projected", "irka-projected replaying irka")):
        o, m = _compare_replay(fom, ref, fom, new, r, omega, what)
        if o is not None:
            o.metrics.update(metrics)
            return o
        if m.get("rel_diff", 0) >= worst.get("rel_diff", -1):
            worst = m
    metrics.update(worst)
    return Outcome("pass", "", "", metrics)


def _rom_cond(rom, shifts, omega=None):
    """Largest condition number of the reduced pencil at the shifts and on the grid."""
    pts = list(shifts[:6]) + ([] if omega is None else list(1j * np.asarray(omega)))
    P = np.array([a * a * rom.M + a * rom.D + rom.K for a in pts])
    with np.errstate(all="ignore"):
        c = np.linalg.cond(P)
    c = np.where(np.isfinite(c), c, 1e300)
    return float(max(1.0, np.max(c)))


def check_g_invariance(fom, r, rng, *, maxit=2, max_decades=3.0) -> Outcome:
    """Transfer values and IRKA's ROMs do not depend on the row order and scaling of G.

    T(s) at three points of the band, and the ROM IRKA returns on the
    transformed model replayed (one iteration, same shifts and directions) on
    the original one. As in :func:`check_agreement`, the whole trajectories
    are compared but not asserted (``metrics["trajectory_diff"]``).
    """
    if fom.n2 == 0:
        return Outcome("pass", "no constraints")
    fom2 = transformed_g(fom, rng, max_decades=max_decades)
    lo, hi = fom.band
    pts = [1j * np.sqrt(lo * hi), 1j * hi / 3, complex(np.sqrt(lo * hi), 0.0)]
    worst = 0.0
    for s in pts:
        outs = []
        for f in (fom, fom2):
            try:
                outs.append(f.transfer(s))
            except Exception as exc:  # noqa: BLE001
                outs.append(exc)
        errs = [o for o in outs if isinstance(o, Exception)]
        if errs:
            o = classify_exception(fom, errs[0], [])
            if o.outcome == "refused" and len(errs) == 1:
                o = Outcome("refused-spurious", f"only one G scaling refused s = {s:.3g}: {o.detail}", o.error_class)
            return o
        e = _EqLU(fom, s)
        X = e.solve(fom.F)
        k = max(e.cond(), equilibrated_condition(fom2, s))
        tol = scaled_tol(NULLSPACE_TOL, k)
        den = max(np.linalg.norm(fom.L @ X), CANCEL * np.linalg.norm(fom.L, 2) * np.linalg.norm(X, 2),
                  np.finfo(float).tiny)
        d = float(np.linalg.norm(outs[0] - outs[1]) / den)
        worst = max(worst, d)
        if not d <= tol:
            return Outcome("FAIL-silent", f"T({s:.3g}) changes by {d:.2e} > {tol:.1e} when G's rows are permuted "
                           "and scaled", "", {"rel_diff": d, "tol": tol})
    opts = dict(init="given", init_shifts=given_shifts(fom, r), maxit=maxit)
    (ra, ea, wa), (rb, eb, wb) = (_run_reducer("irka", f, r, opts) for f in (fom, fom2))
    if ea is not None or eb is not None:
        if (ea is None) != (eb is None):
            o = classify_exception(fom, ea or eb, wa if ea is not None else wb)
            if o.outcome == "refused":
                o = Outcome("refused-spurious", f"only one G scaling refused: {o.detail}", o.error_class)
            return o
        return classify_exception(fom, ea, wa)
    omega = np.logspace(np.log10(lo), np.log10(hi), N_GRID)
    metrics = {"transfer_rel_diff": worst, "trajectory_diff": _rom_diff(ra.rom, rb.rom, omega)}
    o, m = _compare_replay(fom2, rb, fom, "irka", r, omega, "IRKA on the original G replaying the transformed G")
    metrics.update(m)
    if o is not None:
        o.metrics.update(metrics)
        return o
    return Outcome("pass", "", "", metrics)
