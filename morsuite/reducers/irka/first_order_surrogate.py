r"""The surrogate phase of ``irka-fo`` (:class:`SurrogatePhase`, mixed into
:class:`~morsuite.reducers.irka.first_order.IRKAFO`): the surrogate's order, its construction from the
start's balanced truncation, the iteration against it and Newton's method on its fixed-point map
(``docs/design/irka_fo.md``, section "What was kept"). Cost: dense work only, no sparse LU;
the surrogate's construction (a first-order BT projection with N states) is
:math:`O(n_1\,\mathrm{rank}\,N)`, each map evaluation :math:`O(Nr(r + m + p) + r^3)`.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from .surrogate import ModalSurrogate, SurrogateMap, fixed_point_jacobian, iterate, newton_fixed_point

__all__ = ["SurrogatePhase", "SURROGATE_HEADROOM"]

#: a new surrogate projection is built for this many times the N asked for, so that it serves the
#: next orders of a sweep too (N grows slowly with r: 166 / 254 / 307 / 347 on tcom(nc=2000) at
#: 12 / 28 / 44 / 60 states; one build at 381 columns then serves 28 to 60)
SURROGATE_HEADROOM = 1.5


class SurrogatePhase:
    """Methods of ``irka-fo``'s surrogate strategy (module docstring); they use the reducer's
    ``options``, ``fom``, ``_bt_reducer()`` and ``max_order()``."""

    def _surrogate_states(self, r) -> int:
        """N: surrogate_states, or the smallest N >= 2r whose Hankel tail sum is below
        surrogate_tol times the tail beyond r (at most surrogate_max_states and the number
        of Hankel singular values bt keeps)."""
        o = self.options
        bt = self._bt_reducer()
        hsv = np.asarray(bt._svd("fo")[1]) if bt._gram is not None else None
        if hsv is None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                hsv = np.asarray(bt.reduce(min(r, self.max_order())).info["hsv"])
        n_ok = int(np.sum(hsv > bt.options["hsv_tol"] * hsv[0]))
        if o["surrogate_states"]:
            return min(o["surrogate_states"], n_ok)
        tail = np.concatenate([np.cumsum(hsv[::-1])[::-1], [0.0]])  # tail[i] = sum_{j >= i} hsv_j
        target = o["surrogate_tol"] * tail[min(r, tail.size - 1)]
        ok = np.flatnonzero(tail <= target)
        n = int(ok[0]) if ok.size else hsv.size
        return int(max(min(max(n, 2 * r), o["surrogate_max_states"], n_ok), min(r, n_ok)))

    def _surrogate_phase(self, r, data):
        """Plain IRKA against the surrogate, then Newton from its best iterates if needed; the
        data the full model starts from (module docstring)."""
        o = self.options
        t0 = time.perf_counter()
        n = self._surrogate_states(r)
        sur = self._modal_surrogate(n)
        smap = SurrogateMap(sur, self.fom.band)
        tol = min(o["tol"], 1e-8)
        kw = dict(maxit=o["surrogate_maxit"], tol=tol, plain=o["surrogate_plain"],
                  relaxation=o["surrogate_relaxation"], keep=o["newton_starts"], stall=o["surrogate_stall"])
        run = iterate(smap, *data, stop_below=o["newton_early"], **kw)
        rec = {"states": sur.states, "kappa": sur.kappa, "newton": [], "newton_early": None}
        found, handed_over = [], False
        if run["stopped_early"]:
            # a contracting iteration near a fixed point: Newton's method (closed-form Jacobian) finishes it;
            # if it does not converge, the iteration goes on where it stopped
            nr = newton_fixed_point(smap, *run["last"], tol=1e-10, maxit=min(o["newton_maxit"], 10), stall_tol=10 * tol)
            rec["newton_early"] = {"at_iteration": run["iterations"], "measure": run["measure"], "resumed": False}
            rec["newton"].append(_newton_record(nr, run["iterations"]))
            if nr.converged and np.isfinite(nr.e2) and nr.jacobian is not None:
                found.append(nr)
            elif run["measure"] >= 10.0 * o["tol"]:
                run = iterate(smap, *run["last"], start=run["iterations"], best=run["best"], **kw)
                rec["newton_early"]["resumed"] = True
            else:
                handed_over = True
            # else: the surrogate's map is at its rounding floor within ten times the full model's tol
            # (dsms(g=1000) at 12 states: 3.6e-6 after 4 steps, Newton stalls there): the full model finishes
        best = run["best"]
        rec.update({"converged": run["converged"], "iterations": run["iterations"],
                    "relaxed_from": run["relaxed_from"], "measure": run["measure"], "stalled": run["stalled"],
                    "best_h2": [float(np.sqrt(max(b[0], 0.0))) for b in best]})
        data = run["last"] if run["converged"] or handed_over else (best[0][2] if best else run["last"])
        if found or handed_over or (run["converged"] and run["relaxed_from"] is None):
            starts = []  # Newton converged already, or the plain iteration converges: so will the full model's
        elif run["converged"] or run["measure"] < o["newton_switch"]:
            starts = [(np.nan, run["iterations"], run["last"])]  # polish, and the Jacobian for the chord
        else:
            starts = best[:o["newton_starts"]]
        for e2, it, start in starts:
            nr = newton_fixed_point(smap, *start, tol=1e-10, maxit=o["newton_maxit"], stall_tol=10 * tol)
            rec["newton"].append(_newton_record(nr, it))
            if nr.converged and np.isfinite(nr.e2) and nr.jacobian is not None:
                found.append(nr)
        chart = jac = None
        if found:
            nr = min(found, key=lambda t: t.e2)
            data, chart, jac = nr.data, nr.chart, nr.jacobian
        elif run["converged"] and run["relaxed_from"] is not None:
            chart, jac = fixed_point_jacobian(smap, *run["last"])  # Newton stalled: the relaxed fixed point
        if jac is not None:
            try:
                step = np.linalg.inv(np.eye(jac.shape[0]) - jac)
                self._chord = {"chart": chart, "step": step, "residual": np.inf, "steps": 0, "active": True,
                               "dropped_at": None}
                rec["jacobian_spectral_radius"] = float(np.max(np.abs(np.linalg.eigvals(jac))))
            except np.linalg.LinAlgError:
                pass
        if run["relaxed_from"] is not None:
            # the plain iteration did not converge against the surrogate: nor will it against the model
            self._fallback_relaxation = o["surrogate_relaxation"]
        rec.update(evaluations=smap.evaluations, analytic_jacobians=smap.analytic_jacobians,
                   build_s=self._surrogate_build_s, time_s=time.perf_counter() - t0,
                   h2_of_start_data=rec["best_h2"][0] if rec["best_h2"] else None)
        self._surrogate = rec
        return data

    def _modal_surrogate(self, n):
        """The first-order BT with n states from the start's SVD, in modal form (no stability check:
        balanced truncation of a stable model is stable). The projection is cached on the BT reducer
        with headroom (:data:`SURROGATE_HEADROOM`) and serves later orders: its time, when this call
        built it, is ``_surrogate_build_s`` and ``_projection_cost`` (an r-independent part of the
        setup, as bt's SVD)."""
        bt = self._bt_reducer()
        bt._gramians()
        U, hsv, Vt = bt._svd("fo")
        before = (bt._gram["projected"].get("first-order") or {}).get("R", 0)
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rom, _ = bt._first_order(n, U, hsv, Vt, headroom=SURROGATE_HEADROOM)
        t = time.perf_counter() - t0
        if bt._gram["projected"]["first-order"]["R"] != before:
            self._surrogate_build_s = t
            self._projection_cost = t
        return ModalSurrogate(rom)


def _newton_record(nr, it):
    return {"start_iteration": it, "converged": nr.converged, "steps": nr.steps, "residual": nr.residual,
            "h2": float(np.sqrt(max(nr.e2, 0.0))) if np.isfinite(nr.e2) else None}


