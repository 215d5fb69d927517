r"""Constrained modal truncation, with an optional static (residual-flexibility) correction.

The undamped constrained modes :math:`K\varphi + G^T\mu = \omega^2M\varphi`, :math:`G\varphi = 0`
come from shift-invert Lanczos with the saddle matrix :math:`[[K - \sigma M, G^T], [G, 0]]`
factored once (:func:`morsuite.linalg.eigen.constrained_modes`); :math:`\Pi` is never formed.
``selection`` chooses k of them (:mod:`morsuite.reducers.modal.selection`): the lowest, those
in a band, the most dominant, or (``"cutoff"``, the engineers' rule) every mode up to ``cutoff``
times the band's upper end, r capping their number. The basis is

.. math::

    V = [\Phi_k,\ X_s],\qquad
    X_0 = [I\ 0]\,S(0)^{-1}\begin{bmatrix}F\\0\end{bmatrix},\qquad
    S(0) = \begin{bmatrix}K & G^T\\ G & 0\end{bmatrix},

with ``static_correction=True``: :math:`X_0` (the constrained static response to the inputs,
one LU at s = 0, none when :math:`\sigma = 0`) M-orthogonalised against :math:`\Phi_k`
(twice), its M-rank kept (columns below ``static_tol`` of the largest dropped), then rotated
by the Rayleigh-Ritz of K on that block. So :math:`V^TMV = I` and
:math:`V^TKV = \operatorname{diag}(\Omega_k^2, \tilde\Omega_s^2)` (the modes' block is
diagonal because :math:`\varphi^TKx = \omega^2\varphi^TMx - \mu^TGx = 0` for x in
:math:`\ker G` M-orthogonal to :math:`\varphi`). The reduced model is the Galerkin projection

.. math::

    \hat M = V^TMV,\quad \hat D = V^TDV,\quad \hat K = V^TKV,\quad \hat F = V^TF,\quad \hat L = LV,

a :class:`~morsuite.rom.SecondOrderROM` with ``basis = V``: symmetric positive definite
:math:`\hat M, \hat K` and semidefinite :math:`\hat D` when M, K, D are (a congruence), hence
stable; its undamped frequencies include the k selected ones exactly; with the correction
:math:`\hat T(0) = T(0)` (:math:`X_0 \in \operatorname{range}V` and
:math:`V^TKX_0 = V^TF`): Craig-Bampton's residual flexibility with the loaded positions as
interface.

Orders: ``reduce(r)``: r is the second-order order (2r states), k = r minus the static
columns (at most m). The modes are computed on the first call for the largest k needed so far
and kept on the reducer, with the reducer's solver and its LU; a later call that needs more
modes repeats only the Lanczos run (twice the modes, the same LU).

Status: ``direct`` when every mode asked for converged (and a band was covered); ``partial``
when ARPACK converged only some of them within ``maxiter`` restarts (the reduced model is built
from those: fewer modes than asked, not necessarily the lowest), ``cap`` when a band was not
covered within the modes' cap; both with ``converged=False``, ``status_reason`` and a
:class:`~morsuite.errors.ConvergenceWarning` recorded in ``info["warnings"]`` on every call that
uses the pool.

Cost: one sparse LU (two with the static correction and :math:`\sigma \ne 0`), the Lanczos
solves (about 2k to 4k, k more for the refinement), m static solves and O(n1 r²) dense work.
Design note and measurements: ``docs/design/modal.md``.
"""

from __future__ import annotations

import math
import time
import warnings
from numbers import Integral

import numpy as np
import scipy.linalg as sla

from ...errors import ConvergenceWarning, InputError, RankWarning, SingularShiftError
from ...linalg.eigen import constrained_modes
from ...rom import SecondOrderROM
from ..base import Option, Reducer
from ..cost import cost_record
from ..registry import Description
from .selection import band_order, dominance, dominance_order, lowest_order

__all__ = ["Modal", "SELECTIONS"]

