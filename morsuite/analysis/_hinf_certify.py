r"""The H-infinity search's refinement of a peak, and the certificate of its value (:mod:`morsuite.analysis.hinf`).

:func:`refine_peak` maximises :math:`\sigma_{\max}` on a bracket (secant on the derivative, bisection
safeguard); :func:`climb` finds the maximum of the hump that holds a frequency; :func:`certify`
runs the level-set test (:func:`morsuite.linalg.levelset.level_set`) on the dense error system
(:mod:`morsuite.analysis._hinf_dense`) at :math:`(1 + \tau)` times the peak, samples the
frequencies it reports, refines missed peaks and repeats; :func:`certificate` decides whether the
test is affordable (:math:`n_1 - n_2 \le` ``certify_dim``) and records the result. The
mathematics and the rules are in the module docstring of :mod:`morsuite.analysis.hinf`.
"""

from __future__ import annotations

import time

import numpy as np

from ..linalg.levelset import level_set

__all__ = ["refine_peak", "peak_check", "polish", "climb", "verify", "certify", "certificate", "RESOLUTION", "LOCAL", "TRUNCATION",
           "REALIZATION"]

EPS = np.finfo(float).eps
#: an eigenvalue near the axis is checked locally only if |Re| <= LOCAL * max(frequency, lowest band frequency)
LOCAL = 0.05


def refine_peak(sig, lo, c, hi, rtol, budget, bar=None):
    r"""Maximise sig on [lo, hi] from the sample c, the best of the three (secant on a derivative, bracket
    safeguard); c may be an end of the bracket.

    The bracket keeps the best sample at one of its ends, its derivative pointing inward, and the other
    end no higher: the largest value on the bracket is then taken inside it, at a local maximum of
    :math:`\sigma` at least as high as the best sample, which the bracket closes in on. A new sample
    that beats the best becomes the end on the side its derivative points away from; one that does not
    becomes the far end, whatever its slope (issue 45: moving an end to a lower sample because its
    slope had the end's sign left the best sample's hump: on tcom(100), BT at r = 120, 18 samples
    converged on a lower maximum 3% away and the search reported a sample 2.4% below the peak next to it).

    The step is the secant root, through the last two samples, of
    :math:`g = \sigma'/\sigma^3 = -\tfrac12 (\sigma^{-2})'`: for one lightly damped pole, :math:`\sigma^{-2} = ((\omega - \omega_0)^2 + b)/|\rho|^2`
    is quadratic, :math:`g` is linear and the secant lands on the peak; near a peak with a background
    it converges superlinearly. A step outside the bracket's inner 98% falls back to regula falsi on
    the bracket, then to bisection (also where the ends' slopes do not change sign). (Regula falsi on
    :math:`\sigma'` itself, the rule before 2026-11-28, stagnated at sharp resonances: 13 to 38 samples
    where this takes 5 to 7, docs/design/norms.md.)

    At a crossing of the two largest singular values (a kink: a bracket end's slope changes by less
    than :data:`KINK_SLOPE` when the end moves) the step is where the two ends' tangents meet, and
    the gain is bounded by the tangents' meeting value (each side concave near the peak); bisection
    there took 42 samples for one peak of fem_block(1000).

    Stops when the gain still predicted by the local quadratic model,
    :math:`\sigma'(x)^2 / (2|\sigma''|)` with :math:`\sigma''` from the last two
    derivatives, is below :data:`STOP_MARGIN` times ``rtol`` times the
    best value, when the bracket has shrunk to rounding or below what its ends' slopes times its width
    could add to the best value (also :data:`STOP_MARGIN` ``rtol``: samples whose rounding exceeds
    ``rtol`` made the bracket shrink by bisection to 1e-13, 20 samples more on tcom(136)), or when
    ``budget`` LUs are spent; with ``bar`` (a value
    found elsewhere) also when the peak the model predicts, raised by
    :data:`BAR_MARGIN`, stays below ``bar``: this maximum cannot be the largest.
    """
    def g(f, d):
        return d / f ** 3

    def meet():  # where the bracket ends' tangents meet, and their value there
        xt = (fb - fa + da * a - db * b) / (da - db)
        return xt, fa + da * (xt - a)

    # the superlinear secant resolves the peak well inside rtol for one sample or two more
    stop = STOP_MARGIN * rtol
    fl, dl = sig(lo)
    fc, dc = sig(c)
    fh, dh = sig(hi)
    best = (fc, c)
    used = 0
    if c <= lo or c >= hi:  # c an end: the whole bracket, the best end its best sample
        a, fa, da, b, fb, db = lo, fl, dl, hi, fh, dh
        other = (hi, g(fh, dh)) if c <= lo else (lo, g(fl, dl))
        best = max((fl, lo), (fh, hi))
    elif dc > 0:  # the maximum next to c is on the side its derivative points to
        a, fa, da, b, fb, db = c, fc, dc, hi, fh, dh
        other = (hi, g(fh, dh))
    else:
        a, fa, da, b, fb, db = lo, fl, dl, c, fc, dc
        other = (lo, g(fl, dl))
    prev = (c, dc)
    last = (c, g(fc, dc))
    kink = False  # the largest singular value's peak is a crossing: both sides' slopes stay put
    history = []
    while used < budget and b - a > 1e-13 * abs(b):
        inner = (a + 0.01 * (b - a), b - 0.01 * (b - a))
        x = None
        if da > 0 > db:
            (p, gp), (q, gq) = other, last
            if kink:
                x = meet()[0]
            elif gq != gp:
                x = q - gq * (q - p) / (gq - gp)  # the secant through the last two samples
            if x is None or not inner[0] < x < inner[1]:
                ga, gb = g(fa, da), g(fb, db)
                x = a + (b - a) * ga / (ga - gb)  # regula falsi on the bracket
            if not inner[0] < x < inner[1]:
                x = 0.5 * (a + b)
        else:
            x = 0.5 * (a + b)
        fx, dx = sig(x)
        used += 1
        history.append((x, fx, dx))
        other, last = last, (x, g(fx, dx))
        curv = (dx - prev[1]) / (x - prev[0]) if x != prev[0] else 0.0
        prev = (x, dx)
        signs = da > 0 > db
        if fx > best[0]:  # the new best: an end, its derivative pointing inward
            best = (fx, x)
            right = dx > 0
        else:  # the far end from the best
            right = fa < fb
        old = da if right else db
        if right:
            a, fa, da = x, fx, dx
        else:
            b, fb, db = x, fx, dx
        if signs and dx * old > 0:
            # a slope that changes by less than KINK_SLOPE while its end moves: the side is a line
            kink = kink or abs(dx - old) <= KINK_SLOPE * abs(old)
        if kink and da > 0 > db:
            # two concave sides lie below their tangents: the peak is at most where the tangents meet
            if meet()[1] - best[0] <= stop * best[0]:
                break
        elif curv < 0 and fx >= best[0] and dx * dx / (2.0 * -curv) <= stop * fx:
            break
        if max(abs(da), abs(db)) * (b - a) <= stop * best[0]:
            break  # the bracket is narrower than its ends' slopes could gain on: samples at the rounding level
        if bar is not None and curv < 0 and (1.0 + BAR_MARGIN) * (fx + dx * dx / (2.0 * -curv)) < bar:
            break
    return best, used, history


