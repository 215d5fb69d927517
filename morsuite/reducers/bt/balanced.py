r"""Balanced truncation of index-3 second-order systems from low-rank ADI Gramian factors.

The Gramians of the system on its hidden manifold (first-order form
:math:`E = \mathrm{blkdiag}(I, M)`, :math:`A = [[0, I], [-K, -D]]`,
:math:`B = [0; F]`, :math:`C = [L, 0]`, see :mod:`morsuite.linalg.lradi`) are
approximated by :math:`P \approx ZZ^T`, :math:`Q \approx YY^T`, with position
and velocity blocks :math:`Z = [Z_p; Z_v]`, :math:`Y = [Y_p; Y_v]`
(:math:`Z_p, Z_v, Y_v` in :math:`\ker G`, :math:`Y_p` in
:math:`\operatorname{range}\Pi`). Both factors come from one lock-step LR-ADI run
(:func:`~morsuite.linalg.lradi.lradi_pair`: one LU per shift for both equations)
made on the first ``reduce`` call and kept on the reducer, so a sweep over r
costs one pair of ADI runs plus small dense work per r.

``form="first-order"`` (default): square-root balanced truncation
    With the SVD :math:`Y^TEZ = Y_p^TZ_p + Y_v^TMZ_v = U\Sigma V^T` (the Hankel
    singular values :math:`\sigma_i`), :math:`T_l = YU_r\Sigma_r^{-1/2}`,
    :math:`T_r = ZV_r\Sigma_r^{-1/2}` and

    .. math::

        \hat E = I,\quad \hat A = T_l^TAT_r,\quad \hat B = T_l^TB,\quad \hat C = CT_r,

    a :class:`~morsuite.rom.FirstOrderROM` with r first-order states. It is
    stable and :math:`\|T - \hat T\|_{\mathcal H_\infty} \le 2\sum_{i>r}\sigma_i`
    (``info["error_bound"]``) when the Gramians are exact. It is the default
    because it is the only level with both guarantees and because it is the
    reference method of ``models.md``.

``form="pp" | "pv" | "vp" | "vv" | "fv"``: structure-preserving second-order BT
    (Reis and Stykel 2008 for the position/velocity levels, Meyer and Srinivasan
    1996 for free velocity), with r the second-order dimension (2r states).
    The level's SVD picks the right basis :math:`V` and the left basis :math:`W`:

    ===== ===================================== ===================================
    form  V from (right singular vectors)       W from (left singular vectors)
    ===== ===================================== ===================================
    pp    :math:`Z_p`, SVD of :math:`Y_p^TZ_p`  :math:`Y_v`, SVD of :math:`Y_v^TMZ_v`
    pv    :math:`Z_p`, SVD of :math:`Y_v^TMZ_p` :math:`Y_v`, same SVD
    vp    :math:`Z_v`, SVD of :math:`Y_p^TZ_v`  :math:`Y_v`, SVD of :math:`Y_v^TMZ_v`
    vv    :math:`Z_v`, SVD of :math:`Y_v^TMZ_v` :math:`Y_v`, same SVD
    fv    :math:`Z_p`, SVD of :math:`Y_p^TZ_p`  :math:`W = V`
    ===== ===================================== ===================================

    (pyMOR's ``SOBT*Reductor`` conventions). V and W are orthonormalised
    (balancing-free square root) and
    :math:`\hat M = W^TMV`, :math:`\hat D = W^TDV`, :math:`\hat K = W^TKV`,
    :math:`\hat F = W^TF`, :math:`\hat L = LV`, a
    :class:`~morsuite.rom.SecondOrderROM`. Every basis used lies in
    :math:`\ker G`, so this is a projection of the :math:`\Pi`-projected system
    and :math:`\Pi` is never needed. Only ``fv`` is stable by construction (a
    congruence, for symmetric positive definite M, K and semidefinite D); the
    others can return unstable models, which is then said by a
    :class:`StabilityWarning` and ``info["stable"] = False``. The paper
    compares its IRKA with ``vv``.

Accuracy: the ADI tolerance ``tol`` defaults to 1e-12, tighter than
:func:`~morsuite.linalg.lradi`'s 1e-10 (the reference setting of ``models.md``).
1e-10 resolves the Hankel singular values to about 1e-7 relative down to 1e-5
of the largest (measured on the DSMS), but truncating where the discarded
values are near 1e-11 of the largest (the DSMS at r = 20) then goes wrong: the
tail values come out 10-20% low, and the error (2.2e-12) exceeds the computed
bound (2.0e-12); with 1e-12 it is 1.8e-12 against a bound of 3.7e-12, for 10
more ADI iterations (5 LUs). On tcom(2000) 1e-12 costs about 1200 iterations
per Gramian instead of 950 (+25% time). ``tol=1e-10`` gives the reference setting.
``refine=1`` (default; the shared factors' setting, so that BT and the exact H2
norms share one LR-ADI run) refines each controllability solve once in long
double; the ROMs change only in low digits (band errors at r = 10, 20, 30 by
1e-13 to 1e-10 relative on tcom(2000)), and BT takes +23% (dsms(6000)) and
+29% (tcom(2000)) longer, no extra LU (``docs/design/norms.md``).

Truncation: r is capped at the number of singular values above ``hsv_tol``
times the largest (tiny ones carry noise of the ADI residual, and the square
root method divides by them); a :class:`RankWarning` and ``info["r"] <
info["r_requested"]`` say so.

The LR-ADI factors are kept in the model's cache (option ``gramian_cache``,
:func:`~morsuite.linalg.gramians.gramian_factors`): every ``bt`` reducer of the
same model object and ADI options, and :func:`morsuite.analysis.h2_norm` /
``h2_error``, share one LR-ADI run.

``info`` holds ``adi`` (per equation: iterations, converged, residual history,
shifts, rank, columns, LUs reused and dropped, ``shift_reuse``, ``lu_pool_mib``, ``pool_full_reuse``,
``compress_tol``),
``compress_tol`` (the column compression used: option ``compress_tol``, by default 0 below
:attr:`BT.COMPRESS_MIN_N1` positions and :attr:`BT.COMPRESS_AUTO_TOL` from there on, where the
plain factors may no longer fit in memory; a factor is compressed only once it exceeds lradi's
``compress_from_mib``, 1024 MiB, and ``info["adi"]`` records its ``compressions``; a compressed
factor cannot serve the exact H2 error's error-Gramian route, which then runs its own LR-ADI),
``adi_iterations``, ``residual_history``, ``factor_ranks``,
``lu_count`` (the LR-ADI's LUs when this call ran it, else 0), ``lu_count_shared`` (the
LR-ADI's LUs, whoever paid them), ``time_breakdown`` (adi, of which lu, solves, shifts; svd;
projection), ``hsv`` (first-order Hankel singular values), ``error_bound``
(first-order form; None otherwise), ``level_singular_values`` (second-order
forms), ``converged`` (both ADIs converged) with ``status`` "direct" (else "cap":
an LR-ADI stopped at its maxiter), ``iterations`` (ADI steps of the
lock-step run), ``setup_reused`` and ``setup_cost`` (the Gramian and SVD work
paid once per reducer).
"""

