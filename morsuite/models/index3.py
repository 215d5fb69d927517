r"""The full-order model: a second-order index-3 descriptor system.

.. math::

    M \ddot x + D \dot x + K x + G^T z = F u, \qquad G x = 0, \qquad y = L x.

Its transfer function is evaluated without the hidden-manifold projector:

.. math::

    T(s) = \begin{bmatrix} L & 0 \end{bmatrix} S(s)^{-1}
           \begin{bmatrix} F \\ 0 \end{bmatrix},\qquad
    S(s) = \begin{bmatrix} s^2 M + s D + K & G^T \\ G & 0 \end{bmatrix}.
"""

from __future__ import annotations

import hashlib

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import DtypeWarning, ModelError, ShapeError, InputError
from ..linalg.accuracy import FORWARD_MAX_STEPS, forward_tol, target_off
from ..linalg.refine import SaddleOperator, refine_columns
from ..linalg.saddle import SaddlePointSolver
from ..utils import band_pair, blas_threads

__all__ = ["Index3Model", "as_real_matrix"]

#: G M^-1 G^T (row-equilibrated) with a condition number above this is rank deficient.
GRAM_COND_MAX = 1e12


def as_real_matrix(name: str, X, *, sparse: bool):
    """Return ``X`` as real float64 (sparse CSR or dense 2-D), refusing bad content.

    Integer and boolean input is converted exactly. Complex input with a zero
    imaginary part is converted with a :class:`DtypeWarning`; complex input
    with a nonzero imaginary part is refused: the suite is for real systems.
    """
    if X is None:
        raise InputError(f"matrix {name} is missing (got None)")
    if sp.issparse(X):
        # own copy: sum_duplicates() below sorts indices in place, and a model must
        # not change when the caller later edits the matrix it passed
        X = sp.csr_matrix(X, copy=True)
        data = X.data
    else:
        try:
            X = np.asarray(X)
        except (ValueError, TypeError) as exc:  # ragged nested lists
            raise InputError(f"matrix {name} is not a rectangular array ({exc})") from exc
        if X.dtype == object:
            raise InputError(f"matrix {name} has dtype object; expected a numeric array")
        if X.ndim > 2:
            raise ShapeError(f"matrix {name} must be 2-D; got {X.ndim}-D")
        data = X
    if np.iscomplexobj(data):
        if np.any(np.imag(data) != 0):
            raise InputError(
                f"matrix {name} is complex with a nonzero imaginary part; morsuite models are real"
            )
        warnings.warn(f"matrix {name} is complex with zero imaginary part; converted to real",
                      DtypeWarning, stacklevel=3)
        X = X.real
    elif not (np.issubdtype(data.dtype, np.number) or data.dtype == bool):
        raise InputError(f"matrix {name} has non-numeric dtype {data.dtype}")
    if sp.issparse(X):
        X = sp.csr_matrix(X, dtype=np.float64)
        X.sum_duplicates()
        vals = X.data
    else:
        X = np.array(X, dtype=np.float64)  # a copy, as for sparse input
        if sparse:
            X = sp.csr_matrix(X)
        vals = X.data if sp.issparse(X) else X
    if not np.all(np.isfinite(vals)):
        raise InputError(f"matrix {name} has non-finite entries (NaN or inf)")
    return X


def _dense(name, X, shape_hint):
    X = as_real_matrix(name, X, sparse=False)
    if sp.issparse(X):
        X = X.toarray()
    if X.ndim == 1:
        X = X.reshape(shape_hint(X.size))
    if X.ndim != 2:
        raise ShapeError(f"matrix {name} must be 2-D; got {X.ndim}-D")
    return np.ascontiguousarray(X)