def peak_check(sig, w, rtol):
    r"""Whether the sample at ``w`` is a local maximum of :math:`\sigma` to ``rtol``: the gain still predicted
    there by the quadratic model, :math:`\sigma'(w)^2 / (2|\sigma''|)` with :math:`\sigma''` from the
    derivatives at ``w`` and at the nearest sample on the side :math:`\sigma'(w)` points to (which must lie
    below), at most ``rtol`` :math:`\sigma(w)` plus the samples' rounding, :math:`16\varepsilon\|T\|`
    (``sig.scale``); a slope below :math:`16\varepsilon\|T'(j\omega)\|` (the derivative's rounding: it is
    not refined, and an error of 1e-11 of :math:`\|T\|` has slopes at that level) counts as zero. :math:`\omega = 0`
    (where :math:`\sigma' = 0` by symmetry) counts when the next sample's slope is not positive. Returns
    ``(ok, record)``; no LU."""
    f, d = sig(w)
    ws = np.array(sorted(sig.samples))
    i = int(np.searchsorted(ws, w))
    rec = {"frequency": float(w), "value": float(f), "derivative": float(d), "gain": None}
    if w == 0.0:
        ok = ws.size < 2 or sig.samples[ws[1]][1] <= 0
        rec["gain"] = 0.0 if ok else np.inf
        return bool(ok), rec
    full = getattr(sig, "full", {})
    if w in full and abs(d) <= 16.0 * EPS * float(np.linalg.norm(np.asarray(full[w][1]))):
        rec["gain"] = 0.0  # a slope at the rounding of T' (the derivative is not refined): a maximum to rounding
        return True, rec
    j = i + 1 if d > 0 else i - 1
    if not 0 <= j < ws.size:
        rec["gain"] = np.inf if d != 0 else 0.0
        return d == 0, rec
    fj, dj = sig.samples[ws[j]]
    curv = (dj - d) / (ws[j] - w)
    if d == 0:
        gain = 0.0
    elif fj > f or not curv < 0:
        gain = np.inf  # a higher or convex neighbour: the quadratic model says nothing
    else:
        gain = d * d / (2.0 * -curv)
    rec["gain"] = float(gain)
    return bool(gain <= rtol * f + 16.0 * EPS * getattr(sig, "scale", 0.0)), rec


