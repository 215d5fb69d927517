r"""Solves with one sparse LU of the saddle-point matrix, checked for accuracy.

A :class:`SaddleLU` holds the LU factors (SuperLU, or a banded LU of
:mod:`~morsuite.linalg.backends`) of the equilibrated, possibly
symmetrically renumbered matrix :math:`A_e = (D_r S D_c)[q][:, q]` of

.. math::

    S = \begin{bmatrix} aM + bD + cK & G^T \\ G & 0 \end{bmatrix}

made by :class:`~morsuite.linalg.saddle.SaddlePointSolver`, and solves
:math:`Sx = b` or :math:`S^Tx = b` (plain transpose) for one or many
right-hand sides; for real data it also stands for the conjugate matrix. Each
solve is checked by its normwise backward error on the factorized system,
:math:`\eta = \|b_e - A_e x_e\| / (\|A_e\|\|x_e\| + \|b_e\|)` (defined precisely, with what
"reached" means, in :mod:`morsuite.linalg.accuracy`):

- above ``backward_tol`` (1e-10; an unstable factor): one step of iterative refinement, then
  the fallback factorizations in turn, then :class:`SingularShiftError`;
- then, down to ``backward_target`` (1e-15, about 9 units of roundoff): certified in double where
  the residual's rounding bound allows it, else measured with a double-double residual; above the
  target, refinement with that residual and the same LU (at most ``refine_steps``), then one
  fallback factorization, then the solve is returned flagged (``stats.above_target``, an
  :class:`~morsuite.errors.AccuracyWarning`, the run's record of :mod:`~morsuite.linalg.accuracy`).

``backward_target=0`` restores the check before 2026-12-02 (``backward_tol`` only).
:func:`rcond_estimate` estimates the reciprocal condition of the equilibrated matrix for ``rcond_tol``.

Cost: a solve is two triangular solves; the check one sparse product (about 3% of an LU),
plus one with :math:`|A_e|` for the certificate in double, or one double-double product (about
90 flops per complex entry: 2-4% of a 3D element model's LU at n1 = 2e4, where it is always
needed); a refinement step one solve and one double-double product; a fallback one more LU
(counted in ``stats.factorizations`` and ``stats.refactorizations``); :func:`rcond_estimate` a few
solves (10-20% of an LU). Measured: ``docs/design/backends.md`` (2026-12-02).
"""

from __future__ import annotations

import threading
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import AccuracyWarning, InputError, SingularShiftError
from . import accuracy
from .accuracy import TargetRefinement

__all__ = ["SaddleLU", "SolverStats", "fallback_factors", "rcond_estimate"]

_STATS_LOCK = threading.Lock()  # the counters are shared by solves that run concurrently (shift-parallel)


@dataclass
class SolverStats:
    """Counters of one :class:`SaddlePointSolver` (plain data)."""

    factorizations: int = 0
    refactorizations: int = 0  # of them, stable re-factorizations after a failed accuracy check
    reused: int = 0
    solves: int = 0  # right-hand-side columns solved
    factor_time_s: float = 0.0
    solve_time_s: float = 0.0
    assemble_time_s: float = 0.0
    # the backward-error target (:mod:`morsuite.linalg.accuracy`): right-hand sides checked, of them
    # returned above the target (flagged), refinement steps and fallback LUs on the way to it, the worst
    # certified backward error and the largest target (these two merge by maximum, not by sum)
    checked_solves: int = 0
    above_target: int = 0
    refinement_steps: int = 0
    target_fallbacks: int = 0
    backward_error_max: float = 0.0
    backward_target: float = 0.0

    #: counters that merge by maximum
    MAXIMA = ("backward_error_max", "backward_target")

    def add(self, **amounts):
        """Add to counters (the largest for :data:`MAXIMA`), thread-safely (factorizations and solves may
        run in a thread pool)."""
        with _STATS_LOCK:
            for k, v in amounts.items():
                setattr(self, k, max(getattr(self, k), v) if k in self.MAXIMA else getattr(self, k) + v)

    def as_dict(self) -> dict:
        """The counters as a plain dict (for ``info`` and manifests)."""
        return dict(self.__dict__)

    def copy(self) -> "SolverStats":
        """A snapshot of the counters, for :meth:`since`."""
        return SolverStats(**self.__dict__)

    def since(self, earlier: "SolverStats") -> dict:
        """Counters accumulated since the snapshot ``earlier`` (:data:`MAXIMA`: the value now)."""
        return {k: v if k in self.MAXIMA else v - getattr(earlier, k) for k, v in self.__dict__.items()}


