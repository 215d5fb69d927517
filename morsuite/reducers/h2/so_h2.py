r"""``so-h2``: structure-preserving H2 descent for second-order reduced models.

Minimises :math:`J = \|T - T_r\|_{\mathcal H_2}^2` over second-order reduced models
:math:`T_r(s) = \hat L(s^2\hat M + s\hat D + \hat K)^{-1}\hat F` with
:math:`\hat M = I` (no loss, :mod:`~morsuite.reducers.h2.params`), in the spirit of the structured
H2 literature (Mlinarić, Benner and Gugercin, arXiv 2209.00714 and 2401.10047;
Sato, arXiv 1803.04097; Schwerdtner and Voigt's SOBMOR, arXiv 2011.07567).

1. **Candidates**: the second-order BT levels ``levels`` (and the paper's IRKA with
   ``irka_start``) at the same r (:mod:`~morsuite.reducers.h2.starts`), ranked against a surrogate
   :math:`T_N` (first-order BT of the cached Gramian factors, at most ``surrogate_tol``
   times the best candidate's error from the model); those the surrogate cannot separate
   get an exact error (:func:`.h2_decision.decision_h2`, r LUs each).
2. **Descent** (``descent``). ``"varpro"`` (one input, ``parametrization="general"``; the
   default there; several outputs: :mod:`~morsuite.reducers.h2.simo`): a second-order model of
   order r is a first-order one of degree 2r whose residues sum to zero
   (:mod:`morsuite.reducers.h2.poles`); from the ``starts`` candidates, variable projection (the
   residues by one linear solve) and trust-region Newton over the poles against :math:`T_N` (:mod:`morsuite.reducers.h2.poles_descent`), then chord steps on
   the full model's gradient (r LUs each, at most ``chord_maxit``) (:mod:`~morsuite.reducers.h2.siso`).
   ``"lbfgs"`` (the default otherwise): monotone preconditioned L-BFGS in the entries of
   :math:`\hat K, \hat D, \hat F, \hat L` against :math:`T_N`, then at most ``full_maxit``
   iterations against the model (:mod:`morsuite.reducers.h2.lbfgs`).
3. **Certificate**: the relative gradient
   :math:`\rho = \|\Pi E\|_{\mathcal H_2}/\|E\|_{\mathcal H_2}` of the result against the
   full model (:math:`\Pi`: projection onto the tangent space of the reduced models;
   :mod:`morsuite.reducers.h2.stationarity`, r LUs). ``converged`` is
   :math:`\rho \le` ``gtol``; ``info["status"]`` is ``"converged"``, ``"cap"`` (an iteration
   limit was reached first), ``"stalled"`` (no further decrease at the objective's accuracy,
   or the result was worse than the start, which is then returned) or ``"skipped"`` (the
   start's exact error is below what the formula resolves: its floor above ``resolution``
   of it; or the surrogate's error of the start differs from the exact one by more than
   ``SURROGATE_MISMATCH`` of it, so that the surrogate does not resolve the model at that error:
   the DSMS from r = 18; the start is returned with an :class:`~morsuite.errors.AccuracyWarning`).
   :math:`\|E\|^2` in :math:`\rho` is the exact evaluator's where the pole-residue value is rounding
   (``info["relative_gradient_norm"]``).
   Anything but ``"converged"`` comes with ``converged=False`` and a warning.

The result is never worse than the start in exact H2 error (:func:`.h2_decision.decision_h2`).

``info``: ``start``, ``start_h2_error`` (+ ``_floor``), ``candidates``, ``descent``,
``h2_error`` (exact, of the result) and ``h2_error_floor``, ``relative_gradient`` and ``gtol``
(SISO, where the partial-fraction form is ill-conditioned: in an orthonormal basis,
:mod:`morsuite.reducers.h2.orthonormal`; ``relative_gradient_form``, ``gram_condition``; the partial-fraction
form beside it as ``relative_gradient_pole_residue``),
``status``, ``returned_start``, ``iterations`` (``iterations_surrogate`` + ``iterations_full``),
``history`` and ``history_full``, ``stop_reason`` and ``stop_reason_full``; varpro: ``starts``
(per start: surrogate errors, iterations, reason), ``descended_from``, ``cluster_record`` (option
``cluster_rounds``: per round the surrogate errors, iterations and relative gradients; docs/design/so_h2.md),
``polish`` (option ``cluster_polish``: the closer surrogate's states, errors before and after, iterations),
``relative_gradient_full``; lbfgs: ``gradient_norm``; ``lu_count`` (made by this call) with
``lu_breakdown`` (gramians, irka, exact) and ``lu_count_gramians``, ``time_breakdown``,
``setup_reused``, ``setup_cost`` and ``setup_paid`` (by part: ``adi``, ``bt_products``, ``bt_svd``,
``surrogates``, ``full_target``; a reducer reused across r pays each once, and
:func:`~morsuite.reducers.outcome.standalone_time` adds back what this call relied on but did
not pay).

Options: :attr:`SOH2.OPTIONS` (defaults recorded in ``info["options"]``). Cost: the Gramian
factors (shared with ``bt`` through the model's cache), one dense SVD per BT level and one for
the surrogate, r LUs per exact evaluation, dense :math:`O(r^3 + rN)` work per Newton trial (varpro)
or :math:`O(N(2r)^2)` per L-BFGS evaluation, r LUs per chord step and for the certificate.
Measurements: ``docs/design/so_h2.md``.
"""