def polish(sig, w, rtol, budget):
    r"""Refine the best sample ``w`` to a local maximum of :math:`\sigma` (:func:`peak_check`): no LU where it
    is one already, else :func:`refine_peak` on the bracket of its nearest samples (at most ``budget`` LUs).
    Returns ``((value, frequency), record)``; ``record["local_max"]`` says whether the check passed after."""
    ok, rec = peak_check(sig, w, rtol)
    rec.update(lus=0, local_max=ok, refined=False)
    if ok or budget < 1 or not np.isfinite(w):
        return (sig(w)[0], w), rec
    ws = np.array(sorted(sig.samples))
    i = int(np.searchsorted(ws, w))
    lo = ws[i - 1] if i > 0 else 0.0
    hi = ws[i + 1] if i + 1 < ws.size else w * 1.01
    calls = sig.calls
    (fv, wv), _, _ = refine_peak(sig, lo, w, hi, rtol, budget)
    ok, after = peak_check(sig, wv, rtol)
    after.update(lus=sig.calls - calls, local_max=ok, refined=True, start=float(w), start_check=rec)
    return (fv, wv), after


#: a bracket end whose slope changed by less than this fraction when it moved marks a crossing of the
#: two largest singular values (a kink): the resonance secant then steps to where the sides' tangents
#: meet and stops when that meeting point's value is within the stop tolerance of the best sample
KINK_SLOPE = 0.1

#: the resonance secant stops when the predicted gain is below STOP_MARGIN * rtol of the value: the peak
#: found then lies within rtol of the true one with room, at the cost of about one sample more
STOP_MARGIN = 0.01

#: ``refine_peak(bar=...)`` gives up on a maximum whose predicted peak is below bar / (1 + BAR_MARGIN)
BAR_MARGIN = 0.25

#: LUs beyond ``max_lus`` (and ``certify_lus``) that :func:`polish` may spend to make the reported peak a local maximum
POLISH_LUS = 24


#: the modal truncation of the model may add at most TRUNCATION * tol * peak to the error (``certify``)
TRUNCATION = 0.25

#: the dense level-set test's resolution: the certified gap is at least RESOLUTION * eps * ||T|| / peak
RESOLUTION = 1e3

#: the dense realization's allowed deviation from the model is at least REALIZATION * eps * ||T|| (measured
#: at most 137 eps |T(jw)| at tcom(100)'s first resonance, docs/design/norms.md)
REALIZATION = 300.0

#: ... and at least VERIFY times the largest deviation measured at the verified samples
VERIFY = 10.0

#: samples verified: the peak, and this many of the largest ||T(jw)|| and of the largest errors each
VERIFY_POINTS = 4

#: the test level gamma - Delta stays above the peak by at least (1 - HEADROOM) tol * peak: tol is raised
#: to Delta / (HEADROOM * peak) where the counted deviations Delta need it
HEADROOM = 0.5


def climb(sig, w, h, rtol, budget):
    """The local maximum of sigma on the hump that holds ``w``: march uphill in steps h, 2h, 4h, ..., then refine.

    Returns ``(value, frequency, lus, complete)``; ``complete`` is False when the budget ran out
    before the maximum was bracketed and refined.
    """
    lu0 = sig.calls
    fa, da = sig(w)
    a, step = w, h
    direction = 1.0 if (da >= 0 or w == 0) else -1.0
    b, fb, complete = a, fa, False
    while sig.calls - lu0 < budget - 2:
        b = max(a + direction * step, 0.0)
        fb, db = sig(b)
        if direction * db <= 0 or fb < fa or b == 0.0:
            complete = True
            break
        a, fa = b, fb
        step *= 2.0
    best = max((fa, a), (fb, b))
    lo, hi = min(a, b), max(a, b)
    left = budget - (sig.calls - lu0)
    if complete and hi > lo:
        # the best end's slope points inward (it was climbed to), the other end is lower or points back
        (fv, wv), used, _ = refine_peak(sig, lo, best[1], hi, rtol, left - 1)
        complete = used < left - 1
        best = max(best, (fv, wv))
    return best[0], best[1], sig.calls - lu0, complete


