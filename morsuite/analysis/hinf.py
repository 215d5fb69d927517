r"""H-infinity norms of the full model and of the error of a reduced model, by refined peak search.

:math:`\|H\|_{\mathcal H_\infty} = \sup_{\omega \ge 0}\sigma_{\max}(H(j\omega))` (real
data: :math:`H(-j\omega) = \overline{H(j\omega)}`), for :math:`H = T` and
:math:`H = T - T_r`.

Search
    1. A start grid: :math:`\omega = 0`; the resonance frequencies
       :math:`|\mathrm{Im}\,\lambda|` of the reduced model's poles; the model's
       resonances, taken from the LR-ADI shifts of Gramian factors already in
       the model's cache (Ritz values of the pencil on the ADI space; none
       when nothing is cached: computing them would cost more LUs than the
       whole search); and a log grid (``per_decade`` points a decade) over the
       model's band widened to cover all those frequencies. At most
       ``grid_lus`` LUs, the model's resonances thinned first.
    2. Each sample costs one sparse LU and gives :math:`\sigma_{\max}` and its
       derivative from the singular vectors,

       .. math::

           \frac{d\sigma}{d\omega} = \mathrm{Re}\bigl(u^H\,j\,(T'(j\omega) - T_r'(j\omega))\,v\bigr),

       :math:`T'` from the same LU (one transposed solve).
    3. The local maxima of the grid, best first, are refined by a safeguarded
       secant iteration on :math:`d\sigma/d\omega = 0` inside the bracket of
       their grid neighbours (bisection when the secant step leaves the
       bracket or the derivative has no sign change), until the upper bound
       of the concave model (the crossing of the tangents at the bracket
       ends) exceeds the best value by less than ``rtol`` relative, or the
       LU budget ``max_lus`` is spent. Also :math:`\|D\|` at
       :math:`\omega = \infty`.

The result is a lower bound of the H-infinity norm, exact (to ``rtol``) at
the peak it found; a peak between grid points that no pole announces can be
missed. ``details`` gives the peak frequency, the LUs, the samples and the
refinement record of each candidate.

Responses are refined in extended precision and subtracted in long double
(:class:`~morsuite.analysis._fom.FomResponse`), so that an error of 1e-12 of
:math:`\|T\|` keeps its digits.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from ..errors import OptionError
from ..linalg.gramians import cached_gramian_factors
from ..utils import blas_threads
from ._common import adi_options, check_fom, infinite, validate_rom
from ._fom import FomResponse
from ._hinf_dense import error_realization, hidden_realization
from ._rom import RomResponse
from .h2 import breakpoints

__all__ = ["hinf_norm", "hinf_error", "hinf_rel_error"]

EPS = np.finfo(float).eps
#: largest hidden-manifold dimension n1 - n2 given the dense level-set test by default (docs/design/norms.md)
CERTIFY_DIM = 300


def _check(max_lus, rtol, per_decade, certify_dim=0, certify_tol=0.5, certify_lus=4):
    if isinstance(certify_dim, bool) or not isinstance(certify_dim, (int, np.integer)) or certify_dim < 0:
        raise OptionError(f"certify_dim must be a non-negative integer; got {certify_dim!r}")
    if not (isinstance(certify_tol, (float, int)) and 0 < certify_tol < 1):
        raise OptionError(f"certify_tol must be a float in (0, 1); got {certify_tol!r}")
    if isinstance(certify_lus, bool) or not isinstance(certify_lus, (int, np.integer)) or certify_lus < 4:
        raise OptionError(f"certify_lus must be an integer >= 4; got {certify_lus!r}")
    if isinstance(max_lus, bool) or not isinstance(max_lus, (int, np.integer)) or max_lus < 4:
        raise OptionError(f"max_lus must be an integer >= 4; got {max_lus!r}")
    if not (isinstance(rtol, (float, int)) and 0 < rtol < 1):
        raise OptionError(f"rtol must be a float in (0, 1); got {rtol!r}")
    if isinstance(per_decade, bool) or not isinstance(per_decade, (int, np.integer)) or per_decade < 1:
        raise OptionError(f"per_decade must be a positive integer; got {per_decade!r}")


class _Sigma:
    """sigma_max(T(jw) - Tr(jw)) and its derivative, one LU per frequency, all samples kept."""

    def __init__(self, fom, rr, refine, rtol):
        self.ev = FomResponse(fom, refine=refine)
        self.rr = rr
        self.rtol = rtol
        self.samples = {}
        #: the largest ||T(jw)||_F sampled: the scale of the cancellation in T - T_r
        self.scale = 0.0

    def __call__(self, w):
        w = float(w)
        if w in self.samples:
            return self.samples[w]
        s = 1j * w
        if self.rr is None:
            T, dT = self.ev.transfer_and_derivative(s, need=lambda T0: False)
        else:
            Tr = self.rr.transfer(s)
            # refine only where the unrefined difference would lose more than rtol / 100 (16 eps |T| / |E|)
            need = lambda T0: bool(16.0 * EPS * np.linalg.norm(T0) > 0.01 * self.rtol * np.linalg.norm(T0 - Tr))  # noqa: E731
            T, dT = self.ev.transfer_and_derivative(s, need=need)
            self.scale = max(self.scale, float(np.linalg.norm(np.asarray(T, dtype=complex))))
            T = T - Tr
            dT = dT - self.rr.derivative(s)
        E = np.asarray(T, dtype=complex)
        if self.rr is None:
            self.scale = max(self.scale, float(np.linalg.norm(E)))
        U, sv, Vh = np.linalg.svd(E)
        u, v = U[:, 0], Vh[0].conj()
        ds = float(np.real(u.conj() @ (1j * dT) @ v)) if w > 0 else 0.0
        self.samples[w] = (float(sv[0]), ds)
        return self.samples[w]


def _grid(fom, rom_poles, ritz, per_decade, budget):
    """Start frequencies: 0, resonances of the reduced model and of the model, a log grid."""
    own = np.abs(np.asarray(rom_poles, dtype=complex).imag)
    own = np.unique(own[own > 0])
    model = breakpoints(ritz) if ritz is not None and ritz.size else np.zeros(0)
    lo, hi = fom.band
    freqs = np.concatenate([own, model])
    if freqs.size:
        lo, hi = min(lo, freqs.min() / 10.0), max(hi, freqs.max() * 10.0)
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
    return pts, {"rom_resonances": int(own.size), "model_resonances": int(model.size), "log_grid": int(logs.size)}


def _refine(sig, lo, c, hi, rtol, budget):
    r"""Maximise sig on [lo, hi] around the sample c (secant on the derivative, bisection safeguard).

    Stops when the gain still predicted by the local quadratic model,
    :math:`\sigma'(x)^2 / (2|\sigma''|)` with :math:`\sigma''` from the last two
    derivatives, is below ``rtol`` times the best value, when the bracket has
    shrunk to rounding, or when ``budget`` LUs are spent.
    """
    fl, dl = sig(lo)
    fc, dc = sig(c)
    fh, dh = sig(hi)
    best = (fc, c)
    used = 0
    if dc > 0:  # the maximum next to c is on the side its derivative points to
        a, fa, da, b, fb, db = c, fc, dc, hi, fh, dh
    else:
        a, fa, da, b, fb, db = lo, fl, dl, c, fc, dc
    prev = (c, dc)
    history = []
    while used < budget and b - a > 1e-13 * abs(b):
        if da > 0 > db:
            x = a + (b - a) * da / (da - db)  # secant root of the derivative
            if not (a + 0.01 * (b - a) < x < b - 0.01 * (b - a)):
                x = 0.5 * (a + b)
        else:
            x = 0.5 * (a + b)
        fx, dx = sig(x)
        used += 1
        history.append((x, fx, dx))
        if fx > best[0]:
            best = (fx, x)
        curv = (dx - prev[1]) / (x - prev[0]) if x != prev[0] else 0.0
        prev = (x, dx)
        if da > 0 > db:
            if dx > 0:
                a, fa, da = x, fx, dx
            else:
                b, fb, db = x, fx, dx
        elif fa >= fb:  # no sign change: keep the half that holds the larger end value
            b, fb, db = x, fx, dx
        else:
            a, fa, da = x, fx, dx
        if curv < 0 and fx >= best[0] and dx * dx / (2.0 * -curv) <= rtol * fx:
            break
    return best, used, history


def _search(fom, rr, rom_poles, feed, *, max_lus, grid_lus, rtol, per_decade, refine, n_peaks, adi):
    gf = cached_gramian_factors(fom, **adi)
    ritz = np.asarray(gf.controllability.shifts) if gf is not None else None
    sig = _Sigma(fom, rr, refine, rtol)
    pts, how = _grid(fom, rom_poles, ritz, per_decade, min(grid_lus, max_lus - 1))
    for w in pts:
        sig(w)
    ws = np.array(sorted(sig.samples))
    fs = np.array([sig.samples[w][0] for w in ws])
    # local maxima of the samples (the ends count), best first
    is_max = np.ones(ws.size, dtype=bool)
    is_max[1:] &= fs[1:] >= fs[:-1]
    is_max[:-1] &= fs[:-1] >= fs[1:]
    cands = np.flatnonzero(is_max)
    cands = cands[np.argsort(-fs[cands])][:n_peaks]
    best = (float(fs.max()), float(ws[np.argmax(fs)]))
    refinements = []
    for i in cands:
        left = max(max_lus - sig.ev.lu_count, 0)
        if left == 0:
            break
        if i == ws.size - 1:
            continue  # the largest grid frequency: the response decays beyond it
        if i == 0 and ws[0] == 0.0 and sig.samples[ws[1]][1] <= 0:
            continue  # a maximum at w = 0 (sigma is even in w)
        lo, hi = ws[max(i - 1, 0)], ws[i + 1]
        (fv, wv), used, hist = _refine(sig, lo, ws[i], hi, rtol, left)
        refinements.append({"start": float(ws[i]), "peak": float(wv), "value": fv, "lus": used})
        if fv > best[0]:
            best = (fv, float(wv))
    value, w_peak = best
    if feed is not None and feed > value:
        value, w_peak = float(feed), np.inf
    rec = {"peak_frequency": w_peak, "lu_count": sig.ev.lu_count, "lu_shifts": list(sig.ev.shifts),
           "samples": len(sig.samples),
           "grid": how, "grid_size": int(pts.size), "model_resonances_from": "cached LR-ADI shifts" if gf else None,
           "refinements": refinements}
    return float(value), rec, sig


#: the dense level-set test's resolution: the certified gap is at least RESOLUTION * eps * ||T|| / peak
RESOLUTION = 1e3


def _climb(sig, w, h, rtol, budget):
    """The local maximum of sigma on the hump that holds ``w``: march uphill in steps h, 2h, 4h, ..., then refine.

    Returns ``(value, frequency, lus, complete)``; ``complete`` is False when the budget ran out
    before the maximum was bracketed and refined.
    """
    lu0 = sig.ev.lu_count
    fa, da = sig(w)
    a, step = w, h
    direction = 1.0 if (da >= 0 or w == 0) else -1.0
    b, fb, complete = a, fa, False
    while sig.ev.lu_count - lu0 < budget - 2:
        b = max(a + direction * step, 0.0)
        fb, db = sig(b)
        if direction * db <= 0 or fb < fa or b == 0.0:
            complete = True
            break
        a, fa = b, fb
        step *= 2.0
    best = max((fa, a), (fb, b))
    lo, hi = min(a, b), max(a, b)
    left = budget - (sig.ev.lu_count - lu0)
    if complete and hi > lo:
        (fv, wv), used, _ = _refine(sig, lo, 0.5 * (lo + hi), hi, rtol, left - 1)
        complete = used < left - 1
        best = max(best, (fv, wv))
    return best[0], best[1], sig.ev.lu_count - lu0, complete


def _certify(sig, realization, value, w_peak, *, tol, rounds, lus, rtol):
    r"""Upper bound by the level-set test at :math:`\gamma = (1 + tol)\,\text{peak}`; missed peaks refined.

    Returns ``(value, w_peak, upper_bound or None, certified, record)``.
    """
    from ..linalg.levelset import level_set

    t0, lu0 = time.perf_counter(), sig.ev.lu_count
    A, B, C, D = realization()
    t_real = time.perf_counter() - t0
    scale = max(sig.scale, value)
    tol = max(tol, RESOLUTION * EPS * scale / value) if value > 0 else tol
    rec = {"method": "level set (Hamiltonian of the dense error system on the hidden manifold)",
           "order": 2 * A.shape[0], "tol": tol, "realization_s": t_real, "rounds": [], "reason": None}
    upper, certified = None, False
    for rnd in range(rounds + 1):
        gamma = (1.0 + tol) * value
        if not gamma > 0:
            rec["reason"] = "the error is zero to rounding: no level to test"
            break
        ls = level_set(A, B, C, D, gamma)
        entry = {"gamma": gamma, "candidates": ls.frequencies.tolist(), "closest": ls.closest, "climbs": []}
        rec["rounds"].append(entry)
        if not ls.crossed:
            upper, certified = gamma, True
            break
        if rnd == rounds:
            rec["reason"] = f"imaginary eigenvalues remained after {rounds} rounds"
            break
        # Boyd-Balakrishnan: sigma exceeds gamma between crossings; probe them and their midpoints
        ws = ls.frequencies
        probe = np.unique(np.concatenate([ws, 0.5 * (ws[1:] + ws[:-1])]))
        if probe.size + 4 > lus - (sig.ev.lu_count - lu0):
            rec["reason"] = f"LU budget certify_lus = {lus} too small for {ws.size} candidates"
            break
        vals = np.array([sig(w)[0] for w in probe])
        i = int(np.argmax(vals))
        if vals[i] >= gamma:
            h = 0.25 * float(np.min(np.abs(np.delete(probe, i) - probe[i]))) if probe.size > 1 else 1e-4 * probe[i]
            fv, wv, used, _ = _climb(sig, float(probe[i]), max(h, 1e-12 * probe[i]), rtol,
                                     max(lus - (sig.ev.lu_count - lu0), 4))
            entry["climbs"].append({"candidate": float(probe[i]), "peak": wv, "value": fv, "lus": used,
                                    "complete": True})
            value, w_peak = max((value, w_peak), (fv, wv))
            continue  # a peak the search missed: test again above it
        improved, dismissed = False, 0
        for w, re in zip(ls.frequencies, ls.real_parts):
            left = lus - (sig.ev.lu_count - lu0)
            if left < 4:
                break
            h = max(4.0 * re, 1e-4 * w, 1e-8 * ls.threshold)
            fv, wv, used, complete = _climb(sig, float(w), h, rtol, left)
            entry["climbs"].append({"candidate": float(w), "peak": wv, "value": fv, "lus": used,
                                    "complete": complete})
            if fv > value:
                value, w_peak = fv, wv
            if fv >= gamma:
                improved = True  # a peak the search missed: test again above it
            elif complete:
                dismissed += 1  # its hump peaks below gamma: an eigenvalue near the axis, not on it
        if improved:
            continue
        if dismissed == ls.frequencies.size:
            upper, certified = gamma, True
        else:
            rec["reason"] = f"LU budget certify_lus = {lus} spent on {dismissed} of {ls.frequencies.size} candidates"
        break
    rec.update(lu_count=sig.ev.lu_count - lu0, time_s=time.perf_counter() - t0)
    return value, w_peak, upper, certified, rec


def _certificate(fom, sig, realization, value, rec, *, certify_dim, certify_tol, certify_lus, rtol):
    """Add ``lower_bound``, ``upper_bound``, ``certified``, ``certificate`` to ``rec`` (and a better peak)."""
    k = fom.n1 - fom.n2
    if k > certify_dim or not np.isfinite(value):
        why = (f"n1 - n2 = {k} exceeds certify_dim = {certify_dim}: no dense level-set test" if k > certify_dim
               else "infinite value")
        rec.update(search_value=value, search_lu_count=rec["lu_count"], lower_bound=value, upper_bound=None,
                   certified=False, certificate={"reason": why})
        return value
    rec["search_value"], rec["search_lu_count"] = value, rec["lu_count"]
    value, w, upper, ok, cert = _certify(sig, realization, value, rec["peak_frequency"], tol=certify_tol, rounds=3,
                                         lus=certify_lus, rtol=rtol)
    rec.update(peak_frequency=w, lu_count=sig.ev.lu_count, lu_shifts=list(sig.ev.shifts), samples=len(sig.samples),
               lower_bound=value, upper_bound=upper, certified=ok, certificate=cert)
    return value


def hinf_norm(fom, *, max_lus: int = 190, grid_lus: int = 120, rtol: float = 1e-10, per_decade: int = 8,
              refine: int = 1, n_peaks: int = 8, adi=None, certify_dim: int = CERTIFY_DIM, certify_tol: float = 1e-6,
              certify_lus: int = 100, details: bool = False):
    r""":math:`\|T\|_{\mathcal H_\infty} = \sup_\omega \sigma_{\max}(T(j\omega))`, a lower bound exact at the peak found.

    See the module docstring for the search. The value is cached in
    ``fom.cache`` per options: relative errors of many reduced models pay for it once.

    Parameters
    ----------
    fom : Index3Model
    max_lus : int
        LU budget (one LU per sample; default 190).
    grid_lus : int
        Of which at most this many for the start grid (default 120).
    rtol : float
        Relative accuracy of a refined peak (default 1e-10).
    per_decade : int
        Log-grid density (default 8 a decade).
    refine : int
        Extended-precision refinement steps of each response.
    n_peaks : int
        Local maxima of the grid refined, best first (default 8).
    adi : dict, optional
        ADI options under which cached Gramian factors supply the model's resonances.
    details : bool
        Also return a dict (``peak_frequency``, ``lu_count``, ``samples``, ``refinements``, ...).

    Returns
    -------
    float, or (float, dict)
    """
    check_fom(fom)
    _check(max_lus, rtol, per_decade, certify_dim, certify_tol, certify_lus)
    adi = adi_options(adi)
    # the start grid depends on whether the model's resonances (cached Gramian factors) are there
    resonances = cached_gramian_factors(fom, **adi) is not None
    key = ("hinf_norm", max_lus, grid_lus, rtol, per_decade, refine, n_peaks, tuple(sorted(adi.items())),
           certify_dim, certify_tol, certify_lus, resonances)
    cache = getattr(fom, "cache", None)
    if cache is not None and key in cache:
        value, rec = cache[key]
        rec = {**rec, "cached": True, "lu_count": 0}
    else:
        t0 = time.perf_counter()
        with blas_threads(1):
            value, rec, sig = _search(fom, None, np.zeros(0), None, max_lus=max_lus, grid_lus=grid_lus, rtol=rtol,
                                      per_decade=per_decade, refine=refine, n_peaks=n_peaks, adi=adi)
            value = _certificate(fom, sig, lambda: hidden_realization(fom), value, rec, certify_dim=certify_dim,
                                 certify_tol=certify_tol, certify_lus=certify_lus, rtol=rtol)
        rec["time_s"] = time.perf_counter() - t0
        rec["cached"] = False
        if cache is not None:
            cache[key] = (value, rec)
    return (value, rec) if details else value


def hinf_error(fom, rom, *, max_lus: int = 190, grid_lus: int = 120, rtol: float = 1e-10, per_decade: int = 8,
               refine: int = 1, n_peaks: int = 8, adi=None, certify_dim: int = CERTIFY_DIM, certify_tol: float = 1e-6,
               certify_lus: int = 100, details: bool = False):
    r""":math:`\|T - T_r\|_{\mathcal H_\infty}`: a lower bound, exact (to ``rtol``) at the peak it found.

    The peak of :math:`\sigma_{\max}(T(j\omega) - T_r(j\omega))` over the whole
    axis :math:`\omega \in [0, \infty]` (module docstring): a start grid at the
    reduced model's and the model's resonances and on a log grid, then the
    best local maxima refined with the derivative from the singular vectors.
    Cost: at most ``max_lus`` sparse LUs (default 190), each with one plain and one
    transposed solve.

    Parameters
    ----------
    fom : Index3Model
    rom : SecondOrderROM or FirstOrderROM
    max_lus, grid_lus, rtol, per_decade, refine, n_peaks, adi, details
        As in :func:`hinf_norm`.

    Returns
    -------
    float, or (float, dict)
        ``inf`` with a :class:`StabilityWarning` for an unstable reduced model.

    Raises
    ------
    ShapeError
        ``rom`` has other input or output dimensions than ``fom``.
    InputError
        ``rom`` has non-finite matrices or a singular E.
    """
    _check(max_lus, rtol, per_decade, certify_dim, certify_tol, certify_lus)
    adi = adi_options(adi)
    arrays, why = validate_rom(fom, rom, "rom")
    if why is not None:
        out = infinite(*why, details)
        if details:
            out[1].update(lower_bound=np.inf, upper_bound=np.inf, certified=True)
        return out
    t0 = time.perf_counter()
    rr = RomResponse(*arrays, refine=refine)
    feed = float(np.linalg.norm(arrays[4], 2)) if np.any(arrays[4] != 0) else None
    with blas_threads(1):
        value, rec, sig = _search(fom, rr, rom.poles(), feed, max_lus=max_lus, grid_lus=grid_lus, rtol=rtol,
                                  per_decade=per_decade, refine=refine, n_peaks=n_peaks, adi=adi)
        value = _certificate(fom, sig, lambda: error_realization(fom, arrays), value, rec, certify_dim=certify_dim,
                             certify_tol=certify_tol, certify_lus=certify_lus, rtol=rtol)
    rec["time_s"] = time.perf_counter() - t0
    rec["value"] = value
    return (value, rec) if details else value


def hinf_rel_error(fom, rom, *, details: bool = False, **options):
    r""":math:`\|T - T_r\|_{\mathcal H_\infty} / \|T\|_{\mathcal H_\infty}` (both by
    :func:`hinf_error` / :func:`hinf_norm` with ``options``; lower bounds over a lower bound)."""
    e, d = hinf_error(fom, rom, details=True, **options)
    n, dn = hinf_norm(fom, details=True, **options)
    value = e / n if np.isfinite(e) else np.inf
    if not details:
        return value
    return value, {**d, "norm": n, "norm_details": dn, "rel_value": value}
