r"""A monotone, preconditioned L-BFGS descent that never accepts an increase of the objective.

For the H2 descent of ``so-h2``: the objective may be infinite (a step that
leaves the stable set), is known only to an absolute accuracy (``floor``), and
its variables have scales that differ by many orders of magnitude, so:

- the initial inverse Hessian of every two-loop recursion is
  :math:`\gamma\,\mathrm{diag}(h)` with a given diagonal :math:`h` (a
  preconditioner, e.g. the inverse Gauss-Newton diagonal) and
  :math:`\gamma = s^Ty/y^T\mathrm{diag}(h)y` from the last pair (Nocedal and
  Wright, eq. 7.20, with the diagonal in place of the identity);
- the step is found by backtracking from 1 (Armijo, ``c1``): halved after a
  finite increase, cut by 10 after an infinite value; a step is accepted only
  if it decreases the objective by more than its accuracy (``floor``);
- when no step decreases it, the memory is dropped and the preconditioned
  gradient direction is tried once; if that fails too, the objective cannot be
  decreased at its accuracy and the descent stops (``reason = "stalled"``).

It also stops when the objective decreased by less than ``rtol`` times its value
over the last ``window`` iterations (``"small decrease"``), or at ``maxit``.
Pairs with :math:`s^Ty \le 0` are skipped (the update would not be positive definite).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

__all__ = ["Evaluation", "LBFGSResult", "lbfgs_descent"]


@dataclass
class Evaluation:
    """What the objective returns: value (``inf`` outside the domain), its absolute accuracy, gradient."""

    value: float
    floor: float = 0.0
    gradient: np.ndarray | None = None
    data: object = None


@dataclass
class LBFGSResult:
    """Result of :func:`lbfgs_descent`: the best point, its evaluation, and the record of the run."""

    x: np.ndarray
    best: Evaluation
    iterations: int
    evaluations: int
    reason: str
    history: list = field(default_factory=list)   # objective value after each accepted step (start first)
    memory: tuple = ((), ())

    @property
    def converged(self) -> bool:
        """True unless the run stopped at the iteration limit (``reason == "maxit"``)."""
        return self.reason != "maxit"


def _two_loop(g, S, Y, h):
    q = g.copy()
    alpha = []
    for s, y in zip(reversed(S), reversed(Y)):
        a = (s @ q) / (y @ s)
        alpha.append(a)
        q -= a * y
    if S:
        s, y = S[-1], Y[-1]
        gam = (s @ y) / (y @ h(y))
    else:
        gam = 1.0
    z = gam * h(q)
    for s, y, a in zip(S, Y, reversed(alpha)):
        b = (y @ z) / (y @ s)
        z += s * (a - b)
    return -z


def lbfgs_descent(fun: Callable[[np.ndarray], Evaluation], x0, *, precond=None, maxit: int = 1000,
                  memory: int = 20, rtol: float = 1e-6, window: int = 20, c1: float = 1e-4,
                  max_backtracks: int = 40, retry: bool = True, first: Evaluation | None = None, pairs=None,
                  callback=None) -> LBFGSResult:
    r"""Minimise ``fun`` from ``x0`` by monotone preconditioned L-BFGS (module docstring).

    Parameters
    ----------
    fun : callable x -> Evaluation
        Value, absolute accuracy and gradient; ``value = inf`` marks a point
        outside the domain (its gradient is not read).
    x0 : (n,) array
    precond : (n,) array of positive numbers, or callable v -> H0 v, optional
        The initial inverse Hessian :math:`H_0`: its diagonal, or its product with a
        vector (symmetric positive definite; default the identity). The very first
        step is scaled so that its predicted decrease is 1e-3 of the value.
    maxit, memory, rtol, window, c1, max_backtracks
        Iteration cap, number of kept pairs, the small-decrease test, Armijo
        constant, backtracking steps per line search.
    retry : bool
        After a failed line search along the quasi-Newton direction, try the
        preconditioned gradient once (default); False stops at once (where an
        evaluation is expensive).
    first : Evaluation, optional
        ``fun(x0)`` if already known (saves one evaluation).
    pairs : (S, Y), optional
        Curvature pairs to start with (from an earlier descent of a nearby objective).
    callback : callable (iteration, x, Evaluation), optional

    Returns
    -------
    LBFGSResult
        ``reason``: "small decrease", "stalled" (no decrease above the accuracy of the
        objective in either direction), "maxit", or "infinite start".
    """
    x = np.array(x0, dtype=float)
    if precond is None:
        h = lambda v: v  # noqa: E731
    elif callable(precond):
        h = precond
    else:
        diag = np.asarray(precond, dtype=float)
        h = lambda v: diag * v  # noqa: E731
    cur = first if first is not None else fun(x)
    nfev = 0 if first is not None else 1
    if not np.isfinite(cur.value):
        return LBFGSResult(x, cur, 0, nfev, "infinite start", [cur.value])
    S, Y = ([list(v) for v in pairs] if pairs is not None else ([], []))
    hist = [cur.value]
    reason = "maxit"
    it = 0
    for it in range(1, maxit + 1):
        g = cur.gradient
        d = _two_loop(g, S, Y, h)
        if not S:
            # no curvature yet: predicted decrease 1e-3 of the value along the preconditioned gradient
            d *= 1e-3 * max(cur.value, 1e-300) / max(-(g @ d), 1e-300)
        accepted = None
        for attempt in range(2):
            gd = g @ d
            if not gd < 0:
                S, Y = [], []
                d = -h(g)
                d *= 1e-3 * max(cur.value, 1e-300) / max(-(g @ d), 1e-300)
                continue
            t = 1.0
            for _ in range(max_backtracks):
                trial = fun(x + t * d)
                nfev += 1
                if np.isfinite(trial.value):
                    drop = cur.value - trial.value
                    if drop > max(cur.floor, trial.floor) and drop >= -c1 * t * gd:
                        accepted = (t, trial)
                        break
                    t *= 0.5
                else:
                    t *= 0.1
            if accepted is not None or not S or not retry:
                break
            # the quasi-Newton direction failed: forget the memory, try the preconditioned gradient
            S, Y = [], []
            d = -h(g)
            d *= 1e-3 * max(cur.value, 1e-300) / max(-(g @ d), 1e-300)
        if accepted is None:
            reason = "stalled"
            it -= 1
            break
        t, trial = accepted
        s = t * d
        y = trial.gradient - g
        if s @ y > 1e-12 * np.sqrt((s @ s) * (y @ y)):
            S.append(s)
            Y.append(y)
            if len(S) > memory:
                S.pop(0)
                Y.pop(0)
        x = x + s
        cur = trial
        hist.append(cur.value)
        if callback is not None:
            callback(it, x, cur)
        if len(hist) > window and hist[-1 - window] - hist[-1] <= rtol * hist[-1]:
            reason = "small decrease"
            break
    return LBFGSResult(x, cur, it, nfev, reason, hist, (tuple(S), tuple(Y)))