from __future__ import annotations

import time

import numpy as np

from ...errors import AccuracyWarning, ConvergenceWarning, InputError, OptionError
from ...linalg.gramians import ADI_DEFAULTS
from ...linalg.h2 import norm_squared
from .gradient import FullTarget, gauss_newton_diagonal, h2_objective, h2_value
from .stationarity import full_stationarity
from .lbfgs import Evaluation, lbfgs_descent
from ...utils import blas_threads
from ..base import Group, Option, Reducer
from ..registry import Description
from ..h2_decision import decision_h2
from .params import PARAMETRISATIONS
from .siso import pole_phase
from .simo import simo_phase
from ..outcome import SetupLedger
from .starts import LEVELS, STARTS, Surrogates, candidate_roms, standard_realization

__all__ = ["SOH2"]

#: levels among the default candidates: each costs one dense SVD of a product of the factors (5 s on
#: tcom(2000)); pv was never the best start, vp only on tcom(200) (docs/design/so_h2.md)
DEFAULT_LEVELS = ("pp", "vv", "fv")
ADI_OPTIONS = ("tol", "maxiter", "shifts", "num_shifts", "selection", "refine")
#: the descent is skipped when the surrogate's H2 error of the start differs from its exact error by more than this
#: fraction of it (the surrogate does not resolve the model at that error)
SURROGATE_MISMATCH = 0.5
#: start chosen when no candidate's exact error is resolved: the paper's level first
PREFERENCE = ("vv", "pp", "vp", "pv", "fv", "irka")