class Index3Model:
    r"""A constrained second-order system :math:`(M, D, K, G, F, L)`.

    Parameters
    ----------
    M, D, K : sparse or dense, (n1, n1)
        Mass, damping and stiffness in the physical sign convention.
    G : sparse or dense, (n2, n1)
        Constraint matrix, full row rank, n2 < n1 (n2 = 0 allowed: no constraints).
    F : dense, (n1, m)
        Input matrix (a 1-D array is one input).
    L : dense, (p, n1)
        Output matrix (a 1-D array is one output).
    name : str
        Label used in reports.
    band : (float, float)
        Default frequency band in rad/s for error reports.
    check_constraints : bool
        Check that G has full row rank through the condition of the
        row-equilibrated :math:`G M^{-1} G^T` (n2 x n2, one sparse LU of M).

    Raises
    ------
    ShapeError, InputError, ModelError
        For every inconsistent input; the message names the matrix.
    """

    def __init__(self, M, D, K, G, F, L, *, name: str = "model", band=(1e-2, 1.0),
                 check_constraints: bool = True):
        M = as_real_matrix("M", M, sparse=True)
        n1 = M.shape[0]
        if M.ndim != 2 or M.shape[0] != M.shape[1]:
            raise ShapeError(f"matrix M must be square; got shape {M.shape}")
        if n1 == 0:
            raise ShapeError("matrix M is empty (n1 = 0)")
        D = as_real_matrix("D", D, sparse=True)
        K = as_real_matrix("K", K, sparse=True)
        for nm, X in (("D", D), ("K", K)):
            if X.shape != (n1, n1):
                raise ShapeError(f"matrix {nm} has shape {X.shape}; expected ({n1}, {n1}) like M")
        if G is None:
            G = sp.csr_matrix((0, n1))
        G = as_real_matrix("G", G, sparse=True)
        if G.shape[1] != n1:
            raise ShapeError(f"matrix G has {G.shape[1]} columns; expected n1 = {n1}")
        n2 = G.shape[0]
        if n2 >= n1:
            raise ShapeError(f"matrix G has n2 = {n2} rows; expected n2 < n1 = {n1}")
        F = _dense("F", F, lambda k: (k, 1))
        L = _dense("L", L, lambda k: (1, k))
        if F.shape[0] != n1:
            raise ShapeError(f"matrix F has {F.shape[0]} rows; expected n1 = {n1}")
        if L.shape[1] != n1:
            raise ShapeError(f"matrix L has {L.shape[1]} columns; expected n1 = {n1}")
        if F.shape[1] == 0 or L.shape[0] == 0:
            raise ShapeError(f"the model needs at least one input and one output; got F {F.shape}, L {L.shape}")
        self.M, self.D, self.K, self.G = M, D, K, G
        self.F, self.L = F, L
        self.name = str(name)
        self.band = band_pair(band)
        if n2:
            rownnz = np.diff(G.indptr)
            zero_rows = np.flatnonzero((abs(G).sum(axis=1).A1 == 0))
            if zero_rows.size:
                raise ModelError(f"matrix G has zero rows {zero_rows[:10].tolist()}: every constraint must involve a coordinate")
            del rownnz
            if check_constraints:
                self._check_constraint_rank()
        self._solver = None
        #: quantities computed once per model and reused by later calls (e.g. the Gramian
        #: factors of :func:`morsuite.linalg.gramians.gramian_factors`); ``cache.clear()`` drops them
        self.cache = {}

    # -- sizes -----------------------------------------------------------
    @property
    def n1(self) -> int:
        """Number of positions (the dimension of M)."""
        return self.M.shape[0]

    @property
    def n2(self) -> int:
        """Number of constraints (rows of G)."""
        return self.G.shape[0]

    @property
    def m(self) -> int:
        """Number of inputs (columns of F)."""
        return self.F.shape[1]

    @property
    def p(self) -> int:
        """Number of outputs (rows of L)."""
        return self.L.shape[0]

    @property
    def order(self) -> int:
        """Dimension of the hidden manifold, n1 - n2 (order of the projected model)."""
        return self.n1 - self.n2

    def __repr__(self):
        return (f"Index3Model(name={self.name!r}, n1={self.n1}, n2={self.n2}, m={self.m}, "
                f"p={self.p}, band={self.band})")

    def summary(self) -> dict:
        """Sizes, sparsity and band as plain data."""
        return {"name": self.name, "n1": self.n1, "n2": self.n2, "m": self.m, "p": self.p,
                "first_order_states": 2 * self.n1 + self.n2,
                "nnz": {k: int(getattr(self, k).nnz) for k in ("M", "D", "K", "G")},
                "band": list(self.band)}

    def digest(self) -> str:
        """SHA-256 of the matrices M, D, K, G, F, L (shapes, sparsity patterns and values).

        Two models with equal digests have the same matrices bit for bit, whatever their names
        and bands: the key of what is computed from the matrices alone across processes
        (the Gramian factors' store, :func:`morsuite.linalg.gramians.use_store`). Computed once
        per model (kept in ``cache``); cost: one pass over the matrices' data.
        """
        hit = self.cache.get("digest")
        if hit is None:
            h = hashlib.sha256()
            for name in ("M", "D", "K", "G"):
                X = getattr(self, name).tocsr()  # as stored: equal models built alike have equal layouts
                h.update(f"{name}{X.shape}{X.data.dtype}".encode())
                for a in (X.indptr.astype(np.int64), X.indices.astype(np.int64), X.data):
                    h.update(np.ascontiguousarray(a).tobytes())
            for name in ("F", "L"):
                X = np.ascontiguousarray(getattr(self, name))
                h.update(f"{name}{X.shape}{X.dtype}".encode())
                h.update(X.tobytes())
            hit = self.cache["digest"] = h.hexdigest()
        return hit

    # -- checks ----------------------------------------------------------
    def _check_constraint_rank(self):
        try:
            lu = spla.splu(sp.csc_matrix(self.M))
        except RuntimeError as exc:
            raise ModelError("matrix M is singular; the constraint check needs M^-1") from exc
        GT = self.G.T.toarray() if self.n2 * self.n1 <= 5e7 else None
        if GT is None:
            raise ModelError(f"n2 = {self.n2} too large for the dense constraint check; pass check_constraints=False")
        S = self.G @ lu.solve(GT)
        S = 0.5 * (S + S.T)
        d = np.abs(np.diag(S))
        if np.any(d == 0) or not np.all(np.isfinite(S)):
            raise ModelError("G M^-1 G^T has a zero diagonal entry: G is rank deficient")
        Sn = S / np.sqrt(np.outer(d, d))
        cond = np.linalg.cond(Sn)
        if not cond < GRAM_COND_MAX:
            raise ModelError(
                f"matrix G is numerically rank deficient: the row-equilibrated G M^-1 G^T has "
                f"condition number {cond:.2e} >= {GRAM_COND_MAX:.0e}"
            )
        self.constraint_gram_cond = float(cond)

    # -- evaluation ------------------------------------------------------
    @property
    def solver(self) -> SaddlePointSolver:
        """The model's saddle-point solver (pattern built on first use)."""
        if self._solver is None:
            self._solver = SaddlePointSolver(self.M, self.D, self.K, self.G, backend=self.lu_backend)
        return self._solver

    @property
    def lu_backend(self) -> str:
        """The sparse-LU backend of the model's solvers: ``"auto"`` (default), ``"superlu"``, ``"banded"``, ``"klu"``, ``"rslab"``, ``"pardiso"``.

        ``"auto"`` chooses from the sparsity pattern alone
        (:func:`morsuite.linalg.backends.choose`); setting it forces one for every
        later solver of this model (the pattern and its analysis are kept).
        """
        return getattr(self, "_lu_backend", "auto")

    @lu_backend.setter
    def lu_backend(self, value: str):
        from ..linalg.backends import resolve_backend
        resolve_backend(value)  # validates
        self._lu_backend = value
        if self._solver is not None:  # the model's own solver follows; its pattern is kept
            self._solver = SaddlePointSolver(self.M, self.D, self.K, self.G, backend=value,
                                             pattern=self._solver.pattern)

    def lu_analysis(self) -> dict:
        """The structural analysis behind the model's LU backend (plain data; see ``SaddlePointSolver.analysis``)."""
        return dict(self.solver.analysis)

    def new_solver(self, **options) -> SaddlePointSolver:
        """A fresh saddle-point solver (own counters and cache) for a reducer run.

        The sparsity pattern is built once per model and shared (read-only); the
        backend is the model's ``lu_backend`` unless ``backend=`` is given.
        """
        options.setdefault("backend", self.lu_backend)
        return SaddlePointSolver(self.M, self.D, self.K, self.G, pattern=self.solver.pattern, **options)

    def transfer(self, s, *, derivative: bool = False):
        r"""Transfer function :math:`T(s) = L x`, one sparse LU at ``s``.

        The solve reaches the backward-error target of :mod:`morsuite.linalg.accuracy` and is refined
        against the exact :math:`S(s)` in double-double (:meth:`freqresp`). With ``derivative=True``
        return :math:`T'(s) = -L_0 S^{-1} S'(s) S^{-1} F_0`,
        :math:`S'(s) = \mathrm{blkdiag}(2sM + D, 0)`, reusing the same LU.
        """
        s = _check_shift(s)
        f = self.solver.factor(s)
        if not derivative and not target_off():
            op = getattr(self, "_refiner", None)
            if op is None or op.pattern is not self.solver.pattern:
                op = self._refiner = SaddleOperator(self.solver.pattern)
            return _output(self.L, _refined(f, self.F, f.solve(self.F, full=True), s, op))
        X = f.solve(self.F)
        if not derivative:
            return _output(self.L, X)
        Y = f.solve(self.L.T.astype(X.dtype), trans=True)  # left solve
        return -(Y.T @ ((2 * s) * (self.M @ X) + self.D @ X))

    def freqresp(self, omega, *, progress: bool = False, refine: bool = True):
        """Frequency response at ``s = 1j * omega``: complex (len(omega), p, m).

        One LU per frequency, all inputs solved at once; no factorization is
        kept, so memory is O(nnz) whatever the grid size. Each solve reaches the
        backward-error target of :mod:`morsuite.linalg.accuracy`; with ``refine`` (default
        True) it is then refined against the exact :math:`S(j\\omega)` (residual in
        double-double, the same LU) until its estimated relative error is below
        ``FORWARD_TOL`` (one step, more near a lightly damped resonance:
        :func:`~morsuite.linalg.refine.refine_columns`), as the band response of
        :func:`morsuite.analysis.response.band_response` is. Cost of the refinement: one solve and
        one double-double product per frequency, 0.3-0.6 of an LU on chains, a few percent on
        3D elements (``docs/design/backends.md``, 2026-12-02); ``refine=False``: the LU's
        solution, backward stable, whose error the condition of :math:`S(j\\omega)` multiplies.
        """
        omega = _check_omega(omega)
        if not isinstance(refine, (bool, np.bool_)):
            raise InputError(f"refine must be True or False; got {refine!r}")
        out = np.empty((omega.size, self.p, self.m), dtype=complex)
        solver = self.new_solver(cache_size=0)
        op = None if target_off() or not refine else SaddleOperator(solver.pattern)
        it = range(omega.size)
        if progress:
            from tqdm.auto import tqdm
            it = tqdm(it, desc=f"freqresp {self.name}", unit="freq", leave=False)
        with blas_threads(1):
            for i in it:
                f = solver.factor(1j * omega[i])
                if op is None:
                    out[i] = _output(self.L, f.solve(self.F))
                else:
                    out[i] = _output(self.L, _refined(f, self.F, f.solve(self.F, full=True), 1j * omega[i], op))
        self.last_freqresp_stats = solver.stats.as_dict()
        return out

    def first_order(self):
        """Sparse first-order descriptor realization (E, A, B, C) of size 2 n1 + n2.

        ``E = blkdiag(I, M, 0)``, ``A = [[0, I, 0], [-K, -D, -G^T], [G, 0, 0]]``,
        ``B = [0; F; 0]``, ``C = [L, 0, 0]``: the M.E.S.S. layout, physical signs.
        """
        n1, n2 = self.n1, self.n2
        I = sp.identity(n1, format="csr")
        E = sp.block_diag([I, self.M, sp.csr_matrix((n2, n2))], format="csr")
        A = sp.bmat([[None, I, sp.csr_matrix((n1, n2))], [-self.K, -self.D, -self.G.T],
                     [self.G, None, sp.csr_matrix((n2, n2))]], format="csr")
        B = np.vstack([np.zeros((n1, self.m)), self.F, np.zeros((n2, self.m))])
        C = np.hstack([self.L, np.zeros((self.p, n1 + n2))])
        return E, A, B, C

    def with_io(self, F=None, L=None, name=None) -> "Index3Model":
        """Same dynamics, other inputs/outputs (constraint check not repeated)."""
        return Index3Model(self.M, self.D, self.K, self.G, self.F if F is None else F,
                           self.L if L is None else L, name=name or self.name, band=self.band,
                           check_constraints=False)