def verify(sig, real, response, w_peak):
    r"""The dense realization ``real`` against the model's own samples: the largest
    :math:`\|\hat G(j\omega) - (T - T_r)(j\omega)\|_2` over the peak frequency and the samples with the
    :data:`VERIFY_POINTS` largest :math:`\|T(j\omega)\|` (where a realization's rounding is largest: the
    model's sharpest resonances) and largest errors; the samples' values are the refined sparse solves
    (``sig.reference``). ``response(real, ws)`` evaluates the realization. Returns the record
    ``{"frequencies", "measured"}``."""
    ws = np.array(sorted(sig.reference))
    gain = np.array([sig.gain[w] for w in ws])
    err = np.array([sig.samples[w][0] for w in ws])
    pick = set(ws[np.argsort(-gain, kind="stable")[:VERIFY_POINTS]].tolist())
    pick |= set(ws[np.argsort(-err, kind="stable")[:VERIFY_POINTS]].tolist())
    if np.isfinite(w_peak) and w_peak in sig.reference:
        pick.add(float(w_peak))
    pick = np.array(sorted(pick))
    G = response(real, pick)
    dev = [float(np.linalg.norm(G[i] - sig.reference[w], 2)) for i, w in enumerate(pick)]
    return {"frequencies": pick.tolist(), "measured": max(dev) if dev else 0.0,
            "at": float(pick[int(np.argmax(dev))]) if dev else None}


