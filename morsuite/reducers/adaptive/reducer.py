r"""The ``adaptive`` reducer: greedy rational interpolation, points where the estimated band error is largest.

See :mod:`morsuite.reducers.adaptive` for the method, its options and its cost.
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np

from ...errors import ConvergenceWarning, OptionError, RankWarning, SingularShiftError
from ...linalg.dense import sigma_max
from ...rom import SecondOrderROM
from ..base import Option, Reducer
from ..registry import Description
from ..krylov.reducer import definiteness, is_symmetric
from ..krylov.soar import KernelProjector, RealBasis
from .estimate import ReducedResponse, band_estimate, band_option, local_maxima, order_at_tol
from .points import make_point

__all__ = ["Adaptive"]

#: a candidate frequency closer than this (relative) to a frequency already sampled is skipped
MIN_GAP = 1e-3
#: an estimate at or below this (relative to the band peak) is rounding: the model is exact on the band
#: (its basis holds every direction of T that the band sees), and no point can improve it
EXACT = 1e-11
#: ``compress``: the surrogate's first tolerance without ``tol``, how much closer to T than the compressed model it
#: must come (its estimate at most this times their distance), and the rounds of tightening
SURROGATE_TOL = 1e-4
SURROGATE_RATIO = 0.1
SURROGATE_ROUNDS = 6
#: a point where S(s) is singular (at a pole) moves off the axis by this fraction of |s|
OFF_AXIS = 1e-3


class Adaptive(Reducer):
    """Greedy rational interpolation driven by an error estimate (module :mod:`morsuite.reducers.adaptive`).

    ``reduce(r)`` returns a :class:`~morsuite.rom.SecondOrderROM`: with ``tol`` None, of order r (the
    first r columns of the greedy basis); with ``tol``, the greedy basis when its estimated band error
    first meets ``tol`` (r is then the largest order allowed). The points, their samples and the basis
    are kept: a later call continues the greedy and pays only the LUs of new points.
    """

    name = "adaptive"

    DESCRIPTION = Description(
        label="adaptive interpolation (estimate-driven points)", result="by-option",
        targets="band error below tol, estimated from a richer model and validated by true samples",
        cost="one per greedy point (and per validation sample), released before the next",
        use_for="large finite-element models to a band tolerance at a few LUs; with compress, an "
                "H2-optimal model at a few LUs",
        options=("tol", "max_lus", "levels", "validate", "compress"), stress={"max_lus": 8}, default=True,
        band_option="band", page="adaptive", order=75)

    OPTIONS = {
        "tol": Option(None, "float", "target of the estimated band error, max over the band of sigma_max(T - T_r) "
                      "relative to the band peak of sigma_max(T); None: grow to r columns",
                      low=0, high=1, open_low=True, open_high=True, nullable=True),
        "max_lus": Option(40, "int", "budget of sparse LUs (expansion points and validation samples)", low=1),
        "levels": Option(6, "int", "moments per point and side (F and L^T) in the reduced model", low=1),
        "enrich_levels": Option(2, "int", "further moments per point and side in the richer model of the estimate",
                                low=1),
        "validate": Option(0, "int", "once the estimate meets tol: true samples (one LU each) at the estimate's "
                           "largest peaks; one above tol becomes a point", low=0),
        "grid": Option(400, "int", "log-spaced frequencies of the estimate (the peak's and the reduced models' band "
                       "poles are added)", low=16),
        "peak_grid": Option(200, "int", "log-spaced frequencies of the band peak of sigma_max(T) that tol is relative "
                            "to (the suite's sampled band errors: 200); 0: every frequency of the estimate", low=0),
        "band": Option(None, "array", "band (w1, w2) in rad/s (default: the model's band)", nullable=True),
        "start": Option("auto", "any", "first point: 'auto' (real, the band's geometric mean), 'center' (j times "
                        "it) or a number in the closed right half-plane"),
        "compress": Option(None, "choice", "return r first-order states: this reducer applied to the greedy's model "
                           "(a surrogate, grown until 10 times closer to T than the result; no LU of the full "
                           "model); None: the greedy's second-order model", choices=(None, "bt", "irka-fo"),
                           nullable=True),
        "orth_tol": Option(1e-10, "float", "deflation tolerance of SOAR and of the basis", low=0, high=1,
                           open_low=True, open_high=True),
        "reorth": Option(2, "int", "Gram-Schmidt passes per column", low=1, high=3),
    }

    def __init__(self, fom, **options):
        super().__init__(fom, **options)
        self._state = None

    @classmethod
    def states_for(cls, options: dict) -> int:
        """2 (a second-order model of order r), or 1 with ``compress`` (r first-order states). Cost: none."""
        return 1 if options.get("compress") else 2

    def _check_options(self):
        o = self.options
        self.options["band"] = band_option(o["band"], "Adaptive")
        start = o["start"]
        if isinstance(start, str):
            if start not in ("auto", "center"):
                raise OptionError(f"The 'start' parameter of Adaptive must be 'auto', 'center' or a number in the "
                                  f"closed right half-plane. Got {start!r} instead.")
        else:
            try:
                s = complex(start)
            except (TypeError, ValueError):
                s = complex("nan")
            if isinstance(start, bool) or not np.isfinite(s) or s.real < 0:
                raise OptionError(f"The 'start' parameter of Adaptive must be 'auto', 'center' or a number in the "
                                  f"closed right half-plane. Got {start!r} instead.")

    def _band(self):
        b = self.options["band"]
        return tuple(float(x) for x in (b if b is not None else self.fom.band))

    def _start(self) -> complex:
        start, (lo, hi) = self.options["start"], self._band()
        if start == "auto":
            return complex(math.sqrt(lo * hi))
        if start == "center":
            return complex(0.0, math.sqrt(lo * hi))
        s = complex(start)
        return complex(s.real, abs(s.imag))

    # -- state: points, basis, samples ------------------------------------------------------
    def _init_state(self):
        fom, o = self.fom, self.options
        symmetric = all(is_symmetric(X) for X in (fom.M, fom.D, fom.K))
        transposed = (fom.M, fom.D, fom.K) if symmetric else tuple(X.T.tocsr() for X in (fom.M, fom.D, fom.K))
        project = KernelProjector(fom.G) if fom.n2 else None
        self._state = {
            "solver": fom.new_solver(cache_size=0), "symmetric": symmetric, "transposed": transposed,
            "project": project, "basis": RealBasis(fom.n1, o["orth_tol"], o["reorth"], project),
            "points": [], "enrichment": [], "samples": [], "log": [], "lus": 0, "seconds": 0.0,
            "products": {"cols": 0, "MV": None, "DV": None, "KV": None},
            "rich": None,  # (basis columns it was made for, Q, MQ, DQ, KQ)
        }
        return self._state

    def _add_point(self, s, *, lu=None, kind="point", before=None):
        st, o = self._state, self.options
        t0 = time.perf_counter()
        try:
            pt = make_point(self.fom, st["solver"], s, o["levels"], o["enrich_levels"], transposed=st["transposed"],
                            orth_tol=o["orth_tol"], reorth=o["reorth"], lu=lu, symmetric=st["symmetric"])
        except SingularShiftError:  # s is a pole of the model (an undamped mode on the axis): step off it
            s = complex(OFF_AXIS * abs(s), s.imag) if s.imag else complex(s.real * (1 + OFF_AXIS))
            self.warn(f"adaptive: S(s) is singular at the point s = {s:.6g}; moved to {s:.6g}")
            pt = make_point(self.fom, st["solver"], s, o["levels"], o["enrich_levels"], transposed=st["transposed"],
                            orth_tol=o["orth_tol"], reorth=o["reorth"], symmetric=st["symmetric"])
            lu = None
        if lu is None:
            st["lus"] += 1
        basis = st["basis"]
        for block in pt.primary:
            basis.add(block)
        st["enrichment"].extend(pt.enrichment)
        st["points"].append(pt)
        if pt.omega is not None:
            st["samples"].append({"omega": pt.omega, "T": pt.T, "point": True})
        st["seconds"] += time.perf_counter() - t0
        row = {"kind": kind, "point": pt.s, "columns": basis.cols, "lus": st["lus"], "seconds": st["seconds"],
               "lu_seconds": pt.lu_seconds, "solve_seconds": pt.solve_seconds, "solves": pt.solves,
               "levels": pt.levels}
        if before is not None:
            row.update(before)
        st["log"].append(row)
        return pt

    def _sample(self, omega):
        """One true sample T(j omega) (one LU); returns (T, lu, (LU seconds, solve seconds)), the LU kept for a
        promotion to a point."""
        st = self._state
        t0 = time.perf_counter()
        lu = st["solver"].factor(1j * omega)
        t1 = time.perf_counter()
        X = lu.solve(self.fom.F)
        T = self.fom.L @ X.real + 1j * (self.fom.L @ X.imag)
        st["lus"] += 1
        st["seconds"] += time.perf_counter() - t0
        st["samples"].append({"omega": float(omega), "T": T, "point": False})
        return T, lu, (t1 - t0, time.perf_counter() - t1)

    # -- projections ----------------------------------------------------------------------------------
    def _products(self):
        """M V, D V, K V for the whole basis, grown by the new columns only."""
        st, fom = self._state, self.fom
        V, pr = st["basis"].V, st["products"]
        c0 = pr["cols"]
        if c0 < V.shape[1]:
            new = V[:, c0:]
            for key, X in (("MV", fom.M), ("DV", fom.D), ("KV", fom.K)):
                block = X @ new
                pr[key] = block if pr[key] is None else np.hstack([pr[key], block])
            pr["cols"] = V.shape[1]
        return V, pr["MV"], pr["DV"], pr["KV"]

    def _rich_part(self):
        """Q: the enrichment columns orthonormalised against the basis (with M Q, D Q, K Q), per basis size."""
        st, fom, o = self._state, self.fom, self.options
        V = st["basis"].V
        if st["rich"] is not None and st["rich"][0] == (V.shape[1], len(st["enrichment"])):
            return st["rich"][1:]
        Q = RealBasis(fom.n1, o["orth_tol"], o["reorth"], st["project"])
        Q._V = np.zeros((fom.n1, max(16, V.shape[1] + 4 * len(st["enrichment"]))))
        Q._V[:, :V.shape[1]] = V
        Q.cols = V.shape[1]
        for block in st["enrichment"]:
            Q.add(block)
        Qe = Q.V[:, V.shape[1]:].copy()
        rich = (Qe, fom.M @ Qe, fom.D @ Qe, fom.K @ Qe)
        st["rich"] = ((V.shape[1], len(st["enrichment"])),) + rich
        return rich

    def _reduced(self, r):
        """(Mr, Dr, Kr, Fr, Lr) of the first r columns and of the richer space U, and V_r."""
        fom, st = self.fom, self._state
        V, MV, DV, KV = self._products()
        Q, MQ, DQ, KQ = self._rich_part()
        U = np.hstack([V, Q])
        sym = st["symmetric"]
        mats = []
        for XV, XQ in ((MV, MQ), (DV, DQ), (KV, KQ)):
            XU = np.hstack([XV, XQ])
            A = U.T @ XU
            mats.append(0.5 * (A + A.T) if sym else A)
        FU, LU = U.T @ fom.F, fom.L @ U
        rich = tuple(mats) + (FU, LU)
        rom = tuple(X[:r, :r] for X in mats) + (FU[:r], LU[:, :r])
        return rom, rich, V[:, :r]

    def _estimate(self, r):
        rom_m, rich_m, Vr = self._reduced(r)
        lo, hi = self._band()
        check = 1j * np.geomspace(lo, hi, 5)
        rom, rich = ReducedResponse(*rom_m, check=check), ReducedResponse(*rich_m, check=check)
        est = band_estimate(rom, rich, (lo, hi), self.options["grid"], self.options["peak_grid"])
        return est, rom_m, Vr

    def _true_errors(self, est, rom):
        """The true relative error of the model at every kept sample (plain rows)."""
        rows = []
        for x in self._state["samples"]:
            s = np.array([1j * x["omega"]])
            err = float(sigma_max((x["T"] - rom(s)[0])[None])[0]) / est.peak
            rows.append({"omega": x["omega"], "true_rel_error": err, "estimate": est.at(x["omega"]),
                         "point": x["point"]})
        return rows

    def _next_frequency(self, est):
        """The largest local maximum of the estimate away from every frequency sampled so far."""
        taken = np.array([x["omega"] for x in self._state["samples"]])
        for i in local_maxima(est.estimate):
            w = est.grid[i]
            if not taken.size or np.min(np.abs(taken - w)) > MIN_GAP * w:
                return float(w)
        return None

    # -- the greedy -------------------------------------------------------------------------------------
    def _grow(self, r, tol):
        """Add points until the basis has r columns (tol None) or the estimate meets tol (validated if asked),
        or the budget ends. Returns (status, estimate, rom matrices, V_r, order)."""
        st, o = self._state, self.options
        if not st["points"]:
            self._add_point(self._start(), kind="start")
        while True:
            order = min(r, st["basis"].cols)
            est, rom_m, Vr = self._estimate(order)
            if tol is None and (st["basis"].cols >= r or est.max <= EXACT):
                return "direct", est, rom_m, Vr, order
            if tol is not None and est.max <= max(tol, EXACT):
                if o["validate"] == 0:
                    return "converged", est, rom_m, Vr, order
                status = self._validate(est, order, tol)
                if status == "passed":
                    return "converged", est, rom_m, Vr, order
                if status == "budget":
                    return "budget", est, rom_m, Vr, order
                continue  # a failed sample became a point (or the next point is its frequency)
            if tol is not None and st["basis"].cols >= r:
                return "cap", est, rom_m, Vr, order
            if st["lus"] >= o["max_lus"]:
                return "budget", est, rom_m, Vr, order
            w = self._next_frequency(est)
            if w is None:  # every peak of the estimate is sampled already: nothing left to learn from it
                return ("converged" if tol is None else "stalled"), est, rom_m, Vr, order
            before = {"omega": w, "estimate_max_before": est.max, "estimate_at": est.at(w), "r_before": order}
            pt = self._add_point(1j * w, before=before)
            # the point's own sample is the true error of the model before it: the estimate validated there
            err = float(sigma_max((pt.T - est.rom(np.array([pt.s]))[0])[None])[0]) / est.peak
            st["log"][-1]["true_rel_error"] = err

    def _validate(self, est, order, tol):
        """True samples at the estimate's largest peaks until ``validate`` of them hold for this model;
        a sample above tol becomes a point (its LU reused). Returns "passed", "failed" or "budget"."""
        st, o = self._state, self.options
        rows = [x for x in self._true_errors(est, est.rom) if not x["point"]]
        worst = max(rows, key=lambda x: x["true_rel_error"], default=None)
        if worst is not None and worst["true_rel_error"] > tol:  # an old sample fails the new model
            if st["lus"] >= o["max_lus"]:
                return "budget"
            self._add_point(1j * worst["omega"], kind="validation-failed",
                            before={"omega": worst["omega"], "true_rel_error": worst["true_rel_error"],
                                    "estimate_at": worst["estimate"], "r_before": order})
            return "failed"
        have = len(rows)
        while have < o["validate"]:
            if st["lus"] >= o["max_lus"]:
                return "budget"
            w = self._next_frequency(est)
            if w is None:
                return "passed"
            T, lu, (lu_s, solve_s) = self._sample(w)
            err = float(sigma_max((T - est.rom(np.array([1j * w]))[0])[None])[0]) / est.peak
            st["log"].append({"kind": "validation", "point": complex(0, w), "omega": w, "true_rel_error": err,
                              "estimate_at": est.at(w), "r_before": order, "lus": st["lus"],
                              "columns": st["basis"].cols, "seconds": st["seconds"], "lu_seconds": lu_s,
                              "solve_seconds": solve_s, "solves": self.fom.m})
            if err > tol:
                st["samples"].pop()  # it becomes a point: its sample is kept as the point's
                self._add_point(1j * w, lu=lu, kind="validation-failed",
                                before={"omega": w, "true_rel_error": err, "estimate_at": est.at(w),
                                        "r_before": order})
                return "failed"
            have += 1
        return "passed"

    # -- reduce -----------------------------------------------------------------------------------------
    def _reduce(self, r):
        fresh = self._state is None
        st = self._state or self._init_state()
        lus0, sec0 = st["lus"], st["seconds"]
        t0 = time.perf_counter()
        fom, o = self.fom, self.options
        if o["compress"]:  # the surrogate: tightened until it is 10 times closer to T than the compressed model
            tol = o["tol"] if o["tol"] is not None else SURROGATE_TOL
            for _ in range(SURROGATE_ROUNDS):
                status, est, rom_m, Vr, order = self._grow(fom.order, tol)
                rom = SecondOrderROM(*rom_m, basis=Vr)
                packed = self._compress_once(rom, est, r)
                gap = float(packed[1].max())
                if status != "converged" or est.max <= SURROGATE_RATIO * gap or tol <= EXACT:
                    break
                tol = max(0.5 * SURROGATE_RATIO * gap, EXACT)
        else:
            status, est, rom_m, Vr, order = self._grow(r, o["tol"])
            rom = SecondOrderROM(*rom_m, basis=Vr)
        t1 = time.perf_counter()
        if order < r and o["tol"] is None and not o["compress"]:
            why = (f"the estimate is at rounding ({est.max:.1e} <= {EXACT:g}): the model is exact on the band"
                   if est.max <= EXACT else "every peak of the estimate is sampled")
            self.warn(f"adaptive: the basis stopped at {order} columns ({why}); r capped from {r} to {order}",
                      RankWarning)
        if status == "budget":
            self.warn(f"adaptive: the LU budget max_lus = {o['max_lus']} ended the greedy with the estimated band "
                      f"error at {est.max:.3e}" + (f" (tol {o['tol']:g})" if o["tol"] is not None else ""),
                      ConvergenceWarning)
        elif status in ("cap", "stalled"):
            self.warn(f"adaptive: the estimated band error {est.max:.3e} is above tol = {o['tol']:g} at order "
                      f"{order} ({'the order r reached' if status == 'cap' else 'every peak of the estimate sampled'})",
                      ConvergenceWarning)
        stable = bool(rom.is_stable())
        new_lus = st["lus"] - lus0
        needed = self._lus_needed(order)
        rows = self._true_errors(est, est.rom)
        info = {
            "status": status, "converged": status in ("converged", "direct"), "iterations": len(st["log"]),
            "tol": o["tol"], "estimate_max": est.max, "estimate_grid": est.grid, "estimate": est.estimate,
            "peak": est.peak, "points": [p.s for p in st["points"]],
            "validated": [{k: x[k] for k in ("omega", "true_rel_error", "estimate")} for x in rows if not x["point"]],
            "samples_at_points": [{k: x[k] for k in ("omega", "true_rel_error", "estimate")}
                                  for x in rows if x["point"]],
            "history": [self._plain_row(x) for x in st["log"]],
            "lu_count": new_lus, "lu_count_shared": 0 if fresh else max(0, needed - new_lus),
            "setup_reused": not fresh,
            "solves": sum(p.solves for p in st["points"]),
            "stable": stable, "symmetric": st["symmetric"], "basis_columns": st["basis"].cols,
            "rich_columns": int(est.rich.M.shape[0]), "response_method": {"rom": est.rom.method,
                                                                          "rich": est.rich.method},
            "time_breakdown": {"greedy": st["seconds"] - sec0, "estimate_and_projection": (t1 - t0)
                               - (st["seconds"] - sec0)},
            "setup_cost": {"greedy": self._seconds_needed(order)},
            "setup_paid": {"greedy": st["seconds"] - sec0},
        }
        if st["symmetric"]:
            info["definite"] = definiteness(*rom_m[:3])
        if o["compress"]:
            return self._compressed(packed, est, info, tol)
        return rom, info

    def _compress_once(self, surrogate, est, r):
        r"""(reduction, gap): the surrogate reduced to r first-order states with ``compress``, and the distance
        :math:`\sigma_{\max}(T_V - T_c)/\text{peak}` on the estimate's grid."""
        import scipy.sparse as sp

        from ...models.index3 import Index3Model
        from ..registry import get_class

        o = self.options
        k = surrogate.order
        model = Index3Model(sp.csr_matrix(surrogate.M), sp.csr_matrix(surrogate.D), sp.csr_matrix(surrogate.K),
                            sp.csr_matrix((0, k)), surrogate.F, surrogate.L, band=self._band(),
                            name=f"adaptive surrogate of {self.fom.name} (order {k})", check_constraints=False)
        if r > 2 * k:
            raise OptionError(f"r = {r} first-order states exceed the 2 x {k} states of the surrogate the tolerance "
                              f"gave; ask for at most {2 * k} or a smaller tol")
        with warnings.catch_warnings():  # the compression's warnings are the surrogate's, said in info
            warnings.simplefilter("ignore")
            res = get_class(o["compress"])(model).reduce(r)
        s = 1j * est.grid
        return res, sigma_max(est.rom(s) - res.rom.transfer_many(s)) / est.peak

    def _compressed(self, packed, est, info, tol):
        r"""The compressed model and its ``info``: its estimate is the surrogate's plus the exact distance between
        the two reduced models on the estimate's grid, :math:`\Delta(\omega) + \sigma_{\max}(T_V - T_c)(j\omega)/
        \text{peak}` (the triangle inequality with the estimated term). The compression's sparse LUs are of the
        surrogate, not of the full model: ``info["compress"]["lu_count"]``, not in ``lu_count``."""
        res, gap = packed
        o = self.options
        k = int(est.rom.M.shape[0])
        curve = est.estimate + gap
        converged = info["converged"] and res.info["converged"]
        rows = []  # the validation samples, for the model returned
        for x in self._state["samples"]:
            if x["point"]:
                continue
            w = np.array([1j * x["omega"]])
            Tc = res.rom.transfer_many(w)
            rows.append({"omega": x["omega"],
                         "true_rel_error": float(sigma_max(x["T"][None] - Tc)[0] / est.peak),
                         "estimate": est.at(x["omega"]) + float(sigma_max(est.rom(w) - Tc)[0] / est.peak)})
        info.update({
            "estimate": curve, "estimate_max": float(curve.max()), "stable": bool(res.rom.is_stable()),
            "status": info["status"] if not info["converged"] or converged else res.info["status"],
            "converged": converged, "validated": rows, "samples_at_points": [],
            "compress": {"method": o["compress"], "states": int(res.rom.states), "surrogate_order": int(k),
                         "surrogate_estimate_max": float(est.max), "surrogate_gap_max": float(gap.max()),
                         "surrogate_tol": tol,
                         "lu_count": int(res.info.get("lu_count", 0)), "status": res.info["status"],
                         "time_s": float(res.info["time_s"])},
        })
        info.pop("definite", None)
        return res.rom, info

    def _lus_needed(self, order):
        """LUs the greedy had made when its basis first held ``order`` columns (at least the start's)."""
        for row in self._state["log"]:
            if row["columns"] >= order:
                return int(row["lus"])
        return int(self._state["lus"])

    def _seconds_needed(self, order):
        for row in self._state["log"]:
            if row["columns"] >= order:
                return float(row["seconds"])
        return float(self._state["seconds"])

    @staticmethod
    def _plain_row(row):
        return {k: (v if not isinstance(v, dict) else dict(v)) for k, v in row.items()}

    def order_guess(self, tol: float, *, measure: str, scale: float) -> int | None:
        """The order at which the estimate meets a band tolerance (:func:`~morsuite.reducers.adaptive.estimate.order_at_tol`:
        the LUs it pays are reused by the reductions that follow); None for "h2" and "hinf"."""
        return order_at_tol(self, tol, measure)

    def max_order(self) -> int:
        """Largest admissible r: the dimension of the hidden manifold, n1 - n2."""
        return self.fom.order
