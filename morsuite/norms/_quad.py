r"""Adaptive Gauss-Kronrod quadrature over :math:`[0, \infty)` on a mapped axis, for costly integrands.

:math:`\int_0^\infty f(\omega)\,d\omega = \int_0^1 f(\omega(t))\,\omega'(t)\,dt` with
:math:`\omega = \omega_0 t/(1-t)`, :math:`\omega' = \omega_0/(1-t)^2`: an
integrand decaying like :math:`\omega^{-2}` or faster stays bounded at
:math:`t = 1`. The interval is first cut at given breakpoints (pole
frequencies), then the 15-point Kronrod rule with its embedded 7-point Gauss
rule (QUADPACK's QK15 and its error estimate) is applied per piece, and the
piece with the largest error estimate is bisected until the sum of the
estimates is below the tolerance or the node budget is spent. The two halves
of a bisected piece get the smaller of their QK15 estimates and the
difference between the parent's value and theirs (the parent's error, which
bounds theirs once the rule has converged). Every node is
one call of ``f`` (for the norms: one sparse LU); nodes are never at
:math:`t = 0` or 1.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass, field

import numpy as np

__all__ = ["QuadResult", "integrate_half_axis", "XGK", "WGK", "WG"]

#: QK15 abscissae (positive half, the last one 0), Kronrod weights, and Gauss weights of the nodes 1, 3, 5, 7
XGK = np.array([0.991455371120812639206854697526329, 0.949107912342758524526189684047851,
                0.864864423359769072789712788640926, 0.741531185599394439863864773280788,
                0.586087235467691130294144845693013, 0.405845151377397166906606412076961,
                0.207784955007898467600689403773245, 0.0])
WGK = np.array([0.022935322010529224963732008058970, 0.063092092629978553290700663189204,
                0.104790010322250183839876322541518, 0.140653259715525918745189590510238,
                0.169004726639267902826583426598550, 0.190350578064785409913256402421014,
                0.204432940075298892414161999234649, 0.209482141084727828012999174891714])
WG = np.array([0.129484966168869693270611432679082, 0.279705391489276667901467771423780,
               0.381830050505118944950369775488975, 0.417959183673469387755102040816327])
_NODES = np.concatenate([-XGK[:-1], XGK[::-1]])  # 15 nodes in [-1, 1], increasing
_WK = np.concatenate([WGK[:-1], WGK[::-1]])
_WG = np.zeros(15)
_WG[[1, 3, 5, 7, 9, 11, 13]] = np.concatenate([WG[:-1], WG[::-1]])


@dataclass
class QuadResult:
    """Value, error estimate, nodes used, whether the tolerance was met, and the pieces."""

    value: float
    error: float
    nodes: int
    converged: bool
    pieces: int
    covered: bool = True  # every piece of [0, inf) was integrated (else the value misses a part of the axis)
    aux: float = 0.0  # the same rule applied to the auxiliary values returned by f (if any)
    samples: list = field(default_factory=list, repr=False)  # (omega, f) of every node


def _qk15(fvals, a, b):
    h = 0.5 * (b - a)
    resk = h * np.dot(_WK, fvals)
    resg = h * np.dot(_WG, fvals)
    reskh = resk / (2 * h) if h else 0.0
    resasc = h * np.dot(_WK, np.abs(fvals - reskh))
    err = abs(resk - resg)
    if resasc != 0 and err != 0:  # QUADPACK's scaling of the raw difference
        err = resasc * min(1.0, (200.0 * err / resasc) ** 1.5)
    return resk, err


def integrate_half_axis(f, w0: float, breakpoints=(), *, rtol: float = 1e-10, atol: float = 0.0,
                        max_nodes: int = 2000) -> QuadResult:
    r""":math:`\int_0^\infty f(\omega)\,d\omega` by adaptive QK15 on :math:`\omega = \omega_0 t/(1-t)`.

    Parameters
    ----------
    f : callable
        ``f(omega) -> float`` or ``(float, float)``: the integrand and an
        auxiliary nonnegative quantity integrated by the same rule (used for
        rounding estimates).
    w0 : float > 0
        Scale of the map (the midpoint :math:`t = 1/2` is :math:`\omega_0`).
    breakpoints : iterable of float
        Frequencies at which the axis is cut first (e.g. pole frequencies).
    rtol, atol : float
        Stop when the summed error estimate is at most ``max(atol, rtol |I|, A)``,
        :math:`A` the integral of the auxiliary values (the rounding level of
        the integrand: below it the estimates measure noise). A piece whose
        estimate is below its own part of :math:`A` is not split.
    max_nodes : int
        Largest number of calls of ``f`` (15 per piece).
    """
    bp = np.asarray([w for w in breakpoints if np.isfinite(w) and w > 0], dtype=float)
    tb = np.unique(np.concatenate([[0.0, 1.0], bp / (w0 + bp)]))
    samples = []

    def piece(a, b):
        t = 0.5 * (a + b) + 0.5 * (b - a) * _NODES
        vals = np.empty(15)
        auxv = np.zeros(15)
        for i, ti in enumerate(t):
            w = w0 * ti / (1.0 - ti)
            out = f(w)
            fv, av = (out if isinstance(out, tuple) else (out, 0.0))
            jac = w0 / (1.0 - ti) ** 2
            vals[i], auxv[i] = fv * jac, av * jac
            samples.append((w, fv))
        val, err = _qk15(vals, a, b)
        return val, err, 0.5 * (b - a) * np.dot(_WK, auxv)

    heap = []
    total = total_err = aux = 0.0
    nodes = 0
    # merge pieces narrower than 1e-12 of the axis (duplicate breakpoints after the map)
    keep = [tb[0]]
    for t in tb[1:]:
        if t - keep[-1] > 1e-12:
            keep.append(t)
    keep[-1] = 1.0
    # the whole axis first: more breakpoints than the budget can cover are thinned (evenly), never dropped
    # from the end, so that the value never misses a part of the axis
    most = max(1, max_nodes // 15)
    if len(keep) - 1 > most:
        inner = np.asarray(keep[1:-1])
        pick = np.unique(np.linspace(0, inner.size - 1, most - 1).round().astype(int)) if most > 1 else []
        keep = [0.0, *inner[pick], 1.0]
    for a, b in zip(keep[:-1], keep[1:]):
        if nodes + 15 > max_nodes and heap:
            break
        v, e, x = piece(a, b)
        nodes += 15
        heapq.heappush(heap, (-e, a, b, v, x))
        total, total_err, aux = total + v, total_err + e, aux + x
    covered = keep[-1] if not heap else max(h[2] for h in heap)
    converged = covered >= 1.0
    done = []  # pieces whose error estimate is below their rounding level: splitting them cannot help
    while converged and total_err > max(atol, rtol * abs(total), aux):
        if not heap:
            break
        if nodes + 30 > max_nodes:
            converged = False
            break
        ne, a, b, v, x = heapq.heappop(heap)
        m = 0.5 * (a + b)
        if -ne <= x or m <= a or m >= b:
            done.append((ne, a, b, v, x))
            continue
        left, right = piece(a, m), piece(m, b)
        nodes += 30
        # the parent's value against its children's is a second, sharper error estimate: the parent's
        # actual error, which bounds the children's once the rule converges; QUADPACK's estimate of a
        # resolved piece is 1e3-1e6 above its error (measured), which would waste nodes
        el, er = left[1], right[1]
        diff = abs(v - left[0] - right[0])
        if el + er > diff:
            el, er = (el * diff / (el + er), er * diff / (el + er)) if el + er > 0 else (0.0, 0.0)
        total += left[0] + right[0] - v
        total_err += el + er + ne
        aux += left[2] + right[2] - x
        heapq.heappush(heap, (-el, a, m, left[0], left[2]))
        heapq.heappush(heap, (-er, m, b, right[0], right[2]))
    heap += done
    # the running sums drift by rounding over many splits: recompute from the pieces
    total = float(sum(h[3] for h in heap))
    total_err = float(sum(-h[0] for h in heap))
    aux = float(sum(h[4] for h in heap))
    converged = bool(converged and total_err <= max(atol, rtol * abs(total), aux))
    return QuadResult(total, total_err, nodes, converged, len(heap), covered >= 1.0, aux, samples)