SELECTIONS = ("lowest", "band", "dominance", "cutoff")


class Modal(Reducer):
    """Constrained modal truncation (module docstring); r is the second-order order (2r states)."""

    name = "modal"
    DESCRIPTION = Description(
        label="modal truncation + static correction", result="second-order",
        targets="the undamped modes (lowest, in a band, dominant), T(0)",
        cost="one (two with a shift != 0 and the static correction)", use_for="the engineering baseline at one LU",
        options=("selection", "band", "sigma", "static_correction"), default=True, stress={}, page="modal", order=60)

    OPTIONS = {
        "selection": Option("lowest", "choice", "which modes: the lowest, those in the band (then its nearest), "
                            "the most dominant in the band (largest modal-term gain), or every mode up to cutoff "
                            "times the band's upper end (the engineers' rule; r caps their number)",
                            choices=SELECTIONS),
        "cutoff": Option(2.0, "float", "'cutoff': keep the modes below cutoff times the band's upper end",
                         low=1.0),
        "band": Option(None, "array", "band (w1, w2) in rad/s of 'band' and 'dominance' (default: the model's band)",
                       nullable=True),
        "sigma": Option(None, "float", "shift (rad^2/s^2) of the one LU of K - sigma M; default 0 for 'lowest' and "
                        "'dominance' (a negative one if K is singular on ker G), w1^2 for 'band'", nullable=True),
        "static_correction": Option(True, "bool", "append the constrained static response to the inputs, "
                                    "M-orthogonalised against the modes, so that T_r(0) = T(0)"),
        "static_tol": Option(1e-8, "float", "static columns whose M-norm after orthogonalisation is below "
                             "static_tol times the largest are dropped", low=0, high=1, open_high=True),
        "pool": Option(2.0, "float", "'dominance' chooses among the lowest ceil(pool * r) modes", low=1.0),
        "tol": Option(0.0, "float", "ARPACK's relative accuracy of the eigenvalues (0: machine precision)",
                      low=0, high=1, open_high=True),
        "maxiter": Option(None, "int", "ARPACK's restart cap (default max(1000, 10 k))", low=1, nullable=True),
    }

    def __init__(self, fom, **options):
        super().__init__(fom, **options)
        self._solver = None
        self._lus = {}  # sigma -> the LU of K - sigma M bordered, kept across calls
        self._lu_total = 0  # every LU this reducer made (the r-independent work's)
        self._modes = None  # the computed pool: omega, shapes, residuals, info, time
        self._static = None  # X0 and its cost

    def _check_options(self):
        b = self.options["band"]
        if b is not None:
            arr = np.ravel(b).astype(float)
            if arr.size != 2 or not (0 <= arr[0] < arr[1]):
                raise InputError(f"The 'band' parameter of Modal must be (w1, w2) with 0 <= w1 < w2; got "
                                 f"{b.tolist()!r}: the band is empty")
            self.options["band"] = arr

    def max_order(self) -> int:
        """Largest admissible r: :math:`n_1 - n_2 - 1` (Lanczos cannot return every mode)."""
        return self.fom.order - 1

    def _validate_r(self, r):
        if isinstance(r, Integral) and not isinstance(r, (bool, np.bool_)) and r > self.max_order():
            raise InputError(f"r = {r} exceeds the most modes shift-invert Lanczos can return (n1 - n2 - 1 = "
                             f"{self.max_order()}) for modal")
        return super()._validate_r(r)

    def _band(self):
        b = self.options["band"]
        return tuple(float(x) for x in (b if b is not None else self.fom.band))

    def _sigma(self):
        s = self.options["sigma"]
        if s is not None:
            return s
        return self._band()[0] ** 2 if self.options["selection"] == "band" else 0.0

    # -- r-independent work, kept on the reducer --------------------------
    def _factor(self, sigma):
        """The LU of [[K - sigma M, G^T], [G, 0]], made once per sigma and kept."""
        if sigma not in self._lus:
            self._lus[sigma] = self._solver.factor(coeffs=(-sigma, 0.0, 1.0))
        return self._lus[sigma]

    def _compute_modes(self, k_needed):
        """The pool of modes (at least k_needed, or every one in the band), computed or grown."""
        sel, fom = self.options["selection"], self.fom
        have = self._modes
        if have is not None and have["omega"].size >= k_needed:
            return False
        limit = fom.order - 1
        k = min(limit, max(k_needed, 2 * have["omega"].size if have else k_needed))
        sigma = self._sigma() if have is None else have["sigma"]
        t0 = time.perf_counter()
        try:
            lu = self._factor(sigma)
        except SingularShiftError:
            if self.options["sigma"] is not None:
                raise
            # K singular on ker G (rigid-body modes): a shift below the spectrum
            old, sigma = sigma, -(self._band()[0] or 1.0) ** 2
            self.warn(f"modal: K - sigma M is singular at sigma = {old:g} (rigid-body modes?); shift moved to "
                      f"sigma = {sigma:g}")
            lu = self._factor(sigma)
        kw = {"sigma": sigma, "tol": self.options["tol"], "maxiter": self.options["maxiter"], "factorization": lu}
        if sel == "band":
            kw.update(band=self._band(), within_band=False)
        elif sel == "cutoff":  # every mode from 0 to cutoff * w2 (k grows until they are covered)
            kw.update(band=(0.0, self.options["cutoff"] * self._band()[1]), within_band=False)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)  # said by _reduce on every call that uses them
            res = constrained_modes(fom, k=max(k, 1), **kw)
        self._modes = {"omega": res.omega, "shapes": res.shapes, "residuals": res.residuals, "sigma": sigma,
                       "info": res.info, "time": time.perf_counter() - t0}
        if sel == "dominance":
            self._modes["dominance"] = dominance(res.omega, res.shapes, fom.D, fom.F, fom.L, self._band())
        return True

    def _static_response(self):
        """X0 = [I 0] S(0)^{-1} [F; 0] (no columns when K is singular on ker G: warned, and said in info)."""
        if self._static is None:
            t0 = time.perf_counter()
            try:
                X0 = self._factor(0.0).solve(self.fom.F)
            except SingularShiftError:
                self.warn("modal: K is singular on ker G (rigid-body modes): T(0) is not finite, no static correction")
                X0 = np.zeros((self.fom.n1, 0))
            self._static = {"X0": np.real(X0), "time": time.perf_counter() - t0}
        return self._static

    # -- reduction ------------------------------------------------------------
    def _order(self, modes, r):
        sel = self.options["selection"]
        if sel == "lowest":
            return lowest_order(modes["omega"])
        if sel == "cutoff":
            low = lowest_order(modes["omega"])
            return low[modes["omega"][low] <= self.options["cutoff"] * self._band()[1]]
        if sel == "band":
            return band_order(modes["omega"], self._band(), modes["sigma"])
        pool = min(modes["omega"].size, math.ceil(self.options["pool"] * r))
        low = lowest_order(modes["omega"])[:pool]
        return low[dominance_order(modes["omega"][low], modes["dominance"][low])]

    def _reduce(self, r):
        fom, o = self.fom, self.options
        t0 = time.perf_counter()
        if self._solver is None:
            self._solver = fom.new_solver(cache_size=0)  # the reducer keeps its LUs itself (_factor)
        before = self._solver.stats.copy()
        static_fresh = o["static_correction"] and self._static is None
        st = self._static_response() if o["static_correction"] else None
        m_static = st["X0"].shape[1] if st is not None else 0  # 0 when K is singular on ker G (warned)
        t1 = time.perf_counter()
        if r < m_static:
            raise InputError(f"r = {r} is smaller than the m = {m_static} static-correction columns of modal; "
                             "use r >= m or static_correction=False")
        k = r - m_static
        need = max(k, math.ceil(o["pool"] * r)) if o["selection"] == "dominance" else k
        need = min(need, fom.order - 1)
        grown = self._compute_modes(max(need, 1))
        modes = self._modes
        t2 = time.perf_counter()
        chosen = self._order(modes, r)[:k]
        chosen = chosen[np.argsort(modes["omega"][chosen], kind="stable")]
        Phi = modes["shapes"][:, chosen]
        V, n_static = Phi, 0
        if m_static:
            Xs = _static_block(fom, Phi, st["X0"], o["static_tol"])
            n_static = Xs.shape[1]
            V = np.hstack([Phi, Xs])
        MV, KV = fom.M @ V, fom.K @ V
        sym = lambda X: 0.5 * (X + X.T)  # noqa: E731
        Mr, Kr, Dr = sym(V.T @ MV), sym(V.T @ KV), sym(V.T @ (fom.D @ V))
        rom = SecondOrderROM(Mr, Dr, Kr, V.T @ fom.F, fom.L @ V, basis=V)
        t3 = time.perf_counter()
        paid = self._solver.stats.since(before)["factorizations"]
        self._lu_total += paid
        shared = self._lu_total
        covered = bool(modes["info"]["covered"])
        status, reason = "direct", None
        if not covered:  # ARPACK converged only part of the pool, or a band was not covered within k_max
            status = "partial" if modes["info"]["status"] == "partial" else "cap"
            reason = f"modal: {modes['info']['reason']}"
            self.warn(reason, ConvergenceWarning)
        if k and chosen.size < k:
            self.warn(f"modal: {chosen.size} modes available of the {k} asked for; the reduced order is "
                      f"{rom.order}, not {r}", ConvergenceWarning)
        if n_static < m_static:
            self.warn(f"modal: {m_static - n_static} static column(s) lie in the span of the modes (below "
                      f"static_tol = {o['static_tol']:g}); the reduced order is {rom.order}, not {r}", RankWarning)
        info = {
            "selection": o["selection"], "sigma": modes["sigma"], "modes": int(chosen.size),
            "static_columns": int(n_static),
            "omega": modes["omega"][chosen], "modes_computed": int(modes["omega"].size),
            "static_dropped": bool(o["static_correction"] and not m_static),  # K singular on ker G
            "max_residual": float(modes["residuals"][chosen].max(initial=0.0)),
            "converged": covered, "status": status, "status_reason": reason,
            # the LUs of the modes and the static response: r-independent, kept across calls
            **cost_record(lus_shared=shared, lus_paid=paid,
                          setup_cost={"modes": modes["time"], "static": st["time"] if st is not None else 0.0},
                          paid={"static": t1 - t0 if static_fresh else 0.0, "modes": t2 - t1 if grown else 0.0},
                          breakdown={"projection": t3 - t2}),
        }
        if o["selection"] == "dominance":
            info["dominance"] = modes["dominance"][chosen]
        return rom, info


def _static_block(fom, Phi, X0, tol):
    r"""X0 M-orthogonalised against Phi (twice), M-orthonormal after dropping dependent columns, and
    rotated by the Rayleigh-Ritz of K on its span (so the block of :math:`V^TKV` is diagonal)."""
    X = X0.copy()
    for _ in range(2):
        X -= Phi @ (Phi.T @ (fom.M @ X))
    Mx = X.T @ (fom.M @ X)
    ev, U = np.linalg.eigh(0.5 * (Mx + Mx.T))
    keep = ev > tol * max(ev.max(initial=0.0), np.finfo(float).tiny)
    X = X @ (U[:, keep] / np.sqrt(ev[keep]))
    if X.shape[1]:
        X -= Phi @ (Phi.T @ (fom.M @ X))  # the rotation above can reintroduce rounding along Phi
        Kx, Mx = X.T @ (fom.K @ X), X.T @ (fom.M @ X)
        _, C = sla.eigh(0.5 * (Kx + Kx.T), 0.5 * (Mx + Mx.T))
        X = X @ C
    return X