def certify(sig, realization, value, w_peak, *, tol, rounds, lus, rtol, w_lo, response):
    r"""Upper bound by the level-set test at :math:`\gamma = (1 + tol)\,\text{peak}`; missed peaks refined.

    ``realization(budget)`` gives the dense error system ``(A, B, C, D, delta, info)``, possibly with
    the model modally truncated (:mod:`morsuite.analysis._hinf_dense`), :math:`\delta \le` ``budget`` =
    :data:`TRUNCATION` :math:`\cdot\,tol\cdot` peak bounding the truncation and the modal form's rounding.
    The realization is then compared with the model's samples (:func:`verify`, ``response(real, ws)``
    evaluates it), and its deviation from the model is allowed
    :math:`\Delta_r = \max(` :data:`REALIZATION` :math:`\varepsilon\|T\|,` :data:`VERIFY` :math:`\cdot`
    measured :math:`)`. With :math:`\Delta = \delta + \Delta_r`, ``tol`` is raised to at least
    :math:`\Delta / (` :data:`HEADROOM` :math:`\cdot\,\text{peak})` and the test runs at
    :math:`\hat\gamma = \gamma - \Delta`: no crossing there means :math:`\|T - T_r\| < \gamma`. An
    eigenvalue near the axis is dismissed by a climb only when its real part is at most :data:`LOCAL`
    times its frequency (or ``w_lo``, the model's lowest band frequency): farther off, the true
    eigenvalue it may stand for could sit on another hump, and the value stays uncertified; and only
    when the hump peaks below :math:`\gamma - 2\Delta`.

    Returns ``(value, w_peak, upper_bound or None, certified, record)``.
    """
    t0, lu0, made0 = time.perf_counter(), sig.calls, sig.ev.lu_count  # lu0: samples (one LU each without the memo)
    scale = max(sig.scale, value)
    tol = max(tol, RESOLUTION * EPS * scale / value) if value > 0 else tol
    real = realization(TRUNCATION * tol * value if value > 0 else 0.0)
    A, B, C, D, delta_t, trunc = real
    t_real = time.perf_counter() - t0
    check = verify(sig, real, response, w_peak)
    allowance = max(REALIZATION * EPS * scale, VERIFY * check["measured"])
    delta = delta_t + allowance
    if value > 0:
        tol = max(tol, delta / (HEADROOM * value))
    check.update(allowance=allowance, floor=REALIZATION * EPS * scale)
    rec = {"method": "level set (Hamiltonian of the dense error system on the hidden manifold)",
           "order": 2 * A.shape[0], "tol": tol, "realization_s": t_real, "truncation": trunc, "rounds": [],
           "delta": {"total": delta, "modal": delta_t, "realization": allowance}, "verified": check,
           "reason": None}
    upper, certified = None, False
    for rnd in range(rounds + 1):
        gamma = (1.0 + tol) * value
        if not gamma > 0:
            rec["reason"] = "the error is zero to rounding: no level to test"
            break
        ls = level_set(A, B, C, D, gamma - delta)  # ||T - That|| <= delta: gamma bounds the model's error
        entry = {"gamma": gamma, "tested": gamma - delta, "candidates": ls.frequencies.tolist(),
                 "closest": ls.closest, "climbs": []}
        rec["rounds"].append(entry)
        if not ls.crossed:
            upper, certified = gamma, True
            break
        if rnd == rounds:
            rec["reason"] = f"imaginary eigenvalues remained after {rounds} rounds"
            break
        far = ls.real_parts > LOCAL * np.maximum(ls.frequencies, w_lo)
        if np.any(far):
            rec["reason"] = (f"{int(far.sum())} eigenvalue(s) near the axis with real parts up to "
                             f"{ls.real_parts.max():.2e}, beyond a local check: the double-precision level-set "
                             "test cannot resolve this error level")
            break
        # Boyd-Balakrishnan: sigma exceeds gamma between crossings; probe them and their midpoints
        ws = ls.frequencies
        probe = np.unique(np.concatenate([ws, 0.5 * (ws[1:] + ws[:-1])]))
        if probe.size + 4 > lus - (sig.calls - lu0):
            rec["reason"] = f"LU budget certify_lus = {lus} too small for {ws.size} candidates"
            break
        vals = np.array([sig(w)[0] for w in probe])
        i = int(np.argmax(vals))
        if vals[i] >= gamma - 2.0 * delta:
            h = 0.25 * float(np.min(np.abs(np.delete(probe, i) - probe[i]))) if probe.size > 1 else 1e-4 * probe[i]
            fv, wv, used, _ = climb(sig, float(probe[i]), max(h, 1e-12 * probe[i]), rtol,
                                    max(lus - (sig.calls - lu0), 4))
            entry["climbs"].append({"candidate": float(probe[i]), "peak": wv, "value": fv, "lus": used,
                                    "complete": True})
            value, w_peak = max((value, w_peak), (fv, wv))
            continue  # a peak the search missed: test again above it
        improved, dismissed = False, 0
        for w, re in zip(ls.frequencies, ls.real_parts):
            left = lus - (sig.calls - lu0)
            if left < 4:
                break
            h = max(4.0 * re, 1e-4 * w, 1e-8 * ls.threshold)
            fv, wv, used, complete = climb(sig, float(w), h, rtol, left)
            entry["climbs"].append({"candidate": float(w), "peak": wv, "value": fv, "lus": used,
                                    "complete": complete})
            if fv > value:
                value, w_peak = fv, wv
            if fv >= gamma - 2.0 * delta:
                improved = True  # a peak the search missed (or within delta of the level): test again above it
            elif complete:
                dismissed += 1  # its hump peaks below gamma: an eigenvalue near the axis, not on it
        if improved:
            continue
        if dismissed == ls.frequencies.size:
            upper, certified = gamma, True
        else:
            rec["reason"] = f"LU budget certify_lus = {lus} spent on {dismissed} of {ls.frequencies.size} candidates"
        break
    rec.update(lu_count=sig.ev.lu_count - made0, time_s=time.perf_counter() - t0)
    return value, w_peak, upper, certified, rec


def certificate(fom, sig, realization, response, value, rec, *, certify_dim, certify_tol, certify_lus, rtol):
    """Add ``lower_bound``, ``upper_bound``, ``certified``, ``certificate`` to ``rec`` (and a better peak)."""
    k = fom.n1 - fom.n2
    if k > certify_dim or not np.isfinite(value):
        why = (f"n1 - n2 = {k} exceeds certify_dim = {certify_dim}: no dense level-set test" if k > certify_dim
               else "infinite value")
        rec.update(search_value=value, search_lu_count=rec["lu_count"], lower_bound=value, upper_bound=None,
                   certified=False, certificate={"reason": why})
        return value
    rec["search_value"], rec["search_lu_count"] = value, rec["lu_count"]
    value, w, upper, ok, cert = certify(sig, realization, value, rec["peak_frequency"], tol=certify_tol, rounds=3,
                                        lus=certify_lus, rtol=rtol, w_lo=float(fom.band[0]), response=response)
    if w != rec["peak_frequency"]:  # a missed peak the certificate climbed to: refined to a local maximum too
        (fv, wv), check = polish(sig, w, rtol, POLISH_LUS)
        rec["peak_check"] = check
        if fv > value:
            value, w = fv, wv
    rec.update(peak_frequency=w, lu_count=sig.ev.lu_count, lu_shifts=list(sig.ev.shifts), samples=len(sig.samples),
               lower_bound=value, upper_bound=upper, certified=ok, certificate=cert)
    return value
