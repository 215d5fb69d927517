r"""The pole-residue phase of ``so-h2`` for SISO models: variable projection and Newton, then chord steps.

A second-order SISO reduced model of order r is, generically, a first-order model of degree 2r
whose residues sum to zero, and back (:mod:`morsuite.reducers.h2.poles`): the descent runs in those
4r - 1 coordinates, with no redundancy, where the second-order entries have about
:math:`(r - 1)^2` redundant directions that make every first-order method crawl.

1. From each of the ``starts`` best candidates (by their error against the surrogate): variable
   projection against the surrogate :math:`T_N` (the residues that minimise J for the poles, one
   linear solve; trust-region Newton over the poles with the exact Hessian's Schur complement),
   to a surrogate relative gradient of ``1e-3 * gtol``, for ``probe`` iterations each; the best by
   surrogate error continues up to ``maxit``, and the second if the first does not converge. If
   none converges, optionally (``cluster_rounds``) rounds alternating Gauss-Newton in cluster-polynomial
   coordinates with this descent (:func:`~morsuite.reducers.h2.clusters.alternating_descent`), from the best
   start that stalled (else the best), their result polished on a closer surrogate (``tighter``: Newton,
   then one more round if that does not converge) so that the chord steps start within that surrogate's
   distance of the model's stationary point.
2. Chord steps against the full model: its gradient (one LU per pole pair) with the surrogate's
   Hessian, until the full model's relative gradient is at most ``gtol`` or ``chord_maxit`` steps.
   They converge at the rate of the surrogate's error relative to the model's error.
3. The second-order realization of the result (:func:`~morsuite.reducers.h2.poles.second_order_of`).

Cost: dense, :math:`O(r^3 + rN)` per Newton iteration and start; r LUs per chord step.
Measurements: ``docs/design/so_h2.md``.
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from .poles import Coordinates, FullValues, ModalValues, chord_step, evaluate, optimal_residues, second_order_of
from .clusters import alternating_descent
from .poles_descent import pole_descent
from .starts import standard_realization

__all__ = ["pole_phase"]

#: (k, f): the cluster Gauss-Newton of the rounds hands over to the pole descent when sqrt(J) decreased by less
#: than the fraction f over its last k iterations (None: at its iteration cap only); docs/design/so_h2.md
PLATEAU = (20, 5e-3)
#: Newton iterations of the polish on the closer surrogate (and the cap of its alternation round)
POLISH_MAXIT = 60


def pole_phase(roms, order, sur, full, *, gtol, maxit, chord_maxit, starts, probe=30, finalists=2,
               cluster_rounds=0, tighter=None, polish_maxit=POLISH_MAXIT):
    """Run steps 1 to 3 of the module docstring.

    Parameters
    ----------
    roms : dict label -> SecondOrderROM (the candidates)
    order : labels by increasing surrogate error
    sur : ModalTarget (the surrogate); full : FullTarget
    gtol, maxit, chord_maxit, starts : the options of so-h2
    probe : iterations every start gets before the best (by surrogate error) gets the rest of ``maxit``
    finalists : starts continued, best first, until one reaches stationarity on the surrogate; the
        result is the best converged one, or the best of all if none converged
    cluster_rounds : when the result has not converged on the surrogate, at most this many rounds of
        :func:`~morsuite.reducers.h2.clusters.alternating_descent` from it (0: none)
    tighter : None, or a function returning a closer surrogate (ModalTarget); called only when the
        rounds ran: their result is then polished against it (:func:`_polish`) before the chord steps
    polish_maxit : Newton iterations of the polish (and the iterations of its one alternation round)

    Returns
    -------
    ((K, D, F, L) or None, record)
        None when no start could be descended from or the result has no second-order realization;
        ``record``: per start its surrogate error before and after, iterations, reason; the chosen
        start; ``iterations_surrogate``, ``iterations_full``, ``history``, ``history_full``,
        ``stop_reason``, ``stop_reason_full``, ``relative_gradient_full`` (after the chord steps),
        ``cluster_record`` (the rounds of ``cluster_rounds``, if any).
    """
    tv = ModalValues(sur)
    runs, alive = {}, []
    for label in list(order)[:starts]:
        A, B, C = standard_realization(roms[label])
        try:
            co, x = Coordinates.of_model(A, B, C)
            res = pole_descent(co, x, tv, maxit=min(probe, maxit), gtol=1e-3 * gtol)
        except (InputError, np.linalg.LinAlgError, ValueError) as exc:
            runs[label] = {"failed": f"{type(exc).__name__}: {exc}"}
            continue
        alive.append((label, res))
    # successive halving: every start gets ``probe`` iterations; then, best by surrogate error first, up to
    # ``finalists`` of them continue to ``maxit`` until one reaches the surrogate's stationarity
    score = {label: tv.precise(res[0], res[1].x)[0] for label, res in alive}
    results = {}
    for label, (co, ev, its, reason, hist, changes) in alive:
        results[label] = (label, co, ev, its, reason, hist, changes)
        runs[label] = {"surrogate_h2_error_start": hist[0], "surrogate_h2_error": float(np.sqrt(max(score[label], 0))),
                       "iterations": its, "reason": reason, "relative_gradient": ev.rho, "real_poles": co.nr,
                       "structure_changes": changes}
    for label in sorted(results, key=score.get)[:finalists]:
        _, co, ev, its, reason, hist, changes = results[label]
        if reason != "converged" and maxit > probe:
            co, ev, its2, reason, hist2, ch2 = pole_descent(co, ev.x, tv, maxit=maxit - probe, gtol=1e-3 * gtol)
            results[label] = (label, co, ev, its + its2, reason, hist + hist2[1:], changes + ch2)
            score[label] = tv.precise(co, ev.x)[0]
            runs[label].update(iterations=its + its2, reason=reason, relative_gradient=ev.rho,
                               surrogate_h2_error=float(np.sqrt(max(score[label], 0))),
                               structure_changes=changes + ch2)
        if reason == "converged":
            break
    done = [k for k in results if results[k][4] == "converged"]
    best = results[min(done or results, key=score.get)] if results else None
    rec = {"starts": runs, "iterations_surrogate": sum(v.get("iterations", 0) for v in runs.values()),
           "history": [], "history_full": [], "iterations_full": 0, "stop_reason": "no start",
           "stop_reason_full": None, "relative_gradient_full": None, "descended_from": None}
    if best is None:
        return None, rec
    rec["cluster_record"] = []
    if best[4] != "converged" and cluster_rounds:
        # the rounds leave stalls at clusters, where the pole-residue metric fails: from the best start that
        # stalled there rather than one still descending at its iteration cap (docs/design/so_h2.md, third
        # session: at tcom(2000), r = 30, from vv (cap) the rounds end at a point they do not converge at)
        stalled = [k for k in results if results[k][4] == "stalled"]
        if stalled:
            best = results[min(stalled, key=score.get)]
    label, co, ev, its, reason, hist, _ = best
    if reason != "converged" and cluster_rounds:
        co, ev, its_c, reason, rounds = alternating_descent(co, ev.x, tv, rounds=cluster_rounds, gtol=1e-3 * gtol,
                                                            plateau=PLATEAU)
        rec["cluster_record"] = rounds
        rec["iterations_surrogate"] += its_c
        if tighter is not None:
            co, ev, its_p, reason, rec["polish"] = _polish(co, ev, tighter, gtol=1e-3 * gtol, maxit=polish_maxit)
            rec["iterations_surrogate"] += its_p
    rec.update(descended_from=label, history=hist, stop_reason=reason)
    fv = FullValues(full)
    evf = evaluate(co, ev.x, fv, hessian=False)
    if evf is None:
        rec["stop_reason_full"] = "the surrogate's result is outside the domain"
        return None, rec
    rec["history_full"] = [float(np.sqrt(max(evf.value, 0.0)))]
    steps, why = 0, "converged"
    while evf.rho > gtol:
        if steps >= chord_maxit:
            why = "cap"
            break
        trial = None
        for mu in (0.0, 1e-4, 1e-2, 1.0):     # damped when the surrogate's Hessian misleads (r LUs each)
            xn = chord_step(co, evf, ev.H, mu=mu)
            trial = None if xn is None else evaluate(co, xn, fv, hessian=False)
            if trial is not None and trial.value <= evf.value + 2.0 * max(evf.floor, trial.floor):
                break
            trial = None
        steps += 1
        if trial is None:
            why = "stalled"
            break
        evf = trial
        rec["history_full"].append(float(np.sqrt(max(evf.value, 0.0))))
    rec.update(iterations_full=steps, stop_reason_full=why, relative_gradient_full=evf.rho)
    try:
        return second_order_of(co, evf.x), rec
    except (InputError, np.linalg.LinAlgError) as exc:
        rec["stop_reason_full"] = f"no second-order realization: {exc}"
        return None, rec


def _polish(co, ev, tighter, *, gtol, maxit):
    r"""The rounds' result moved to a closer surrogate: residues re-optimised, the pole descent
    (:func:`~morsuite.reducers.h2.poles_descent.pole_descent`) for at most ``maxit`` iterations and, if that does
    not converge, one alternation round (:func:`~morsuite.reducers.h2.clusters.alternating_descent`). The chord
    steps then start within the closer surrogate's distance of the model's stationary point (their rate is
    that distance over the error). Returns ``(Coordinates, evaluation, iterations, reason, record)``
    (on a failure, the input poles with their residues for the closer surrogate)."""
    tv = ModalValues(tighter())
    start = optimal_residues(co, ev.x, tv)
    if start is None:
        return co, ev, 0, "stalled", {"failed": "outside the domain on the closer surrogate"}
    v0 = tv.precise(co, start.x)[0]
    rec = {"states": int(tv.mu.size), "h2_start": float(np.sqrt(max(v0, 0.0)))}
    try:
        co2, ev2, its, reason, _, _ = pole_descent(co, start.x, tv, maxit=maxit, gtol=gtol)
        if reason != "converged":
            co2, ev2, its2, reason, rounds = alternating_descent(co2, ev2.x, tv, rounds=1, cluster_maxit=maxit,
                                                                 pole_maxit=maxit, gtol=gtol, plateau=PLATEAU)
            its += its2
            rec["rounds"] = rounds
    except (InputError, np.linalg.LinAlgError, ValueError) as exc:
        rec["failed"] = f"{type(exc).__name__}: {exc}"
        return co, start, 0, "stalled", rec
    rec.update(h2=float(np.sqrt(max(tv.precise(co2, ev2.x)[0], 0.0))), iterations=its, reason=reason,
               relative_gradient=float(ev2.rho))
    return co2, ev2, its, reason, rec
