r"""Starts and surrogate of the H2 descent (``so-h2``): candidate ROMs, the dense model they are ranked on.

**Candidates.** The second-order BT levels (``bt`` with ``form`` pp, pv, vp, vv,
fv; one set of Gramian factors, shared through the model's cache) and the paper's
IRKA (``irka``), each at the requested r. Unstable ones are dropped.

**Surrogate.** A first-order BT model :math:`T_N` from the same factors, in modal
form (:class:`~morsuite.reducers.h2.gradient.ModalTarget`): every evaluation of the
H2 error against it is dense, :math:`O(N(2r)^2)`, no LU. Its own distance to the
model, :math:`\delta_N = \|T - T_N\|`, is estimated by :math:`\|T_{2N} - T_N\|`
(dense, cancellation-free; where BT errors shrink fast with N this is close) and N is
doubled from ``max(4r, 20)`` until :math:`\delta_N \le` ``surrogate_tol`` times the best
candidate's error against :math:`T_{2N}`, or until :math:`T_{2N}` holds every Hankel
singular value above ``hsv_tol`` (then :math:`T_{2N}` is the surrogate).
Since :math:`|\,\|T - T_r\| - \|T_N - T_r\|\,| \le \delta_N` for every reduced model,
ranking against :math:`T_N` can only confuse candidates closer than :math:`2\delta_N`:
those are ranked by their exact error (:class:`~morsuite.reducers.h2.gradient.FullTarget`,
r LUs each).
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from ...errors import ConvergenceWarning, RankWarning, StabilityWarning
from ...linalg.h2 import modal_form
from .gradient import ModalTarget, h2_value, second_order_realization
from ..registry import make
from ..outcome import SetupLedger

__all__ = ["LEVELS", "STARTS", "candidate_roms", "Surrogates", "standard_realization"]

LEVELS = ("pp", "pv", "vp", "vv", "fv")
STARTS = LEVELS + ("irka",)


def standard_realization(rom):
    """(A, B, C) with E = I of a second-order reduced model (its M applied as M^-1)."""
    solve = np.linalg.solve
    return second_order_realization(solve(rom.M, rom.K), solve(rom.M, rom.D), solve(rom.M, rom.F), rom.L)


def candidate_roms(fom, r, labels, adi, keep=None, bt=None):
    """The reduced models of the candidate starts ``labels`` at order r.

    Returns ``(roms, records, bt)``: label -> SecondOrderROM for the stable ones
    accepted by ``keep`` (a predicate on the ROM), label -> record (order, stable,
    lu_count, time_s, why dropped) for all, and the first-order ``bt`` reducer
    whose Gramian factors the levels used (the surrogate's source). Passing the ``bt``
    of an earlier call reuses its factor products and level SVDs (a sweep over r).
    """
    roms, recs = {}, {}
    bt = bt if bt is not None else make("bt", fom, gramian_cache="model", **adi)
    for label in labels:
        t0 = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            if label == "irka":
                res = make("irka", fom).reduce(r)
            else:
                res = make("bt", fom, form=label, gramian_cache="model", **adi).use_gramians_of(bt).reduce(r)
        rom = res.rom
        rec = {"order": int(rom.order), "stable": bool(res.info["stable"]), "time_s": time.perf_counter() - t0,
               "lu_count": int(res.info.get("lu_count", 0)), "converged": bool(res.info.get("converged", True)),
               "warnings": [f"{w.category.__name__}: {w.message}" for w in caught
                            if issubclass(w.category, (ConvergenceWarning, RankWarning, StabilityWarning))]}
        if not rec["stable"]:
            rec["dropped"] = "unstable"
        elif keep is not None and not keep(rom):
            rec["dropped"] = "not representable in the parametrisation"
        else:
            roms[label] = rom
        recs[label] = rec
    return roms, recs, bt


class Surrogates:
    """First-order BT models of a ``bt`` reducer in modal form, by order, with their estimated distances.

    Kept on the ``so-h2`` reducer: a sweep over r reuses them.
    """

    def __init__(self, bt, ledger=None):
        self.bt = bt
        self.ledger = ledger if ledger is not None else SetupLedger()  # cost of each model, made once
        self._targets = {}      # N (order asked) -> (ModalTarget, order returned)
        self._distance = {}     # N -> ||T_2N - T_N||

    def target(self, n):
        """``(ModalTarget, rom, kappa)`` of the first-order BT model of order ``n`` (capped by the
        Gramians' rank), made once and kept."""
        n = min(int(n), self.bt.max_order())
        if n not in self._targets:
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RankWarning)  # capped: the order returned says so
                rom = self.bt.reduce(int(n)).rom
            md = modal_form(rom.E, rom.A, rom.B, rom.C, rom.D)
            self._targets[n] = (ModalTarget(md.poles, md.B, md.C), rom, md.kappa)
            self.ledger.made(("surrogates", "target", n), time.perf_counter() - t0)
        self.ledger.used(("surrogates", "target", n))
        return self._targets[n]

    def distance(self, n):
        """Estimate of ||T - T_n||: ||T_2n - T_n||, dense (inf if T_n is unstable; None if T_n holds
        every Hankel singular value above hsv_tol, so that there is nothing to compare it with)."""
        if n not in self._distance:
            big, rom2, _ = self.target(2 * n)
            _, rom, _ = self.target(n)
            t0 = time.perf_counter()
            if rom.order >= rom2.order:
                self._distance[n] = None
            else:
                ev = h2_value(big, rom.A, rom.B, rom.C)
                self._distance[n] = float(np.sqrt(max(ev.value, 0.0))) if ev.stable else np.inf
            self.ledger.made(("surrogates", "distance", n), time.perf_counter() - t0)
        else:
            self.target(2 * n), self.target(n)  # relied on: their cost counts for this call too
        self.ledger.used(("surrogates", "distance", n))
        return self._distance[n]

    def choose(self, r, candidates, tol, states=None):
        """(ModalTarget, record): the model of order ``states`` if given, else the smallest
        N = max(4r, 20) 2^k whose estimated distance is at most ``tol`` times the best candidate's
        error, or the largest the factors give (every Hankel singular value above hsv_tol) if none is."""
        t0 = time.perf_counter()
        tried = []
        if states is not None:
            n = int(states)
            dist = self.distance(n)
            capped = dist is None
        else:
            n = max(4 * r, 20)
            while True:
                tgt2, rom2, _ = self.target(2 * n)
                dist = self.distance(n)
                capped = rom2.order < 2 * n
                errs = []
                for rom in candidates.values():
                    ev = h2_value(tgt2, *standard_realization(rom))
                    errs.append(np.sqrt(max(ev.value, 0.0)) if ev.stable else np.inf)
                ref = min(errs) if errs else np.inf
                tried.append({"states": self.target(n)[1].order, "distance": dist, "best_candidate_error": ref})
                if dist is not None and dist <= tol * ref:
                    break
                if capped:  # T_2n holds every Hankel singular value: the most accurate model the factors give
                    n, dist = 2 * n, None
                    break
                n *= 2
        tgt, rom, kappa = self.target(n)
        return tgt, {"states": rom.order, "states_asked": n, "distance": dist, "kappa": kappa,
                     "all_hankel_values": bool(capped), "time_s": time.perf_counter() - t0, "tried": tried}