@dataclass
class SaddleLU(TargetRefinement):
    """A factorization of :math:`a M + b D + c K` bordered by G and G^T.

    Its solves are checked, and refined to ``target``, by the methods of
    :class:`~morsuite.linalg.accuracy.TargetRefinement`.

    ``conjugate`` is True when this object stands for the conjugate of the
    factorized matrix (real data: :math:`S(\\bar s) = \\overline{S(s)}`).
    """

    coeffs: tuple
    lu: object = field(repr=False)
    n1: int
    n2: int
    conjugate: bool
    stats: SolverStats = field(repr=False)
    min_pivot_ratio: float
    complex_lu: bool
    matrix: object = field(default=None, repr=False)  # the factorized (equilibrated) matrix, for the check
    backward_tol: float = 0.0
    norms: dict = field(default_factory=dict, repr=False)  # {trans: norm} of ``matrix``, filled lazily
    dr: object = field(default=None, repr=False)  # scaling: the LU is of diag(dr) S diag(dc)
    dc: object = field(default=None, repr=False)
    fallback: tuple = ()  # callables () -> another LU of the same matrix, tried in order
    refactored: bool = False
    q: object = field(default=None, repr=False)  # the LU is of (Dr S Dc)[q][:, q] (a reused ordering)
    target: float = 0.0  # backward_target (0: backward_tol only, the check before 2026-12-02)
    refine_steps: int = 0  # most refinement steps per solve on the way to the target
    structure: object = field(default=None, repr=False)  # the pattern dict of ``matrix`` (cached structures)
    #: largest ratio of successive backward errors seen in the target refinement (the factor's contraction)
    contraction: float = 0.0
    target_fallback: bool = False  # the one fallback LU of a missed target was tried

    def solve(self, rhs, *, trans: bool = False, full: bool = False):
        """Solve :math:`S x = b` (``trans=False``) or :math:`S^T x = b`.

        Parameters
        ----------
        rhs : array_like, shape (n1,) or (n1, k), or (n1 + n2,) or (n1 + n2, k)
            Right-hand side. With n1 rows the constraint block is zero, as in
            every transfer-function and interpolation solve.
        trans : bool
            Solve with the plain (not conjugate) transpose.
        full : bool
            Return the whole solution including the Lagrange multipliers.
        """
        b = np.asarray(rhs)
        vector = b.ndim == 1
        if vector:
            b = b[:, None]
        n = self.n1 + self.n2
        if b.shape[0] == self.n1 and self.n2:
            b = np.vstack([b, np.zeros((self.n2, b.shape[1]), dtype=b.dtype)])
        elif b.shape[0] != n:
            raise InputError(
                f"rhs has {b.shape[0]} rows; expected n1 = {self.n1} or n1 + n2 = {n}"
            )
        t0 = time.perf_counter()
        # the check works on the equilibrated system As xs = bs that was factorized
        # (S = Dr^-1 As Dc^-1: S x = b <=> As (Dc^-1 x) = Dr b; S^T x = b <=> As^T (Dr^-1 x) = Dc b)
        b = self._to_lu_space(b, trans)
        x = self._lu_solve(b, trans)
        if not np.all(np.isfinite(x)):
            raise SingularShiftError(
                f"saddle-point solve at s-coefficients {self.coeffs} produced non-finite values: "
                "the shift is (numerically) a pole of the system"
            )
        if self.matrix is not None:
            x = self._checked(b, x, trans)
        x = self._from_lu_space(x, trans)
        self.stats.add(solve_time_s=time.perf_counter() - t0, solves=b.shape[1])
        if not full:
            x = x[: self.n1]
        return x[:, 0] if vector else x

    def backward_error(self, rhs, *, trans: bool = False) -> float:
        """Normwise backward error of one unchecked solve with ``rhs`` (n1 or n1 + n2 rows) on the
        equilibrated system, from a residual in double (the check certifies it:
        :mod:`morsuite.linalg.accuracy`)."""
        if self.matrix is None:
            raise InputError("backward_error needs a factorization made with backward_tol > 0")
        b = np.asarray(rhs).reshape(np.shape(rhs)[0], -1)
        if b.shape[0] == self.n1 and self.n2:
            b = np.vstack([b, np.zeros((self.n2, b.shape[1]), dtype=b.dtype)])
        b = self._to_lu_space(b, trans)
        return self._backward_error(b, self._lu_solve(b, trans), trans)[0]

    def _apply(self, x, trans):
        """The factorized matrix (conjugated/transposed as this view says) times x."""
        A = self.matrix.T if trans else self.matrix
        return np.conj(A @ np.conj(x)) if self.conjugate else A @ x

    def _norm(self):
        """1-norm (largest column sum) of the factorized matrix, computed once.

        It is also the inf-norm of its transpose, so the check of a plain solve
        works in the 1-norm and that of a transposed solve in the inf-norm, both
        from the column sums of the CSC data (one contiguous pass).
        """
        if "1" not in self.norms:
            A = self.matrix
            av = np.abs(A.data)
            self.norms["1"] = float(np.add.reduceat(av, A.indptr[:-1]).max()) if av.size else 0.0
        return self.norms["1"]

    def _etas(self, b, x, trans, r=None):
        """Normwise backward error of each column, its residual and its denominator:
        ``(eta, r, den)`` with ``eta = ||r|| / den``, ``den = ||A|| ||x|| + ||b||``.

        1-norms for ``A x = b``, inf-norms for ``A^T x = b`` (``||A^T||_inf = ||A||_1``). ``r``, if
        given, is the residual (formed in extended precision); else ``b - A x`` in double.
        """
        if r is None:
            r = b - self._apply(x, trans)
        red = np.max if trans else np.sum
        den = self._norm() * red(np.abs(x), axis=0) + red(np.abs(b), axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            eta = np.where(den > 0, red(np.abs(r), axis=0) / np.where(den > 0, den, 1.0), 0.0)
        return eta, r, den

    def _backward_error(self, b, x, trans):
        """Normwise backward error per column, the worst: ``(max eta, r)`` (:meth:`_etas`)."""
        eta, r, _ = self._etas(b, x, trans)
        return float(np.max(eta)) if eta.size else 0.0, r

    def _checked(self, b, x, trans):
        etas, r, ext = self._measure(b, x, trans)
        if not np.max(etas) <= self.backward_tol:
            x, eta = self._stabilised(b, x, r, trans)
            etas, r, ext = self._measure(b, x, trans) if self.target > 0 else (np.full(b.shape[1], eta), None, False)
        steps = fell = 0
        if self.target > 0:
            x, etas, steps, fell = self._to_target(b, x, trans, etas, r, ext)
        above = int(np.count_nonzero(etas > self.target)) if self.target > 0 else 0
        worst = float(np.max(etas)) if etas.size else 0.0
        self.stats.add(checked_solves=b.shape[1], above_target=above, refinement_steps=steps, target_fallbacks=fell,
                       backward_error_max=worst, backward_target=self.target)
        accuracy.note(eta=worst, target=self.target, checked=b.shape[1], above_target=above, refinement_steps=steps,
                      fallback_lus=fell)
        if above:
            warnings.warn("saddle-point solves stayed above their backward-error target after refinement and a "
                          "fallback LU (near a pole?): counted in the solver's stats.above_target and in the run's "
                          "solve_accuracy record", AccuracyWarning, stacklevel=4)
        return x

    def _stabilised(self, b, x, r, trans):
        """An unstable factor (backward error above ``backward_tol``): one refinement step, then the fallback
        factorizations in turn; :class:`SingularShiftError` if none passes. Returns ``(x, eta)``."""
        x = x + self._lu_solve(r, trans)  # one step of iterative refinement
        eta, _ = self._backward_error(b, x, trans)
        while not eta <= self.backward_tol and self.fallback:
            # an unstable pivot sequence: refactor the same matrix with the next
            # pivoting/ordering of the fallback list (cheapest first) and solve again
            # (the cases that needed it: docs/design/saddle.md)
            t0 = time.perf_counter()
            make, self.fallback = self.fallback[0], self.fallback[1:]
            self.lu, self.refactored = make(), True
            self.stats.add(factorizations=1, refactorizations=1, factor_time_s=time.perf_counter() - t0)
            x = self._lu_solve(b, trans)
            eta, r = self._backward_error(b, x, trans)
            if not eta <= self.backward_tol:
                x = x + self._lu_solve(r, trans)
                eta, _ = self._backward_error(b, x, trans)
        if not eta <= self.backward_tol:
            raise SingularShiftError(
                f"saddle-point solve at s-coefficients {self.coeffs} is inaccurate: backward error "
                f"{eta:.1e} > backward_tol {self.backward_tol:.0e} after one refinement step "
                "(the shift is at or next to a pole)"
            )
        return x, eta

    def _to_lu_space(self, b, trans):
        """Right-hand side of the factorized system Ae = (Dr S Dc)[q][:, q] for S x = b (S^T x = b).

        S x = b <=> Ae y = (Dr b)[q], x[q] = Dc[q] y; S^T x = b <=> Ae^T y = (Dc b)[q], x[q] = Dr[q] y.
        The backward-error check works in this space.
        """
        lo = self.dc if trans else self.dr
        if lo is not None:
            b = lo[:, None] * b
        return b if self.q is None else b[self.q]

    def _from_lu_space(self, x, trans):
        if self.q is not None:
            y, x = x, np.empty_like(x)
            x[self.q] = y
        hi = self.dr if trans else self.dc
        return x if hi is None else hi[:, None] * x

    def _raw_solve(self, b, trans):
        """Unchecked solve with S (``trans``: S^T) for a 2-D ``b`` of n1 + n2 rows."""
        return self._from_lu_space(self._lu_solve(self._to_lu_space(b, trans), trans), trans)

    def _lu_solve(self, b, trans):
        tr = "T" if trans else "N"
        if self.conjugate:
            x = np.conj(self.lu.solve(np.ascontiguousarray(np.conj(b), dtype=complex), trans=tr))
        elif not self.complex_lu and np.iscomplexobj(b):
            # a real LU: solve real and imaginary parts together as 2k real columns
            k = b.shape[1]
            y = self.lu.solve(np.ascontiguousarray(np.hstack([b.real, b.imag]), dtype=float), trans=tr)
            x = y[:, :k] + 1j * y[:, k:]
        else:
            x = self.lu.solve(np.ascontiguousarray(b, dtype=complex if self.complex_lu else float), trans=tr)
        return x


def fallback_factors(As, lu, pattern, spec: str, thresh: float) -> tuple:
    """The fallback list of the factorization ``lu`` of ``As``: callables () -> another LU of the same
    matrix, cheapest first (``spec``: the column ordering ``lu`` used, ``thresh``: the pivot threshold).
    Each costs one LU; :meth:`SaddleLU._stabilised` takes them in turn, the target's check the first."""
    from .backends import BandedBorderLU
    from .backends_ext import KLULU, PardisoLU
    from .backends_rslab import RslabLDLT, RslabLU

    return ((
        # rslab's LDL^T perturbs tiny pivots: its own LU (threshold pivoting) of the same matrix first
        lambda: RslabLU(As, pattern),
    ) if isinstance(lu, RslabLDLT) else ()) + ((
        # the banded LU pivots within A11 only (KLU, PARDISO: own pivoting): SuperLU on the same matrix first
        lambda: spla.splu(As, permc_spec="COLAMD", diag_pivot_thresh=thresh),
    ) if isinstance(lu, (BandedBorderLU, KLULU, RslabLU, RslabLDLT, PardisoLU)) else ()) + (
        # more weight on the diagonal of the equilibrated matrix, same ordering (cheap)
        lambda: spla.splu(As, permc_spec=spec, diag_pivot_thresh=min(0.01, thresh)),
        # a fresh column ordering
        lambda: spla.splu(As, permc_spec="COLAMD", diag_pivot_thresh=thresh),
        # symmetric ordering, partial pivoting: the last resort (it can fill in heavily)
        lambda: spla.splu(As, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=1.0),
    )


def rcond_estimate(A, solve, n1: int, mag) -> float:
    """Reciprocal 1-norm condition estimate of the equilibrated matrix D S D, through the LU.

    D = blkdiag(D1, D2): D1 scales the rows and columns of the magnitudes
    ``mag = |a||M| + |b||D| + |c||K|`` of the (1,1) block to unit row maxima
    (magnitudes of the terms, not of their sum, so that the cancellation
    that makes s a pole is not scaled away), D2 then scales G D1 likewise. The
    condition of S itself mixes the scales ``|s|^2 M`` and G (1e31 at s = 1e7j on
    the DSMS, whose solve is accurate to 4e-16): only the equilibrated one says
    whether s is near a pole.
    """
    N = A.shape[0]
    absA = mag.tocsr()
    rowmax = np.asarray(absA[:n1, :n1].max(axis=1).todense()).ravel()
    d = np.ones(N)
    d[:n1] = 1.0 / np.sqrt(np.where(rowmax > 0, rowmax, 1.0))
    if N > n1:
        Gs = absA[n1:, :n1] @ sp.diags(d[:n1])
        gmax = np.asarray(Gs.max(axis=1).todense()).ravel()
        d[n1:] = 1.0 / np.where(gmax > 0, gmax, 1.0)
    Dm = sp.diags(d)
    As = Dm @ A @ Dm
    dtype = A.dtype
    di = (1.0 / d)

    def inv(X, trans=False):
        X = np.asarray(X, dtype=dtype)
        Y = (X.T * di).T
        Y = np.conj(solve(np.conj(Y), True)) if trans else solve(Y, False)
        return (Y.T * di).T

    op = spla.LinearOperator((N, N), dtype=dtype, matvec=inv, matmat=inv,
                             rmatvec=lambda x: inv(x, True), rmatmat=lambda X: inv(X, True))
    norm_inv = spla.onenormest(op, t=2)
    norm_a = abs(As).sum(axis=0).max()
    if not np.isfinite(norm_inv) or norm_inv == 0:
        return 0.0
    return float(1.0 / (norm_a * norm_inv))