def _refined(f, F, X, s, op):
    """The first block of the solution ``X`` (n1 + n2 rows) of ``S(s) X = [F; 0]`` refined against the exact
    S(s) (:func:`~morsuite.linalg.refine.refine_columns`, one step and more while its estimate is above
    ``FORWARD_TOL``), rounded to double."""
    F = F.toarray() if sp.issparse(F) else np.asarray(F)
    xr, xi, _ = refine_columns(f, F, X, False, s, op, steps=1, tol=forward_tol(), max_steps=FORWARD_MAX_STEPS)
    n1 = f.n1
    out = np.asarray(xr[:n1], dtype=float)
    return out if xi is None else out + 1j * np.asarray(xi[:n1], dtype=float)


def _output(L, X):
    """``L @ X`` for real L and complex X without converting L to complex (two real products)."""
    if np.iscomplexobj(X) and not np.iscomplexobj(L):
        return L @ X.real + 1j * (L @ X.imag)
    return L @ X


def _check_shift(s):
    try:
        s = complex(s)
    except (TypeError, ValueError) as exc:
        raise InputError(f"s must be a scalar number; got {s!r}") from exc
    if not np.isfinite(s):
        raise InputError(f"s must be finite; got {s}")
    return s if s.imag != 0 else s.real


def _check_omega(omega):
    w = np.atleast_1d(np.asarray(omega))
    if w.ndim != 1 or w.size == 0:
        raise InputError(f"omega must be a non-empty 1-D array of frequencies; got shape {w.shape}")
    if np.iscomplexobj(w) or not np.issubdtype(w.dtype, np.number):
        raise InputError("omega must be real (rad/s); for complex s use transfer(s)")
    w = w.astype(float)
    if not np.all(np.isfinite(w)):
        raise InputError("omega has non-finite entries")
    return w