class SOH2(Reducer):
    """Structure-preserving H2 descent (see the module docstring); ``reduce(r)`` returns a
    :class:`~morsuite.rom.SecondOrderROM` of order r (2r states) with :math:`\\hat M = I`."""

    name = "so-h2"
    DESCRIPTION = Description(
        label="so-h2 (second-order H2 descent)", result="second-order",
        targets="minimum H2 error among second-order models", cost="Gramians, then tens to hundreds",
        use_for="second-order structure with the smallest H2 error",
        options=("start", "descent", "gtol", "maxit", "starts"), default=True, gramians="reads", page="so_h2", order=30)
    costly_orders = True  # each order is a descent of its own: a tolerance search steers it by a proxy

    OPTIONS = {
        "start": Option("best", "choice", "start model: the best by exact H2 error of the candidates, or one "
                        "of them (second-order BT level or the paper's IRKA)", choices=("best",) + STARTS),
        "levels": Option(DEFAULT_LEVELS, "any", "second-order BT levels among the candidates of start='best' (a "
                         "tuple of pp, pv, vp, vv, fv; each level costs one SVD of a product of the factors)"),
        "irka_start": Option(False, "bool", "include the paper's IRKA among the candidates of start='best' "
                             "(its LUs are counted)"),
        "descent": Option("auto", "choice", "varpro: pole-residue variable projection and Newton (one "
                          "input, general parametrization; several outputs: reducers/h2/simo.py); lbfgs: "
                          "L-BFGS in the parametrization's entries; auto: varpro where it applies",
                          choices=("auto", "varpro", "lbfgs")),
        "gtol": Option(1e-4, "float", "converged when the relative gradient ||Pi E|| / ||E|| against the full "
                       "model is at most this", low=0, high=1, open_low=True, open_high=True),
        "starts": Option(5, "int", "varpro: candidates (best by surrogate error first) descended from", low=1),
        "newton_maxit": Option(300, "int", "varpro: Newton iterations per start against the surrogate", low=1),
        "simo_maxit": Option(1500, "int", "varpro with several outputs (reducers/h2/simo.py): Newton iterations "
                             "against the surrogate (the DSMS at r = 10 and 14 needs 700 to 1,100 to reach the "
                             "floor of its relative gradient; docs/design/so_h2.md)", low=1),
        "chord_maxit": Option(5, "int", "varpro: chord steps against the full model (r LUs each)", low=0),
        "cluster_rounds": Option(3, "int", "varpro: when no start converges on the surrogate, rounds of "
                                 "Gauss-Newton in cluster-polynomial coordinates alternated with it, from the best "
                                 "stalled start (0: none; linalg/h2_clusters.py)", low=0),
        "cluster_polish": Option(2, "int", "varpro: when the cluster rounds ran, their result is polished on the "
                                 "surrogate of this many times the states (0: not; 2: the one that estimated the "
                                 "surrogate's distance, no new SVD)", low=0),
        "parametrization": Option("general", "choice", "general K, D, F, L with steps leaving the stable set "
                                  "rejected, or passive: K diagonal positive, D = L_D L_D^T (stable by "
                                  "construction; starts from the fv level)", choices=tuple(PARAMETRISATIONS)),
        "surrogate_tol": Option(0.01, "float", "largest estimated H2 distance of the surrogate to the model, "
                                "relative to the start's error", low=0, high=1, open_low=True, open_high=True),
        "surrogate_states": Option(None, "int", "first-order states of the surrogate (None: chosen by "
                                   "surrogate_tol)", low=2, nullable=True),
        "maxit": Option(3000, "int", "iterations of the surrogate phase", low=0),
        "full_maxit": Option(3, "int", "iterations against the full model after the surrogate phase "
                             "(r LUs per evaluation)", low=0),
        "full_backtracks": Option(3, "int", "step halvings per line search against the full model (each "
                                  "costs r LUs)", low=1),
        "refinements": Option(2, "int", "times the surrogate is doubled when its result is not better than "
                              "the start in exact error", low=0),
        "rtol": Option(1e-6, "float", "stop when J decreased by less than rtol times its value over the last "
                       "window iterations", low=0, high=1, open_high=True),
        "window": Option(20, "int", "iterations over which the decrease is measured", low=1),
        "memory": Option(100, "int", "curvature pairs kept by L-BFGS", low=1),
        "precondition": Option("gauss-newton", "choice", "initial inverse Hessian: inverse Gauss-Newton "
                               "diagonal or the identity", choices=("gauss-newton", "none")),
        "precond_every": Option(200, "int", "iterations between refreshes of the Gauss-Newton diagonal "
                                "(0: never)", low=0),
        "resolution": Option(0.25, "float", "the descent is skipped when the floor of the start's exact H2 "
                             "error exceeds this fraction of it", low=0, high=1, open_low=True),
        "tol": Option(ADI_DEFAULTS["tol"], "float", "LR-ADI tolerance of the Gramian factors (as bt)",
                      low=0, high=1, open_low=True, open_high=True),
        "maxiter": Option(ADI_DEFAULTS["maxiter"], "int", "LR-ADI iteration cap (as bt)", low=1),
        "shifts": Option(ADI_DEFAULTS["shifts"], "choice", "LR-ADI shift strategy (as bt)",
                         choices=("projection", "penzl")),
        "num_shifts": Option(ADI_DEFAULTS["num_shifts"], "int", "LR-ADI shifts per computation (as bt)", low=1),
        "selection": Option(ADI_DEFAULTS["selection"], "choice", "LR-ADI projection shift selection (as bt)",
                            choices=("residual", "gain")),
        "refine": Option(ADI_DEFAULTS["refine"], "int", "long-double refinement steps of each shifted LR-ADI "
                         "solve (as bt)", low=0),
    }
    GROUPS = {
        "varpro": Group("the variable-projection Newton descent (descent='varpro')",
                        ("newton_maxit", "simo_maxit", "chord_maxit", "cluster_rounds", "cluster_polish")),
        "surrogate": Group("the surrogate model the descent runs against",
                           ("surrogate_tol", "surrogate_states", "refinements"), prefix="surrogate_"),
        "full_model": Group("the iterations against the full model after the surrogate phase",
                            ("full_maxit", "full_backtracks"), prefix="full_"),
        "lbfgs": Group("the L-BFGS descent (descent='lbfgs') and its stopping rule",
                       ("rtol", "window", "memory", "precondition", "precond_every")),
        "adi": Group("LR-ADI of the Gramian factors (as bt's)", ADI_OPTIONS),
    }

    def __init__(self, fom, **options):
        super().__init__(fom, **options)
        self._surrogates = None
        self._full = None
        self._ledger = SetupLedger()  # r-independent pieces (surrogate models, the full target) and their cost
        self._adi_charged = set()  # ids of the Gramian records already charged to a call (reuse across r)

    def _check_options(self):
        o = self.options
        lv = o["levels"]
        if (isinstance(lv, str) or not isinstance(lv, (tuple, list)) or not lv
                or any(x not in LEVELS for x in lv) or len(set(lv)) != len(lv)):
            raise OptionError(f"The 'levels' parameter of SOH2 must be a non-empty tuple of distinct levels "
                              f"from {', '.join(LEVELS)}. Got {lv!r} instead.")
        o["levels"] = tuple(lv)
        if o["parametrization"] == "passive" and o["start"] not in ("best", "fv"):
            raise InputError(f"parametrization='passive' starts from the fv level only (symmetric M, D, K); "
                             f"got start={o['start']!r}")
        if o["descent"] == "varpro" and (self.fom.m != 1 or o["parametrization"] != "general"):
            raise InputError(f"descent='varpro' needs a single-input model and parametrization='general'; got "
                             f"m = {self.fom.m}, parametrization={o['parametrization']!r}")

    # -- pieces ---------------------------------------------------------------
    def _labels(self):
        o = self.options
        if o["start"] != "best":
            return (o["start"],)
        if o["parametrization"] == "passive":
            return ("fv",)
        return tuple(o["levels"]) + (("irka",) if o["irka_start"] else ())

    def _full_target(self, adi):
        if self._full is None:
            t0 = time.perf_counter()
            n2, f2, rec, _ = norm_squared(self.fom, adi)
            self._full = FullTarget(self.fom, n2, f2)
            self._ledger.made(("full_target",), time.perf_counter() - t0)
        self._ledger.used(("full_target",))
        return self._full

    def _objective(self, target, param, counter):
        def fun(theta):
            ev = h2_objective(target, *param.matrices(theta))
            counter["evaluations"] += 1
            counter["lu"] += ev.lu_count
            if not ev.stable:
                return Evaluation(np.inf)
            return Evaluation(ev.value, ev.floor, param.gradient(theta, ev.gradient), ev)
        return fun

    def _precond(self, param, theta):
        if self.options["precondition"] == "none":
            return np.ones(param.size)
        H = param.gauss_newton(theta, gauss_newton_diagonal(*param.matrices(theta)))
        return 1.0 / np.maximum(H, 1e-10 * np.max(H))

    def _descend(self, target, param, theta, first, maxit, pairs=None):
        """Monotone L-BFGS from theta, the preconditioner refreshed every precond_every iterations."""
        o = self.options
        counter = {"evaluations": 0, "lu": 0}
        fun = self._objective(target, param, counter)
        chunk = o["precond_every"] or maxit
        done, hist, reason, res = 0, [], "maxit", None
        cur = first
        while done < maxit or res is None:
            h = self._precond(param, theta)
            res = lbfgs_descent(fun, theta, precond=h, maxit=min(chunk, maxit - done), memory=o["memory"],
                                rtol=o["rtol"], window=o["window"], first=cur, pairs=pairs)
            hist += res.history[1:] if hist else res.history
            done += res.iterations
            theta, cur, pairs = res.x, res.best, res.memory
            reason = res.reason
            if reason != "maxit" or maxit == 0:
                break
        return theta, cur, pairs, done, reason, hist, counter, h

    # -- the reduction ----------------------------------------------------------
    def _start(self, r, adi, param_cls):
        """Candidates, surrogate, and the start: its label, ROM and exact evaluation (module docstring)."""
        o, fom = self.options, self.fom
        roms, cands, bt = candidate_roms(fom, r, self._labels(), adi, keep=param_cls.accepts,
                                         bt=None if self._surrogates is None else self._surrogates.bt)
        if not roms:
            raise InputError(f"so-h2: no stable candidate start at r = {r} "
                             "(" + ", ".join(f"{k}: {v.get('dropped')}" for k, v in cands.items()) + ")")
        if self._surrogates is None:
            self._surrogates = Surrogates(bt, self._ledger)
        self._full_target(adi)  # the full model as target (made once; later steps and LU counts use it)
        sur, srec = self._surrogates.choose(r, roms, o["surrogate_tol"], o["surrogate_states"])
        unresolved = False
        for label, rom in roms.items():
            ev = h2_value(sur, *standard_realization(rom))
            cands[label]["surrogate_h2_error"] = float(np.sqrt(max(ev.value, 0.0)))
            unresolved |= bool(ev.floor > o["resolution"] * abs(ev.value))
        # |e - e_surrogate| <= delta for every model: only candidates within 2 delta of the best can be
        # in the wrong order, and only they get exact errors (r LUs each); all of them where the surrogate
        # values are rounding
        best_s = min(cands[k]["surrogate_h2_error"] for k in roms)
        band = np.inf if unresolved else best_s + 2.0 * (srec["distance"] or 0.0) + 1e-3 * best_s
        exact = {}

        def evaluate(label):
            exact[label] = e, floor, trusted = decision_h2(fom, roms[label], counter=self._decision_lus)
            cands[label].update(h2_error=e, h2_error_floor=floor, h2_error_trusted=trusted)

        for label in roms:
            if cands[label]["surrogate_h2_error"] <= band:
                evaluate(label)
        start = min(exact, key=lambda k: exact[k][0])
        resolved = exact[start][1] <= o["resolution"] * exact[start][0]
        if not resolved:
            # every error is below what the formula resolves (errors near sqrt(eps) ||T||): the ranking is
            # rounding, so take the first of the preference order, the paper's level first
            start = next(k for k in PREFERENCE if k in roms)
            if start not in exact:
                evaluate(start)
        order = sorted(roms, key=lambda k: cands[k]["surrogate_h2_error"])
        return start, roms, order, exact[start], resolved, cands, sur, srec, bt._gram

    def _phases(self, r, param, theta0, ev0, sur, srec, roms_for_refinement):
        """Surrogate phase, exact check (refining the surrogate if needed), full phase; returns
        (theta, evaluation, record)."""
        o, full = self.options, self._full
        rec = {"iterations_surrogate": 0, "iterations_full": 0, "evaluations": 0, "refinements": 0,
               "history": [], "history_full": [], "stop_reason_full": None, "precond": None}
        while True:
            ev_s = h2_objective(sur, *param.matrices(theta0))
            first_s = Evaluation(ev_s.value, ev_s.floor, param.gradient(theta0, ev_s.gradient), ev_s)
            th, cur_s, pairs, its, reason_s, hs, cnt, h = self._descend(sur, param, theta0, first_s, o["maxit"])
            rec.update({"iterations_surrogate": rec["iterations_surrogate"] + its, "stop_reason": reason_s,
                        "history": [float(np.sqrt(max(v, 0.0))) for v in hs], "precond": h, "surrogate": srec,
                        "h2_error_surrogate": float(np.sqrt(max(cur_s.value, 0.0))),
                        "h2_error_surrogate_start": float(np.sqrt(max(ev_s.value, 0.0)))})
            rec["evaluations"] += cnt["evaluations"] + 2
            ev_f = h2_objective(full, *param.matrices(th))
            if ev_f.stable and ev_f.value < ev0.value - ev0.floor:
                break
            if rec["refinements"] >= o["refinements"] or srec["all_hankel_values"]:
                rec["stop_reason_full"] = "surrogate result not better than the start in exact error"
                return theta0, Evaluation(ev0.value, ev0.floor, param.gradient(theta0, ev0.gradient), ev0), rec
            rec["refinements"] += 1
            sur, srec = self._surrogates.choose(r, roms_for_refinement, o["surrogate_tol"], 2 * srec["states_asked"])
        cur = Evaluation(ev_f.value, ev_f.floor, param.gradient(th, ev_f.gradient), ev_f)
        rec["history_full"] = [float(np.sqrt(max(ev_f.value, 0.0)))]
        if not o["full_maxit"]:
            rec["stop_reason_full"] = "full_maxit = 0"
            return th, cur, rec
        cnt = {"evaluations": 0, "lu": 0}
        # each evaluation costs r LUs: stop after the first iteration that gains less than rtol, and after
        # the first failed line search (the surrogate's optimum is within its distance of this one)
        res = lbfgs_descent(self._objective(full, param, cnt), th, precond=h, maxit=o["full_maxit"],
                            memory=o["memory"], rtol=o["rtol"], window=1, first=cur, pairs=pairs,
                            max_backtracks=o["full_backtracks"], retry=False)
        rec["history_full"] += [float(np.sqrt(max(v, 0.0))) for v in res.history[1:]]
        rec.update({"iterations_full": res.iterations, "stop_reason_full": res.reason})
        rec["evaluations"] += cnt["evaluations"]
        return res.x, res.best, rec

    def _setup_parts(self, gram, gram_fresh, adi_fresh, svd_before):
        """(setup_cost, setup_paid): what a fresh reducer pays for the r-independent work this call
        relied on, by part, and what this call paid of it (:func:`~morsuite.reducers.outcome.standalone_time`).

        Parts: ``adi`` (the Gramian factors), ``bt_products`` (the factor products), ``bt_svd`` (the
        SVDs of the BT levels and of the first-order surrogate source), ``surrogates`` (the first-order
        surrogate models and their distances, :class:`~morsuite.reducers.h2.starts.Surrogates`) and ``full_target``.
        """
        svd_keys = set(self._labels()) - {"irka"} | {"fo"}
        svd_times = gram["svd_times"]
        used = [k for k in svd_keys if k in svd_times]
        sur_cost, sur_paid = self._ledger.parts("surrogates")
        full_cost, full_paid = self._ledger.parts("full_target")
        cost = {"adi": gram["times"]["adi"], "bt_products": gram["times"]["products"],
                "bt_svd": float(sum(svd_times[k] for k in used)), "surrogates": sur_cost,
                "full_target": full_cost}
        paid = {"adi": gram["times"]["adi"] if adi_fresh else 0.0,
                "bt_products": gram["times"]["products"] if gram_fresh else 0.0,
                "bt_svd": float(sum(svd_times[k] for k in used if k not in svd_before)),
                "surrogates": sur_paid, "full_target": full_paid}
        return cost, paid

    def _descent(self):
        o, fom = self.options, self.fom
        if o["descent"] != "auto":
            return o["descent"]
        return "varpro" if (fom.m == 1 and o["parametrization"] == "general") else "lbfgs"

    def _reduce(self, r):
        o, fom = self.options, self.fom
        adi = {k: o[k] for k in ADI_OPTIONS}
        t0 = time.perf_counter()
        param_cls = PARAMETRISATIONS[o["parametrization"]]
        lu0 = self._full.lu_count if self._full is not None else 0
        self._decision_lus = {"lu": 0}  # LUs of the H2 evaluator's decisions (h2_decision.decision_h2)
        self._ledger.begin()
        bt0 = None if self._surrogates is None else self._surrogates.bt
        svd_before = set(bt0._gram["svd_times"]) if bt0 is not None and bt0._gram is not None else set()
        start, roms, order, (e0, f0, _), resolved, cands, sur, srec, gram = self._start(r, adi, param_cls)
        start_rom = roms[start]
        # paid by this call only when the factors were computed for this reducer and not charged before
        # (a reducer reused across r pays them once; later calls report them as reused setup)
        gram_fresh = id(gram) not in self._adi_charged
        adi_fresh = bool(gram.get("adi_computed")) and gram_fresh
        self._adi_charged.add(id(gram))
        setup_cost, setup_paid = self._setup_parts(gram, gram_fresh, adi_fresh, svd_before)
        t_ranked = time.perf_counter()
        param = param_cls(start_rom.order, fom.m, fom.p)
        theta0 = param.from_rom(start_rom)
        descent = self._descent()
        # the descents keep the order of their start: candidates of another order (capped by the Gramians'
        # rank) are not descended from
        order = [k for k in order if roms[k].order == start_rom.order]
        rec = {"iterations_surrogate": 0, "iterations_full": 0, "evaluations": 0, "refinements": 0,
               "history": [], "history_full": [], "stop_reason": None, "stop_reason_full": None, "surrogate": srec}
        theta, skipped, gnorm = theta0, None, None
        e_sur = cands[start]["surrogate_h2_error"]
        if not resolved:
            skipped = (f"the start's exact H2 error {e0:.3e} is below the resolution of the objective (its "
                       f"floor {f0:.1e} > {o['resolution']:g} of it): returned unchanged")
            rec.update(stop_reason="skipped", stop_reason_full="skipped")
        elif not abs(e_sur - e0) <= SURROGATE_MISMATCH * e0:
            # the most accurate surrogate the Gramian factors give is farther from the model than the start's
            # error (the DSMS from r = 18: 24 states, all Hankel values above hsv_tol): no descent against it
            skipped = (f"the surrogate ({srec['states']} states) gives the start an H2 error of {e_sur:.3e}, its "
                       f"exact error is {e0:.3e}: the surrogate does not resolve the model at this error; the "
                       f"start is returned unchanged")
            rec.update(stop_reason="skipped", stop_reason_full="skipped")
        elif descent == "varpro" and fom.p > 1:
            with blas_threads(1):
                kdfl, prec = simo_phase(roms, order, sur, self._full, gtol=o["gtol"], maxit=o["simo_maxit"],
                                        chord_maxit=o["chord_maxit"], starts=o["starts"])
            rec.update(prec)
            if kdfl is not None:
                theta = np.concatenate([np.asarray(X, dtype=float).ravel() for X in kdfl])
        elif descent == "varpro":
            with blas_threads(1):
                kdfl, prec = pole_phase(roms, order, sur, self._full, gtol=o["gtol"], maxit=o["newton_maxit"],
                                        chord_maxit=o["chord_maxit"], starts=o["starts"],
                                        cluster_rounds=o["cluster_rounds"],
                                        tighter=None if not o["cluster_polish"] else
                                        (lambda: self._surrogates.target(o["cluster_polish"] * srec["states_asked"])[0]))
            rec.update(prec)
            if kdfl is not None:
                theta = np.concatenate([np.asarray(X, dtype=float).ravel() for X in kdfl])
        else:
            ev0 = h2_objective(self._full, *param.matrices(theta0))
            theta, cur, prec = self._phases(r, param, theta0, ev0, sur, srec, {start: start_rom})
            prec.pop("precond", None)
            rec.update(prec)
            gnorm = float(np.linalg.norm(cur.gradient))
        t_desc = time.perf_counter()
        rom = param.rom(theta)
        returned_start = theta is theta0
        if skipped:
            e, floor, st = e0, f0, {"rho": None, "value": e0 ** 2, "lu_count": 0}
        else:
            # the start returned unchanged: its exact evaluation stands (no second quadrature)
            e, floor, _ = (e0, f0, None) if returned_start else decision_h2(fom, rom, counter=self._decision_lus)
            if not returned_start and e > e0 + floor + f0:
                # never worse than the start (at the decision's accuracy)
                rec["stop_reason_full"] = f"result ({e:.6e}) worse than the start ({e0:.6e}): start returned"
                theta, rom, returned_start = theta0, param.rom(theta0), True
                e, floor, _ = decision_h2(fom, rom, counter=self._decision_lus)
            # ||E||^2 for rho from the H2 evaluator where the pole-residue formula's value is rounding
            st = full_stationarity(self._full, *standard_realization(rom),
                                   reference=(e * e, 2.0 * e * floor + floor ** 2))
        rho = st["rho"]
        converged = bool(not skipped and rho is not None and rho <= o["gtol"])
        reasons = (rec.get("stop_reason"), rec.get("stop_reason_full"))
        status = ("skipped" if skipped else "converged" if converged
                  else "cap" if any(x in ("cap", "maxit") for x in reasons) else "stalled")
        lu_exact = self._full.lu_count - lu0 + self._decision_lus["lu"]
        lu_irka = cands.get("irka", {}).get("lu_count", 0)
        lu_gram = int(gram["c"].lu_count) if adi_fresh else 0
        info = {
            "start": start, "start_ranking_resolved": bool(resolved), "start_h2_error": e0,
            "start_h2_error_floor": f0, "candidates": cands, "descent": descent, "parametrization": param.name,
            "variables": param.size, "h2_norm": float(np.sqrt(self._full.norm2)),
            "h2_error": float(e), "h2_error_floor": float(floor), **rec, "skipped": skipped,
            "returned_start": bool(returned_start),
            "iterations": rec["iterations_surrogate"] + rec["iterations_full"],
            "converged": converged, "status": status, "relative_gradient": rho, "gtol": o["gtol"],
            "relative_gradient_pole_residue": st.get("rho_pole_residue"), "relative_gradient_form": st.get("rho_form"),
            "relative_gradient_norm": st.get("value_form"),
            "gram_condition": st.get("gram_condition"),
            "gradient_norm": gnorm, "max_pole_real": float(np.max(rom.poles().real)),
            "lu_count": lu_gram + lu_irka + lu_exact,
            "lu_breakdown": {"gramians": lu_gram, "irka": lu_irka, "exact": lu_exact},
            "lu_count_gramians": int(gram["c"].lu_count),
            "time_breakdown": {"adi": gram["times"]["adi"] if adi_fresh else 0.0,
                               "starts_and_ranking": t_ranked - t0, "descent": t_desc - t_ranked,
                               "certificate": time.perf_counter() - t_desc},
            "setup_cost": setup_cost, "setup_paid": setup_paid,
            "setup_reused": any(setup_cost[k] > setup_paid[k] for k in setup_cost),
        }
        if skipped:
            self.warn(f"so-h2: {skipped}", AccuracyWarning)
        elif not converged:
            self.warn(f"so-h2 at r = {r} did not converge ({status}): relative gradient {rho:.2e} > gtol = "
                      f"{o['gtol']:g} against the full model (H2 error {e:.4e}, start {start} {e0:.4e})",
                      ConvergenceWarning)
        return rom, info
