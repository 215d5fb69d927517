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
assembling and equilibrating :math:`S(s)` afterwards is one pass over the
stored entries, and the column ordering of the first LU is reused for every
later shift. Solves and their accuracy check are in
:mod:`morsuite.linalg.saddle_lu`; measurements behind the defaults in
``docs/design/saddle.md``.

Options of :class:`SaddlePointSolver` (defaults): ``cache_size=2``,
``pivot_tol=0`` (off), ``rcond_tol=0`` (off), ``permc_spec="COLAMD"``,
``diag_pivot_thresh=0.1``, ``backward_tol=1e-10``, ``backward_target=1e-15``,
``refine_steps=4``, ``scaling="diagonal"``,
``ruiz_sweeps=2``, ``reuse_ordering=True``, ``backend="auto"`` (the LU:
banded with a Schur-complement border for narrow RCM bands, KLU for narrow bands
with a larger border, rslab's supernodal LU (or PARDISO) for wide bands, chosen from the pattern alone by :mod:`morsuite.linalg.backends`; measurements
in ``docs/design/backends.md``).

Cost: one sparse LU per distinct shift, none for a cached shift or the
conjugate of one (real data); ``rcond_tol > 0`` adds 10-20% of an LU, Ruiz
scaling about 12% per sweep, the diagonal scaling O(n1). A solve that fails
the backward-error check costs one more LU per fallback tried; a refinement
step towards ``backward_target`` one more solve (:mod:`morsuite.linalg.accuracy`).
"""


from __future__ import annotations

import threading
import time
from collections import OrderedDict

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import InputError, SingularShiftError
from . import kernels
from .backends import LIBRARY_BACKENDS, BandedBorderLU, analyse, permuted_pattern, resolve_backend, superlu_ordering
from .backends_ext import KLULU, PardisoLU
from .backends_rslab import rslab_factor
from .accuracy import check_options, without_check_caches
from .saddle_lu import SaddleLU, SolverStats, fallback_factors, rcond_estimate

__all__ = ["SaddlePointSolver", "SaddleLU", "SolverStats"]

#: the factorization (class or factory: rslab chooses its LDL^T or LU) of each library backend
_LIBRARY_LU = {"klu": KLULU, "rslab": rslab_factor, "pardiso": PardisoLU}


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
        to, a pole). ``0`` (default) turns the check off: the ratio depends on
        the scaling of the blocks, and Ruiz scaling can hide a cancellation on
        the diagonal (``rcond_tol`` is the check that finds poles); reading U
        copies the factors (10% of an LU). Exactly singular matrices and
        non-finite solutions always raise :class:`SingularShiftError`.
    rcond_tol : float
        If positive, estimate the reciprocal 1-norm condition number of each
        factorized, equilibrated matrix (Hager-Higham estimator, a few extra
        solves: 10-20% of an LU) and raise :class:`SingularShiftError` below
        ``rcond_tol``. Scale-aware, unlike the pivot ratio. Default 0 (off).
    permc_spec, diag_pivot_thresh : str, float
        Column ordering and partial-pivoting threshold of SuperLU; default
        COLAMD with threshold 0.1 (fastest and backward stable on both
        benchmark models; SuperLU's default 1.0 is not).
    scaling, ruiz_sweeps : str, int
        Equilibration of S(s) before it is factored (solutions are unscaled).
        ``"diagonal"`` (default): symmetric scaling D S D with
        :math:`D_1 = (|s|^2|M_{ii}| + |s||D_{ii}| + |K_{ii}|)^{-1/2}` and the
        constraint rows scaled by the largest :math:`|G_{kj}| D_{1,j}`; O(n1)
        per shift. ``"ruiz"``: ``ruiz_sweeps`` (2) sweeps of Ruiz row/column
        max-norm scaling (about 12% of an LU per sweep). ``"none"``: models
        whose coefficients spread over many decades then lose every digit.
    reuse_ordering : bool
        Compute the column ordering (``permc_spec``) once, at the first
        factorization, and reuse it for every later shift (default True): the
        ordering depends only on the sparsity pattern, while the row pivots are
        still chosen per factorization. The ordering is stored with the pattern
        and so shared by every solver given the same ``pattern``. Not with Ruiz
        scaling (its column scaling is computed per column of S).
    backward_tol : float
        Largest normwise backward error of the factorized, equilibrated system
        accepted from a solve (default 1e-10; 0 turns every check off). Above it
        one step of iterative refinement is made; if that does not help, the
        matrix is refactored with, in turn, the same ordering and diagonal
        pivot threshold 0.01, a fresh COLAMD ordering, and MMD_AT_PLUS_A with
        partial pivoting (the last resort: it can fill in heavily), each solve
        checked again; if none passes, :class:`SingularShiftError`: an
        inaccurate solve is never returned silently.
    backward_target, refine_steps : float, int
        The backward error every checked solve reaches (None, default: 1e-15, about
        9 units of roundoff, or 0 where ``MORSUITE_SOLVE_TARGET=off``; 0: the check of
        ``backward_tol`` alone, before 2026-12-02): above it, at most ``refine_steps``
        (4) refinement steps with an extended residual and the same LU, one fallback
        LU, then the solve is returned flagged (:mod:`morsuite.linalg.accuracy`).
    pattern : dict, optional
        The ``pattern`` of another solver of the same M, D, K, G (shared,
        read-only, with its stored column ordering); default: built here.
    backend : {"auto", "superlu", "banded", "klu", "rslab", "pardiso"}
        The sparse LU (:mod:`morsuite.linalg.backends`): ``"auto"`` (default)
        chooses from the pattern alone (banded LU with a Schur-complement border
        for narrow RCM bands and few constraints, KLU for narrow bands with more
        constraints, PARDISO (an extra) or else rslab's supernodal LU for wide bands,
        SuperLU where the library is not installed); the analysis, done once per pattern, is in
        ``analysis``. The banded and library backends fall back to SuperLU
        wherever their solve fails the backward-error check.

    Notes
    -----
    ``stats.factorizations`` counts every LU made; it is the floor against which
    the run time of a reducer is judged. ``stats.checked_solves``, ``above_target``,
    ``refinement_steps``, ``target_fallbacks`` and ``backward_error_max`` record the
    backward-error target (also in the open :func:`~morsuite.linalg.accuracy.recording`).
    """

    def __init__(self, M, D, K, G, *, cache_size: int = 2, pivot_tol: float = 0.0,
                 rcond_tol: float = 0.0, permc_spec: str = "COLAMD", diag_pivot_thresh: float = 0.1,
                 backward_tol: float = 1e-10, scaling: str = "diagonal", ruiz_sweeps: int = 2,
                 pattern: dict | None = None, reuse_ordering: bool = True, backend: str = "auto",
                 backward_target: float | None = None, refine_steps: int = 4):
        self.n1 = M.shape[0]
        self.n2 = G.shape[0]
        self.cache_size = int(cache_size)
        self.pivot_tol = float(pivot_tol)
        self.rcond_tol = float(rcond_tol)
        self.permc_spec = permc_spec
        self.diag_pivot_thresh = float(diag_pivot_thresh)
        self.backward_tol = float(backward_tol)
        self.backward_target, self.refine_steps = check_options(backward_target, refine_steps)
        if scaling not in ("diagonal", "ruiz", "none"):
            raise InputError(f"scaling must be 'diagonal', 'ruiz' or 'none'; got {scaling!r}")
        self.scaling = scaling
        self.ruiz_sweeps = int(ruiz_sweeps)
        self.reuse_ordering = bool(reuse_ordering)
        self.stats = SolverStats()
        self.real = all(not np.iscomplexobj(X.data) for X in (M, D, K, G))
        self._cache: OrderedDict = OrderedDict()
        if pattern is None:
            pattern = self._build_pattern(M, D, K, G)
        elif pattern.get("shape") != (self.n1, self.n2):
            raise InputError(f"pattern is of a model with (n1, n2) = {pattern.get('shape')}, "
                             f"not {(self.n1, self.n2)}")
        #: the fixed sparsity pattern and the blocks' values on it (read-only arrays,
        #: shareable between solvers of the same model through ``pattern=``)
        self.pattern = pattern
        for k, v in pattern.items():
            if isinstance(k, str) and k != "shape":
                setattr(self, k, v)
        self._work = (np.empty(self._m.size), np.empty(self._m.size))  # scratch of _combine / _assemble_scaled
        backend = resolve_backend(backend)
        if backend == "banded" and scaling == "ruiz":
            raise InputError("backend='banded' needs scaling 'diagonal' or 'none' (Ruiz scales per column of S)")
        if backend in LIBRARY_BACKENDS and (scaling == "ruiz" or self.pivot_tol > 0):
            raise InputError(f"backend={backend!r} needs scaling 'diagonal' or 'none' and pivot_tol = 0")
        plain = scaling == "ruiz" or self.pivot_tol > 0  # needs SuperLU (or banded) factors
        #: the structural analysis of the pattern (plain data; ``analysis["backend"]`` is the LU used)
        self.analysis = dict(analyse(pattern, "superlu" if scaling == "ruiz" and backend == "auto" else backend))
        if plain and self.analysis["backend"] in LIBRARY_BACKENDS:
            self.analysis = dict(analyse(pattern, "superlu"), requested="auto",
                                 reason="scaling='ruiz' or pivot_tol > 0 need SuperLU's factors")
        self.backend = self.analysis["backend"]

    def __getstate__(self):
        """Pickled (e.g. to Dask workers) without the cached factorizations (KLU's and PARDISO's
        are handles of this process) and without the structures the backward-error check keeps
        with the pattern (:func:`~morsuite.linalg.accuracy.without_check_caches`)."""
        state = dict(self.__dict__)
        state["_cache"] = OrderedDict()
        state["pattern"] = without_check_caches(self.pattern)
        return state

    # -- pattern ---------------------------------------------------------
    def _build_pattern(self, M, D, K, G) -> dict:
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
        indices = (uniq % N).astype(np.int32)
        colnum = uniq // N
        vals = []
        start = 0
        for r, _, d in parts:
            v = np.zeros(nnz)
            np.add.at(v, inv[start:start + r.size], d)
            vals.append(v)
            start += r.size
        rows_ = indices.astype(np.int64)
        cols_ = colnum.astype(np.int64)
        Gc = sp.csr_matrix(G)
        pattern = {
            "shape": (n1, n2), "N": N,
            "_indices": indices,
            "_indptr": np.concatenate([[0], np.cumsum(np.bincount(colnum, minlength=N))]).astype(np.int32),
            "_m": vals[0], "_d": vals[1], "_k": vals[2], "_g": vals[3] + vals[4],
            # the fixed pattern seen row by row, for the row maxima of Ruiz scaling
            "_cols": cols_, "_rows": rows_,
            "_csr_perm": np.lexsort((cols_, rows_)),
            "_rowptr": np.concatenate([[0], np.cumsum(np.bincount(rows_, minlength=N))]),
            # what the diagonal scaling needs
            "_diag_mag": tuple(np.abs(np.asarray(X.diagonal())) for X in (M, D, K)),
            "_g_abs": np.abs(Gc.data), "_g_cols": Gc.indices, "_g_ptr": Gc.indptr,
        }
        for v in pattern.values():
            if isinstance(v, np.ndarray):
                v.flags.writeable = False
        return pattern

    def matrix(self, s=None, *, coeffs=None) -> sp.csc_matrix:
        """The assembled bordered matrix for shift ``s`` (or ``coeffs=(a, b, c)``)."""
        a, b, c = self._coeffs(s, coeffs)
        # own index arrays: the pattern's are shared and read-only
        return sp.csc_matrix((self._combine(a, b, c, self.pattern), self._indices.copy(), self._indptr.copy()),
                             shape=(self.N, self.N))

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
            self.stats.add(reused=1)
            return self._cache[key]
        if self.real and conj_key in self._cache:
            base = self._cache[conj_key]
            self._cache.move_to_end(conj_key)
            self.stats.add(reused=1)
            return SaddleLU(key, base.lu, self.n1, self.n2, not base.conjugate, self.stats,
                            base.min_pivot_ratio, base.complex_lu, base.matrix, base.backward_tol, base.norms,
                            base.dr, base.dc, q=base.q, target=base.target, refine_steps=base.refine_steps,
                            structure=base.structure, contraction=base.contraction)
        t0 = time.perf_counter()
        perm = self._ordering()
        dr, dc, As, norms = self._assemble_scaled(a, b, c, perm)
        t1 = time.perf_counter()
        banded = self.backend == "banded"
        other = self.backend != "superlu"  # a backend with SuperLU as its first fallback
        try:
            lu = None
            if other:
                try:
                    if banded:
                        lu = BandedBorderLU(As.data, self.n1, self.n2, self.analysis["kl"], self.analysis["ku"],
                                            perm["banded"])
                    else:
                        lu = _LIBRARY_LU[self.backend](As, self.pattern)
                except SingularShiftError:  # A11 singular where S need not be: SuperLU decides
                    self.stats.add(refactorizations=1)
            if lu is None:
                lu = spla.splu(As, permc_spec="NATURAL" if perm and not banded else self.permc_spec,
                               diag_pivot_thresh=self.diag_pivot_thresh)
        except RuntimeError as exc:  # "Factor is exactly singular"
            raise SingularShiftError(
                f"saddle-point matrix at s-coefficients {(a, b, c)} is exactly singular: "
                "the shift is a pole of the system (or G is rank deficient)"
            ) from exc
        ratio = float("nan")
        if self.pivot_tol > 0:
            u = np.abs(lu.u_diagonal() if hasattr(lu, "u_diagonal") else lu.U.diagonal())
            ratio = float(u.min() / u.max()) if u.size else 1.0
            if not ratio > self.pivot_tol:
                raise SingularShiftError(
                    f"saddle-point matrix at s-coefficients {(a, b, c)} is singular to working "
                    f"precision (smallest/largest pivot {ratio:.2e} <= pivot_tol {self.pivot_tol:.1e}): "
                    "the shift is at or next to a pole of the system"
                )
        if self.rcond_tol > 0:
            A = self.matrix(coeffs=(a, b, c))
            mag = sp.csc_matrix((abs(a) * np.abs(self._m) + abs(b) * np.abs(self._d) + abs(c) * np.abs(self._k)
                                 + np.abs(self._g), self._indices, self._indptr), shape=A.shape)
            probe = SaddleLU(key, lu, self.n1, self.n2, False, self.stats, ratio, np.iscomplexobj(As.data),
                             dr=dr, dc=dc, q=perm["q"] if perm else None)
            rcond = rcond_estimate(A, lambda X, tr: probe._raw_solve(X.reshape(X.shape[0], -1), tr)
                                    .reshape(X.shape), self.n1, mag)
            if not rcond > self.rcond_tol:
                raise SingularShiftError(
                    f"saddle-point matrix at s-coefficients {(a, b, c)} is singular to working "
                    f"precision (estimated reciprocal condition {rcond:.2e} <= rcond_tol {self.rcond_tol:.1e}): "
                    "the shift is at or next to a pole of the system"
                )
            ratio = rcond
        t2 = time.perf_counter()
        self.stats.add(factorizations=1, assemble_time_s=t1 - t0, factor_time_s=t2 - t1)
        checked = self.backward_tol > 0

        spec = "NATURAL" if perm and not banded else self.permc_spec
        fallback = fallback_factors(As, lu, self.pattern, spec, self.diag_pivot_thresh) if checked else ()
        f = SaddleLU(key, lu, self.n1, self.n2, False, self.stats, ratio, np.iscomplexobj(As.data),
                     As if checked else None, self.backward_tol, norms, dr, dc,
                     fallback, q=perm["q"] if perm else None, target=self.backward_target if checked else 0.0,
                     refine_steps=self.refine_steps, structure=perm if perm else self.pattern)
        if self.cache_size > 0:
            self._cache[key] = f
            while len(self._cache) > self.cache_size:
                self._cache.popitem(last=False)
        return f

    # -- reuse of the column ordering ------------------------------------
    def _reusable(self) -> bool:
        return self.reuse_ordering and self.scaling != "ruiz" and self.permc_spec != "NATURAL"

    def _ordering(self):
        """The renumbered pattern of the backend's ordering (found once per pattern), or None.

        Banded: the RCM renumbering of :func:`~morsuite.linalg.backends.analyse`.
        SuperLU: its column ordering (COLAMD, MMD_*) depends only on the sparsity
        pattern, the same for every shift; it is found once, from the pattern alone
        (:func:`~morsuite.linalg.backends.superlu_ordering`), so that every shift,
        the first included, is factored the same way whatever ran before (the row
        pivots, which depend on the values, are still chosen per factorization).
        The pattern is stored with the entries of M, D, K, G renumbered, so later
        shifts assemble the renumbered matrix directly and factor it with NATURAL.
        """
        if self.backend == "banded":
            return self.pattern[("ordering", "banded")]
        if self.backend in LIBRARY_BACKENDS:  # they order the matrix themselves (ordering kept in the pattern)
            return None
        if not self._reusable():
            return None
        key = ("ordering", self.permc_spec)
        if key not in self.pattern:
            # symmetric renumbering Ae = As[q][:, q]: SuperLU's threshold pivoting prefers the
            # diagonal of the matrix it is given, so the rows must follow the columns (a column
            # permutation alone made it prefer off-diagonal entries)
            self.pattern[key] = permuted_pattern(self.pattern, superlu_ordering(self.pattern, self.permc_spec))
        return self.pattern[key]

    def _assemble_scaled(self, a, b, c, perm=None):
        """Assemble and equilibrate in one pass: returns (dr, dc, Dr S Dc, norms) ((None, None, S, {}) if off);
        ``norms``: ``{"1": ||Dr S Dc||_1}`` where the compiled assembly computed it on the way (the
        backward-error check's norm, :class:`SaddleLU` ``norms``), else empty (computed when needed).

        The diagonal scaling needs only the diagonals of M, D, K and the entries
        of G, so it is computed first and applied while the entries of S are
        combined: no unscaled matrix is built.
        """
        P = perm if perm is not None else self.pattern
        if self.scaling == "diagonal" and kernels.use_kernels():
            # one compiled pass (combine, scale, 1-norm): docs/design/backends.md, 2026-11-26 (second session)
            d = self._diagonal_scaling(a, b, c)
            real = self.real and all(complex(x).imag == 0 for x in (a, b, c))
            data, norm1 = kernels.assemble_scaled(P, d, a, b, c, real)
            return d, d, self._csc(data, P), {"1": norm1}  # the check's ||A||_1, from the same pass
        data = self._combine(a, b, c, P)
        if self.scaling == "ruiz":
            return (*self._ruiz(data), {})
        if self.scaling == "none":
            return None, None, self._csc(data, P), {}
        d = self._diagonal_scaling(a, b, c)
        w, w2 = self._scratch()
        # mode="clip": the indices are valid by construction, and take's default mode "raise"
        # buffers ``out`` (measured 2026-11-26: 19 ms against 2 ms for 6e5 entries)
        np.take(d, P["_rows"], out=w, mode="clip")
        np.take(d, P["_cols"], out=w2, mode="clip")
        w *= w2
        data *= w
        return d, d, self._csc(data, P), {}

    def _combine(self, a, b, c, P):
        """Entries of a M + b D + c K + [G^T; G] on the fixed pattern (a new array).

        For real data the real and imaginary parts are formed separately in
        place, skipping zero coefficients (a frequency response has a, c real and
        b imaginary): a few passes over the entries, no complex temporaries.
        """
        m, d, k, g = P["_m"], P["_d"], P["_k"], P["_g"]
        if not self.real:
            data = a * m + b * d + c * k
            data += g
            return data
        a, b, c = complex(a), complex(b), complex(c)
        is_complex = any(x.imag != 0 for x in (a, b, c))
        data = np.empty(self._m.size, dtype=complex if is_complex else float)
        parts = ((data.real, "real"), (data.imag, "imag")) if is_complex else ((data, "real"),)
        tmp = self._scratch()[0]
        for out, part in parts:
            first = True
            for coef, arr in ((a, m), (b, d), (c, k)):
                x = getattr(coef, part)
                if x == 0:
                    continue
                if first:
                    np.multiply(arr, x, out=out)
                    first = False
                else:
                    np.multiply(arr, x, out=tmp)
                    out += tmp
            if first:
                out[...] = 0.0
        (data.real if is_complex else data)[...] += g
        return data

    def _scratch(self):
        """Scratch arrays of the pattern's size: shared in the main thread, fresh in others
        (factorizations may run in a thread pool, :mod:`morsuite.reducers.irka.shift_solves`)."""
        if threading.current_thread() is threading.main_thread():
            return self._work
        return np.empty(self._m.size), np.empty(self._m.size)

    def _csc(self, data, P=None):
        P = self.pattern if P is None else P
        A = sp.csc_matrix((data, P["_indices"], P["_indptr"]), shape=(self.N, self.N), copy=False)
        A.has_sorted_indices = True  # the pattern is built sorted and without duplicates
        A.has_canonical_format = True
        return A

    def _diagonal_scaling(self, a, b, c):
        r"""The vector d of the symmetric scaling diag(d) S(s) diag(d) (``scaling="diagonal"``)."""
        a, b, c = abs(a), abs(b), abs(c)
        mm, dd, kk = self._diag_mag
        mag = a * mm + b * dd + c * kk
        d = np.ones(self.N)
        d1 = d[:self.n1]
        np.sqrt(mag, out=d1, where=mag > 0)
        np.divide(1.0, d1, out=d1)
        if self.n2:
            gmax = np.maximum.reduceat(self._g_abs * d1[self._g_cols], self._g_ptr[:-1])
            d[self.n1:] = 1.0 / np.where(gmax > 0, gmax, 1.0)
        return d

    def _ruiz(self, data):
        """Ruiz-equilibrate the entries ``data`` of S (fixed pattern): returns (dr, dc, Dr S Dc)."""
        N = self.N
        av = np.abs(data)
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
        return dr, dc, self._csc(data * dr[rows] * dc[cols])

    def solve(self, s, rhs, *, trans: bool = False):
        """Convenience: ``factor(s).solve(rhs, trans=trans)``."""
        return self.factor(s).solve(rhs, trans=trans)

    def clear(self):
        """Drop cached factorizations (counters are kept)."""
        self._cache.clear()

