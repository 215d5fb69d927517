r"""The next order a tolerance search evaluates (:mod:`morsuite.analysis.tolerance`).

An error curve is modelled as :math:`\log e` piecewise linear in the order (first-order states on
the x axis, so that a proxy method of another kind fits on the same axis). Two rules pick the next
order:

:func:`grow`
    above the largest miss: where the curve through the evaluated orders (or the proxy's curve
    scaled by the method's measured ratio to it) crosses the tolerance, between 1.25 and ``growth``
    times the largest miss;
:func:`between`
    strictly between a miss and a meet: the crossing again (rounded up, so the order just below
    the boundary comes first), or the midpoint when the bracket did not halve in two steps.

A *proxy* is a cheaper method's search on the same error (one-point Krylov: one LU) whose error
curve steers the costly method (the IRKA family) while it has one evaluated order: its error at s
states is predicted as the proxy's at s times the ratio measured at that order; from two orders on,
the method's own curve decides (the two curves' slopes differ). Cost: O(points) per decision.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["curve", "grow", "between", "proxy_prediction"]


def curve(points):
    """``(states, log values)`` of ``points`` (pairs (states, value)) with finite positive values, sorted by
    states (the smallest value kept where states repeat)."""
    best = {}
    for s, v in points:
        if v is not None and np.isfinite(v) and v > 0:
            best[s] = min(v, best.get(s, math.inf))
    xs = sorted(best)
    return np.asarray(xs, float), np.log([best[x] for x in xs])


def _crossing(xs, ys, tol, lo_states):
    """The states (continuous) above ``lo_states`` where the piecewise-linear log curve falls to log tol,
    extrapolated with the last segment's slope; None when it does not fall."""
    if xs.size < 2:
        return None
    target = math.log(tol)
    for i in range(xs.size - 1):
        if xs[i + 1] <= lo_states:
            continue
        if ys[i] > target >= ys[i + 1]:
            return xs[i] + (target - ys[i]) / (ys[i + 1] - ys[i]) * (xs[i + 1] - xs[i])
    slope = (ys[-1] - ys[-2]) / (xs[-1] - xs[-2])
    if slope >= 0 or ys[-1] <= target:
        return None
    return xs[-1] + (target - ys[-1]) / slope


def proxy_prediction(own, proxy, near_states):
    """The proxy's curve (pairs (states, value)) scaled to the method's: times the ratio of the method's
    value to the proxy's interpolated one at the method's one evaluated order; None without a proxy, or
    when the method has none or several (``near_states`` picks the nearest, for a caller's variant)."""
    px, py = curve(proxy or [])
    ox, oy = curve(own)
    if px.size < 2 or ox.size != 1:  # two or more own points: the method's own curve is the better guide
        return None
    j = int(np.argmin(np.abs(ox - near_states)))
    shift = oy[j] - np.interp(ox[j], px, py)
    return px, py + shift


def grow(own, lo, tol, spo, growth, r_max, proxy=None):
    """The next order above the largest miss ``lo`` (module docstring); ``own``: the method's (states,
    value) pairs; ``proxy``: the proxy's, or None."""
    step_max = max(lo + 1, math.floor(lo * growth))
    nxt = step_max
    pred = proxy_prediction(own, proxy, lo * spo)
    xs, ys = pred if pred is not None else curve([p for p in own if p[0] <= lo * spo])
    cross = _crossing(xs, ys, tol, lo * spo)
    if cross is not None:
        nxt = int(math.ceil(1.1 * cross / spo))
    nxt = min(max(nxt, lo + max(1, math.ceil(0.25 * lo))), step_max)
    return min(nxt, r_max)


def between(own, lo, hi, tol, spo, bisect, proxy=None):
    """An order strictly between the miss ``lo`` and the meet ``hi`` (module docstring); ``lo = 0`` (only
    meets so far): a quarter of ``hi`` below it (at least one order), or where the proxy's curve says."""
    if lo == 0:
        pred = proxy_prediction(own, proxy, hi * spo)
        cross = _crossing(*pred, tol, 0) if pred is not None and not bisect else None
        step = hi - max(1, math.ceil(0.25 * hi))
        return max(1, min(hi - 1, int(math.ceil(cross / spo)) if cross is not None else step))
    nxt = (lo + hi) // 2
    if not bisect:
        pred = proxy_prediction(own, proxy, hi * spo)
        xs, ys = pred if pred is not None else curve([p for p in own if lo * spo <= p[0] <= hi * spo])
        cross = _crossing(xs, ys, tol, lo * spo)
        if cross is not None:
            nxt = int(math.ceil(cross / spo))
    if nxt >= hi - 1 or hi - lo <= 2:
        nxt = hi - 1
    return min(max(nxt, lo + 1), hi - 1)
