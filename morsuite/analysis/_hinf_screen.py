r"""Screening of the H-infinity search's resonance samples (:mod:`morsuite.analysis.hinf`, option ``screen``).

The start grid of a search holds the resonance frequencies of the reduced model and of the
full model besides the band grid and the log grid. Each costs one sparse LU where the memo
does not hold it; most of them lie far below the peak. With ``screen``, the base points (0,
the band grid, the log grid) are sampled first, and a resonance frequency :math:`\omega_c` is
sampled only when the largest value of a surrogate of the error between its two sampled
neighbours :math:`a < \omega_c < b`, raised by the refinement's margin
:data:`~morsuite.analysis._hinf_certify.BAR_MARGIN` (25%), reaches the best value sampled: the
bar under which the refinement gives up on a maximum (``refine_peak(bar=...)``).

The surrogate of the full model on :math:`[a, b]` interpolates :math:`T` and :math:`T'`
(which every sample has: one transposed solve with its LU) at both ends by

.. math::

    \tilde T(s) = \sum_{k} \frac{R_k}{s - \lambda_k} + \sum_{i < 4 - \#\lambda} C_i\,t^i,
    \qquad t = \frac{s - ja}{j(b - a)},

with the model's poles :math:`\lambda_k = -\delta_k + j\omega_k` (the resonances the search
knows: Ritz values of cached Gramian factors) whose centres lie within half the interval of
it, at most two: a lightly damped pole between two samples is what a polynomial cannot
follow, and its residue is fixed by the samples on its flanks. The error's surrogate is
:math:`\sigma_{\max}(\tilde T - T_r)` (the reduced model exact) on 32 points of
:math:`[a, b]`, the candidate and the poles' centres; its largest value is the prediction.
An interval with more than two poles, or a candidate outside the sampled range, is always
sampled. The screening only decides which LUs are paid: every value reported is a sample.
"""

from __future__ import annotations

import numpy as np

from ..norms.h2 import resonances

__all__ = ["model_poles", "predicted_peak", "screen"]

#: points of the surrogate's sweep of an interval
SWEEP = 32
#: at most this many of the model's poles in one interval; more: the candidate is sampled
MAX_POLES = 2


def model_poles(ritz) -> np.ndarray:
    r"""The resonant poles :math:`-\delta + j\omega_p` of ``ritz`` that stand apart
    (:func:`morsuite.norms.h2.resonances`: poles closer than their widths are one feature, its
    sharpest pole), sorted by frequency."""
    if ritz is None or not np.size(ritz):
        return np.zeros(0, dtype=complex)
    return np.array([-d + 1j * w for w, d in resonances(ritz)], dtype=complex)


def _surrogate(a, b, Ta, Tb, dTa, dTb, poles):
    """Coefficients and an evaluator of the Hermite surrogate on [a, b] (module docstring)."""
    sa, sb = 1j * a, 1j * b
    scale = sb - sa
    npoly = 4 - poles.size

    def basis(s, deriv):
        row = []
        for lam in poles:
            row.append(-1.0 / (s - lam) ** 2 if deriv else 1.0 / (s - lam))
        t = (s - sa) / scale
        for i in range(npoly):
            if deriv:
                row.append(i * t ** (i - 1) / scale if i else 0.0)
            else:
                row.append(t ** i)
        return np.array(row, dtype=complex)
    A = np.array([basis(sa, False), basis(sb, False), basis(sa, True), basis(sb, True)])
    p, m = Ta.shape
    rhs = np.stack([Ta.reshape(-1), Tb.reshape(-1), dTa.reshape(-1), dTb.reshape(-1)])
    coef = np.linalg.solve(A, rhs)

    def at(ws):
        rows = np.array([basis(1j * w, False) for w in ws])
        return (rows @ coef).reshape(len(ws), p, m)
    return at


def predicted_peak(w_c, ws, data, poles, rr) -> float:
    r"""The surrogate's largest :math:`\sigma_{\max}(\tilde T - T_r)` between the samples around ``w_c``.

    ``ws``: the sampled frequencies (sorted); ``data[w] = (T, T')``; ``poles``: :func:`model_poles`;
    ``rr``: the reduced model's response (None: the full model's norm). ``inf`` where the surrogate
    cannot be trusted (``w_c`` outside the samples, more than :data:`MAX_POLES` poles, a singular fit).
    """
    i = int(np.searchsorted(ws, w_c))
    if i == 0 or i >= ws.size:
        return np.inf
    a, b = float(ws[i - 1]), float(ws[i])
    half = 0.5 * (b - a)
    near = poles[(poles.imag > a - half) & (poles.imag < b + half)]
    if near.size > MAX_POLES:
        return np.inf
    (Ta, dTa), (Tb, dTb) = data[a], data[b]
    try:
        with np.errstate(all="raise"):
            at = _surrogate(a, b, np.asarray(Ta, dtype=complex), np.asarray(Tb, dtype=complex),
                            np.asarray(dTa, dtype=complex), np.asarray(dTb, dtype=complex), near)
    except (np.linalg.LinAlgError, FloatingPointError):
        return np.inf
    pts = np.concatenate([np.linspace(a, b, SWEEP), [w_c], near.imag[(near.imag > a) & (near.imag < b)]])
    E = at(pts)
    if rr is not None:
        E = E - np.array([np.asarray(rr.transfer(1j * w), dtype=complex) for w in pts])
    if not np.all(np.isfinite(E)):
        return np.inf
    return float(np.max(np.linalg.svd(E, compute_uv=False)[:, 0]))


def screen(sig, candidates, poles, rr, margin, budget):
    """Sample the ``candidates`` whose predicted peak, raised by ``margin``, reaches the best sample.

    The predictions are made on the samples taken before (the base points), most promising first;
    the best value is updated after each sample. ``budget``: samples allowed. Returns the record
    ``{"candidates", "sampled", "skipped"}`` (the skipped ones with their predictions).
    """
    ws = np.array(sorted(sig.samples))
    best = max(v for v, _ in sig.samples.values())
    pred = [(predicted_peak(w, ws, sig.full, poles, rr), float(w)) for w in candidates if w not in sig.samples]
    pred.sort(key=lambda t: (-t[0], t[1]))
    sampled, skipped = [], []
    for p, w in pred:
        if (1.0 + margin) * p < best or len(sampled) >= budget:
            skipped.append({"frequency": w, "predicted": p})
            continue
        v = sig(w)[0]
        best = max(best, v)
        sampled.append({"frequency": w, "predicted": p, "value": v})
    return {"candidates": len(pred), "sampled": len(sampled), "skipped": skipped, "sampled_at": sampled}
