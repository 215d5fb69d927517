r"""The trust-region descent of the H2 error in pole-residue coordinates (:mod:`~morsuite.reducers.h2.poles`), with the
residues eliminated (variable projection), and its restarts across changes of the pole split.

For fixed poles J is quadratic in the residues, with the Gauss-Newton block as Hessian
(:func:`~morsuite.reducers.h2.poles.optimal_residues`): the descent runs over the poles alone, with the Schur
complement of the exact Hessian. Where a conjugate pair meets the real axis or two real poles meet,
the coordinates break down (the residues grow without bound); :func:`pole_descent` then changes the
split (:func:`restructure`) and restarts. Cost per iteration: one evaluation of the target's values
at the 2r mirrored poles and :math:`O(r^3)` dense work per trial step. Measurements:
``docs/design/so_h2.md``.
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from .poles import Coordinates, _scaling, optimal_residues

__all__ = ["varpro_descent", "pole_descent", "restructure", "SPLIT_TOL"]


def _schur(M, mask):
    """The Schur complement of M on ``mask`` (the other block eliminated)."""
    a, b = mask, ~mask
    return M[np.ix_(a, a)] - M[np.ix_(a, b)] @ np.linalg.solve(M[np.ix_(b, b)], M[np.ix_(b, a)])


def _next_radius(radius, ratio, step):
    """The trust radius after an accepted step of scaled length ``step`` whose actual over predicted
    decrease is ``ratio``: doubled after a good step to the boundary, a quarter of the step after a poor one."""
    if ratio > 0.75 and step > 0.9 * radius:
        return 2.0 * radius
    return 0.25 * step if ratio < 0.25 else radius


def _tr_step(S, D, g, radius):
    r"""The trust-region step: :math:`\min g^Tp + \frac12p^TSp` subject to :math:`\|D^{1/2}p\| \le` radius,
    by the eigen-decomposition of the scaled :math:`S` (indefinite allowed; the hard case takes the
    lowest eigenvector). Returns (p, predicted decrease)."""
    ds = np.sqrt(D)
    w, Q = np.linalg.eigh(S / ds[:, None] / ds[None, :])
    a = Q.T @ (g / ds)

    def p_of(mu):
        return -(Q @ (a / (w + mu)))

    lo = max(0.0, -w[0])
    if w[0] > 0 and np.linalg.norm(p_of(0.0)) <= radius:
        pt = p_of(0.0)
    else:
        base = lo * (1 + 1e-12) + 1e-300
        if np.linalg.norm(p_of(base)) <= radius:   # the hard case: add the lowest eigenvector
            pt = p_of(base)
            pt = pt + Q[:, 0] * np.sqrt(max(radius ** 2 - pt @ pt, 0.0))
        else:
            hi = max(lo, 1e-300) * 2 + np.linalg.norm(a) / radius
            while np.linalg.norm(p_of(hi)) > radius:
                hi *= 2
            lo_ = base
            for _ in range(100):
                mid = 0.5 * (lo_ + hi)
                if np.linalg.norm(p_of(mid)) > radius:
                    lo_ = mid
                else:
                    hi = mid
                if hi - lo_ <= 1e-10 * hi:
                    break
            pt = p_of(hi)
    p = pt / ds
    return p, -(g @ p + 0.5 * p @ (S @ p))


def varpro_descent(co: Coordinates, x, target, *, maxit: int = 300, gtol: float = 1e-8, optimal=optimal_residues,
                   reduced_gradient: bool = False):
    r"""Trust-region Newton over the poles alone, the residues eliminated (variable projection):
    :math:`J(\lambda) = \min_\varphi J(\lambda, \varphi)`, gradient :math:`g_\lambda` at the optimal
    residues, Hessian the Schur complement :math:`S = H_{\lambda\lambda} - H_{\lambda\varphi}
    H_{\varphi\varphi}^{-1}H_{\varphi\lambda}` (indefinite allowed), trust region in the norm of the
    damping diagonal :math:`D` (:func:`_scaling` of S and the Gauss-Newton Schur complement: a step of
    radius :math:`\Delta` changes :math:`T_r` by about :math:`\Delta` in H2 norm), starting at
    :math:`\Delta = \sqrt J`. A step is taken when it decreases J by at least 1e-4 of the predicted
    decrease (below the pole-residue formula's rounding, J is compared without its cancellation
    where the target can, else the relative gradient must decrease). Stops when the relative gradient
    is at most ``gtol`` (``"converged"``), when the radius has shrunk below 1e-12 of the start's
    (``"stalled"``), or at ``maxit`` (``"cap"``). ``optimal``: the variable projection (coordinates, x,
    target) -> evaluation (:func:`~morsuite.reducers.h2.poles.optimal_residues`; the SIMO one of
    :mod:`~morsuite.reducers.h2.simo`). ``reduced_gradient``: the poles' gradient of
    :math:`J(\lambda)` with the residues' remaining gradient :math:`g_\varphi` eliminated,
    :math:`g_\lambda - H_{\lambda\varphi}H_{\varphi\varphi}^{-1}g_\varphi` (consistent with S; where the
    residue block is ill-conditioned, the residues of one solve leave a :math:`g_\varphi` whose
    correction is of the size of :math:`g_\lambda`: the SIMO descent at the DSMS's errors of 1e-9 of its
    norm, docs/design/so_h2.md 2026-11-28); False (the SISO path): :math:`g_\lambda`.
    Returns ``(evaluation, iterations, reason, history)``."""
    ev = optimal(co, x, target)
    if ev is None:
        raise InputError("the start is outside the domain (unstable, or a pair on the real axis)")
    lm = co.lam_mask
    Zl = co.Z[:, lm]
    hist = [float(np.sqrt(max(ev.value, 0.0)))]
    reason, it = "cap", 0
    precise = None
    radius = r0 = np.sqrt(max(ev.value, 0.0))
    for it in range(1, maxit + 1):
        if ev.rho <= gtol:
            reason, it = "converged", it - 1
            break
        try:
            S, SG = _schur(ev.H, lm), _schur(ev.G, lm)
        except np.linalg.LinAlgError:
            reason, it = "stalled", it - 1
            break
        D = _scaling(S, SG)
        gl = ev.g[lm]
        if reduced_gradient:
            try:
                gl = gl - ev.H[np.ix_(lm, ~lm)] @ np.linalg.solve(ev.H[np.ix_(~lm, ~lm)], ev.g[~lm])
            except np.linalg.LinAlgError:
                reason, it = "stalled", it - 1
                break
        accepted = None
        while radius > 1e-12 * r0:
            p, pred = _tr_step(S, D, gl, radius)
            trial = optimal(co, ev.x + Zl @ p, target)
            if trial is None:
                radius *= 0.25
                continue
            act = ev.value - trial.value
            fl = max(ev.floor, trial.floor)
            pt = None
            if pred <= 10.0 * fl and hasattr(target, "precise"):
                # the decrease is below the pole-residue formula's rounding: compare without it (the value of
                # the projection where the target has it: the residues are the optimal ones)
                value_of = getattr(target, "projected", target.precise)
                if precise is None:
                    precise = value_of(co, ev.x)
                pt = value_of(co, trial.x)
                act, fl = precise[0] - pt[0], max(precise[1], pt[1])
            tiny = act > -fl and pred <= 4.0 * fl
            ratio = act / pred if pred > 0 else 0.0
            if (ratio >= 1e-4 and act > -fl) or (tiny and trial.rho < ev.rho):
                accepted = trial
                radius = _next_radius(radius, ratio, np.linalg.norm(np.sqrt(D) * p))
                precise = pt
                break
            radius = 0.25 * np.linalg.norm(np.sqrt(D) * p)
        if accepted is None:
            reason, it = "stalled", it - 1
            break
        ev = accepted
        hist.append(float(np.sqrt(max(ev.value, 0.0))))
    else:
        if ev.rho <= gtol:
            reason = "converged"
    return ev, it, reason, hist


#: a conjugate pair with Im(lambda) / abs(lambda) below this, or two real poles closer than this
#: relative to their size, are near the boundary of the coordinates: the descent changes the split
#: and restarts
SPLIT_TOL = 1e-3


def restructure(co: Coordinates, x):
    r"""New coordinates after the descent stalled at the boundary of the current ones: the pair nearest
    the real axis (:math:`\mathrm{Im}\,\lambda/|\lambda|` below ``SPLIT_TOL``) becomes two real poles
    :math:`a(1 \pm 10^{-2})`, or the two closest real poles (relative distance below ``SPLIT_TOL``)
    become the pair :math:`a(1 \pm 10^{-2}i)`; the residues are re-optimised by the caller. Returns
    ``(Coordinates, x)`` or None when neither applies."""
    lam, phi = co.split(x)
    nr, nc = co.nr, co.nc
    lr, pr = lam[:nr].real, phi[:nr].real
    lu, pu = lam[nr:nr + nc], phi[nr:nr + nc]
    ratio = np.abs(lu.imag) / np.abs(lu) if nc else np.array([])
    if nc and ratio.min() < SPLIT_TOL:
        j = int(np.argmin(ratio))
        a = lu[j].real
        lr2 = np.concatenate([lr, [a * 0.99, a * 1.01]])
        pr2 = np.concatenate([pr, [pu[j].real, pu[j].real]])
        keep = np.arange(nc) != j
        new = Coordinates(nr + 2, nc - 1)
        return new, _with_pivot(new, new.join(lr2, pr2, lu[keep], pu[keep]))
    if nr >= 2:
        srt = np.argsort(lr)
        gaps = np.abs(np.diff(lr[srt])) / np.abs(lr[srt][1:])
        k = int(np.argmin(gaps))
        if gaps[k] < SPLIT_TOL:
            i, j = srt[k], srt[k + 1]
            a = 0.5 * (lr[i] + lr[j])
            keep = np.setdiff1d(np.arange(nr), [i, j])
            new = Coordinates(nr - 2, nc + 1)
            lu2 = np.concatenate([lu, [a + 1e-2j * abs(a)]])
            pu2 = np.concatenate([pu, [0.5 * (pr[i] + pr[j])]])
            return new, _with_pivot(new, new.join(lr[keep], pr[keep], lu2, pu2))
    return None


def _with_pivot(co: Coordinates, x):
    """x with the constraint enforced through the largest residue coordinate, made the pivot."""
    co.set_pivot(int(np.argmax(np.where(co.a != 0, np.abs(x), -1.0))))
    x = x.copy()
    x[co.pivot] -= (co.a @ x) / co.a[co.pivot]
    return x


def pole_descent(co: Coordinates, x, target, *, maxit: int = 300, gtol: float = 1e-8, restarts: int = 6):
    """:func:`varpro_descent`, restarted in new coordinates (:func:`restructure`) when it stalls at
    their boundary (a pair meeting the real axis, two real poles meeting); the best result by J.
    Returns ``(Coordinates, evaluation, iterations, reason, history, changes)``."""
    ev, its, reason, hist = varpro_descent(co, x, target, maxit=maxit, gtol=gtol)
    value = _best_value(target, co, ev)
    best = (co, ev, reason, value)
    cur = (co, ev)
    total, changes = its, 0
    while reason == "stalled" and changes < restarts and total < maxit:
        nxt = restructure(*cur[:1], cur[1].x)
        if nxt is None:
            break
        try:
            ev2, its2, reason, hist2 = varpro_descent(*nxt, target, maxit=maxit - total, gtol=gtol)
        except (InputError, np.linalg.LinAlgError):
            break
        changes += 1
        total += its2
        hist = hist + hist2[1:]
        cur = (nxt[0], ev2)
        v2 = _best_value(target, nxt[0], ev2)
        if v2 < best[3]:
            best = (nxt[0], ev2, reason, v2)
    co, ev, reason, _ = best
    return co, ev, total, reason, hist, changes


def _best_value(target, co, ev):
    """J for comparing results: without the pole-residue formula's cancellation where the target can."""
    return target.precise(co, ev.x)[0] if hasattr(target, "precise") else ev.value
