r"""The smallest reduced model of a method that meets a tolerance, and what it cost to find it.

An engineer asks "which method gives me a model within 1% of my structure's response in my
band, how many states has it, and what does it cost?". :class:`ToleranceSearch` answers it
for one method: it reduces at a sequence of orders r on ONE reducer instance (so the work
that does not depend on r is paid once: BT's Gramian factors, modal's LU and Lanczos run,
Krylov's LU), measures each reduced model's error and finds the smallest order whose error
meets the tolerance, **within the method's own step** (one order: 2 first-order states for a
second-order reduced model, 1 for a first-order one): the chosen order r meets it and the
next smaller one, r - 1, is evaluated too and misses it. The errors (``measure``) are

``"band"``
    :math:`\max_k \sigma_{\max}(T(j\omega_k) - T_r(j\omega_k)) / \max_k \sigma_{\max}(T(j\omega_k))`
    on a grid of the band (the full response once, :func:`~morsuite.analysis.response.band_response`,
    one LU per frequency, shared by every method): a sampled value.
``"h2"``
    :math:`\|T - T_r\|_{\mathcal H_2} / \|T\|_{\mathcal H_2}`, exact
    (:func:`~morsuite.analysis.compare.error_norm`), with its floor.
``"hinf"``
    :math:`\|T - T_r\|_{\mathcal H_\infty} / \|T\|_{\mathcal H_\infty}` by the certified upper bound
    of the level-set test (:func:`~morsuite.analysis.hinf_error`); a peak found without a
    certificate is a lower bound and never meets a tolerance.

A value counts as meeting ``tol`` only when it is trusted (the H2 value within its floor, the
Hinf value certified, the band value above the sampled response's rounding level
:data:`BAND_FLOOR`), the reduced model is stable, and value plus floor is at most ``tol``
(conservative by the floor). Errors are not monotone in r in general: the search returns an
order r that meets the tolerance while r - 1 misses it, not a proof that no smaller order meets it.

**The route.** From a start order (:meth:`~morsuite.reducers.Reducer.order_guess` where the
reducer can guess from what it computed, e.g. BT's Hankel singular values; else
``start_states``), orders grow geometrically (at most ``growth`` per step, steered by a
log-linear extrapolation of the last two errors) until one meets the tolerance, then the
bracket between the largest miss below and the smallest meet shrinks by log-linear
interpolation with bisection as a safeguard until the two are one order apart. Each reduction
can continue from the nearest earlier reduced model (:meth:`~morsuite.reducers.Reducer.continue_from`:
the paper's IRKA starts from its poles). Several tolerances are searched loosest first,
sharing every evaluated order.

**Budget.** ``budget_lus`` (the method's sparse LUs, what it would cost from a fresh model:
shared work reused from the model's cache is counted once) and ``budget_s`` (seconds of the
search: reductions and error evaluations) are checked before each new order: when either is
spent the search stops with status ``"budget"`` and returns the best model found. A
reduction in progress is not interrupted.

Statuses of an :class:`Outcome` (:data:`OUTCOMES`): ``met``, ``budget``, ``cap`` (the largest
order allowed, or the reducer's numerical order, misses), ``untrusted`` (values below the
tolerance could not be trusted), ``failed`` (the reductions failed). Design note and
measurements: ``docs/design/tolerance.md``.

Cost: the reductions' own (the method's LUs) plus, per evaluated order, the error's: none
for ``"band"`` beyond the shared full response, the H2 error's (the error-Gramian route from
the model's cached factors, or r LUs), the Hinf search's (up to ``max_lus``).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError, MorsuiteError, OptionError
from . import _tolerance_route as route
from ._tolerance_error import BAND_FLOOR, Reference

__all__ = ["MEASURES", "OUTCOMES", "BAND_FLOOR", "Candidate", "Outcome", "ToleranceSearch", "reach_tolerance"]

#: the error measures of a tolerance
MEASURES = ("band", "h2", "hinf")

#: statuses of a tolerance's outcome and what each means
OUTCOMES = {
    "met": "an order meets the tolerance and the next smaller order (evaluated too) misses it",
    "budget": "the LU or time budget was spent before an order met the tolerance; the best model found is returned",
    "cap": "the largest order allowed (max_states, or the reducer's numerical order) misses the tolerance",
    "untrusted": "errors below the tolerance were found but none could be trusted (below its floor, "
                 "not certified)",
    "failed": "the reductions failed",
}

#: consecutive failed reductions after which a search gives up
MAX_FAILURES = 2

#: failures of one order that are recorded (the search goes on), as a study records them
_CAUGHT = (MorsuiteError, ArithmeticError, ValueError, RuntimeError, MemoryError, np.linalg.LinAlgError)


@dataclass
class Candidate:
    """One evaluated order: the reduced model, its error and what it cost.

    ``value`` is the relative error of ``measure`` (the certified upper bound for ``"hinf"``
    when there is one, else the peak found); ``floor`` its estimated accuracy (relative);
    ``trusted`` whether the value is within it; ``stable`` the reduced model's stability;
    ``lus`` / ``time_s`` the reduction's cost in the search (shared work counted at its first
    use), ``eval_lus`` / ``eval_time_s`` the error's; ``cum_lus`` (the method's LUs),
    ``cum_eval_lus`` (the errors') and ``cum_time_s`` (both) the search's totals up to this order.
    ``error`` is the reduction's failure, if any.
    """

    r: int
    order: int = 0
    states: int = 0
    value: float = math.inf
    floor: float | None = None
    trusted: bool = False
    stable: bool = False
    status: str = ""
    converged: bool = False
    lus: int = 0
    time_s: float = 0.0
    eval_lus: int = 0
    eval_time_s: float = 0.0
    cum_lus: int = 0
    cum_eval_lus: int = 0
    cum_time_s: float = 0.0
    index: int = 0
    error: str | None = None
    record: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict, repr=False)
    rom: object = field(default=None, repr=False)

    def meets(self, tol: float) -> bool:
        """True when the value is trusted, the model stable and ``value + floor <= tol``."""
        return self.error is None and self.trusted and self.stable and \
            self.value + (self.floor or 0.0) <= tol

    def plain(self) -> dict:
        """The candidate as plain data (no model, no reducer ``info`` beyond its status and counts)."""
        keys = ("r", "order", "states", "value", "floor", "trusted", "stable", "status", "converged", "lus", "time_s",
                "eval_lus", "eval_time_s", "cum_lus", "cum_eval_lus", "cum_time_s", "index", "error")
        out = {k: getattr(self, k) for k in keys}
        out["value"] = None if not np.isfinite(self.value) else float(self.value)
        out["record"] = dict(self.record)
        out["iterations"] = int(self.info.get("iterations", 0) or 0)
        return out


@dataclass
class Outcome:
    """What a search found for one tolerance: ``status`` (:data:`OUTCOMES`) and ``reason``,
    ``chosen`` (the order that meets it; for another status the best one found), ``smaller``
    (the next smaller order, which misses it), and the search's totals when it was settled: ``lus``
    the method's LUs, ``eval_lus`` the errors', ``time_s`` both."""

    tol: float
    status: str
    reason: str
    chosen: Candidate | None
    smaller: Candidate | None
    lus: int
    eval_lus: int
    time_s: float

    def plain(self) -> dict:
        """The outcome as plain data (candidates by their order r)."""
        return {"tol": float(self.tol), "status": self.status, "reason": self.reason,
                "chosen": None if self.chosen is None else self.chosen.r,
                "smaller": None if self.smaller is None else self.smaller.r,
                "lus": int(self.lus), "eval_lus": int(self.eval_lus), "time_s": float(self.time_s)}


def _positive(name, value, kind=float, allow_none=True):
    if value is None and allow_none:
        return None
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
    if not ok or not math.isfinite(float(value)) or value <= 0 or (kind is int and int(value) != value):
        raise InputError(f"{name} must be a positive {'integer' if kind is int else 'number'}; got {value!r}")
    return kind(value)


class ToleranceSearch:
    """The smallest order of one method whose error meets tolerances (module docstring).

    Parameters
    ----------
    fom : Index3Model
        The full model.
    method : str
        A registered reducer name (``morsuite.reducers.available()``).
    options : dict, optional
        The reducer's options.
    measure : {"band", "h2", "hinf"}
        The error (default ``"band"``).
    omega : array_like, optional
        The band's grid (rad/s) of ``"band"``; default 200 log-spaced frequencies on ``fom.band``.
    H_full : ndarray, optional
        The full response on ``omega`` (``(len(omega), p, m)``), when already computed (a study's
        full-order response); else computed here (one LU per frequency, ``reference_lus``).
    norm_options : dict, optional
        Options of the H2 or Hinf error (:func:`~morsuite.analysis.compare.error_norm`).
    budget_lus, budget_s : optional
        The method's LU and time budget (module docstring); default none.
    max_states : int, optional
        Largest number of first-order states tried (default :data:`MAX_STATES_DEFAULT`, capped by the
        model's order).
    start_states : int, optional
        First-order states of the first order tried when the reducer cannot guess (default 2).
    growth : float
        Largest factor between two orders of the growing phase (default 2).
    reducer : Reducer, optional
        A reducer instance to use instead of ``make(method, fom, **options)`` (its state is reused).
    proxy : str or None
        A cheap method whose search on the same error steers this one (its order the first guess, a
        quarter of it first when large, its model the first start; ``_tolerance_route``): ``"auto"``
        (default) takes :data:`PROXY` for a reducer with ``costly_orders`` (the IRKA family, so-h2) and
        none otherwise; its LUs and time are this search's.
    reference : Reference, optional
        Another search's reference (:class:`~morsuite.analysis._tolerance_error.Reference`), shared instead
        of computing the band response or norm again.

    Attributes
    ----------
    candidates : dict
        r -> :class:`Candidate`, every order evaluated.
    scale : float
        The absolute norm the tolerance is relative to: the band peak of sigma_max(T), or
        :math:`\\|T\\|_{\\mathcal H_2}`, :math:`\\|T\\|_{\\mathcal H_\\infty}` (the peak found).
    """

    def __init__(self, fom, method: str, *, options=None, measure: str = "band", omega=None, H_full=None,
                 norm_options=None, budget_lus=None, budget_s=None, max_states=None, start_states=None,
                 growth: float = 2.0, reducer=None, proxy: str | None = "auto", reference=None):
        from .. import reducers

        if measure not in MEASURES:
            raise OptionError(f"measure must be one of {', '.join(map(repr, MEASURES))}; got {measure!r}")
        self.fom, self.method, self.measure = fom, method, measure
        self.options = dict(options or {})
        self.budget_lus = _positive("budget_lus", budget_lus, int)
        self.budget_s = _positive("budget_s", budget_s)
        self.growth = _positive("growth", growth)
        if self.growth <= 1:
            raise InputError(f"growth must be > 1; got {growth!r}")
        self.red = reducer if reducer is not None else reducers.make(method, fom, **self.options)
        self.spo = int(self.red.states_per_order())
        max_states = _positive("max_states", max_states, int) or MAX_STATES_DEFAULT
        self.r_max = max(1, min(self.red.max_order(), max_states // self.spo))
        start = _positive("start_states", start_states, int) or 2
        self.r_start = max(1, min(self.r_max, -(-start // self.spo)))
        self.norm_options = dict(norm_options or {})
        self.candidates: dict = {}
        self._t0 = None
        self._cum_lus, self._cum_eval, self._cum_time = 0, 0, 0.0
        self._shared_counted = False
        self._failures = 0
        # what the errors are relative to; a proxy shares its caller's (nothing computed again)
        self.ref = reference if reference is not None else \
            Reference(fom, measure, omega=omega, H_full=H_full, norm_options=self.norm_options)
        self.scale, self.model_norm = self.ref.scale, self.ref.model_norm
        self.reference_lus, self.reference_time_s = (0, 0.0) if reference is not None else (self.ref.lus,
                                                                                           self.ref.time_s)
        if proxy == "auto":
            proxy = PROXY if getattr(self.red, "costly_orders", False) else None
        if proxy is not None and proxy == method:
            proxy = None
        self.proxy_method, self.proxy, self._proxy_outcomes = proxy, None, []

    def _cost(self, info, wall) -> tuple[int, float]:
        """(LUs, seconds) of one reduction in the search: its own, plus the shared work it relied on the
        first time such work appears (what a fresh model would have paid)."""
        from ..reducers.outcome import standalone_lu_count, standalone_time

        lus, t = int(info.get("lu_count") or 0), float(info.get("time_s", wall))
        if not self._shared_counted and info.get("setup_reused"):
            lus, t = standalone_lu_count(info), standalone_time(info, wall)
        if info.get("lu_count_shared"):
            self._shared_counted = True
        return lus, t

    def evaluate(self, r: int) -> Candidate:
        """Reduce at order r (continuing from the nearest evaluated model where the reducer can) and
        measure its error; kept in :attr:`candidates`."""
        if r in self.candidates:
            return self.candidates[r]
        near = [c for c in self.candidates.values() if c.rom is not None and c.error is None and np.isfinite(c.value)]
        if not near and self.proxy is not None:  # the first order: from the proxy's model of about these states
            near = [c for c in self.proxy.candidates.values() if c.rom is not None and c.error is None]
        if near:
            self.red.continue_from(min(near, key=lambda c: (abs(c.states - r * self.spo), c.states > r * self.spo)).rom)
        cand = Candidate(r=int(r), index=len(self.candidates))
        t0 = time.perf_counter()
        # the time budget binds inside a long run too: an iterative reducer stops at this deadline (Reducer.deadline)
        self.red.deadline = None if self.budget_s is None else t0 + max(0.0, self.budget_s - self._cum_time)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the reducer records its warnings in info["warnings"]
                try:
                    res = self.red.reduce(int(r))
                finally:
                    self.red.deadline = None  # this reduction's alone, whatever ends it
        except _CAUGHT as exc:
            cand.error = f"{type(exc).__name__}: {exc}"
            cand.time_s = time.perf_counter() - t0
            self._failures += 1
        else:
            self._failures = 0
            info = res.info
            cand.rom, cand.info = res.rom, info
            cand.order, cand.states = int(res.rom.order), int(res.rom.states)
            cand.status, cand.converged = str(info.get("status")), bool(info.get("converged"))
            cand.stable = bool(info.get("stable", res.rom.is_stable()))
            cand.lus, cand.time_s = self._cost(info, time.perf_counter() - t0)
            t1 = time.perf_counter()
            err = self.ref.error(res.rom)
            cand.eval_time_s = time.perf_counter() - t1
            cand.value, cand.floor, cand.trusted = err["value"], err["floor"], err["trusted"]
            cand.eval_lus, cand.record = err["lus"], err["record"]
        self._cum_lus += cand.lus
        self._cum_eval += cand.eval_lus
        self._cum_time += cand.time_s + cand.eval_time_s
        cand.cum_lus, cand.cum_eval_lus, cand.cum_time_s = self._cum_lus, self._cum_eval, self._cum_time
        self.candidates[r] = cand
        return cand

    # -- the search ----------------------------------------------------------------
    def _spent(self) -> str:
        if self.budget_lus is not None and self._cum_lus >= self.budget_lus:
            return f"{self._cum_lus} LUs spent of a budget of {self.budget_lus}"
        if self.budget_s is not None and self._cum_time >= self.budget_s:
            return f"{self._cum_time:.1f} s spent of a budget of {self.budget_s:g} s"
        return ""

    def _best(self, tol):
        done = [c for c in self.candidates.values() if c.error is None and np.isfinite(c.value) and c.stable]
        return min(done, key=lambda c: (c.value, c.r)) if done else None

    def _run_proxy(self, tol):
        """The proxy's search for ``tol`` (once per tolerance), its LUs and time added to this search's."""
        if self.proxy_method is None:
            return None
        if self.proxy is None:
            self.proxy = ToleranceSearch(self.fom, self.proxy_method, measure=self.measure, norm_options=self.norm_options,
                                         max_states=self.r_max * self.spo, proxy=None, reference=self.ref)
        before = (self.proxy._cum_lus, self.proxy._cum_eval, self.proxy._cum_time)
        out = self.proxy.run([tol])[0]
        self._cum_lus += self.proxy._cum_lus - before[0]
        self._cum_eval += self.proxy._cum_eval - before[1]
        self._cum_time += self.proxy._cum_time - before[2]
        return out

    def _guess(self, tol):
        if self.proxy is not None:  # the proxy's order that met the tolerance, in this method's orders
            out = next((o for o in self._proxy_outcomes if o.tol == tol), None)
            if out is not None and out.status == "met":
                return int(min(max(1, -(-out.chosen.states // self.spo)), self.r_max))
        try:
            g = self.red.order_guess(tol, measure=self.measure, scale=self.scale)
        except (MorsuiteError, ValueError, ArithmeticError, np.linalg.LinAlgError):
            return None
        return None if g is None else int(min(max(1, g), self.r_max))

    def _points(self):
        """(states, value) of every evaluated order with a finite value."""
        return [(c.states, c.value) for c in self.candidates.values() if c.error is None and np.isfinite(c.value)]

    def _proxy_points(self, tol):
        return None if self.proxy is None else [(c.states, c.value) for c in self.proxy.candidates.values()
                                                if c.error is None and np.isfinite(c.value)]

    def _settle(self, tol) -> Outcome:
        if self.proxy_method is not None:
            self._proxy_outcomes.append(self._run_proxy(tol))
        guessed, widths = False, []
        while True:
            evald = self.candidates
            meets = sorted(r for r, c in evald.items() if c.meets(tol))
            hi = meets[0] if meets else None
            if hi is not None and (hi == 1 or (hi - 1) in evald):
                why = (f"{evald[hi].states} states meet it, {evald[hi - 1].states or 'one order fewer'} miss it"
                       if hi > 1 else "the smallest order meets it")
                return Outcome(tol, "met", why, evald[hi], evald.get(hi - 1), self._cum_lus, self._cum_eval,
                               self._cum_time)
            spent = self._spent()
            if spent:
                return self._stop(tol, "budget", spent)
            if self._failures >= MAX_FAILURES:
                last = evald[max(evald, key=lambda r: evald[r].index)]
                return self._stop(tol, "failed", last.error or "the reductions failed")
            below = [r for r in evald if (hi is None or r < hi)]
            lo = max(below) if below else None
            if not guessed and (g := self._guess(tol)) is not None and g not in evald \
                    and (lo is None or g > lo) and (hi is None or g < hi):
                guessed = True
                if self.proxy is not None and not evald and g >= 4 * CALIBRATE:
                    # a costly method's first run is a small one: it calibrates the proxy's curve to this
                    # method's before the run near the tolerance (grow below predicts from both)
                    self.evaluate(max(1, g // CALIBRATE))
                else:
                    self.evaluate(g)
                continue
            if lo is None and hi is None:
                nxt = self.r_start
            elif lo is None:  # only meets so far: towards the boundary below the smallest one
                nxt = route.between(self._points(), 0, hi, tol, self.spo, False, self._proxy_points(tol))
            elif hi is None:
                c = evald[lo]
                if lo >= self.r_max:
                    return self._stop(tol, "cap", f"the largest order allowed, {self.r_max} ({self.r_max * self.spo} "
                                                  "states), misses it")
                if c.error is None and c.order < c.r and (c.order, c.r) != (0, 0):
                    return self._stop(tol, "cap", f"the reducer capped the order at {c.order} ({c.states} states), "
                                                  "its numerical order, which misses it")
                if self._untrusted_below(tol):
                    return self._stop(tol, "untrusted", "errors below the tolerance could not be trusted (below "
                                                        "their floor or not certified)")
                nxt = route.grow(self._points(), lo, tol, self.spo, self.growth, self.r_max,
                                 self._proxy_points(tol))
            else:
                widths.append(hi - lo)
                bisect = len(widths) >= 3 and widths[-1] > widths[-3] / 2  # no halving in two steps
                nxt = route.between(self._points(), lo, hi, tol, self.spo, bisect, self._proxy_points(tol))
            self.evaluate(nxt)

    def _untrusted_below(self, tol) -> bool:
        """Two evaluated orders whose values are at or below ``tol`` without being trusted."""
        return sum(1 for c in self.candidates.values() if c.error is None and c.stable and c.value <= tol
                   and not c.trusted) >= 2

    def _stop(self, tol, status, reason) -> Outcome:
        best = self._best(tol)
        smaller = None if best is None else self.candidates.get(best.r - 1)
        return Outcome(tol, status, reason, best, smaller, self._cum_lus, self._cum_eval, self._cum_time)

    def run(self, tols) -> list:
        """Search every tolerance of ``tols`` (relative, in (0, 1)), loosest first; returns one
        :class:`Outcome` per tolerance in the order given."""
        tols = [float(t) for t in np.atleast_1d(tols)]
        if not tols or any(not (0 < t < 1) for t in tols):
            raise InputError(f"tol must be numbers in (0, 1) (relative errors); got {tols}")
        out = {}
        for t in sorted(set(tols), reverse=True):
            out[t] = self._settle(t)
        return [out[t] for t in tols]

    def record(self, outcomes) -> dict:
        """The search as plain data: method, measure, scale, reference cost, every candidate, the outcomes."""
        px = None if self.proxy is None else {"method": self.proxy_method, "lus": int(self.proxy._cum_lus),
                                              "candidates": [c.plain() for c in sorted(self.proxy.candidates.values(),
                                                                                       key=lambda c: c.index)]}
        norm = None if self.model_norm is None else {k: self.model_norm.get(k) for k in (
            "value", "route", "floor", "rel_floor", "trusted", "lower_bound", "upper_bound", "certified", "options")}
        return {"method": self.method, "measure": self.measure, "scale": self.scale, "norm": norm, "proxy": px,
                "states_per_order": self.spo, "r_max": self.r_max, "budget_lus": self.budget_lus,
                "budget_s": self.budget_s, "reference_lus": int(self.reference_lus),
                "reference_time_s": float(self.reference_time_s),
                "candidates": [c.plain() for c in sorted(self.candidates.values(), key=lambda c: c.index)],
                "outcomes": [o.plain() for o in outcomes], "lus": int(self._cum_lus),
                "eval_lus": int(self._cum_eval), "time_s": float(self._cum_time)}


#: default largest number of first-order states a search tries
MAX_STATES_DEFAULT = 400

#: the proxy of methods whose orders are costly (``costly_orders``): one-point Krylov, one LU in all
PROXY = "krylov"

#: a proxy-steered search first runs the costly method at 1 / CALIBRATE of the proxy's order (when that
#: order is at least 4 CALIBRATE): its error against the proxy's calibrates the prediction of the next
CALIBRATE = 4


def reach_tolerance(fom, method: str, tol, **kwargs):
    """``(outcomes, search)``: :class:`ToleranceSearch` (keyword arguments as there) run on ``tol`` (a number
    or a sequence of numbers in (0, 1)); one :class:`Outcome` per tolerance.

    Example: ``outcomes, s = reach_tolerance(ms.models.dsms(g=1000), "bt", 1e-3, measure="h2")``;
    ``outcomes[0].chosen.states`` and ``outcomes[0].chosen.rom``.
    """
    search = ToleranceSearch(fom, method, **kwargs)
    return search.run(tol), search
