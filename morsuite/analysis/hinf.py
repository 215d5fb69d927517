r"""H-infinity norms of the full model and of a reduced model's error: refined peak search, certified bounds.

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
       ``grid_lus`` LUs, the model's resonances thinned first. With
       ``screen`` (and ``band_grid``, ``skip_factor``), the resonances are
       sampled after the other points, and only where a surrogate of the
       error between their sampled neighbours, raised by 25%, reaches the
       best sample (:mod:`morsuite.analysis._hinf_screen`).
    2. Each sample costs one sparse LU and gives :math:`\sigma_{\max}` and its
       derivative from the singular vectors,

       .. math::

           \frac{d\sigma}{d\omega} = \mathrm{Re}\bigl(u^H\,j\,(T'(j\omega) - T_r'(j\omega))\,v\bigr),

       :math:`T'` from the same LU (one transposed solve).
    3. The local maxima of the grid, best first, are refined by a safeguarded
       secant iteration on :math:`d\sigma/d\omega = 0` inside the bracket of
       their grid neighbours (bisection when the secant step leaves the
       bracket or the derivative has no sign change; the bracket keeps the
       best sample at an end), until the gain the local quadratic model
       still predicts is below ``rtol`` relative, or the LU budget
       ``max_lus`` is spent. Maxima other than the best whose sample is below
       :math:`10^3\varepsilon\|T\|` (rounding, not peaks) are not refined.
       Also :math:`\|D\|` at :math:`\omega = \infty`.
    4. The best sample is checked to be a local maximum to ``rtol`` (the gain
       :math:`\sigma'^2 / (2|\sigma''|)` the quadratic model through it and its
       nearest sample predicts, :func:`~morsuite.analysis._hinf_certify.peak_check`)
       and refined where not (at most
       :data:`~morsuite.analysis._hinf_certify.POLISH_LUS` LUs beyond ``max_lus``);
       ``details["peak_check"]`` records the check.

The search's result is a lower bound of the H-infinity norm, a local maximum of
:math:`\sigma_{\max}` (to ``rtol``) at the peak it found; a peak between grid
points that no pole announces can be missed.

Certificate
    Where the hidden manifold is small, :math:`n_1 - n_2 \le` ``certify_dim``
    (default 1000):

    5. A dense standard realization of the error system on the hidden manifold
       (:mod:`morsuite.analysis._hinf_dense`: an orthonormal basis of
       :math:`\ker G`, the reduced model stacked; from 150 positions the model's
       modes with a negligible bounded contribution dropped, where the modal
       form's own rounding, bounded a posteriori from its residuals, fits
       the budget) and the level-set test
       (:func:`morsuite.linalg.levelset.level_set`) at
       :math:`\gamma - \Delta`, :math:`\gamma = (1 + \tau)\,\text{peak}`,
       :math:`\tau = \max(c,\ 10^3\varepsilon\|T\|/\text{peak},\ 2\Delta/\text{peak})`,
       :math:`c` = ``certify_tol`` (the second term: the double-precision realization
       of :math:`T - T_r` cancels :math:`\|T\|` to the peak's size). :math:`\Delta`
       counts every deviation of the dense realization from the model: the dropped
       modes and the modal form's rounding (bounds), and the realization's own rounding,
       an allowance :math:`\max(300\varepsilon\|T\|, 10 m)`, :math:`m` its largest
       deviation from the model's refined samples at the peak and at the samples of
       largest :math:`\|T\|` and error (measured:
       :func:`~morsuite.analysis._hinf_certify.verify`). No eigenvalue of the
       Hamiltonian on (or within :math:`\sqrt\varepsilon\|H\|` of) the
       imaginary axis: :math:`\gamma` is a certified upper bound.
    6. Otherwise the frequencies of those eigenvalues and their midpoints are
       sampled (Boyd-Balakrishnan-Bruinsma-Steinbuch); a sample above
       :math:`\gamma` is a missed peak: it is refined (steps 2-3), and the test
       repeated above it (at most 3 rounds). An eigenvalue near the axis whose
       hump of :math:`\sigma_{\max}` (climbed and refined from its frequency)
       peaks below :math:`\gamma - 2\Delta` is not a crossing (rounding near a local
       maximum just below :math:`\gamma`, or near a lightly damped pole): when
       every one is explained so, :math:`\gamma` is certified. At most
       ``certify_lus`` further LUs.

``details``: ``lower_bound`` (the value returned), ``upper_bound`` (None where
not computed), ``certified``, ``certificate`` (the record of the test: order,
:math:`\tau`, ``delta`` (:math:`\Delta` and its parts), ``verified`` (the
frequencies compared and the deviation measured), ``truncation`` (the modal
form: kept order, bounds, :math:`\kappa_1(V)`), the rounds with their candidate
frequencies and climbs, LUs, time, or why there is none), ``search_value`` and
``search_lu_count`` (the search alone), ``peak_check`` (step 4), the peak
frequency, the LUs, the samples and the refinement record of each candidate. The level-set test is one dense eigenvalue problem of
order :math:`2(2(n_1 - n_2) + r)` a round, :math:`O((n_1 - n_2)^3)`; its measured
cost, the threshold and the measured gaps: ``docs/design/norms.md``.

Responses are refined in extended precision and subtracted in long double
(:class:`~morsuite.norms._fom.FomResponse`), so that an error of 1e-12 of
:math:`\|T\|` keeps its digits.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from ..errors import OptionError
from ..linalg.gramians import cached_gramian_factors
from ..utils import blas_threads
from ..norms._common import adi_options, check_fom, flexible_route, infinite, refuse_rigid, validate_rom
from ..norms._fom import FomResponse
from ._hinf_certify import BAR_MARGIN, POLISH_LUS, RESOLUTION, certificate as _certificate, polish as _polish, \
    refine_peak as _refine
from ._hinf_grid import start_grid as _grid
from ._hinf_screen import model_poles, predicted_peak, screen as screen_resonances
from ._hinf_dense import error_realization, hidden_realization, realization_response
from ..norms._rom import RomResponse

__all__ = ["hinf_norm", "hinf_error", "hinf_rel_error"]

EPS = np.finfo(float).eps
#: largest hidden-manifold dimension n1 - n2 given the dense level-set test by default (docs/design/norms.md)
CERTIFY_DIM = 1000


def _band_grid(band_grid):
    """``band_grid`` checked: None, or ``(lo, hi, n)`` with 0 < lo < hi finite and an integer n >= 2."""
    if band_grid is None:
        return None
    try:
        lo, hi, n = band_grid
        ok = (0 < float(lo) < float(hi) < np.inf and not isinstance(n, bool)
              and isinstance(n, (int, np.integer)) and n >= 2)
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise OptionError(f"band_grid must be None or (lo, hi, n) with 0 < lo < hi and an integer n >= 2; "
                          f"got {band_grid!r}")
    return (float(lo), float(hi), int(n))


def _check(max_lus, rtol, per_decade, certify_dim=0, certify_tol=0.5, certify_lus=4, skip_factor=0.0, screen=False):
    if not isinstance(screen, (bool, np.bool_)):
        raise OptionError(f"screen must be True or False; got {screen!r}")
    if not (isinstance(skip_factor, (float, int)) and not isinstance(skip_factor, bool) and 0 <= skip_factor < 1):
        raise OptionError(f"skip_factor must be a number in [0, 1); got {skip_factor!r}")
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
        # the model's memo: the start grids of a model's reduced models share most frequencies
        self.ev = FomResponse(fom, refine=refine, memo=True)
        self.rr = rr
        self.rtol = rtol
        self.samples = {}
        #: the full model's (T, T') per sampled frequency (the screening's surrogate, option ``screen``)
        self.full = {}
        #: frequencies evaluated (one LU each without the model's memo): the budgets count these, so
        #: that a search does not depend on what the memo holds
        self.calls = 0
        #: the largest ||T(jw)||_F sampled: the scale of the cancellation in T - T_r
        self.scale = 0.0
        #: per sample, T - T_r from the refined solves (the certificate checks its realization against them)
        self.reference = {}
        #: per sample, ||T(jw)||_F
        self.gain = {}

    def __call__(self, w):
        w = float(w)
        if w in self.samples:
            return self.samples[w]
        s = 1j * w
        self.calls += 1
        # always refined and kept: the entry then serves every search and the band response alike
        T0, Tx, dT = self.ev.sample(s)
        self.full[w] = (T0, dT)
        best = T0 if Tx is None else Tx
        self.gain[w] = float(np.linalg.norm(np.asarray(best, dtype=complex)))
        self.scale = max(self.scale, self.gain[w])
        if self.rr is None:
            T = T0
            self.reference[w] = np.asarray(best, dtype=complex)
        else:
            Tr = self.rr.transfer(s)
            # refined only where the unrefined difference would lose more than rtol / 100 (16 eps |T| / |E|)
            need = bool(16.0 * EPS * np.linalg.norm(T0) > 0.01 * self.rtol * np.linalg.norm(T0 - Tr))
            T = Tx if need and Tx is not None else T0
            self.reference[w] = np.asarray(best - Tr, dtype=complex)
            T = T - Tr
            dT = dT - self.rr.derivative(s)
        E = np.asarray(T, dtype=complex)
        U, sv, Vh = np.linalg.svd(E)
        u, v = U[:, 0], Vh[0].conj()
        ds = float(np.real(u.conj() @ (1j * dT) @ v)) if w > 0 else 0.0
        self.samples[w] = (float(sv[0]), ds)
        return self.samples[w]


def _search(fom, rr, rom_poles, feed, *, max_lus, grid_lus, rtol, per_decade, refine, n_peaks, adi,
            band_grid=None, skip_factor=0.0, screen=False):
    gf = cached_gramian_factors(fom, **adi)
    ritz = np.asarray(gf.controllability.shifts) if gf is not None else None
    sig = _Sigma(fom, rr, refine, rtol)
    pts, how, optional = _grid(fom, rom_poles, ritz, per_decade, min(grid_lus, max_lus - 1), band_grid)
    screened = None
    if not (screen and skip_factor > 0 and optional.any()):
        optional[:] = False
    for w in pts[~optional]:
        sig(w)
    # the band grid's samples are the band response's (one memo): the budgets count the others
    sig.calls -= how.get("band_grid", 0)
    if optional.any():  # the resonances whose surrogate may reach the bar (module _hinf_screen)
        poles = model_poles(ritz)
        screened = screen_resonances(sig, pts[optional], poles, rr, BAR_MARGIN,
                                     max(min(grid_lus, max_lus - 1) - sig.calls, 0))
    ws = np.array(sorted(sig.samples))
    fs = np.array([sig.samples[w][0] for w in ws])
    # local maxima of the samples (the ends count), best first
    is_max = np.ones(ws.size, dtype=bool)
    is_max[1:] &= fs[1:] >= fs[:-1]
    is_max[:-1] &= fs[:-1] >= fs[1:]
    cands = np.flatnonzero(is_max)
    cands = cands[np.argsort(-fs[cands])][:n_peaks]
    est = np.array([_resonance_peak(ws, fs, i) for i in cands])
    if screened is not None:  # no finite isolated-resonance estimate: the surrogate's, where it has one
        est = np.array([e if np.isfinite(e) or not 0 < i < ws.size - 1 else
                        max(predicted_peak(0.5 * (ws[i - 1] + ws[i]), ws, sig.full, poles, rr),
                            predicted_peak(0.5 * (ws[i] + ws[i + 1]), ws, sig.full, poles, rr))
                        for i, e in zip(cands, est)])
    if skip_factor > 0:  # the most promising first: the others then meet a higher bar
        cands, est = cands[np.argsort(-est, kind="stable")], est[np.argsort(-est, kind="stable")]
    best = (float(fs.max()), float(ws[np.argmax(fs)]))
    refinements, skipped = [], []
    for i, e in zip(cands, est):
        left = max(max_lus - sig.calls, 0)
        if left == 0:
            break
        if e < skip_factor * best[0]:
            skipped.append({"start": float(ws[i]), "estimate": float(e)})
            continue
        if fs[i] < best[0] and fs[i] < RESOLUTION * EPS * sig.scale:
            # a maximum at the samples' rounding level (below the certificate's resolution): noise, not a peak
            skipped.append({"start": float(ws[i]), "value": float(fs[i]), "reason": "rounding level"})
            continue
        if i == ws.size - 1:
            continue  # the largest grid frequency: the response decays beyond it
        if i == 0 and ws[0] == 0.0 and sig.samples[ws[1]][1] <= 0:
            continue  # a maximum at w = 0 (sigma is even in w)
        lo, hi = ws[max(i - 1, 0)], ws[i + 1]
        # with skip_factor, a maximum after the first is refined only while it may still beat the best
        bar = best[0] if skip_factor > 0 and refinements else None
        (fv, wv), used, hist = _refine(sig, lo, ws[i], hi, rtol, left, bar)
        refinements.append({"start": float(ws[i]), "peak": float(wv), "value": fv, "lus": used})
        if fv > best[0]:
            best = (fv, float(wv))
    # the best sample refined to a local maximum where the refinements left it short (budget, rounding)
    best, check = _polish(sig, best[1], rtol, POLISH_LUS)
    value, w_peak = best
    if feed is not None and feed > value:
        value, w_peak = float(feed), np.inf
    rec = {"peak_frequency": w_peak, "lu_count": sig.ev.lu_count, "lu_shifts": list(sig.ev.shifts),
           "samples": len(sig.samples),
           "grid": how, "grid_size": int(pts.size), "model_resonances_from": "cached LR-ADI shifts" if gf else None,
           "refinements": refinements, "skipped": skipped, "screened": screened, "peak_check": check}
    return float(value), rec, sig


def _resonance_peak(ws, fs, i) -> float:
    r"""Estimated peak of the local maximum ``fs[i]`` of the samples: the isolated resonance
    :math:`\sigma(\omega)^{-2} = a(\omega - \omega_0)^2 + b` through it and its two neighbours (exact
    for one lightly damped pole, :math:`|
ho / (j\omega - \lambda)|`); ``inf`` at an end of the grid or
    where the model has no positive minimum of :math:`\sigma^{-2}` (no finite estimate)."""
    if i == 0 or i == ws.size - 1:
        return np.inf
    x, f = ws[i - 1:i + 2], fs[i - 1:i + 2]
    if np.any(f <= 0):
        return np.inf
    q = 1.0 / f ** 2
    c = x[1]
    h1, h2 = x[0] - c, x[2] - c
    # q(c + h) = q1 + B h + A h^2 through the three samples
    d1, d2 = (q[0] - q[1]) / h1, (q[2] - q[1]) / h2
    A = (d2 - d1) / (h2 - h1)
    B = d1 - A * h1
    if not A > 0:
        return np.inf
    qmin = q[1] - B * B / (4.0 * A)
    return float(1.0 / np.sqrt(qmin)) if qmin > 0 else np.inf


def hinf_norm(fom, *, max_lus: int = 190, grid_lus: int = 120, rtol: float = 1e-10, per_decade: int = 8,
              refine: int = 1, n_peaks: int = 8, adi=None, certify_dim: int = CERTIFY_DIM, certify_tol: float = 1e-6,
              certify_lus: int = 100, band_grid=None, skip_factor: float = 0.0, screen: bool = False,
               details: bool = False):
    r""":math:`\|T\|_{\mathcal H_\infty} = \sup_\omega \sigma_{\max}(T(j\omega))`: the peak found (a lower
    bound), with a certified upper bound where :math:`n_1 - n_2 \le` ``certify_dim``.

    See the module docstring for the search and the certificate. The value is
    cached in ``fom.cache`` per options and per whether the model's resonances
    (cached Gramian factors) were available: relative errors of many reduced
    models pay for it once.

    Parameters
    ----------
    fom : Index3Model
    max_lus : int
        LU budget (one LU per sample; default 190; the peak's local-maximum check may add up to 24).
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
    certify_dim : int
        Largest :math:`n_1 - n_2` given the dense level-set test (default 1000; 0: never).
    certify_tol : float
        Relative gap :math:`\tau` of the upper bound above the peak (default 1e-6; raised
        to the realization's resolution, module docstring).
    certify_lus : int
        LUs for the certificate's samples (default 100).
    band_grid : (float, float, int), optional
        ``(lo, hi, n)``: the frequencies of a band response of the model (``n`` log-spaced in
        [lo, hi], :func:`~morsuite.analysis.freq_grid`), sampled too and drawn from the model's memo of
        :math:`T(j\omega)` (:class:`~morsuite.norms._fom.FomResponse`) that the band response
        fills (``morsuite compare`` sets it to its band grid). They replace the log grid inside
        [lo, hi] (outside it, ``per_decade`` points a decade anchored at lo and hi, the same
        for every search) and are not counted in ``grid_lus`` and ``max_lus``, which count
        the other samples; default None: the log grid over the whole range.
    skip_factor : float
        In [0, 1): a local maximum of the start grid is refined only if its estimated peak
        reaches ``skip_factor`` times the best value found so far, the most promising first;
        the estimate is the isolated resonance :math:`\sigma^{-2} = a(\omega - \omega_0)^2 + b`
        through the maximum and its two neighbours (exact for one lightly damped pole;
        unbounded at the grid's ends). Default 0: each of the ``n_peaks`` best maxima is
        refined (``morsuite compare`` uses 0.5: refinements of maxima far below the peak
        are most of a search's LUs). The skipped ones are in ``details["skipped"]``.
    screen : bool
        With ``band_grid`` and ``skip_factor`` > 0: the resonance frequencies of the start grid (the
        reduced model's and the model's) are sampled only where the largest value of a surrogate of
        the error between their sampled neighbours, Hermite interpolation of :math:`T` and :math:`T'`
        with the model's poles in that interval (:mod:`morsuite.analysis._hinf_screen`), raised by
        the refinement's 25% margin, reaches the best sample: the bar under which a maximum is not
        refined; the base points (0, the band grid, the log grid) are sampled first. Default False
        (every resonance sampled; ``morsuite compare`` uses True: most resonances lie far below the
        peak and cost one LU each). The record is
        ``details["screened"]`` (candidates, sampled, the skipped ones with their predictions).
    details : bool
        Also return a dict (``lower_bound``, ``upper_bound``, ``certified``, ``certificate``,
        ``peak_frequency``, ``lu_count``, ``samples``, ``refinements``, ...).

    Returns
    -------
    float, or (float, dict)
        The largest peak found: a lower bound of the norm (``details["lower_bound"]``).
    """
    check_fom(fom)
    refuse_rigid(fom, "hinf_norm")
    _check(max_lus, rtol, per_decade, certify_dim, certify_tol, certify_lus, skip_factor, screen)
    band_grid = _band_grid(band_grid)
    adi = adi_options(adi)
    # the start grid depends on whether the model's resonances (cached Gramian factors) are there
    resonances = cached_gramian_factors(fom, **adi) is not None
    key = ("hinf_norm", max_lus, grid_lus, rtol, per_decade, refine, n_peaks, tuple(sorted(adi.items())),
           certify_dim, certify_tol, certify_lus, resonances, band_grid, skip_factor, bool(screen))
    cache = getattr(fom, "cache", None)
    if cache is not None and key in cache:
        value, rec = cache[key]
        rec = {**rec, "cached": True, "lu_count": 0}
    else:
        t0 = time.perf_counter()
        with blas_threads(1):
            value, rec, sig = _search(fom, None, np.zeros(0), None, max_lus=max_lus, grid_lus=grid_lus, rtol=rtol,
                                      per_decade=per_decade, refine=refine, n_peaks=n_peaks, adi=adi,
                                      band_grid=band_grid, skip_factor=skip_factor, screen=screen)
            value = _certificate(fom, sig, lambda b: hidden_realization(fom, b),
                                 lambda real, ws: realization_response(fom, real, ws), value, rec,
                                 certify_dim=certify_dim, certify_tol=certify_tol, certify_lus=certify_lus, rtol=rtol)
        rec["time_s"] = time.perf_counter() - t0
        rec["cached"] = False
        if cache is not None:
            cache[key] = (value, rec)
    return (value, rec) if details else value


def hinf_error(fom, rom, *, max_lus: int = 190, grid_lus: int = 120, rtol: float = 1e-10, per_decade: int = 8,
               refine: int = 1, n_peaks: int = 8, adi=None, certify_dim: int = CERTIFY_DIM, certify_tol: float = 1e-6,
               certify_lus: int = 100, band_grid=None, skip_factor: float = 0.0, screen: bool = False,
               details: bool = False):
    r""":math:`\|T - T_r\|_{\mathcal H_\infty}`: the peak found (a lower bound, exact to ``rtol`` at that
    peak), with a certified upper bound where :math:`n_1 - n_2 \le` ``certify_dim``.

    The peak of :math:`\sigma_{\max}(T(j\omega) - T_r(j\omega))` over the whole
    axis :math:`\omega \in [0, \infty]` (module docstring): a start grid at the
    reduced model's and the model's resonances and on a log grid, then the
    best local maxima refined with the derivative from the singular vectors;
    then, on a small hidden manifold, the level-set test of the dense error
    system at :math:`(1 + \tau)` times the peak, which certifies it as an upper
    bound or points to missed peaks. Cost: at most ``max_lus`` sparse LUs
    (default 190), each with one plain and one transposed solve; the certificate
    one dense eigenvalue problem of order :math:`2(2(n_1 - n_2) + r)` a round and
    at most ``certify_lus`` LUs.

    Parameters
    ----------
    fom : Index3Model
    rom : SecondOrderROM or FirstOrderROM
    max_lus, grid_lus, rtol, per_decade, refine, n_peaks, adi, certify_dim, certify_tol, certify_lus, band_grid,
    skip_factor, screen, details
        As in :func:`hinf_norm`.

    Returns
    -------
    float, or (float, dict)
        The largest peak found, a lower bound (``details``: ``lower_bound``,
        ``upper_bound``, ``certified``, always present; ``upper_bound`` None where
        no certificate was computed); ``inf`` with a :class:`StabilityWarning` for an
        unstable reduced model (then both bounds ``inf``). On a model with rigid-body
        modes, the peak of the flexible parts' difference (as :func:`~morsuite.analysis.h2_error`).

    Raises
    ------
    ShapeError
        ``rom`` has other input or output dimensions than ``fom``.
    InputError
        ``rom`` has non-finite matrices or a singular E.
    """
    _check(max_lus, rtol, per_decade, certify_dim, certify_tol, certify_lus, skip_factor, screen)
    band_grid = _band_grid(band_grid)
    adi = adi_options(adi)
    routed = flexible_route(fom, rom, hinf_error, details, max_lus=max_lus, grid_lus=grid_lus, rtol=rtol,
                            per_decade=per_decade, refine=refine, n_peaks=n_peaks, adi=adi, certify_dim=certify_dim,
                            certify_tol=certify_tol, certify_lus=certify_lus, band_grid=band_grid,
                            skip_factor=skip_factor, screen=screen)
    if routed is not None:  # rigid-body modes: T - T_r is the flexible parts' difference
        return routed
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
                                  per_decade=per_decade, refine=refine, n_peaks=n_peaks, adi=adi,
                                  band_grid=band_grid, skip_factor=skip_factor, screen=screen)
        value = _certificate(fom, sig, lambda b: error_realization(fom, arrays, b),
                             lambda real, ws: realization_response(fom, real, ws, arrays), value, rec,
                             certify_dim=certify_dim, certify_tol=certify_tol, certify_lus=certify_lus, rtol=rtol)
    rec["time_s"] = time.perf_counter() - t0
    rec["value"] = value
    return (value, rec) if details else value


def hinf_rel_error(fom, rom, *, details: bool = False, **options):
    r""":math:`\|T - T_r\|_{\mathcal H_\infty} / \|T\|_{\mathcal H_\infty}`: the ratio of the peaks found
    by :func:`hinf_error` and :func:`hinf_norm` (with ``options``), neither bound. Where both are
    certified, ``details`` has ``rel_lower_bound`` = error lower / norm upper and
    ``rel_upper_bound`` = error upper / norm lower, and ``certified`` is True."""
    e, d = hinf_error(fom, rom, details=True, **options)
    n, dn = hinf_norm(fom, details=True, **options)
    value = e / n if np.isfinite(e) else np.inf
    if not details:
        return value
    ok = bool(d.get("certified") and dn.get("certified"))
    lo = e / dn["upper_bound"] if ok else None
    up = d["upper_bound"] / n if ok else None
    return value, {**d, "norm": n, "norm_details": dn, "rel_value": value, "certified": ok,
                   "rel_lower_bound": lo, "rel_upper_bound": up}