from __future__ import annotations

import time
from numbers import Integral

import numpy as np
import scipy.linalg as sla

from ...errors import ConvergenceWarning, InputError, OptionError, RankWarning, StabilityWarning
from ...linalg.gramians import ADI_DEFAULTS, gramian_factors
from ...rom import FirstOrderROM, SecondOrderROM
from ..base import Group, Option, Reducer
from ..cost import cost_record
from ..registry import Description, Variant

__all__ = ["BT", "FORMS", "SquareRootBT", "level_products"]

FORMS = ("first-order", "pp", "pv", "vp", "vv", "fv")

#: options that change the Gramian factors (reducers agreeing on them can share factors)
ADI_OPTIONS = ("tol", "maxiter", "shifts", "num_shifts", "selection", "refine", "shift_reuse", "lu_pool_mib",
               "compress_tol", "pool_full_reuse")

#: which products Y_a^T (M) Z_b give the right (V) and left (W) bases of each level
_LEVELS = {  # form: (svd for V, factor block of V, svd for W)
    "pp": ("pp", "p", "vv"),
    "pv": ("pv", "p", "pv"),
    "vp": ("vp", "v", "vv"),
    "vv": ("vv", "v", "vv"),
    "fv": ("pp", "p", None),
}


class SquareRootBT(Reducer):
    """The square-root step shared by the balanced truncations (``bt``, ``bt-fl``).

    A subclass declares the option ``form`` (one of :data:`FORMS`) and ``hsv_tol``
    and keeps its Gramian factors in ``self._gram`` (made by its ``_gramians``):
    ``{"c": ..., "o": ..., "prods": level_products(c, o, fom), "svd": {}, "svd_times": {},
    "projected": {}}``, where ``c`` and ``o`` have the blocks ``position``,
    ``velocity`` (and ``o.position_unprojected``) and ``rank`` of
    :class:`~morsuite.linalg.adi_result.LRADIResult`. :meth:`_truncate` then makes the
    reduced model of any r from the cached SVDs and projections.
    """

    name = "square-root-bt"

    # -- orders ------------------------------------------------------------
    def max_order(self) -> int:
        """Largest admissible r: :math:`2(n_1 - n_2)` states for ``form="first-order"``, else :math:`n_1 - n_2`."""
        order = self.fom.order
        return 2 * order if self.options["form"] == "first-order" else order

    @classmethod
    def states_for(cls, options: dict) -> int:
        """1 for ``form="first-order"`` (r counts states), else 2 (a second-order model of order r)."""
        return 1 if options["form"] == "first-order" else 2

    def order_guess(self, tol: float, *, measure: str, scale: float) -> int | None:
        r"""The smallest order whose first discarded Hankel singular value is at most ``tol * scale``:
        :math:`N = \min\{N : \sigma_{N+1} \le \text{tol}\cdot\text{scale}\}` states (r = N, or
        :math:`\lceil N/2\rceil` for a second-order level). A guess, not a bound (the first-order
        bound is :math:`2\sum_{k>N}\sigma_k`). Cost: the Gramian factors when they do not exist yet (what
        the first reduction pays anyway; it then reports them as reused shared work)."""
        if getattr(self, "_gram", None) is None:
            self._gramians()
        hsv = np.asarray(self._svd("fo")[1])
        if hsv.size == 0 or not (scale > 0):
            return None
        above = np.flatnonzero(hsv > tol * scale)
        n = int(above[-1]) + 1 if above.size else 1
        n = max(1, min(n, hsv.size))
        return n if self.options["form"] == "first-order" else max(1, -(-n // 2))

    def _validate_r(self, r):
        if self.options["form"] == "first-order" and isinstance(r, Integral) and not isinstance(r, bool) \
                and r > self.max_order():
            raise InputError(f"r = {r} exceeds the number of first-order states on the hidden manifold "
                             f"(2 (n1 - n2) = {self.max_order()}) for {self.name} with form='first-order'")
        return super()._validate_r(r)

    def _instability_note(self, form):
        """Why a reduced model of ``form`` may be unstable (the end of the StabilityWarning)."""
        return ("; second-order balancing levels other than 'fv' do not preserve stability"
                if form not in ("first-order", "fv") else "; the Gramians are not accurate enough")

    def _truncate(self, r):
        """The reduced model of order r from the kept factors: (rom, extra info, times).

        ``extra`` holds ``hsv``, ``stable`` (with ``unstable_poles`` when not),
        ``error_bound`` (first-order form) or ``level_singular_values``; ``times``
        the seconds of new SVDs (``svd``), of the projection (``projection``), and
        of every SVD this form relies on, whoever paid it (``svd_setup``).
        """
        g = self._gram
        form = self.options["form"]
        svd_before = set(g["svd_times"])
        t0 = time.perf_counter()
        U, hsv, Vt = self._svd("fo")
        extra = {"hsv": hsv}
        if form == "first-order":
            rom, r_used = self._first_order(r, U, hsv, Vt)
            extra["error_bound"] = 2.0 * float(np.sum(hsv[r_used:]))
        else:
            rom, level_sv = self._second_order(r, form)
            extra["error_bound"] = None
            extra["level_singular_values"] = level_sv
        t1 = time.perf_counter()
        stable = bool(rom.is_stable())
        extra["stable"] = stable
        if not stable:
            lam = rom.poles()
            extra["unstable_poles"] = int(np.sum(lam.real >= 0))
            self.warn(f"{self.name}: the {form} reduced model at r = {rom.order} has {extra['unstable_poles']} "
                      f"poles in the closed right half-plane (max real part {lam.real.max():.3e})"
                      + self._instability_note(form), StabilityWarning)
        svd_new = sum(v for k, v in g["svd_times"].items() if k not in svd_before)
        svd_keys = {"fo"} | ({_LEVELS[form][0], _LEVELS[form][2]} - {None} if form != "first-order" else set())
        times = {"svd": svd_new, "projection": t1 - t0 - svd_new,
                 "svd_setup": sum(g["svd_times"].get(k, 0.0) for k in svd_keys)}
        return rom, extra, times

    def _svd(self, key):
        """Cached SVD of Y_a^T (M) Z_b for key in pp, pv, vp, vv, or 'fo' (Y^T E Z)."""
        g = self._gram
        if key not in g["svd"]:
            t0 = time.perf_counter()
            c, ob, fom = g["c"], g["o"], self.fom
            if key not in g["prods"] and key != "fo":
                g["prods"][key] = (ob.velocity.T @ (fom.M @ c.position) if key == "pv"
                                   else ob.position_unprojected.T @ c.velocity)
            X = g["prods"]["pp"] + g["prods"]["vv"] if key == "fo" else g["prods"][key]
            g["svd"][key] = _svd(X) if X.size else \
                (np.zeros((X.shape[0], 0)), np.zeros(0), np.zeros((0, X.shape[1])))
            g["svd_times"][key] = time.perf_counter() - t0
        return g["svd"][key]

    # -- reduction ----------------------------------------------------------
    def _cap(self, r, s, what):
        """Largest usable order <= r given singular values s; warns when capped (unless what is None)."""
        tol = self.options["hsv_tol"]
        n_ok = int(np.sum(s > tol * s[0])) if s.size and s[0] > 0 else 0
        if n_ok < r and what is not None:
            self.warn(f"{self.name}: only {n_ok} {what} exceed hsv_tol = {tol:g} times the largest (factor ranks "
                      f"{self._gram['c'].rank} and {self._gram['o'].rank}); r capped from {r} to {n_ok}",
                      RankWarning)
        if n_ok == 0:
            raise InputError(f"{self.name}: no singular value above hsv_tol = {tol:g} of the largest; nothing to keep")
        return min(r, n_ok)

    def _projected(self, form, r, n_max, build, headroom=None):
        """Leading r x r blocks of the projected matrices, built for R >= r columns and cached.

        The balancing bases of order r are the first r columns of those of any
        order R >= r (the square-root scaling is per column; Householder QR of the
        first r columns gives the first r columns of Q, up to sign), so one
        projection at R serves every r <= R, and a sweep over r costs a few
        projections (R doubles) plus slicing. With ``headroom`` (irka-fo's surrogate,
        whose order grows slowly with r) a new projection is built at ``headroom * r``
        columns instead of doubling.
        """
        cache = self._gram["projected"].get(form)
        if cache is None or cache["R"] < r:
            R = min(n_max, max(r, int(np.ceil(headroom * r)) if headroom else 2 * (cache["R"] if cache else 8)))
            cache = {"R": R, "mats": build(R)}
            self._gram["projected"][form] = cache
        *square, rows, cols, lift = cache["mats"]  # build(): the r x r ones, W^T F, L V, then the lift V
        return [X[:r, :r] for X in square] + [rows[:r], cols[:, :r], lift[:, :r]]

    def _first_order(self, r, U, hsv, Vt, headroom=None):
        n_ok = self._cap(len(hsv), hsv, None)
        r = self._cap(r, hsv, "Hankel singular values")
        c, ob, fom = self._gram["c"], self._gram["o"], self.fom

        def build(R):
            w = 1.0 / np.sqrt(hsv[:R])
            Ul, Vr = U[:, :R] * w, Vt[:R].T * w
            Tl1, Tl2 = ob.position_unprojected @ Ul, ob.velocity @ Ul  # T_l1 meets only T_r2 in ker G
            Tr1, Tr2 = c.position @ Vr, c.velocity @ Vr
            # A T_r = [T_r2; -K T_r1 - D T_r2]; the G^T z part is annihilated by T_l2 in ker G
            return [Tl1.T @ Tr2 - Tl2.T @ (fom.K @ Tr1 + fom.D @ Tr2), Tl2.T @ fom.F, fom.L @ Tr1, Tr1]

        A, B, C, lift = self._projected("first-order", r, n_ok, build, headroom)
        return FirstOrderROM(None, A, B, C, basis=lift), r

    def _second_order(self, r, form):
        c, ob, fom = self._gram["c"], self._gram["o"], self.fom
        key_v, block, key_w = _LEVELS[form]
        _, sv, Vt = self._svd(key_v)
        n_ok = self._cap(len(sv), sv, None)
        r = self._cap(r, sv, f"singular values of the {form} level")
        level_sv = sv
        if key_w is not None:
            Uw, sw, _ = self._svd(key_w)
            n_ok = min(n_ok, self._cap(len(sw), sw, None))
            r = self._cap(r, sw, f"singular values of the {key_w} level (left basis)")
            if key_w != key_v:
                level_sv = {"right": sv, "left": sw}
        Zb = c.position if block == "p" else c.velocity

        def build(R):
            V = _orthonormal(Zb @ Vt[:R].T)
            W = V if key_w is None else _orthonormal(ob.velocity @ Uw[:, :R])
            return [W.T @ (fom.M @ V), W.T @ (fom.D @ V), W.T @ (fom.K @ V), W.T @ fom.F, fom.L @ V, V]

        Mr, Dr, Kr, Fr, Lr, lift = self._projected(form, r, n_ok, build)
        return SecondOrderROM(Mr, Dr, Kr, Fr, Lr, basis=lift), level_sv


class BT(SquareRootBT):
    """Balanced truncation from LR-ADI Gramian factors (see the module docstring).

    ``reduce(r)``: with ``form="first-order"`` r is the number of first-order
    states of the :class:`~morsuite.rom.FirstOrderROM`; otherwise r is the
    dimension of the :class:`~morsuite.rom.SecondOrderROM` (2r states). Both are
    in ``info`` (``r``, ``states``).
    """

    name = "bt"
    DESCRIPTION = Description(
        label="BT, first-order", result="by-option",
        targets="Hankel singular values; Hinf bound (first order)", cost="LR-ADI: one per ADI shift, once per model",
        use_for="a reliable default, every r at once", options=("form", "tol", "maxiter", "hsv_tol"),
        variants=tuple(Variant(f"bt-{lvl}", {"form": lvl}, f"BT ({lvl}, second-order)", order)
                       for lvl, order in (("vv", 40), ("pp", 90), ("pv", 91), ("vp", 92), ("fv", 93))),
        default=True, default_variants=("bt-vv",), gramians="reads", stress={"maxiter": 150}, page="reducers", order=50)

    OPTIONS = {
        "form": Option("first-order", "choice", "first-order square-root BT (stable, error bound) or a "
                       "second-order balancing level: position-position, position-velocity, "
                       "velocity-position, velocity-velocity (the paper's), free-velocity", choices=FORMS),
        "tol": Option(1e-12, "float", "relative residual norm ||W^T W|| / ||W0^T W0|| at which LR-ADI stops "
                      "(1e-12, not lradi's 1e-10: the truncation and its bound need the tail Hankel singular "
                      "values; on dsms(6000) at r = 20 tol 1e-10 left them 10-20% low and the error 2.24e-12 "
                      "above its computed bound 1.96e-12; 1e-12 gives 1.80e-12 <= 3.66e-12 for 5 more LUs; on "
                      "tcom(2000) it costs 1205 instead of 969 iterations)",
                      low=0, high=1, open_low=True, open_high=True),
        "maxiter": Option(3000, "int", "largest number of LR-ADI iterations per equation (a complex pair "
                          "counts two); the TCOM (nc = 2000) needs about 1200", low=1),
        "shifts": Option("projection", "choice", "shift strategy: adaptive projection (Ritz) shifts or "
                         "Penzl's heuristic", choices=("projection", "penzl")),
        "num_shifts": Option(16, "int", "shifts (a complex pair counted once) taken from each shift "
                             "computation", low=1),
        "selection": Option("residual", "choice", "projection shifts chosen by their share of the current "
                            "residual or by Penzl's greedy rule on the ADI rational function",
                            choices=("residual", "gain")),
        "refine": Option(1, "int", "long-double refinement steps of each shifted LR-ADI solve (1, not lradi's 0: "
                         "without it the factors carry the solves' forward error, 8e-12 of ||T||_H2^2 on "
                         "tcom(2000), which the exact H2 errors sharing them cannot certify; costs no LU, "
                         "docs/design/norms.md)", low=0),
        "shift_reuse": Option(ADI_DEFAULTS["shift_reuse"], "float", "a projection shift within this ADI distance "
                              "|p - q| / |p + conj(q)| of a kept LU's shift q is served by that LU (no new LU; "
                              "0: exact repeats only; docs/design/lradi.md)", low=0, high=1, open_high=True),
        "lu_pool_mib": Option(ADI_DEFAULTS["lu_pool_mib"], "float", "memory budget (MiB) of the LR-ADI's kept "
                              "LUs, least recently used dropped first (0: none kept)", low=0),
        "pool_full_reuse": Option(ADI_DEFAULTS["pool_full_reuse"], "float", "once the kept-LU pool is full (an "
                                  "LU was dropped): a projection shift within this ADI distance of a kept LU's "
                                  "shift is served by it, and the kept LU farthest from the current shift batch "
                                  "is dropped first (<= shift_reuse: the plain rule; a pool that never fills is "
                                  "unchanged; docs/design/lradi.md)", low=0, high=1, open_high=True),
        "compress_tol": Option(None, "float", "column compression of the LR-ADI factors as they grow: new "
                               "directions below compress_tol times the factor's largest singular value are "
                               "dropped (0: none); None (default): 0 below COMPRESS_MIN_N1 positions (the exact "
                               "H2 error's error-Gramian route shares uncompressed factors), COMPRESS_AUTO_TOL "
                               "from there on (tcom at n1 = 1e6: about 1300 columns per factor, 42 GB plain), "
                               "applied once a factor exceeds 1024 MiB; the value used is info['compress_tol']", low=0, high=1, open_high=True,
                               nullable=True),
        "gramian_cache": Option("model", "choice", "where the LR-ADI factors are kept: in the model's cache, "
                                "shared with every bt reducer and analysis.h2_norm / h2_error on the same model "
                                "object and ADI options (LR-ADI runs once per model), or on this reducer only (a "
                                "fresh run per reducer, for benchmarks that time whole runs)",
                                choices=("model", "reducer")),
        "hsv_tol": Option(1e-13, "float", "singular values below hsv_tol times the largest are never kept "
                          "(caps r)", low=0, high=1, open_high=True),
    }
    GROUPS = {"adi": Group("LR-ADI of the Gramian factors: shifts, refinement, the kept LUs",
                           ("shifts", "num_shifts", "selection", "refine", "shift_reuse", "lu_pool_mib",
                            "pool_full_reuse"))}

    #: compress_tol=None: the LR-ADI factors are compressed at COMPRESS_AUTO_TOL from COMPRESS_MIN_N1
    #: positions on (on tcom(3334), n1 = 1e4: 313 and 325 columns of 1294 and 1336 kept, the reduced
    #: transfer function at r = 20 moved by 1.8e-10 of its peak, the Hankel singular values by 9e-7;
    #: docs/design/lradi.md)
    COMPRESS_MIN_N1, COMPRESS_AUTO_TOL = 200_000, 1e-6

    def __init__(self, fom, **options):
        super().__init__(fom, **options)
        self._gram = None  # shared by reducers that agree on ADI_OPTIONS (use_gramians_of)

    def _adi_options(self) -> dict:
        """The LR-ADI options of the factors, ``compress_tol`` resolved when None."""
        o = self.options
        adi = {k: o[k] for k in ADI_OPTIONS}
        if adi["compress_tol"] is None:
            adi["compress_tol"] = self.COMPRESS_AUTO_TOL if self.fom.n1 >= self.COMPRESS_MIN_N1 else 0.0
        return adi

    # -- Gramians (once per reducer) --------------------------------------
    def use_gramians_of(self, other: "BT") -> "BT":
        """Share the Gramian factors (and SVDs) of ``other``, a ``bt`` reducer of the same
        model with the same ADI options (``form`` and ``hsv_tol`` may differ). Returns self."""
        if not isinstance(other, BT):
            raise InputError(f"other must be a BT reducer; got {type(other).__name__}")
        if other.fom is not self.fom:
            raise InputError("other is bound to a different model object; Gramians cannot be shared")
        mine, theirs = self._adi_options(), other._adi_options()
        diff = [k for k in ADI_OPTIONS if mine[k] != theirs[k]]
        if diff:
            raise OptionError(f"other has different ADI options ({', '.join(diff)}); Gramians cannot be shared")
        if other._gram is None:
            other._gramians()
        self._gram = other._gram
        return self

    def _gramians(self) -> dict:
        """The LR-ADI factors and their timing, computed on first use."""
        if self._gram is not None:
            return self._gram
        o = self.options
        gf = gramian_factors(self.fom, use_cache=o["gramian_cache"] == "model", **self._adi_options())
        c, ob = gf.controllability, gf.observability
        t1 = time.perf_counter()
        fom = self.fom
        prods = level_products(c, ob, fom)
        t2 = time.perf_counter()
        self._gram = {"c": c, "o": ob, "prods": prods, "svd": {}, "svd_times": {}, "projected": {},
                      "times": {"adi": gf.time_s, "products": t2 - t1}, "adi_computed": gf.computed}
        return self._gram

    def _reduce(self, r):
        fresh = self._gram is None
        g = self._gramians()
        adi_fresh = fresh and g["adi_computed"]  # False when the model's cache had the factors
        c, ob = g["c"], g["o"]
        form = self.options["form"]
        for res in (c, ob):
            if not res.converged:
                self.warn(f"bt: LR-ADI ({res.equation}) stopped at maxiter = {res.maxiter} with relative "
                          f"residual {res.residual:.2e} > tol = {res.tol:.1e}; the Gramians (and the Hankel "
                          f"singular values and bound) are not accurate to tol", ConvergenceWarning)
        rom, extra, tt = self._truncate(r)
        times = g["times"]
        st_c = c.times
        info = {
            "form": form, "converged": bool(c.converged and ob.converged), "compress_tol": c.compress_tol,
            "status": "direct" if c.converged and ob.converged else "cap",  # LR-ADI's maxiter
            "iterations": max(c.iterations, ob.iterations),
            "adi_iterations": {"controllability": c.iterations, "observability": ob.iterations},
            "residual_history": {"controllability": c.residuals, "observability": ob.residuals},
            "adi": {"controllability": c.summary(history=False), "observability": ob.summary(history=False)},
            "factor_ranks": {"controllability": c.rank, "observability": ob.rank},
            "lu_reused": c.lu_reused,  # LR-ADI steps served by a kept LU (shift_reuse)
            **extra,
            # the Gramian factors' LR-ADI (whoever paid it), their products and the SVDs: r-independent work
            # paid once per reducer or model (studies add it back for 'standalone' times)
            **cost_record(lus_shared=c.lu_count, lus_paid=c.lu_count if adi_fresh else 0,
                          setup_cost={"adi": times["adi"], "products": times["products"], "svd": tt["svd_setup"]},
                          paid={"adi": times["adi"] if adi_fresh else 0.0,
                                "products": times["products"] if fresh else 0.0, "svd": tt["svd"]},
                          breakdown={"lu": st_c["factor"] if adi_fresh else 0.0,
                                     "solves": (c.times["solve"] + ob.times["solve"]) if adi_fresh else 0.0,
                                     "shifts": st_c["shifts"] if adi_fresh else 0.0,
                                     "compress": (c.times["compress"] + ob.times["compress"]) if adi_fresh else 0.0,
                                     "projection": tt["projection"]}),
        }
        return rom, info


def level_products(c, ob, fom) -> dict:
    r"""The two products every form needs, :math:`Y_p^TZ_p` ("pp") and :math:`Y_v^TMZ_v` ("vv").

    Their sum is :math:`Y^TEZ`. :math:`Y_p` enters only through products with
    :math:`Z_p, Z_v \in \ker G`, so its unprojected form (``position_unprojected``) will do.
    Cost: two dense products of n1 x k blocks and one sparse product.
    """
    return {"pp": ob.position_unprojected.T @ c.position, "vv": ob.velocity.T @ (fom.M @ c.velocity)}


def _svd(X):
    """Thin SVD; LAPACK's gesdd can fail to converge on a numerically rank-deficient product
    (factors with many more columns than the model's order), then the slower gesvd does it."""
    try:
        return np.linalg.svd(X, full_matrices=False)
    except np.linalg.LinAlgError:
        return sla.svd(X, full_matrices=False, lapack_driver="gesvd", check_finite=False)


def _orthonormal(X):
    """Orthonormal basis of the columns of X (thin QR; X has full column rank here)."""
    Q, _ = np.linalg.qr(X)
    return Q

