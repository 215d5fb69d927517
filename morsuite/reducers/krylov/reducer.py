r"""The ``krylov`` reducer: second-order moment matching at one or a few expansion points.

See :mod:`morsuite.reducers.krylov` for the method, its options and its cost.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ...errors import AccuracyWarning, OptionError, RankWarning, SingularShiftError, StabilityWarning
from ...rom import SecondOrderROM
from ..base import Option, Reducer
from ..registry import Description
from .soar import SOAR, KernelProjector, RealBasis

__all__ = ["Krylov", "expansion_points"]

#: ``info["kernel_residual"]`` above this (relative) is warned about (AccuracyWarning)
KERNEL_WARN = 1e-8
#: a reduced matrix A_r(s0) with a condition number above this is warned about (AccuracyWarning): its
#: moments then hold to less than about 1e-8 relative
COND_WARN = 1e8
#: the default of the ``moment_tol`` option: a moment counts as matched when measured to this relative error
MOMENT_TOL = 1e-8


def expansion_points(points, npoints: int, band) -> np.ndarray:
    r"""The distinct expansion points of the ``points`` option, one per conjugate pair.

    ``"auto"``: the one real point :math:`s_0 = \sqrt{\omega_1\omega_2}`, the
    band's geometric mean (a real LU, never at a pole of a stable model). Measured
    at r = 20 (``docs/design/krylov.md``), it gave a band error 10, 16 and 1.2 times
    smaller than the lower edge :math:`\omega_1` on dsms(600), tcom(200) and
    fem_block(2000), and smaller than three points :math:`i\omega_k` in the band.
    ``"band"``: ``npoints`` points :math:`i\omega_k` with :math:`\omega_k` spread
    log-uniformly over the band, edges included (one point: the geometric mean);
    each serves its conjugate. A list: those points, duplicates and conjugates
    merged (the one with nonnegative imaginary part kept), in the order given; also
    as text, numbers separated by commas (``"0.5, 1+2j"``, the command line's form).

    Parameters
    ----------
    points : "auto", "band" or array_like of numbers
    npoints : int
    band : (float, float)
        The model's band in rad/s.

    Returns
    -------
    ndarray
        Complex, one entry per distinct point up to conjugation (imaginary part >= 0).

    Raises
    ------
    OptionError
        An empty list, a non-finite or non-numeric entry, a point with negative real
        part, or an unknown string; the message names ``points``. Cost: none.
    """
    lo, hi = band
    if isinstance(points, str):
        if points == "auto":
            return np.array([complex(np.sqrt(lo * hi))])
        if points == "band":
            w = np.array([np.sqrt(lo * hi)]) if npoints == 1 else np.geomspace(lo, hi, npoints)
            return 1j * w
        try:  # a list written as text (the command line's --option points=0.5,1+2j)
            return expansion_points([complex(x.replace(" ", "")) for x in points.strip("[]() ").split(",")],
                                    npoints, band)
        except ValueError:
            pass
        raise OptionError(f"The 'points' parameter of Krylov must be 'auto', 'band' or a list of expansion "
                          f"points. Got {points!r} instead.")
    try:
        arr = np.atleast_1d(np.asarray(points))
        if arr.dtype == object or not np.issubdtype(arr.dtype, np.number):
            raise TypeError
        arr = arr.astype(complex)
    except (TypeError, ValueError):
        raise OptionError(f"The 'points' parameter of Krylov must be 'auto', 'band' or a list of numbers. "
                          f"Got {points!r} instead.") from None
    if arr.ndim != 1 or arr.size == 0:
        raise OptionError(f"The 'points' parameter of Krylov must be a non-empty 1-D list of expansion points. "
                          f"Got {points!r} instead.")
    if not np.all(np.isfinite(arr)):
        raise OptionError(f"The 'points' parameter of Krylov must hold finite numbers. Got {points!r} instead.")
    if np.any(arr.real < 0):
        raise OptionError(f"The 'points' parameter of Krylov must lie in the closed right half-plane (Re s >= 0, "
                          f"where a stable model has no pole). Got {points!r} instead.")
    out: list[complex] = []
    for s in arr:
        s = complex(s.real, abs(s.imag))
        if s not in out:
            out.append(s)
    return np.array(out)


@dataclass
class _Side:
    """One basis (right: inputs, left: outputs) grown level by level, round-robin over the points."""

    soars: list
    basis: RealBasis
    log: list = field(default_factory=list)  # (point, level, columns after, cumulative seconds)
    turn: int = 0
    seconds: float = 0.0

    def grow(self, r: int):
        """Add levels (one point at a time, in turn) until the basis has r columns or every point is exhausted."""
        t0 = time.perf_counter()
        while self.basis.cols < r and not all(s.exhausted for s in self.soars):
            i = self.turn % len(self.soars)
            self.turn += 1
            soar = self.soars[i]
            if soar.exhausted:
                continue
            level = len(soar.levels)
            self.basis.add(soar.step())
            self.seconds += time.perf_counter() - t0
            t0 = time.perf_counter()
            self.log.append((i, level, self.basis.cols, self.seconds))
        self.seconds += time.perf_counter() - t0

    def levels_within(self, r: int) -> list[int]:
        """Per point: how many of its levels (0, 1, ...) lie wholly in the first r columns."""
        count = [0] * len(self.soars)
        open_ = [True] * len(self.soars)
        for i, level, cols, _ in self.log:
            if open_[i] and level == count[i] and cols <= r:
                count[i] += 1
            else:
                open_[i] = False
        return count

    def seconds_to(self, r: int) -> float:
        """Seconds the basis took up to its first r columns."""
        for *_, cols, t in self.log:
            if cols >= r:
                return t
        return self.seconds

    def solves(self) -> int:
        return sum(s.solves for s in self.soars)


def is_symmetric(X) -> bool:
    """Whether the sparse matrix X equals its transpose to 1e-14 of its largest entry."""
    X = sp.csr_matrix(X)
    diff = X - X.T
    return diff.nnz == 0 or abs(diff).max() <= 1e-14 * max(abs(X).max(), np.finfo(float).tiny)


class Krylov(Reducer):
    """Second-order Krylov moment matching (SOAR) through saddle-point solves (module :mod:`morsuite.reducers.krylov`).

    ``reduce(r)`` returns a :class:`~morsuite.rom.SecondOrderROM` of order r (2r
    states): the first r columns of a nested basis grown level by level over the
    expansion points in turn. The LUs (one per point) and the basis are kept, so
    a sweep over r pays the LUs once and each solve once.
    """

    name = "krylov"
    DESCRIPTION = Description(
        label="Krylov moment matching (SOAR)", result="second-order",
        targets="moments of T at one or a few expansion points", cost="one per expansion point (a conjugate pair one)",
        use_for="the engineering baseline at one LU, accurate near its points",
        options=("points", "npoints", "sided", "directions"), default=True, stress={}, page="krylov", order=70)

    OPTIONS = {
        "points": Option("auto", "any", "expansion points: 'auto' (one real point, the band's geometric mean), "
                         "'band' (npoints points i*omega, omega log-uniform over the band, each serving its "
                         "conjugate) or a list of points in the closed right half-plane (conjugates merged)"),
        "npoints": Option(3, "int", "number of expansion points of points='band'", low=1),
        "sided": Option("one", "choice", "one-sided (congruence V^T (.) V: SPD M, K and PSD D stay so, the "
                        "reduced model is stable; k moments per point) or two-sided (W^T (.) V with W from the "
                        "transposed solves: 2k moments, stability not guaranteed, checked and flagged)",
                        choices=("one", "two")),
        "directions": Option("block", "choice", "block: all m inputs (p outputs) at every level; tangential: "
                             "one direction per point (right_directions / left_directions, or random unit "
                             "vectors from seed), matching T^(j)(s0) b", choices=("block", "tangential")),
        "right_directions": Option(None, "array", "tangential input directions: (m,) for every point or "
                                   "(m, points); None: random (seed)", nullable=True),
        "left_directions": Option(None, "array", "tangential output directions: (p,) or (p, points); None: "
                                  "random (seed)", nullable=True),
        "seed": Option(0, "int", "seed of the random tangential directions", low=0),
        "orth_tol": Option(1e-10, "float", "deflation tolerance: a new column whose part outside the basis is at "
                           "most orth_tol of its norm is dropped (its direction is in the subspace to that "
                           "accuracy)", low=0, high=1, open_low=True, open_high=True),
        "reorth": Option(2, "int", "Gram-Schmidt passes per column (2: classical Gram-Schmidt twice, orthogonal "
                         "to rounding)", low=1, high=3),
        "check_moments": Option(True, "bool", "measure the moments the basis spans against the full model's Taylor "
                                "recurrence (one more solve per moment and column); False: info['moments'] counts "
                                "them unmeasured"),
        "moment_tol": Option(MOMENT_TOL, "float", "a moment counts as matched (info['moments']) when its relative "
                             "error, measured against the full model's Taylor recurrence, is at most this",
                             low=0, high=1, open_low=True, open_high=True),
    }

    def __init__(self, fom, **options):
        super().__init__(fom, **options)
        self._state = None

    def _check_options(self):
        o = self.options
        self._points = expansion_points(o["points"], o["npoints"], self.fom.band)
        q = len(self._points)
        for key, size in (("right_directions", self.fom.m), ("left_directions", self.fom.p)):
            d = o[key]
            if d is None:
                continue
            if o["directions"] != "tangential":
                raise OptionError(f"The {key!r} parameter of Krylov needs directions='tangential'.")
            d = np.asarray(d)
            if np.iscomplexobj(d) or d.shape[0] != size or d.ndim > 2 or (d.ndim == 2 and d.shape[1] != q):
                raise OptionError(f"The {key!r} parameter of Krylov must be a real array of shape ({size},) or "
                                  f"({size}, {q}) (one column per expansion point). Got shape {d.shape} instead.")
            if np.any(np.linalg.norm(d.reshape(size, -1), axis=0) == 0):
                raise OptionError(f"The {key!r} parameter of Krylov must have nonzero columns.")

    # -- setup: LUs and the per-point recurrences ------------------------
    def _directions(self, key, size, q, rng):
        d = self.options[key]
        if d is None:
            d = rng.standard_normal((size, q))
        d = np.asarray(d, dtype=float).reshape(size, -1)
        if d.shape[1] == 1:
            d = np.repeat(d, q, axis=1)
        return d / np.linalg.norm(d, axis=0)

    def _setup(self):
        t0 = time.perf_counter()
        fom, o = self.fom, self.options
        solver = fom.new_solver(cache_size=0)  # the LUs are kept here, one per point
        pts = self._points
        q = len(pts)
        rng = np.random.default_rng(o["seed"])
        tangential = o["directions"] == "tangential"
        dirs = {}
        if tangential:
            dirs["right"] = self._directions("right_directions", fom.m, q, rng)
            if o["sided"] == "two":
                dirs["left"] = self._directions("left_directions", fom.p, q, rng)
        lus = []
        for k, s in enumerate(pts):
            s = s.real if s.imag == 0 else s
            try:
                lu = solver.factor(s)
                lu.solve(fom.F[:, :1].astype(complex if np.iscomplexobj(s) else float))  # the accuracy check
            except SingularShiftError as exc:
                raise SingularShiftError(f"The 'points' parameter of Krylov: points[{k}] = {s} is (numerically) "
                                         f"a pole of the model; choose another expansion point ({exc})") from exc
            lus.append((s, lu))
        symmetric = all(is_symmetric(X) for X in (fom.M, fom.D, fom.K))
        project = KernelProjector(fom.G) if fom.n2 else None
        sides = {}
        for side in ("right",) + (("left",) if o["sided"] == "two" else ()):
            trans = side == "left"
            M, D, K = ((X.T.tocsr() if trans and not symmetric else X) for X in (fom.M, fom.D, fom.K))
            start = fom.L.T if trans else fom.F
            soars = []
            for k, (s, lu) in enumerate(lus):
                b = start @ dirs[side][:, k:k + 1] if tangential else start
                solve = (lambda rhs, lu=lu, trans=trans: lu.solve(rhs, trans=trans))
                soars.append(SOAR(solve, (2 * s) * M + D, M, K, D, s, b, o["orth_tol"], o["reorth"]))
            sides[side] = _Side(soars, RealBasis(fom.n1, o["orth_tol"], o["reorth"], project))
        st = solver.stats
        self._state = {"solver": solver, "lus": lus, "sides": sides, "symmetric": symmetric, "directions": dirs,
                       "lu_time": st.factor_time_s + st.assemble_time_s, "setup_time": time.perf_counter() - t0,
                       "taylor": [None] * len(lus)}
        return self._state

    # -- reduction ----------------------------------------------------------
    def _reduce(self, r):
        fresh = self._state is None
        t0 = time.perf_counter()
        state = self._state or self._setup()
        t_setup = time.perf_counter() - t0 if fresh else 0.0  # the LUs, their checks, the kernel projector
        t_lu = state["lu_time"] if fresh else 0.0
        sides = state["sides"]
        before = {k: (s.seconds, s.solves()) for k, s in sides.items()}
        for s in sides.values():
            s.grow(r)
        t1 = time.perf_counter()
        fom = self.fom
        r_used = min(min(s.basis.cols, r) for s in sides.values())
        if r_used < r:
            self.warn(f"krylov: the Krylov subspaces at the {len(state['lus'])} expansion point(s) are exhausted "
                      f"at dimension {r_used} (invariant, or deflated at orth_tol = {self.options['orth_tol']:g}); "
                      f"r capped from {r} to {r_used}", RankWarning)
        V = sides["right"].basis.V[:, :r_used]
        W = sides["left"].basis.V[:, :r_used] if "left" in sides else V
        Mr, Dr, Kr = (W.T @ (X @ V) for X in (fom.M, fom.D, fom.K))
        one = "left" not in sides
        if one and state["symmetric"]:
            Mr, Dr, Kr = ((X + X.T) / 2 for X in (Mr, Dr, Kr))
        rom = SecondOrderROM(Mr, Dr, Kr, W.T @ fom.F, fom.L @ V, basis=V)
        kernel = self._kernel_residual([V] if one else [V, W])
        if kernel > KERNEL_WARN:
            self.warn(f"krylov: the basis leaves ker G by {kernel:.1e} (relative); the saddle solves or the "
                      f"orthogonalisation lost accuracy", AccuracyWarning)
        stable = bool(rom.is_stable())
        extra = {}
        if one:
            extra["definite"] = definiteness(Mr, Dr, Kr)
        if not stable:
            lam = rom.poles()
            extra["unstable_poles"] = int(np.sum(lam.real >= 0))
            self.warn(f"krylov: the {'two' if not one else 'one'}-sided reduced model at r = {r_used} has "
                      f"{extra['unstable_poles']} poles in the closed right half-plane (max real part "
                      f"{lam.real.max():.3e})" + ("; two-sided moment matching does not preserve stability"
                                                  if not one else "; the full model's M, K are not SPD?"),
                      StabilityWarning)
        t2 = time.perf_counter()
        matched = {k: s.levels_within(r_used) for k, s in sides.items()}
        moments, check_solves, short = [], 0, []
        paid_before = sum(ref["seconds"][-1] for ref in state["taylor"] if ref)
        tol = self.options["moment_tol"]
        for i, (s, _) in enumerate(state["lus"]):
            row = {"point": complex(s), "right_levels": matched["right"][i]}
            if not one:
                row["left_levels"] = matched["left"][i]
            spanned = sum(m[i] for m in matched.values())
            # the moments of the reduced model come from solves with A_r(s0): accurate to about cond * eps
            row["condition"] = float(np.linalg.cond(s * s * Mr + s * Dr + Kr)) if r_used else 1.0
            if not self.options["check_moments"]:
                row.update(moments_spanned=int(spanned), moments=int(spanned), moment_errors=None, moment_error=None)
                moments.append(row)
                continue
            errs, n = self._moment_errors(i, spanned, rom) if spanned else ([], 0)
            check_solves += n
            good = next((j for j, e in enumerate(errs) if not e <= tol), len(errs))
            row.update(moments_spanned=int(spanned), moments=int(good), moment_errors=errs,
                       moment_error=float(max(errs[:good], default=0.0)))
            if good < spanned:
                short.append(f"{good} of {spanned} at s0 = {complex(s):.4g} (the next off by {errs[good]:.1e})")
            moments.append(row)
        t3 = time.perf_counter()
        refs = [(ref, row["moments_spanned"]) for ref, row in zip(state["taylor"], moments) if ref]
        reference_paid = sum(ref["seconds"][-1] for ref, _ in refs) - paid_before  # the full model's moments
        reference_cost = sum(ref["seconds"][k - 1] for ref, k in refs if k)  # what this r alone would pay
        if short:
            self.warn(f"krylov: of the moments its basis spans, the reduced model matches to moment_tol = {tol:g} "
                      f"(measured against the full model's Taylor recurrence) only " + "; ".join(short), AccuracyWarning)
        worst = max(row["condition"] for row in moments)
        if worst > COND_WARN:
            self.warn(f"krylov: the reduced matrix s0^2 M_r + s0 D_r + K_r has condition {worst:.1e} at an expansion "
                      f"point: its matched moments hold to about {worst * np.finfo(float).eps:.0e} relative only"
                      + ("; two-sided bases can make W^T V nearly singular (try sided='one' or another r)"
                         if not one else ""), AccuracyWarning)
        nlu = len(state["lus"])
        basis_now = sum(s.seconds - before[k][0] for k, s in sides.items())
        info = {
            "status": "direct", "converged": True, "iterations": 0,
            "sided": "two" if not one else "one", "points": [complex(s) for s, _ in state["lus"]],
            "moments": moments, "stable": stable, "kernel_residual": kernel, **extra,
            "directions": {k: v for k, v in state["directions"].items()},
            "deflated": {k: sum(x.deflated for x in s.soars) for k, s in sides.items()},
            "basis_columns": {k: s.basis.cols for k, s in sides.items()},
            "lu_count": nlu if fresh else 0, "lu_count_shared": nlu, "setup_reused": not fresh,
            "solves": sum(s.solves() - before[k][1] for k, s in sides.items()),
            "moment_check_solves": int(check_solves),
            "solves_total": sum(s.solves() for s in sides.values()),
            "time_breakdown": {"lu": t_lu, "setup_other": t_setup - t_lu, "basis": basis_now,
                               "projection": t2 - t1, "moment_reference": reference_paid,
                               "moment_check": t3 - t2 - reference_paid},
            # the work a sweep over r shares: the LUs (with the rest of the setup) and the nested basis
            "setup_cost": {"lu": state["lu_time"], "setup_other": state["setup_time"] - state["lu_time"],
                           "basis": sum(s.seconds_to(r_used) for s in sides.values()),
                           "moment_reference": reference_cost},
            "solver_stats": state["solver"].stats.as_dict(),
        }
        return rom, info

    def _moment_errors(self, i, count, rom):
        r"""Relative errors of the first ``count`` moments at point i that the basis spans, and the solves paid.

        The moments :math:`\gamma^jq(X_j)` of the full model (the Taylor recurrence of the module
        docstring with the point's LU, scaled by the right basis's :math:`\gamma` so that they neither
        overflow nor vanish; cached on the reducer and extended as r grows: one solve per moment and
        column) against the same recurrence of the reduced model with a dense LU of
        :math:`A_r(s_0)`. :math:`q(X) = LX` (block), :math:`LXb` (tangential) or :math:`c^TLXb`
        (two-sided tangential: the bitangential moments the two bases match)."""
        st = self._state
        s, lu = st["lus"][i]
        fom, dirs = self.fom, st["directions"]
        g = st["sides"]["right"].soars[i].gamma
        b = dirs["right"][:, i:i + 1] if "right" in dirs else None
        c = dirs["left"][:, i:i + 1] if "left" in dirs else None

        def out(L, X):  # X already carries b (the recurrences start from F b)
            return L @ X if c is None else c.T @ (L @ X)

        ref = st["taylor"][i]
        solves, t0 = 0, time.perf_counter()
        if ref is None:
            X0 = lu.solve(fom.F if b is None else fom.F @ b)
            ref = st["taylor"][i] = {"prev": (np.zeros_like(X0), X0), "out": [out(fom.L, X0)], "seconds": []}
            solves += X0.shape[1]
            ref["seconds"].append(time.perf_counter() - t0)
            t0 = time.perf_counter()
        A1 = 2 * s * fom.M + fom.D
        while len(ref["out"]) < count:
            Xm, X = ref["prev"]
            Xn = -lu.solve(g * (A1 @ X) + (g * g) * (fom.M @ Xm))
            solves += Xn.shape[1]
            ref["prev"] = (X, Xn)
            ref["out"].append(out(fom.L, Xn))
            ref["seconds"].append(ref["seconds"][-1] + time.perf_counter() - t0)
            t0 = time.perf_counter()
        Ar = s * s * rom.M + s * rom.D + rom.K
        A1r = 2 * s * rom.M + rom.D
        Fr = rom.F if b is None else rom.F @ b
        try:
            lur = sla.lu_factor(Ar)
        except (ValueError, np.linalg.LinAlgError):
            return [float("inf")] * count, solves
        Xm, X = np.zeros_like(Fr, dtype=complex), sla.lu_solve(lur, Fr.astype(complex))
        errs = []
        for j in range(count):
            if j:
                Xm, X = X, -sla.lu_solve(lur, g * (A1r @ X) + (g * g) * (rom.M @ Xm))
            want, got = ref["out"][j], out(rom.L, X)
            scale = np.linalg.norm(want)
            errs.append(float(np.linalg.norm(got - want) / scale) if scale > 0 else float(np.linalg.norm(got)))
        return errs, solves

    def _kernel_residual(self, bases) -> float:
        """:math:`\\max \\|GV\\|_F / (\\|G\\|_F \\sqrt{r})` over the bases (0 without constraints)."""
        G = self.fom.G
        if G.shape[0] == 0 or bases[0].shape[1] == 0:
            return 0.0
        ng = spla.norm(G)
        return float(max(np.linalg.norm(G @ B) for B in bases) / (ng * np.sqrt(bases[0].shape[1])))


def definiteness(Mr, Dr, Kr) -> dict:
    """Whether M_r, K_r are symmetric positive definite and D_r positive semidefinite (to rounding)."""
    out = {}
    for name, X, strict in (("M_spd", Mr, True), ("K_spd", Kr, True), ("D_psd", Dr, False)):
        if not X.size:  # an empty basis: the base class refuses the order-0 model
            out[name] = True
            continue
        sym = np.allclose(X, X.T, rtol=0, atol=1e-13 * max(np.abs(X).max(), np.finfo(float).tiny))
        lam = np.linalg.eigvalsh((X + X.T) / 2) if X.size else np.zeros(1)
        tol = 0.0 if strict else -1e-12 * max(np.abs(lam).max(), np.finfo(float).tiny)
        out[name] = bool(sym and lam.min() > tol)
    return out
