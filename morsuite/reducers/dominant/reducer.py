r"""The ``dominant`` reducer: modal truncation by dominance over the band, poles from SAQDPA, static correction.

See :mod:`morsuite.reducers.dominant` for the method, its options and its cost.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ...errors import ConvergenceWarning, OptionError, RankWarning
from ...rom import SecondOrderROM
from ..adaptive.estimate import ReducedResponse, band_estimate, band_option, order_at_tol
from ..base import Option, Reducer
from ..registry import Description
from ..krylov.reducer import definiteness, is_symmetric
from ..krylov.soar import RealBasis
from .qdpa import SAQDPA

__all__ = ["Dominant"]


class Dominant(Reducer):
    """Modal truncation by band dominance with the static correction (module :mod:`morsuite.reducers.dominant`).

    ``reduce(r)`` returns a :class:`~morsuite.rom.SecondOrderROM` of order r (tol None) on the static response
    and the real and imaginary parts of the most dominant converged poles' shapes; with ``tol``, the model on
    every converged pole once its estimated band error meets ``tol``. The search space, the shifts and the
    poles are kept: a later call continues the iteration.
    """

    name = "dominant"

    DESCRIPTION = Description(
        label="dominant poles (SAQDPA) + static correction", result="second-order",
        targets="the damped poles of largest dominance over the band, and T(0)",
        cost="one per Newton step (the first, at s = 0, gives the static correction)",
        use_for="models carried by a few well-separated poles (not pole clusters, not FE blocks)",
        options=("tol", "max_lus"), stress={"max_lus": 8}, default=True, band_option="band", page="adaptive",
        order=76)

    OPTIONS = {
        "tol": Option(None, "float", "target of the estimated band error (relative to the band peak of "
                      "sigma_max(T)); None: iterate until r columns", low=0, high=1, open_low=True, open_high=True,
                      nullable=True),
        "max_lus": Option(40, "int", "budget of sparse LUs (Newton steps, the static one included)", low=1),
        "eig_tol": Option(1e-8, "float", "relative constrained residual of a converged pole", low=0, high=1,
                          open_low=True, open_high=True),
        "static_correction": Option(True, "bool", "put the static response K^-1 F first in the basis, so that "
                                    "T_r(0) = T(0)"),
        "band": Option(None, "array", "band (w1, w2) in rad/s of the dominance and the estimate (default: the "
                       "model's band)", nullable=True),
        "grid": Option(400, "int", "log-spaced frequencies of the estimate (plus the models' band poles)", low=16),
        "peak_grid": Option(200, "int", "log-spaced frequencies of the band peak that tol is relative to; 0: every "
                            "frequency of the estimate", low=0),
        "orth_tol": Option(1e-10, "float", "deflation tolerance of the search space and of the modal basis", low=0,
                           high=1, open_low=True, open_high=True),
    }

    def __init__(self, fom, **options):
        super().__init__(fom, **options)
        self._qd = None

    def _check_options(self):
        self.options["band"] = band_option(self.options["band"], "Dominant")
        fom = self.fom
        if not all(is_symmetric(X) for X in (fom.M, fom.D, fom.K)):
            raise OptionError("Dominant needs symmetric M, D and K (its residues use the right eigenvectors as "
                              "left ones); use 'adaptive' or 'krylov' for this model")

    def _band(self):
        b = self.options["band"]
        return tuple(float(x) for x in (b if b is not None else self.fom.band))

    def order_guess(self, tol: float, *, measure: str, scale: float) -> int | None:
        """The order at which the estimate meets a band tolerance (:func:`~morsuite.reducers.adaptive.estimate.order_at_tol`:
        the LUs it pays are reused by the reductions that follow); None for "h2" and "hinf"."""
        return order_at_tol(self, tol, measure)

    def max_order(self) -> int:
        """Largest admissible r: the dimension of the hidden manifold, n1 - n2."""
        return self.fom.order

    # -- the modal basis -------------------------------------------------------------------------------
    def _modal_basis(self, qd, r):
        """Static columns, then Re and Im of each converged shape by decreasing dominance, up to r columns."""
        o, fom = self.options, self.fom
        B = RealBasis(fom.n1, o["orth_tol"], 2, qd.project)
        used = []
        if o["static_correction"] and qd.static is not None:
            B.add(qd.static)
        for pole in sorted(qd.poles, key=lambda p: -p.dominance):
            if B.cols >= r:
                break
            x = pole.shape
            k = int(np.argmax(np.abs(x)))
            x = x * (abs(x[k]) / x[k])  # phase-normalised: a proportionally damped mode is real
            # its imaginary part is then the shape's error (about the residual): not a direction of the mode
            keep_im = np.linalg.norm(x.imag) > math.sqrt(o["eig_tol"]) * np.linalg.norm(x)
            B.add(x[:, None] if keep_im else x.real[:, None])
            used.append(pole)
        return B.V[:, :r], used

    def _model(self, V):
        fom = self.fom
        sym = lambda A: 0.5 * (A + A.T)  # noqa: E731
        return (sym(V.T @ (fom.M @ V)), sym(V.T @ (fom.D @ V)), sym(V.T @ (fom.K @ V)), V.T @ fom.F, fom.L @ V)

    def _estimate(self, qd, rom_m):
        lo, hi = self._band()
        check = 1j * np.geomspace(lo, hi, 5)
        _, *rich_m = qd.reduced()
        rom, rich = ReducedResponse(*rom_m, check=check), ReducedResponse(*rich_m, check=check)
        return band_estimate(rom, rich, (lo, hi), self.options["grid"], self.options["peak_grid"])

    # -- reduce ---------------------------------------------------------------------------------------------
    def _reduce(self, r):
        o, fom = self.options, self.fom
        fresh = self._qd is None
        if fresh:
            self._qd = SAQDPA(fom, fom.new_solver(cache_size=0), self._band(), tol=o["eig_tol"],
                              orth_tol=o["orth_tol"])
            self._log = []
        qd = self._qd
        steps0, sec0 = qd.steps, qd.seconds
        t0 = time.perf_counter()
        if qd.steps == 0:
            qd.step(0.0)
        tol = o["tol"]
        while True:
            nxt = qd.update()
            V, used = self._modal_basis(qd, r)
            rom_m = self._model(V)
            est = self._estimate(qd, rom_m)
            self._log.append({"step": qd.steps, "poles": len(qd.poles), "columns": V.shape[1],
                              "estimate_max": est.max, "seconds": qd.seconds})
            if tol is None and V.shape[1] >= r:
                status = "direct"
                break
            # the estimate compares with the search space: it says nothing while that is the modal basis itself
            if tol is not None and est.max <= tol and qd.basis.cols > V.shape[1] and used:
                status = "converged"
                break
            if tol is not None and V.shape[1] >= r:
                status = "cap"
                break
            if qd.steps >= o["max_lus"]:
                status = "budget"
                break
            if nxt is None:
                status = "stalled"
                break
            qd.step(nxt)
        t1 = time.perf_counter()
        rom = SecondOrderROM(*rom_m, basis=V)
        if status == "budget":
            self.warn(f"dominant: the LU budget max_lus = {o['max_lus']} ended the iteration with {len(qd.poles)} "
                      f"converged poles, {V.shape[1]} columns and the estimated band error at {est.max:.3e}",
                      ConvergenceWarning)
        elif status in ("cap", "stalled"):
            self.warn(f"dominant: the estimated band error {est.max:.3e} is above tol = {o['tol']:g} "
                      f"({'order r reached' if status == 'cap' else 'no Ritz value left to try'})",
                      ConvergenceWarning)
        if tol is None and V.shape[1] < r:
            self.warn(f"dominant: {V.shape[1]} columns from {len(qd.poles)} converged poles; r capped from {r} to "
                      f"{V.shape[1]}", RankWarning)
        new = qd.steps - steps0
        info = {
            "status": status, "converged": status in ("converged", "direct"), "iterations": new,
            "tol": tol, "estimate_max": est.max, "estimate_grid": est.grid, "estimate": est.estimate, "peak": est.peak,
            "poles": [p.value for p in used], "dominance": [p.dominance for p in used],
            "residues": [p.residue for p in used],
            "pole_residuals": [p.residual for p in used], "poles_converged": len(qd.poles),
            "static_columns": int(fom.m if (o["static_correction"] and qd.static is not None) else 0),
            "points": list(qd.shifts), "validated": [], "search_columns": qd.basis.cols,
            "history": list(self._log),
            "lu_count": new, "lu_count_shared": 0 if fresh else steps0, "setup_reused": not fresh,
            "solves": qd.solves, "stable": bool(rom.is_stable()), "definite": definiteness(*rom_m[:3]),
            "time_breakdown": {"steps": qd.seconds - sec0, "ritz_and_estimate": (t1 - t0) - (qd.seconds - sec0)},
            "setup_cost": {"steps": sec0}, "setup_paid": {"steps": 0.0},
        }
        return rom, info
