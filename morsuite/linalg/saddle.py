r"""Sparse LU factorizations of the shifted saddle-point matrix.

For a constrained second-order system the matrix

.. math::

    S(s) = \begin{bmatrix} s^2 M + s D + K & G^T \\ G & 0 \end{bmatrix}

is nonsingular wherever :math:`s` is not a finite pole of the system, and its
solves replace every application of the hidden-manifold projector
:math:`\Pi` (the paper's Lemma 1): the first block :math:`x` of
:math:`S(s)[x; \lambda] = [F b; 0]` equals
:math:`(\Pi(s^2M+sD+K)\Pi^T)^{+}\,\Pi F b` on the hidden manifold.
The transposed matrix gives the left (observability) solves, so one LU serves
both. For real data :math:`S(\bar s) = \overline{S(s)}`, so a conjugate shift
reuses the factorization of its partner.

The sparsity pattern (union of those of M, D, K, G^T and G) is built once;
assembling :math:`S(s)` afterwards is one AXPY over the stored entries.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import InputError, SingularShiftError

__all__ = ["SaddlePointSolver", "SaddleLU", "SolverStats"]


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

    def as_dict(self) -> dict:
        return dict(self.__dict__)

    def copy(self) -> "SolverStats":
        return SolverStats(**self.__dict__)

    def since(self, earlier: "SolverStats") -> dict:
        """Counters accumulated since the snapshot ``earlier``."""
        return {k: v - getattr(earlier, k) for k, v in self.__dict__.items()}


@dataclass
class SaddleLU:
    """A factorization of :math:`a M + b D + c K` bordered by G and G^T.

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
    matrix: object = field(default=None, repr=False)
    backward_tol: float = 0.0
    norms: tuple = (0.0, 0.0)  # (inf-norm, 1-norm) of the matrix, for the backward error
    dr: object = field(default=None, repr=False)  # scaling: the LU is of diag(dr) S diag(dc)
    dc: object = field(default=None, repr=False)
    fallback: object = field(default=None, repr=False)  # () -> a more stable LU of the same matrix
    refactored: bool = False

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
        x = self._raw_solve(b, trans)
        if not np.all(np.isfinite(x)):
            raise SingularShiftError(
                f"saddle-point solve at s-coefficients {self.coeffs} produced non-finite values: "
                "the shift is (numerically) a pole of the system"
            )
        if self.matrix is not None:
            x = self._checked(b, x, trans)
        self.stats.solve_time_s += time.perf_counter() - t0
        self.stats.solves += b.shape[1]
        if not full:
            x = x[: self.n1]
        return x[:, 0] if vector else x

    def _apply(self, x, trans):
        """The factorized matrix (conjugated/transposed as this view says) times x."""
        A = self.matrix.T if trans else self.matrix
        return np.conj(A @ np.conj(x)) if self.conjugate else A @ x

    def _backward_error(self, b, x, trans):
        r = b - self._apply(x, trans)
        norm_a = self.norms[1] if trans else self.norms[0]
        den = norm_a * np.max(np.abs(x), axis=0) + np.max(np.abs(b), axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return float(np.max(np.where(den > 0, np.max(np.abs(r), axis=0) / den, 0.0))), r

    def _checked(self, b, x, trans):
        eta, r = self._backward_error(b, x, trans)
        if eta <= self.backward_tol:
            return x
        x = x + self._raw_solve(r, trans)  # one step of iterative refinement
        eta, _ = self._backward_error(b, x, trans)
        if not eta <= self.backward_tol and self.fallback is not None:
            # an unstable pivot sequence (seen with COLAMD and threshold 0.1 on
            # tcom(nc=3334): backward error 5e-4): refactor once with the
            # symmetric ordering and full partial pivoting, and solve again
            t0 = time.perf_counter()
            self.lu, self.fallback, self.refactored = self.fallback(), None, True
            self.stats.factorizations += 1
            self.stats.refactorizations += 1
            self.stats.factor_time_s += time.perf_counter() - t0
            x = self._raw_solve(b, trans)
            eta, r = self._backward_error(b, x, trans)
            if not eta <= self.backward_tol:
                x = x + self._raw_solve(r, trans)
                eta, _ = self._backward_error(b, x, trans)
        if not eta <= self.backward_tol:
            raise SingularShiftError(
                f"saddle-point solve at s-coefficients {self.coeffs} is inaccurate: backward error "
                f"{eta:.1e} > backward_tol {self.backward_tol:.0e} after one refinement step "
                "(the shift is at or next to a pole)"
            )
        return x

    def _raw_solve(self, b, trans):
        if self.dr is None:
            return self._lu_solve(b, trans)
        # S = Dr^-1 As Dc^-1: S x = b  <=>  x = Dc As^-1 Dr b; S^T x = b  <=>  x = Dr As^-T Dc b
        lo, hi = (self.dc, self.dr) if trans else (self.dr, self.dc)
        return hi[:, None] * self._lu_solve(lo[:, None] * b, trans)

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


class SaddlePointSolver:
    r"""Factory of factorizations of the bordered matrix of a constrained system.

    Parameters
    ----------
    M, D, K : sparse (n1, n1)
    G : sparse (n2, n1)
    cache_size : int
        Number of factorizations kept (least recently used dropped). A conjugate
        shift of a cached one is served from the cache.
    pivot_tol : float
        A factorization whose smallest pivot of U is below ``pivot_tol`` times
        its largest raises :class:`SingularShiftError` (the shift is at, or next
        to, a pole). It sees the factors of the equilibrated matrix, where Ruiz
        scaling can hide a cancellation on the diagonal: ``rcond_tol`` is the
        check that finds poles. ``0`` (default) turns the check off: the ratio depends on
        the scaling of the blocks (at s = 1e7j on the DSMS it is 1e-16 although
        the solve is accurate to 4e-16), and reading U copies the factors
        (10% of an LU). Exactly singular matrices and non-finite solutions
        always raise :class:`SingularShiftError`.
    rcond_tol : float
        If positive, estimate the reciprocal 1-norm condition number of each
        factorized matrix (Hager-Higham estimator, a few extra solves) and raise
        :class:`SingularShiftError` below ``rcond_tol``. Scale-aware, unlike the
        pivot ratio; costs about 10-20% of an LU, hence off by default.
    permc_spec, diag_pivot_thresh : str, float
        Column ordering and partial-pivoting threshold of SuperLU. Measured
        over 40 frequencies of each band (tcom nc=2000, dsms g=6000):
        COLAMD with threshold 0.1 (the default) was fastest (9 ms / 3 ms median)
        and backward stable (3e-17); COLAMD with SuperLU's default threshold 1.0
        left backward errors of 3e-5 on the TCOM (wrong transfer function in
        the 5th digit at s = 1j); MMD_AT_PLUS_A filled in up to 20x near
        w = 0.5 on the TCOM (5.7 s for one LU).
    scaling, ruiz_sweeps : str, int
        Equilibration of S(s) before it is factored (solutions are unscaled).
        ``"diagonal"`` (default): symmetric scaling D S D with
        :math:`D_1 = (|s|^2|M_{ii}| + |s||D_{ii}| + |K_{ii}|)^{-1/2}` and the
        constraint rows scaled by the largest :math:`|G_{kj}| D_{1,j}`; O(n1)
        per shift. ``"ruiz"``: ``ruiz_sweeps`` sweeps of Ruiz row/column
        max-norm scaling (about 12% of an LU per sweep). ``"none"``. Without
        equilibration a model with coefficients spread over 12 decades (or in
        SI units, M ~ 1e-6, K ~ 1e9) lost every digit of T(s) (wrong sign,
        found by the stress suite) although the equilibrated matrix has
        condition 40; both scalings restore it to 1e-16.
    backward_tol : float
        After every solve the normwise backward error
        ``||b - S x||_inf / (||S||_inf ||x||_inf + ||b||_inf)`` is checked (one
        sparse product, about 3% of an LU); above ``backward_tol`` one step of
        iterative refinement is made, and if that does not help a
        :class:`SingularShiftError` is raised: an inaccurate solve is never
        returned silently. ``0`` turns the check off.

    Notes
    -----
    ``stats.factorizations`` counts every LU made; it is the floor against which
    the run time of a reducer is judged.
    """

    def __init__(self, M, D, K, G, *, cache_size: int = 2, pivot_tol: float = 0.0,
                 rcond_tol: float = 0.0, permc_spec: str = "COLAMD", diag_pivot_thresh: float = 0.1,
                 backward_tol: float = 1e-10, scaling: str = "diagonal", ruiz_sweeps: int = 2):
        self.n1 = M.shape[0]
        self.n2 = G.shape[0]
        self.cache_size = int(cache_size)
        self.pivot_tol = float(pivot_tol)
        self.rcond_tol = float(rcond_tol)
        self.permc_spec = permc_spec
        self.diag_pivot_thresh = float(diag_pivot_thresh)
        self.backward_tol = float(backward_tol)
        if scaling not in ("diagonal", "ruiz", "none"):
            raise InputError(f"scaling must be 'diagonal', 'ruiz' or 'none'; got {scaling!r}")
        self.scaling = scaling
        self.ruiz_sweeps = int(ruiz_sweeps)
        self.stats = SolverStats()
        self.real = all(not np.iscomplexobj(X.data) for X in (M, D, K, G))
        self._cache: OrderedDict = OrderedDict()
        self._build_pattern(M, D, K, G)
        self._diag_mag = tuple(np.abs(np.asarray(X.diagonal())) for X in (M, D, K))
        Gc = sp.csr_matrix(G)
        self._g_abs, self._g_cols, self._g_ptr = np.abs(Gc.data), Gc.indices, Gc.indptr

    # -- pattern ---------------------------------------------------------
    def _build_pattern(self, M, D, K, G):
        n1, n2 = self.n1, self.n2
        N = n1 + n2
        parts = []
        for X, roff, coff in ((M, 0, 0), (D, 0, 0), (K, 0, 0), (G.T, 0, n1), (G, n1, 0)):
            C = sp.coo_matrix(X)
            parts.append((C.row.astype(np.int64) + roff, C.col.astype(np.int64) + coff, C.data))
        rows = np.concatenate([p[0] for p in parts])
        cols = np.concatenate([p[1] for p in parts])
        key = cols * N + rows
        uniq, inv = np.unique(key, return_inverse=True)
        nnz = uniq.size
        self._indices = (uniq % N).astype(np.int32)
        colnum = uniq // N
        self._indptr = np.concatenate([[0], np.cumsum(np.bincount(colnum, minlength=N))]).astype(np.int32)
        vals = []
        start = 0
        for r, _, d in parts:
            v = np.zeros(nnz)
            np.add.at(v, inv[start:start + r.size], d)
            vals.append(v)
            start += r.size
        self._m, self._d, self._k = vals[0], vals[1], vals[2]
        # the fixed pattern seen row by row, for the row maxima of Ruiz scaling
        self._cols = colnum.astype(np.int64)
        self._rows = self._indices.astype(np.int64)
        self._csr_perm = np.lexsort((self._cols, self._rows))
        self._rowptr = np.concatenate([[0], np.cumsum(np.bincount(self._rows, minlength=N))])
        self._g = vals[3] + vals[4]
        self.N = N

    def matrix(self, s=None, *, coeffs=None) -> sp.csc_matrix:
        """The assembled bordered matrix for shift ``s`` (or ``coeffs=(a, b, c)``)."""
        a, b, c = self._coeffs(s, coeffs)
        data = a * self._m + b * self._d + c * self._k + self._g
        return sp.csc_matrix((data, self._indices, self._indptr), shape=(self.N, self.N))

    @staticmethod
    def _coeffs(s, coeffs):
        if coeffs is None:
            if s is None:
                raise InputError("give either s or coeffs")
            s = complex(s) if np.iscomplexobj(s) and complex(s).imag != 0 else float(np.real(s))
            if not np.isfinite(s):
                raise InputError(f"shift s must be finite; got {s}")
            return (s * s, s, 1.0)
        a, b, c = coeffs
        if not all(np.isfinite(complex(x)) for x in (a, b, c)):
            raise InputError(f"coeffs must be finite; got {coeffs}")
        return (a, b, c)

    # -- factorizations -------------------------------------------------
    def factor(self, s=None, *, coeffs=None) -> SaddleLU:
        """LU of :math:`S(s)` (or of ``a M + b D + c K`` bordered), cached.

        For a real model the factorization of :math:`\\bar s` is returned as a
        conjugated view of that of :math:`s` (no new LU).
        """
        a, b, c = self._coeffs(s, coeffs)
        key = (complex(a), complex(b), complex(c))
        conj_key = tuple(np.conj(k) for k in key)
        if key in self._cache:
            self._cache.move_to_end(key)
            self.stats.reused += 1
            return self._cache[key]
        if self.real and conj_key in self._cache:
            base = self._cache[conj_key]
            self._cache.move_to_end(conj_key)
            self.stats.reused += 1
            return SaddleLU(key, base.lu, self.n1, self.n2, not base.conjugate, self.stats,
                            base.min_pivot_ratio, base.complex_lu, base.matrix, base.backward_tol, base.norms,
                            base.dr, base.dc)
        t0 = time.perf_counter()
        A = self.matrix(coeffs=(a, b, c))
        dr, dc, As = self._equilibrate(A, (a, b, c))
        t1 = time.perf_counter()
        try:
            lu = spla.splu(As, permc_spec=self.permc_spec, diag_pivot_thresh=self.diag_pivot_thresh)
        except RuntimeError as exc:  # "Factor is exactly singular"
            raise SingularShiftError(
                f"saddle-point matrix at s-coefficients {(a, b, c)} is exactly singular: "
                "the shift is a pole of the system (or G is rank deficient)"
            ) from exc
        ratio = float("nan")
        if self.pivot_tol > 0:
            u = np.abs(lu.U.diagonal())
            ratio = float(u.min() / u.max()) if u.size else 1.0
            if not ratio > self.pivot_tol:
                raise SingularShiftError(
                    f"saddle-point matrix at s-coefficients {(a, b, c)} is singular to working "
                    f"precision (smallest/largest pivot {ratio:.2e} <= pivot_tol {self.pivot_tol:.1e}): "
                    "the shift is at or next to a pole of the system"
                )
        if self.rcond_tol > 0:
            mag = sp.csc_matrix((abs(a) * np.abs(self._m) + abs(b) * np.abs(self._d) + abs(c) * np.abs(self._k)
                                 + np.abs(self._g), self._indices, self._indptr), shape=A.shape)
            rcond = _rcond_estimate(A, lambda X, tr: _scaled_solve(lu, dr, dc, X, tr), self.n1, mag)
            if not rcond > self.rcond_tol:
                raise SingularShiftError(
                    f"saddle-point matrix at s-coefficients {(a, b, c)} is singular to working "
                    f"precision (estimated reciprocal condition {rcond:.2e} <= rcond_tol {self.rcond_tol:.1e}): "
                    "the shift is at or next to a pole of the system"
                )
            ratio = rcond
        t2 = time.perf_counter()
        self.stats.factorizations += 1
        self.stats.assemble_time_s += t1 - t0
        self.stats.factor_time_s += t2 - t1
        norms = (0.0, 0.0)
        if self.backward_tol > 0:
            av = np.abs(A.data)  # inf- and 1-norm from the fixed pattern, no new matrix
            norms = (float(np.bincount(self._rows, weights=av, minlength=self.N).max()),
                     float(np.add.reduceat(av, self._indptr[:-1]).max()))
        def stable_lu(As=As):
            return spla.splu(As, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=1.0)

        f = SaddleLU(key, lu, self.n1, self.n2, False, self.stats, ratio, np.iscomplexobj(A.data),
                     A if self.backward_tol > 0 else None, self.backward_tol, norms, dr, dc,
                     stable_lu if self.backward_tol > 0 else None)
        if self.cache_size > 0:
            self._cache[key] = f
            while len(self._cache) > self.cache_size:
                self._cache.popitem(last=False)
        return f

    def _equilibrate(self, A, coeffs):
        """Scaling of A per ``self.scaling``: returns (dr, dc, Dr A Dc) (None, None, A if off)."""
        if self.scaling == "none":
            return None, None, A
        if self.scaling == "ruiz":
            return self._ruiz(A)
        a, b, c = (abs(complex(x)) for x in coeffs)
        mm, dd, kk = self._diag_mag
        mag = a * mm + b * dd + c * kk
        d1 = 1.0 / np.sqrt(np.where(mag > 0, mag, 1.0))
        d = np.ones(self.N)
        d[:self.n1] = d1
        if self.n2:
            gmax = np.maximum.reduceat(self._g_abs * d1[self._g_cols], self._g_ptr[:-1])
            d[self.n1:] = 1.0 / np.where(gmax > 0, gmax, 1.0)
        As = sp.csc_matrix((A.data * d[self._rows] * d[self._cols], self._indices, self._indptr), shape=A.shape)
        return d, d, As

    def _ruiz(self, A):
        """Ruiz-equilibrate A (fixed pattern): returns (dr, dc, Dr A Dc)."""
        N = self.N
        av = np.abs(A.data)
        dr, dc = np.ones(N), np.ones(N)
        rows, cols, perm = self._rows, self._cols, self._csr_perm
        for _ in range(self.ruiz_sweeps):
            x = av * dr[rows] * dc[cols]
            cmax = np.maximum.reduceat(x, self._indptr[:-1])
            rmax = np.maximum.reduceat(x[perm], self._rowptr[:-1])
            cmax[cmax == 0] = 1.0
            rmax[rmax == 0] = 1.0
            dr /= np.sqrt(rmax)
            dc /= np.sqrt(cmax)
        As = sp.csc_matrix((A.data * dr[rows] * dc[cols], self._indices, self._indptr), shape=A.shape)
        return dr, dc, As

    def solve(self, s, rhs, *, trans: bool = False):
        """Convenience: ``factor(s).solve(rhs, trans=trans)``."""
        return self.factor(s).solve(rhs, trans=trans)

    def clear(self):
        """Drop cached factorizations (counters are kept)."""
        self._cache.clear()


def _scaled_solve(lu, dr, dc, X, trans):
    if dr is None:
        return lu.solve(X, trans="T" if trans else "N")
    lo, hi = (dc, dr) if trans else (dr, dc)
    return (hi * lu.solve(np.ascontiguousarray((lo * X.T).T), trans="T" if trans else "N").T).T


def _rcond_estimate(A, solve, n1: int, mag) -> float:
    """Reciprocal 1-norm condition estimate of the equilibrated matrix D S D, through the LU.

    D = blkdiag(D1, D2): D1 scales the rows and columns of the magnitudes
    ``mag`` = |a||M| + |b||D| + |c||K| of the (1,1) block to unit row maxima
    (magnitudes of the terms, not of their sum, so that the cancellation
    that makes s a pole is not scaled away), D2 then scales G D1 likewise. The
    condition of S itself mixes the scales |s|^2 M and G (1e31 at s = 1e7j on
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
