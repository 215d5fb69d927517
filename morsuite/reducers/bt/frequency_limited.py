r"""Frequency-limited balanced truncation of index-3 second-order systems (``bt-fl``).

On the hidden manifold the system has the first-order realization
:math:`E = \mathrm{blkdiag}(I, M)`, :math:`A = [[0, I], [-K, -D]]`,
:math:`B = [0; F]`, :math:`C = [L, 0]` of :mod:`morsuite.reducers.bt.balanced`. Its
band-restricted Gramians on :math:`\Omega = [-\omega_2, -\omega_1] \cup [\omega_1, \omega_2]`
(Gawronski and Juang 1990) are

.. math::

    P_\Omega = \frac{1}{\pi}\,\mathrm{Re}\int_{\omega_1}^{\omega_2} X(j\omega)X(j\omega)^H d\omega,
    \qquad
    Q_\Omega = \frac{1}{\pi}\,\mathrm{Re}\int_{\omega_1}^{\omega_2} Y(j\omega)Y(j\omega)^H d\omega,

with :math:`X(s) = (sE - A)^{-1}\Pi_l B` and :math:`Y(s) = (sE - A)^{-T}\Pi_r^TC^T`
(real data: the integrand at :math:`-\omega` is the conjugate of that at
:math:`\omega`, so the negative half of the band adds the real part). Each
node is one saddle-point LU: with :math:`S(s)` of :mod:`morsuite.linalg.saddle`,

.. math::

    S(s)\begin{bmatrix} x \\ z \end{bmatrix} = \begin{bmatrix} F \\ 0 \end{bmatrix},\quad
    X(s) = \begin{bmatrix} x \\ s x \end{bmatrix},\qquad
    S(s)^T\begin{bmatrix} y \\ \mu \end{bmatrix} = \begin{bmatrix} L^T \\ 0 \end{bmatrix},\quad
    Y(s) = \begin{bmatrix} (sM + D)^T y \\ y \end{bmatrix},

the right and the transposed left solve on the same LU (the position block of
:math:`Y` is its unprojected form, equal to the projected one modulo
:math:`\operatorname{range} G^T`, which is all balancing needs; :math:`x, y \in \ker G`).
A Gauss-Legendre rule with nodes :math:`\omega_k` and weights :math:`c_k` on
:math:`[\omega_1, \omega_2]` (in :math:`\omega` or in :math:`\log\omega`, option
``variable``) gives the real factors

.. math::

    P_\Omega \approx ZZ^T,\quad
    Z = \bigl[\sqrt{c_k/\pi}\,\mathrm{Re}\,X(j\omega_k),\ \sqrt{c_k/\pi}\,\mathrm{Im}\,X(j\omega_k)\bigr]_k,

and :math:`Y` likewise, which are compressed (a thin QR, then an SVD of the
triangular factor; singular values below ``compress_tol`` times the largest are
dropped, so :math:`\|ZZ^T - Z_cZ_c^T\| \le \mathrm{compress\_tol}^2\|ZZ^T\|`). The
square-root step of :class:`~morsuite.reducers.bt.balanced.SquareRootBT` then balances them:
``form="first-order"`` (default) or one of the second-order levels ``pp``, ``pv``,
``vp``, ``vv``, ``fv``, exactly as ``bt`` does with its LR-ADI factors. This is the
quadrature approach to frequency-limited BT of Benner, Kürschner and Saak (2016,
"Frequency-limited balanced truncation with low-rank approximations", SIAM J. Sci.
Comput. 38(1)), who also compute these Gramians from the matrix logarithm; pyMOR's
``QuadBTReductor`` builds data-driven quadrature BT from transfer-function samples
alone (trapezoid weights), which cannot give the second-order levels.

Quadrature accuracy: the integrand has poles at distance :math:`|\mathrm{Re}\,\lambda|`
from the real axis for each pole :math:`\lambda` of the system, so lightly damped
modes in the band need many nodes. With ``nodes=None`` (default) the rule starts at
``nodes_start`` (32) nodes and doubles until the leading ``quad_hsv`` (20) band Hankel
singular values (those above ``hsv_tol`` of the largest) change by at most ``quad_tol``
(1e-6) relative on doubling, or ``max_nodes`` (1024) is reached (then
``converged=False``, status "cap" and a :class:`ConvergenceWarning`); the last rule's
factors are kept. ``nodes=n`` uses n nodes and measures nothing (``quad_change`` None).
Measurements: ``docs/design/bt_fl.md``.

Cost: one complex sparse LU per node (``nodes``; the conjugate nodes are not needed),
one solve and one transposed solve each, on ``solver_threads`` threads; with doubling,
every level's nodes (``nodes_evaluated``, about twice the last level). Then a thin QR
of each factor (:math:`O(n_1k^2)` for k columns), and the small dense work of ``bt``.
The factors are kept on the reducer: later ``reduce(r)`` calls cost the projections only.
There is no error bound (``error_bound`` None): FL-BT is judged by its band error, and
its first-order reduced models need not be stable (a :class:`StabilityWarning` says so).

``limited="controllability"`` (the default since 2026-11-27; ``"both"`` is the two-sided
FL-BT of the literature, whose first-order models were unstable at every order on
tcom(2000) on a sub-band: ``docs/design/bt_fl.md``): only :math:`P_\Omega` is band-limited; :math:`Q` is the
full observability Gramian from a fresh LR-ADI run with ``bt``'s ADI defaults
(:func:`~morsuite.linalg.gramians.gramian_factors`, its LUs counted in ``lu_count``).
This is Enns' one-sided frequency weighting: in the balanced basis :math:`Q` still
solves its Lyapunov equation, whose leading block is that of the reduced model, so the
first-order reduced models are stable (for an observable truncation). Cost: the
quadrature plus bt's LR-ADI (lock-step, both equations).

``info``: ``band``, ``variable``, ``limited``, ``nodes`` (of the kept rule), ``nodes_evaluated``,
``quad_levels`` (nodes and measured change per level), ``quad_change`` (the last
change; None with fixed nodes), ``quad_tol``, ``lu_count`` (the LUs this call paid:
``nodes_evaluated``, plus the LR-ADI's with ``limited="controllability"``, on the first
call, 0 after), ``lu_count_shared`` (the same count, whoever paid it),
``factor_ranks`` (after compression), ``factor_columns`` (before), ``hsv`` (the singular
values of the pair balanced: with ``limited="controllability"``, the default, those of the
band controllability Gramian and the full observability one, Enns' one-sided weighted
values :math:`\sqrt{\lambda_i(P_\Omega Q)}`; with ``"both"`` the band Hankel singular values
:math:`\sqrt{\lambda_i(P_\Omega Q_\Omega)}`, which the doubling test measures in either case),
``time_breakdown`` (quadrature, with the LR-ADI if any, of which lu,
solves, compression and products, over every level; svd; projection), ``setup_reused``, ``setup_cost`` (quadrature, svd).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ...errors import ConvergenceWarning, InputError
from ...utils import band_pair
from ...linalg.gramians import gramian_factors
from ..base import Group, Option
from ..cost import cost_record
from ..registry import Description
from .balanced import FORMS, SquareRootBT, level_products
from ..irka.shift_solves import default_threads, map_threads

__all__ = ["BTFL", "BandFactor", "band_nodes", "band_factors", "compress"]

VARIABLES = ("auto", "log", "linear")

#: the doubling test ignores band Hankel singular values below HSV_FLOOR times the largest: their
#: relative change is rounding noise (the factors' products resolve about 1e-15 of the largest)
HSV_FLOOR = 1e-8


@dataclass
class BandFactor:
    r"""A real low-rank factor of a band Gramian, in the blocks balanced truncation reads.

    Attributes
    ----------
    position, velocity : ndarray (n1, k)
        :math:`Z = [Z_p; Z_v]` (both blocks in :math:`\ker G`), or for the
        observability factor the velocity block in :math:`\ker G` and the position
        block modulo :math:`\operatorname{range} G^T` (``position_unprojected`` is
        the same array).
    equation : str
        "controllability" or "observability".
    """

    position: np.ndarray
    velocity: np.ndarray
    equation: str

    @property
    def position_unprojected(self) -> np.ndarray:
        """The position block as computed (see the class docstring)."""
        return self.position

    @property
    def rank(self) -> int:
        """Number of columns k."""
        return int(self.position.shape[1])


def band_nodes(band, n: int, variable: str = "log") -> tuple[np.ndarray, np.ndarray]:
    r"""Gauss-Legendre nodes and weights for :math:`\int_{\omega_1}^{\omega_2} f(\omega)\,d\omega`.

    Parameters
    ----------
    band : (float, float)
        :math:`0 \le \omega_1 < \omega_2 < \infty`; ``variable="log"`` needs :math:`\omega_1 > 0`.
    n : int
        Number of nodes (the rule is exact for polynomials of degree 2n - 1 in the variable).
    variable : {"log", "linear"}
        ``"linear"``: the rule in :math:`\omega`; ``"log"``: in :math:`t = \log\omega`,
        weights :math:`c_k\omega_k` (:math:`d\omega = \omega\,dt`), nodes spread evenly over
        the decades of a wide band.

    Returns
    -------
    omega, weights : ndarray (n,)
        Positive nodes in the open band and positive weights (sum :math:`\omega_2 - \omega_1`).
    """
    w1, w2 = band_pair(band, allow_zero=True)
    t, c = np.polynomial.legendre.leggauss(int(n))
    if variable == "log":
        if w1 <= 0:
            raise InputError(f"variable='log' needs band w1 > 0; got band = ({w1:g}, {w2:g})")
        a, b = math.log(w1), math.log(w2)
        omega = np.exp(0.5 * (b - a) * t + 0.5 * (a + b))
        return omega, c * 0.5 * (b - a) * omega
    if variable != "linear":
        raise InputError(f"variable must be 'log' or 'linear'; got {variable!r}")
    return 0.5 * (w2 - w1) * t + 0.5 * (w1 + w2), c * 0.5 * (w2 - w1)


def band_factors(fom, omega, weights, *, solver=None, threads: int = 1):
    r"""Uncompressed band Gramian factors from the solves at :math:`s = j\omega_k` (module docstring).

    Parameters
    ----------
    fom : Index3Model
    omega, weights : ndarray (n,)
        Quadrature nodes (rad/s) and weights, e.g. from :func:`band_nodes`.
    solver : SaddlePointSolver, optional
        Default: ``fom.new_solver(cache_size=0)``; its ``stats`` count the LUs.
    threads : int
        Nodes factored and solved concurrently (:func:`~morsuite.reducers.irka.shift_solves.map_threads`).

    Returns
    -------
    c, o : BandFactor
        Controllability factor (2 m n columns) and observability factor (2 p n columns),
        node by node: the real parts, then the imaginary parts, scaled by :math:`\sqrt{c_k/\pi}`.

    Cost: one complex LU per node, one solve with F and one transposed solve with
    :math:`L^T` on it.
    """
    solver = solver if solver is not None else fom.new_solver(cache_size=0)
    F, LT = fom.F.astype(complex), fom.L.T.astype(complex)
    M, D = fom.M, fom.D

    def node(w):
        s = 1j * float(w)
        lu = solver.factor(s)
        x = lu.solve(F)
        y = lu.solve(LT, trans=True)
        return x, s * x, s * (M.T @ y) + D.T @ y, y

    out = map_threads(node, list(omega), threads)
    scale = np.sqrt(np.asarray(weights) / np.pi)

    def stack(j):
        return np.hstack([blk for (res, sc) in zip(out, scale) for blk in (sc * res[j].real, sc * res[j].imag)])
    return (BandFactor(stack(0), stack(1), "controllability"), BandFactor(stack(2), stack(3), "observability"))


def compress(factor: BandFactor, tol: float) -> BandFactor:
    r"""The factor :math:`Z = [Z_p; Z_v]` with its columns compressed: :math:`Z_c = Q U_k\Sigma_k`.

    From a thin QR :math:`Z = QR` and the SVD :math:`R = U\Sigma V^T`, the singular values
    above ``tol`` times the largest are kept, so :math:`Z_cZ_c^T` differs from
    :math:`ZZ^T` by at most :math:`\mathrm{tol}^2\|ZZ^T\|_2`. Cost: :math:`O(n_1k^2)`.
    """
    n1 = factor.position.shape[0]
    Z = np.vstack([factor.position, factor.velocity])
    if Z.shape[1] == 0:
        return factor
    Q, R = sla.qr(Z, mode="economic", check_finite=False)
    U, s, _ = np.linalg.svd(R, full_matrices=False)
    keep = int(np.sum(s > tol * s[0])) if s[0] > 0 else 0
    Zc = Q @ (U[:, :keep] * s[:keep])
    return BandFactor(np.ascontiguousarray(Zc[:n1]), np.ascontiguousarray(Zc[n1:]), factor.equation)


class BTFL(SquareRootBT):
    """Frequency-limited balanced truncation on a band (see the module docstring).

    ``reduce(r)``: r as for ``bt`` (first-order states with ``form="first-order"``,
    else the second-order dimension). The band Gramian factors are computed on the
    first call and kept.
    """

    name = "bt-fl"
    DESCRIPTION = Description(
        label="BT, frequency-limited to the band (one-sided: stable)", result="by-option",
        targets="Hankel singular values of the band-limited Gramians", cost="one per quadrature node (32 to 1024)",
        use_for="a band that matters more than the rest of the axis", options=("band", "form", "nodes", "limited"),
        band_option="band", stress={"max_nodes": 256}, page="bt_fl", order=95)

    OPTIONS = {
        "band": Option(None, "any", "frequency band (w1, w2) in rad/s, 0 <= w1 < w2 < inf, whose error is "
                       "balanced; None: the model's band (fom.band)", nullable=True),
        "form": Option("first-order", "choice", "first-order square-root BT or a second-order balancing "
                       "level, as for bt", choices=FORMS),
        "nodes": Option(None, "int", "Gauss-Legendre nodes (one LU each); None: doubled from nodes_start until "
                        "the band Hankel singular values settle to quad_tol", low=1, nullable=True),
        "nodes_start": Option(32, "int", "nodes of the first rule with nodes=None", low=1),
        "max_nodes": Option(1024, "int", "largest rule with nodes=None (then converged=False)", low=1),
        "quad_tol": Option(1e-6, "float", "largest relative change of the leading band Hankel singular values "
                           "on doubling the nodes", low=0, high=1, open_low=True, open_high=True),
        "quad_hsv": Option(20, "int", "how many leading band Hankel singular values the doubling test checks",
                           low=1),
        "variable": Option("auto", "choice", "integration variable of the rule: log(w) (nodes per decade), w, "
                           "or auto (log when w1 > 0 and w2 / w1 >= 10)", choices=VARIABLES),
        "compress_tol": Option(1e-10, "float", "factor columns whose singular value is below compress_tol times "
                               "the largest are dropped (Gramian error <= compress_tol^2 of its norm)",
                               low=0, high=1, open_high=True),
        "hsv_tol": Option(1e-13, "float", "singular values below hsv_tol times the largest are never kept "
                          "(caps r)", low=0, high=1, open_high=True),
        "solver_threads": Option(0, "int", "threads that factor and solve nodes concurrently (0: 2 on two or "
                                 "more cores, 1 for KLU)", low=0),
        "limited": Option("controllability", "choice", "which Gramians are band-limited: only the "
                          "controllability one, with the full observability Gramian from bt's LR-ADI (default; "
                          "Enns' one-sided weighting: first-order models stable), or both (the two-sided FL-BT "
                          "of the literature: no stability guarantee)", choices=("controllability", "both")),
    }
    GROUPS = {"quadrature": Group("the Gauss-Legendre rule of the band Gramians, its doubling test and the factors' "
                                  "compression", ("nodes_start", "max_nodes", "quad_tol", "quad_hsv", "variable",
                                                  "compress_tol"))}

    def __init__(self, fom, **options):
        super().__init__(fom, **options)
        self._gram = None

    def _check_options(self):
        o = self.options
        o["band"] = band_pair(self.fom.band if o["band"] is None else o["band"], allow_zero=True,
                               name="The 'band' parameter of BTFL")
        if o["variable"] == "log" and o["band"][0] <= 0:
            raise InputError(f"variable='log' needs band w1 > 0; got band = {o['band']} (use 'linear' or 'auto')")
        if o["nodes"] is None and o["max_nodes"] < o["nodes_start"]:
            raise InputError(f"max_nodes = {o['max_nodes']} is below nodes_start = {o['nodes_start']}")

    def _instability_note(self, form):
        return "; frequency-limited balanced truncation does not preserve stability"

    def _variable(self) -> str:
        v, (w1, w2) = self.options["variable"], self.options["band"]
        if v == "auto":
            return "log" if w1 > 0 and w2 >= 10 * w1 else "linear"
        return v

    # -- band Gramians (once per reducer) ----------------------------------
    def _rule(self, n, solver, threads):
        """The compressed factors of the n-node rule, their products and band Hankel singular values."""
        omega, weights = band_nodes(self.options["band"], n, self._variable())
        t0 = time.perf_counter()
        c, ob = band_factors(self.fom, omega, weights, solver=solver, threads=threads)
        t1 = time.perf_counter()
        columns = {"controllability": c.rank, "observability": ob.rank}
        tol = self.options["compress_tol"]
        c, ob = compress(c, tol), compress(ob, tol)
        t2 = time.perf_counter()
        prods = level_products(c, ob, self.fom)
        hsv = np.linalg.svd(prods["pp"] + prods["vv"], compute_uv=False)
        t3 = time.perf_counter()
        return {"n": n, "omega": omega, "c": c, "o": ob, "prods": prods, "hsv": hsv, "columns": columns,
                "times": {"solves": t1 - t0, "compression": t2 - t1, "products": t3 - t2}}

    def _change(self, s_new, s_old):
        """Largest relative change of the leading quad_hsv values (those above HSV_FLOOR of the largest)."""
        o = self.options
        if not s_new.size or s_new[0] <= 0:
            return 0.0
        k = min(o["quad_hsv"], int(np.sum(s_new > max(o["hsv_tol"], HSV_FLOOR) * s_new[0])))
        old = np.zeros(k)
        old[:min(k, s_old.size)] = s_old[:k]
        return float(np.max(np.abs(s_new[:k] - old) / s_new[:k])) if k else 0.0

    def _gramians(self) -> dict:
        if self._gram is not None:
            return self._gram
        o = self.options
        solver = self.fom.new_solver(cache_size=0)
        threads = o["solver_threads"] or default_threads(solver.backend)
        t0 = time.perf_counter()
        levels, converged = [], True
        rule = self._rule(o["nodes"] or o["nodes_start"], solver, threads)
        spent = dict(rule["times"])
        levels.append({"nodes": rule["n"], "change": None})
        while o["nodes"] is None:
            if 2 * rule["n"] > o["max_nodes"]:
                converged = False
                break
            previous, rule = rule, self._rule(2 * rule["n"], solver, threads)
            spent = {k: spent[k] + rule["times"][k] for k in spent}
            levels.append({"nodes": rule["n"], "change": self._change(rule["hsv"], previous["hsv"])})
            if levels[-1]["change"] <= o["quad_tol"]:
                break
        change = levels[-1]["change"]
        c, ob = rule["c"], rule["o"]
        st = solver.stats
        lus, prods, adi = int(st.factorizations), rule["prods"], None
        if o["limited"] == "controllability":  # the full observability Gramian: a fresh LR-ADI run (its LUs counted)
            gf = gramian_factors(self.fom, use_cache=False)
            ob, lus, adi = gf.observability, lus + gf.lu_count, gf
            prods = level_products(c, ob, self.fom)
        t1 = time.perf_counter()
        self._gram = {
            "c": c, "o": ob, "prods": prods, "svd": {}, "svd_times": {}, "projected": {},
            "times": {"quadrature": t1 - t0, "lu": st.factor_time_s + st.assemble_time_s,
                      "solves": st.solve_time_s,
                      "compression": spent["compression"], "products": spent["products"]},
            "lu_count": lus, "adi": adi, "nodes": rule["n"], "omega": rule["omega"], "levels": levels,
            "change": change, "quad_converged": converged, "columns": rule["columns"], "backend": solver.backend,
            "threads": threads,
        }
        return self._gram

    def _reduce(self, r):
        fresh = self._gram is None
        g = self._gramians()
        o = self.options
        if not g["quad_converged"]:
            self.warn(f"bt-fl: the band Hankel singular values still changed by {g['change']:.2e} > quad_tol = "
                      f"{o['quad_tol']:.1e} at max_nodes = {o['max_nodes']} (last rule: {g['nodes']} nodes); the "
                      f"band Gramians are not accurate to quad_tol", ConvergenceWarning)
        adi_ok = g["adi"] is None or g["adi"].converged
        if not adi_ok:
            self.warn("bt-fl: the LR-ADI of the full observability Gramian stopped at its maxiter; that Gramian "
                      "is not accurate to its tolerance", ConvergenceWarning)
        rom, extra, tt = self._truncate(r)
        extra["error_bound"] = None  # no bound for frequency-limited BT
        times = g["times"]
        nodes_evaluated = sum(level["nodes"] for level in g["levels"])
        paid = {k: (times[k] if fresh else 0.0) for k in ("quadrature", "lu", "solves", "compression", "products")}
        info = {
            "form": o["form"], "band": list(o["band"]), "variable": self._variable(),
            "limited": o["limited"], "converged": bool(g["quad_converged"] and adi_ok),
            "status": "direct" if g["quad_converged"] and adi_ok else "cap",
            "iterations": len(g["levels"]), "nodes": g["nodes"], "nodes_evaluated": nodes_evaluated,
            "omega": g["omega"], "quad_levels": g["levels"], "quad_change": g["change"], "quad_tol": o["quad_tol"],
            "solver_threads": g["threads"],
            "factor_ranks": {"controllability": g["c"].rank, "observability": g["o"].rank},
            "factor_columns": g["columns"], **extra,
            # the band Gramians (their nodes' LUs) and the SVDs: r-independent, paid on the first call
            **cost_record(lus_shared=g["lu_count"], lus_paid=g["lu_count"] if fresh else 0,
                          setup_cost={"quadrature": times["quadrature"], "svd": tt["svd_setup"]},
                          paid={"quadrature": paid.pop("quadrature"), "svd": tt["svd"]},
                          breakdown={**paid, "projection": tt["projection"]}),
        }
        return rom, info

