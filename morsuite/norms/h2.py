r"""Exact H2 norms of the full model and of the error of a reduced model.

For a stable, strictly proper, real :math:`H`,
:math:`\|H\|_{\mathcal H_2}^2 = \frac1{2\pi}\int_{-\infty}^\infty \|H(j\omega)\|_F^2\,d\omega
= \frac1\pi\int_0^\infty \|H(j\omega)\|_F^2\,d\omega`.

:func:`h2_norm`
    :math:`\|T\|_{\mathcal H_2}^2 = \mathrm{tr}(CPC^T) = \|LZ_p\|_F^2` from the
    controllability factor :math:`P \approx ZZ^T` of LR-ADI (shared with
    balanced truncation through the model's cache,
    :func:`~morsuite.linalg.gramians.gramian_factors`), plus the part the
    factor misses, :math:`\mathrm{tr}(W^TQW) \approx \|Y^TW\|_F^2`
    (:func:`~morsuite.linalg.gramians.h2_tail`; with it the value agrees with a
    dense Lyapunov solution to 1e-14 relative even at ADI tolerance 1e-6). The
    controllability solves are refined once in long double (``adi`` option
    ``refine``, default 1): unrefined solves at shifts next to lightly damped
    poles leave :math:`\|LZ_p\|_F^2` off by their forward error, 7.9e-12 relative
    on tcom(2000); refined, 8e-15, inside the floor, which includes the
    solves' estimated error (:func:`~morsuite.linalg.h2.norm_squared`).
:func:`h2_error`
    :math:`\|T - T_r\|_{\mathcal H_2}` by one of three routes, chosen by ``method``:

    ``"pole-residue"``
        :math:`\|T-T_r\|^2 = \|T\|^2 - 2\,\mathrm{Re}\langle T, T_r\rangle + \|T_r\|^2`
        with, for :math:`T_r(s) = \sum_k c_kb_k^T/(s-\lambda_k)` (simple poles;
        Gugercin, Antoulas, Beattie 2008),

        .. math::

            \langle T, T_r\rangle_{\mathcal H_2} = \sum_k c_k^T\,T(-\lambda_k)\,b_k,

        (no conjugates: :math:`\langle H, G\rangle = \frac1{2\pi}\int\mathrm{tr}(H^*G)`,
        residue theorem in the left half-plane), one saddle-point solve with
        :math:`Fb_k` at :math:`s = -\lambda_k` per pole, a conjugate pair
        sharing one LU (r LUs for a second-order model of order r), and
        :math:`\|T_r\|^2 = \sum_{k,l}(c_k^Tc_l)(b_l^Tb_k)/(-\lambda_k-\lambda_l)`
        from the same modal form, so that the rounding of that form enters
        both terms alike. The three terms are of size :math:`\|T\|^2` and
        cancel: the absolute error of :math:`\|T-T_r\|^2` is about
        :math:`\varepsilon(\|T\|^2 + 2\sum_k|t_k| + \sum_{kl}|u_{kl}|)` plus the
        Gramian's floor plus :math:`2\sum_k|t_k|u_k` (:math:`u_k` the estimated
        relative error of the solve at :math:`-\lambda_k`, refined ``refine``
        times: unrefined, a solve next to a lightly damped pole is off by
        :math:`\kappa\varepsilon`, which the cancellation amplified to a 12%
        error on tcom(2000)), so that relative accuracy is lost as
        :math:`(\|T\|/\|T-T_r\|)^2`.
    ``"quadrature"``
        :math:`\frac1\pi\int_0^\infty\|T(j\omega)-T_r(j\omega)\|_F^2\,d\omega` by
        adaptive Gauss-Kronrod quadrature on a mapped axis, cut at the
        reduced model's pole frequencies and at the model's Ritz frequencies
        (the LR-ADI shifts of cached Gramian factors), one sparse LU per node
        (:mod:`morsuite.analysis._quad`). :math:`T(j\omega)` and
        :math:`T_r(j\omega)` are refined with extended-precision residuals
        (:class:`~morsuite.analysis._fom.FomResponse`,
        :class:`~morsuite.analysis._rom.RomResponse`) and subtracted in long
        double, so the difference is accurate to double precision even where
        it is 1e-12 of :math:`T`. No cancellation; its cost is the node count.
    ``"error-gramian"``
        LR-ADI of the error system :math:`T - T_r` with the shifts of the
        model's cached factor (:mod:`morsuite.norms.error_gramian`):
        :math:`\|T-T_r\|^2 = \|LZ_p - C_rZ_r\|_F^2 + t_1 - 2t_2 + t_3`, the
        columns subtracted before they are squared, so that rounding enters
        with one power of :math:`\|T\|/\|T-T_r\|` instead of two. The tail's
        cross term :math:`t_2` is bounded by Cauchy-Schwarz (no LU) or computed
        from solves at the mirrored poles (the pole-residue route's LUs).
    ``"auto"`` (default)
        Escalates until ``rtol`` is met: the error-Gramian route with the bound
        (no LU); the solves at the mirrored poles, which give :math:`t_2` and
        the pole-residue value, a second and independent route; the quadrature
        when it fits ``max_nodes``. The value with the smallest floor is
        returned, and two routes that disagree beyond their floors make it
        untrusted.

Every value carries a floor (``details["floor"]``): an estimate of its error with a
margin, validated against long-double references, not a proved bound. Some terms are
bounds (a quadrature's resolved error, Cauchy-Schwarz on the tail cross term); others
are measured constants with a margin: the Gramian tail's error ``10 * tail *
residual``, the factor's rounding :math:`2\varepsilon\sqrt{\mathrm{rank}}`, the
unrefined solves' :data:`~morsuite.linalg.h2.UNREFINED_UNIT`. Every floor measured
against long-double quadratures (tcom and dsms models, random MIMO models:
``docs/design/norms.md``, ``tests/test_h2_floor.py``,
``tests/test_h2_floor_sharpness.py``) was above its error. ``trusted`` keeps its meaning: the value
is within its stated floor, and a value whose floor is worse than both ``TRUST_FACTOR * rtol`` and
``TRUST_REL`` (four significant digits) relative is flagged: an
:class:`~morsuite.errors.AccuracyWarning` and ``details["trusted"] = False``;
``details["rtol_met"]`` says whether ``rtol`` itself was reached. A quadrature
that stopped at its node budget still covers the whole axis (its breakpoints
are thinned to fit), says ``converged=False`` and keeps its error estimate as
its floor; a squared error that comes out negative is reported as 0 with
``negative=True`` and an infinite relative floor, never silently clipped. An unstable reduced model, or one with a
nonzero feedthrough, has an infinite error: ``inf`` with a warning
(:class:`~morsuite.errors.StabilityWarning`) and ``details["reason"]``.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from ..errors import AccuracyWarning, OptionError, StabilityWarning
from ..linalg.gramians import cached_gramian_factors
from ..linalg.h2 import UNREFINED_UNIT, norm_squared as _norm_squared
from ..utils import blas_threads
from ._common import adi_options, check_fom, flexible_route, infinite, refuse_rigid, validate_rom
from .error_gramian import error_gramian
from ._mirrored import mirrored_solves
from ._fom import FomResponse
from ._quad import integrate_half_axis
from ._rom import RomResponse

__all__ = ["h2_norm", "h2_error", "h2_rel_error", "METHODS"]

METHODS = ("auto", "error-gramian", "pole-residue", "quadrature")
LD = np.longdouble
CLD = np.clongdouble
EPS = np.finfo(float).eps
#: a value whose estimated relative accuracy is worse than TRUST_FACTOR * rtol and TRUST_REL is flagged
TRUST_FACTOR = 100.0
TRUST_REL = 1e-4
#: eigenvector condition number above which the pole-residue route is not used by "auto"
KAPPA_MAX = 1e8


def h2_norm(fom, *, adi=None, details: bool = False):
    r"""Exact :math:`\|T\|_{\mathcal H_2}` of the index-3 model from its Gramian factor.

    .. math::

        \|T\|_{\mathcal H_2}^2 = \mathrm{tr}(LP_{pp}L^T) = \|LZ_p\|_F^2 + \mathrm{tr}(W^TQW),

    :math:`Z_p` the position block of the LR-ADI controllability factor on
    the hidden manifold, the second term the ADI truncation estimated by
    :math:`\|Y^TW\|_F^2` (module docstring).

    Parameters
    ----------
    fom : Index3Model
    adi : dict, optional
        LR-ADI options (default those of ``bt``: tol 1e-12, projection shifts,
        :data:`~morsuite.linalg.gramians.ADI_DEFAULTS`); the factors are
        computed once per model and options and shared with ``bt``.
    details : bool
        Also return a dict: ``method``, ``lu_count`` (LUs made by this call:
        those of LR-ADI unless cached), ``floor`` (estimated absolute
        accuracy), ``rel_floor``, ``trusted``, the ADI record.

    Returns
    -------
    float, or (float, dict)

    Raises
    ------
    InputError
        For a model with rigid-body modes (a pole at 0: the norm is infinite); the
        message names the flexible part's norm.

    Notes
    -----
    Cost: one lock-step LR-ADI run for both Gramians (one LU per shift) on
    the first call per model and options, nothing afterwards.
    """
    check_fom(fom)
    refuse_rigid(fom, "h2_norm")
    with blas_threads(1):
        v2, floor2, rec, gf = _norm_squared(fom, adi_options(adi))
    value = float(np.sqrt(v2))
    rel = 0.5 * floor2 / v2 if v2 > 0 else np.inf
    trusted = bool(rel <= 1e-6)
    if not trusted:
        warnings.warn(f"h2_norm: LR-ADI did not converge (residuals {rec['adi_residuals']}); ||T||_H2 = "
                      f"{value:.6e} is accurate to about {rel:.1e} relative only", AccuracyWarning, stacklevel=2)
    if not details:
        return value
    return value, {**rec, "lu_count": rec["gramian_lu_count"], "floor": rel * value, "rel_floor": rel,
                   "trusted": trusted}


def resonances(lam) -> list:
    r"""The resonances of poles ``lam`` that stand apart: ``(omega_p, delta)`` per feature, by frequency.

    A pole :math:`\lambda = -\delta + j\omega_p` (:math:`\omega_p > \delta`) makes a peak of width
    about :math:`\delta` at :math:`\omega_p`; peaks closer than their widths form one feature,
    represented by its sharpest peak (the centres :func:`breakpoints` cuts at).
    """
    lam = np.asarray(lam, dtype=complex)
    lam = lam[np.isfinite(lam) & (lam.imag >= 0)]
    om, de = np.abs(lam.imag), np.abs(lam.real)
    keep = om > de
    order = np.argsort(om[keep])
    kept = []
    for w, d in zip(om[keep][order], de[keep][order]):
        if kept and w - kept[-1][0] <= max(d, kept[-1][1]):
            if d < kept[-1][1]:  # one cut per cluster, at its sharpest peak
                kept[-1] = (w, d)
            continue
        kept.append((w, d))
    return kept


def breakpoints(lam) -> np.ndarray:
    r"""Frequencies at which to cut the axis for poles ``lam``: resonances that stand apart.

    A pole :math:`\lambda = -\delta + j\omega_p` (:math:`\omega_p > \delta`) makes a
    peak of width about :math:`\delta` at :math:`\omega_p`. Peaks closer than their
    widths form one feature and get one cut, and further cuts at
    :math:`\omega_p \pm 4^k\delta` up to half-way to the next feature.
    """
    kept = resonances(lam)
    out = []
    for i, (w, d) in enumerate(kept):
        out.append(w)
        left = w - kept[i - 1][0] if i else w
        right = kept[i + 1][0] - w if i + 1 < len(kept) else np.inf
        # a sharp peak: cuts graded geometrically (ratio 4) away from it, up to half-way to the next one,
        # so that each piece sees the pole at a fixed relative distance (QK15 then converges to 1e-14
        # per piece) instead of bisecting down to its width
        step = d
        while step < 0.5 * left and w - step > 0:
            out.append(w - step)
            step *= 4.0
        step = d
        while step < 0.5 * min(right, 10.0 * w):
            out.append(w + step)
            step *= 4.0
    return np.asarray(out, dtype=float)


def quadrature_nodes_needed(rom_poles, ritz=None) -> int:
    """Rough node count of the quadrature: 15 per piece, about two pieces per separate resonance."""
    n = breakpoints(rom_poles).size + (breakpoints(ritz).size if ritz is not None and ritz.size else 0)
    return 15 * (4 + 2 * n)


def _quadrature(fom, arrays, rom, rtol, max_nodes, refine, ritz=None):
    """||T - Tr||^2 by adaptive quadrature of ||E(jw)||_F^2, its absolute floor, and a record."""
    E, A, B, C, D = arrays
    rr = RomResponse(E, A, B, C, D, refine=refine)
    ev = FomResponse(fom, refine=refine, memo=True)  # nodes recur across the model's ROMs
    lam = rom.poles()
    bp = breakpoints(lam)
    if ritz is not None and ritz.size:
        # the model's resonances, as many as leave half of the node budget to the adaptive refinement
        extra = breakpoints(ritz)
        room = max(0, max_nodes // 30 - bp.size)
        if extra.size > room:
            extra = extra[np.linspace(0, extra.size - 1, room).astype(int)] if room else extra[:0]
        bp = np.concatenate([bp, extra])
    mags = np.abs(np.concatenate([lam, ritz if ritz is not None else []]))
    mags = mags[mags > 0]
    w0 = float(np.exp(np.median(np.log(mags)))) if mags.size else float(np.sqrt(np.prod(fom.band)))

    def refine_here(T0, Trw):
        # the unrefined difference has relative error about 16 eps |T| / |E|: refine where that
        # would be more than a hundredth of rtol
        e = np.sqrt(np.sum(np.abs(T0 - Trw) ** 2))
        return bool(16.0 * EPS * np.sqrt(np.sum(np.abs(T0) ** 2)) > 0.01 * rtol * e)

    def f(w):
        s = 1j * w
        Trw = rr.transfer(s)
        Tw = ev.transfer(s, need=lambda T0: refine_here(T0, Trw))
        e2 = float(np.sum(np.abs(Tw - Trw) ** 2))  # the difference in long double
        # first-order rounding of |E|^2 when E is accurate to unit_T |T| + unit_r |Tr|
        size = (ev.last_unit * float(np.sqrt(np.sum(np.abs(Tw) ** 2)))
                + rr.last_unit * float(np.sqrt(np.sum(np.abs(Trw) ** 2))))
        return e2, 2.0 * np.sqrt(e2) * size

    res = integrate_half_axis(f, w0, bp, rtol=rtol, max_nodes=max_nodes)
    value2 = res.value / np.pi
    rounding = res.aux / np.pi
    rec = {"value": float(np.sqrt(max(value2, 0.0))), "squared": float(value2), "nodes": res.nodes,
           "pieces": res.pieces, "error_estimate_squared": res.error / np.pi, "rounding_squared": rounding,
           "converged": res.converged, "covered": res.covered, "lu_count": ev.lu_count, "lu_shifts": list(ev.shifts), "w0": w0,
           "breakpoints": int(bp.size)}
    return value2, res.error / np.pi + rounding, rec


def _rel(e2, floor2):
    """Relative accuracy of sqrt(e2) from the absolute floor of e2 (inf where e2 is not positive)."""
    if e2 is None or not np.isfinite(floor2):
        return np.inf
    if e2 <= 0:
        return np.inf
    # |sqrt(e2 +- f) - sqrt(e2)| <= f / (sqrt(e2) + sqrt(max(e2 - f, 0))) <= f / sqrt(e2)
    return float(min(floor2 / e2, floor2 / (np.sqrt(e2) * (np.sqrt(e2) + np.sqrt(max(e2 - floor2, 0.0))))))


def h2_error(fom, rom, *, method: str = "auto", rtol: float = 1e-8, max_nodes: int = 1500, refine: int = 1,
             adi=None, details: bool = False):
    r"""Exact :math:`\|T - T_r\|_{\mathcal H_2}` of a reduced model, with a floor that estimates its error.

    The one H2 evaluator of the suite: the studies, the CLI and the reducers'
    own choices (best iterate, never worse than the start) all call it.

    Parameters
    ----------
    fom : Index3Model
    rom : SecondOrderROM or FirstOrderROM
        Same numbers of inputs and outputs as ``fom``.
    method : {"auto", "error-gramian", "pole-residue", "quadrature"}
        Route (module docstring). ``"auto"`` (default) escalates: the error
        system's Gramian with the tail cross term bounded (no LU); then the
        solves at the reduced model's mirrored poles (one LU per pole pair),
        which give the tail cross term exactly and the pole-residue value as a
        second, independent route; then the quadrature when neither is within
        ``rtol`` and it fits the node budget. The value with the smallest floor
        is returned; two routes whose values differ by more than their floors
        together make the value untrusted.
    rtol : float in (0, 1)
        Relative accuracy asked for (default 1e-8): escalation stops once it is met.
    max_nodes : int
        Node budget of the quadrature (one sparse LU each, default 1500).
    refine : int
        Extended-precision refinement steps of each response (0: plain solves),
        of the quadrature's nodes and of the solves at the mirrored poles alike
        (default 1; no extra LU: a long-double product and a pair of triangular
        solves per step). With the error-Gramian route, a solve at a mirrored
        pole is refined only where its unrefined error could show in the tail
        cross term at ``rtol`` (:mod:`morsuite.norms._mirrored`).
    adi : dict, optional
        LR-ADI options of the Gramian factor (as in :func:`h2_norm`).
    details : bool
        Also return a dict: ``method`` (route used), ``lu_count`` (sparse LUs
        made by this call, LR-ADI included when it ran), ``lu_shifts`` (the
        shifts of the LUs of the routes, LR-ADI's not included), ``floor`` /
        ``rel_floor`` (the estimated absolute / relative error of the value,
        validated against long-double references: module docstring),
        ``trusted`` (the floor, the value's stated accuracy, is within
        ``max(TRUST_FACTOR * rtol, TRUST_REL)`` relative and no two routes disagree), ``rtol_met``, ``squared`` (the
        squared error as computed, before the square root), ``negative``
        (True when the computed square was negative: the value is then 0 and
        untrusted), ``nodes``, ``norm`` (:math:`\|T\|_{\mathcal H_2}`), and the
        records of the routes tried (``error_gramian``, ``pole_residue``,
        ``quadrature``; ``consistent``).

    Returns
    -------
    float, or (float, dict)
        ``inf`` (with a :class:`StabilityWarning`) for an unstable reduced
        model or one with a nonzero feedthrough ``D``. On a model with rigid-body
        modes (:mod:`morsuite.models.rigid`), the H2 norm of the difference of the
        flexible parts, which is :math:`T - T_r` when ``rom`` carries the model's
        rigid part as the reducers return it (``details``: ``rigid_modes``, ``part``);
        ``inf`` with a warning otherwise.

    Raises
    ------
    ShapeError
        ``rom`` has other input or output dimensions than ``fom``.
    InputError
        ``rom`` has non-finite matrices or a singular E; bad arguments.

    Notes
    -----
    Cost: the Gramian factors once per model (shared with ``bt``), then per
    reduced model dense work of order :math:`n_r^3 + k n_r pm` (:math:`k` the
    factor's columns, :math:`n_r` the reduced model's states) and no LU when the first
    route suffices; one LU per real pole or conjugate pair of the reduced model
    when the second runs; one LU per node (typically 100-1000) in the rare case
    the quadrature runs. Measured costs and floors: ``docs/design/norms.md``
    (1.4 to 1.5 times the bare LUs it makes on tcom(2000) at 10 to 30 states,
    2026-11-26).
    """
    if method not in METHODS:
        raise OptionError(f"method must be one of {', '.join(map(repr, METHODS))}; got {method!r}")
    if isinstance(rtol, bool) or not (isinstance(rtol, (float, int)) and 0 < rtol < 1):
        raise OptionError(f"rtol must be a float in (0, 1); got {rtol!r}")
    if isinstance(max_nodes, bool) or not isinstance(max_nodes, (int, np.integer)) or max_nodes < 15:
        raise OptionError(f"max_nodes must be an integer >= 15; got {max_nodes!r}")
    if isinstance(refine, bool) or not isinstance(refine, (int, np.integer)) or refine < 0:
        raise OptionError(f"refine must be an integer >= 0; got {refine!r}")
    adi = adi_options(adi)
    routed = flexible_route(fom, rom, h2_error, details, method=method, rtol=rtol, max_nodes=max_nodes,
                            refine=refine, adi=adi)
    if routed is not None:  # rigid-body modes: T - T_r is the flexible parts' difference
        return routed
    arrays, why = validate_rom(fom, rom, "rom")
    if why is not None:
        return infinite(*why, details)
    if np.any(arrays[4] != 0):
        return infinite("rom has a nonzero feedthrough D: T - Tr is not strictly proper and its H2 norm is "
                         "infinite", StabilityWarning, details)
    t0 = time.perf_counter()
    out = {"requested": method, "rtol": rtol}
    lus = 0
    cands = {}  # route -> (squared value, absolute floor of the square)
    with blas_threads(1):
        norm2 = gf = None
        if method != "quadrature":
            norm2, floor_n2, nrec, gf = _norm_squared(fom, adi)
            lus += nrec["gramian_lu_count"]
            out["norm"] = float(np.sqrt(norm2))
            out["gramian"] = nrec
        eg = None
        if method in ("auto", "error-gramian"):
            c = gf.controllability
            unit = c.solve_error if c.refine else UNREFINED_UNIT
            eg = error_gramian(fom, arrays, gf, nrec, unit)
            v, f = eg.squared()
            out["error_gramian"] = {"columns": eg.columns, "t1": eg.t1, "t3": eg.t3, "t2": None,
                                    "column_error": eg.column_error, "factor_rank": eg.rank,
                                    "squared": v, "floor_squared": f}
            cands["error-gramian"] = (v, f)
        need_solves = (method == "pole-residue" or
                       (method in ("auto", "error-gramian") and _rel(*cands["error-gramian"]) > rtol))
        if need_solves:
            # t2 needs refined solves only where an unrefined one's error would show at rtol
            budget = 0.01 * rtol * max(cands["error-gramian"][0], 0.0) if eg is not None else None
            e2, fl2, prec, tail = mirrored_solves(fom, arrays, rom, norm2, floor_n2, refine, eg, gf, budget)
            lus += prec["lu_count"]
            out["pole_residue"] = prec
            if e2 is not None:
                prec["rel_floor"] = _rel(e2, fl2)
                if method != "error-gramian" and prec["kappa"] <= KAPPA_MAX or method == "pole-residue":
                    cands["pole-residue"] = (e2, fl2)
            if tail is not None:
                v, f = eg.squared(*tail)
                out["error_gramian"].update({"t2": tail[0], "t2_error": tail[1], "squared": v, "floor_squared": f})
                cands["error-gramian"] = (v, f)
        best = min((_rel(*vf), name) for name, vf in cands.items()) if cands else (np.inf, None)
        if method == "quadrature" or (method == "auto" and best[0] > rtol):
            gfc = gf or cached_gramian_factors(fom, **adi)
            ritz = None if gfc is None else np.asarray(gfc.controllability.shifts)
            need = quadrature_nodes_needed(rom.poles(), ritz)
            if method == "auto" and need > max_nodes:
                out["quadrature"] = {"skipped": f"about {need} nodes needed (> max_nodes = {max_nodes})"}
            else:
                q2, qerr2, qrec = _quadrature(fom, arrays, rom, rtol, max_nodes, refine, ritz)
                lus += qrec["lu_count"]
                out["quadrature"] = qrec
                # an axis not covered has no error bound; a covered one that missed rtol keeps its estimate
                qf = qerr2 if qrec["covered"] else np.inf
                qrec["rel_floor"] = _rel(q2, qf)
                cands["quadrature"] = (q2, qf)
    # the value with the smallest floor; the others must agree with it within the two floors
    rel, route = min(((_rel(*vf), name) for name, vf in cands.items()), default=(np.inf, None))
    if route is None or not np.isfinite(cands[route][0]):
        rel, route = np.inf, next(iter(cands), method)
    e2, fl2 = cands.get(route, (np.nan, np.inf))
    consistent = True
    for name, (v2, f2) in cands.items():
        if name != route and np.isfinite(f2) and np.isfinite(v2) and abs(v2 - e2) > 1.5 * (f2 + fl2):
            consistent = False
            out.setdefault("disagree", []).append({"route": name, "squared": float(v2), "floor_squared": float(f2)})
    negative = bool(e2 < 0)
    value = float(np.sqrt(max(e2, 0.0))) if np.isfinite(e2) else float("nan")
    floor = rel * value if np.isfinite(rel) else np.inf
    if negative:
        rel = np.inf
        floor = float(np.sqrt(max(fl2, 0.0)))
    trusted = bool(consistent and not negative and rel <= max(TRUST_FACTOR * rtol, TRUST_REL))
    if not trusted:
        q = out.get("quadrature", {})
        why = ("; the computed squared error is negative (cancellation): the value 0 is a placeholder"
               if negative else "; two routes disagree beyond their floors" if not consistent else
               f"; the quadrature stopped at max_nodes = {max_nodes}" if q.get("converged") is False else
               "; the quadrature was skipped: " + q["skipped"] if "skipped" in q else "")
        warnings.warn(f"h2_error: the value {value:.6e} ({route}) is accurate to about {rel:.1e} relative only "
                      f"(rtol {rtol:g}){why}", AccuracyWarning, stacklevel=2)
    if not details:
        return value
    out["lu_shifts"] = out.get("pole_residue", {}).get("lu_shifts", []) + out.get("quadrature", {}).get("lu_shifts", [])
    out.update({"method": route, "value": value, "squared": float(e2), "negative": negative,
                "consistent": consistent, "lu_count": int(lus), "floor": float(floor), "rel_floor": float(rel),
                "trusted": trusted, "rtol_met": bool(rel <= rtol), "nodes": out.get("quadrature", {}).get("nodes", 0),
                "time_s": time.perf_counter() - t0})
    return value, out


def h2_rel_error(fom, rom, *, details: bool = False, **options):
    r""":math:`\|T - T_r\|_{\mathcal H_2} / \|T\|_{\mathcal H_2}` (options as :func:`h2_error`)."""
    e, d = h2_error(fom, rom, details=True, **options)
    n = d.get("norm")
    if n is None:
        n = h2_norm(fom, adi=options.get("adi"))
    value = e / n if np.isfinite(e) else np.inf
    if not details:
        return value
    return value, {**d, "norm": n, "rel_value": value}
