"""The start grid of the H-infinity search (:mod:`morsuite.analysis.hinf`, step 1 of its module docstring).

0, the resonance frequencies of the reduced model and of the model, a log grid over the model's
band widened to cover them; with a band response's grid, that grid inside the band and log points
anchored at its ends outside it. :func:`start_grid` also marks the resonances that are no base
point: those that option ``screen`` samples only where a surrogate may reach the bar
(:mod:`morsuite.analysis._hinf_screen`).
"""

from __future__ import annotations

import numpy as np

from ..norms.h2 import breakpoints, resonances
from .response import freq_grid

__all__ = ["start_grid"]


def _anchored(lo, hi, b_lo, b_hi, per_decade):
    """Log-lattice points ``b_lo 10^(-k/per_decade)`` down to ``lo`` and ``b_hi 10^(k/per_decade)`` up to ``hi``
    (k >= 1): anchored at the band's ends, so that searches whose ranges differ share their points."""
    below = int(np.ceil(per_decade * np.log10(b_lo / lo))) if lo < b_lo else 0
    above = int(np.ceil(per_decade * np.log10(hi / b_hi))) if hi > b_hi else 0
    return np.concatenate([b_lo * 10.0 ** (-np.arange(below, 0, -1) / per_decade),
                           b_hi * 10.0 ** (np.arange(1, above + 1) / per_decade)])


def start_grid(fom, rom_poles, ritz, per_decade, budget, band_grid=None):
    """Start frequencies: 0, resonances of the reduced model and of the model, a log grid; with
    ``band_grid`` that grid's points (not counted in ``budget``) and the log grid outside it only.
    Returns ``(points, record, optional)``: ``optional`` marks the resonances that are no base point
    (only with ``band_grid``; what option ``screen`` screens)."""
    own = np.abs(np.asarray(rom_poles, dtype=complex).imag)
    own = np.unique(own[own > 0])
    if ritz is None or not ritz.size:
        model = np.zeros(0)
    elif band_grid is None:
        model = breakpoints(ritz)
    else:  # the band grid resolves the flanks: the resonances' centres only
        model = np.array([w for w, _ in resonances(ritz)], dtype=float)
    lo, hi = fom.band if band_grid is None else (float(band_grid[0]), float(band_grid[1]))
    freqs = np.concatenate([own, model])
    if freqs.size:
        lo, hi = min(lo, freqs.min() / 10.0), max(hi, freqs.max() * 10.0)
    if band_grid is not None:
        return _banded(own, model, _anchored(lo, hi, float(band_grid[0]), float(band_grid[1]), per_decade),
                       freq_grid(band_grid[:2], band_grid[2]), budget)
    n_log = int(np.ceil(np.log10(hi / lo) * per_decade)) + 1
    logs = np.logspace(np.log10(lo), np.log10(hi), n_log)
    room = budget - 1 - own.size - logs.size
    if model.size > max(room, 0):
        model = model[np.linspace(0, model.size - 1, max(room, 0)).astype(int)] if room > 0 else model[:0]
    pts = np.unique(np.concatenate([[0.0], own, model, logs]))
    if pts.size > budget:  # too many of the reduced model's own resonances: thin the log grid first
        keep = np.unique(np.concatenate([[0.0], own, model]))
        rest = np.setdiff1d(pts, keep)
        n = max(budget - keep.size, 0)
        pts = np.unique(np.concatenate([keep, rest[np.linspace(0, rest.size - 1, n).astype(int)] if n else []]))
        pts = pts[:budget] if pts.size > budget else pts
    # a conjugate pair's |Im| can differ in the last bit: one sample per frequency
    pts = pts[np.concatenate([[True], np.diff(pts) > 1e-10 * pts[1:]])]
    return pts, {"rom_resonances": int(own.size), "model_resonances": int(model.size),
                 "log_grid": int(logs.size)}, np.zeros(pts.size, dtype=bool)


def _banded(own, model, logs, band, budget):
    """:func:`_grid` with a band grid: ``band`` kept whole (free), the model's resonances thinned to the
    ``budget`` left by 0, the reduced model's resonances and the log points outside the band."""
    room = budget - 1 - own.size - logs.size
    if model.size > max(room, 0):
        model = model[np.linspace(0, model.size - 1, max(room, 0)).astype(int)] if room > 0 else model[:0]
    pts = np.unique(np.concatenate([[0.0], own, model, logs, band]))
    # a conjugate pair's |Im| can differ in the last bit: one sample per frequency (the band's points kept)
    near = np.concatenate([[False], np.diff(pts) <= 1e-10 * pts[1:]]) & ~np.isin(pts, band)
    pts = pts[~near]
    # the resonances (not also a base point: 0, the log grid, the band grid): what option screen screens
    optional = np.isin(pts, np.concatenate([own, model])) & ~np.isin(pts, np.concatenate([[0.0], logs, band]))
    return pts, {"rom_resonances": int(own.size), "model_resonances": int(model.size),
                 "log_grid": int(logs.size), "band_grid": int(band.size)}, optional
