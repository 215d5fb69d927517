r"""Sparse LU backends of the saddle-point matrix: the pattern analysed once, a choice by rule.

:class:`~morsuite.linalg.saddle.SaddlePointSolver` factors

.. math::

    S(s) = \begin{bmatrix} A_{11} & G^T \\ G & 0 \end{bmatrix}, \qquad A_{11} = s^2 M + s D + K,

once per shift. Its sparsity pattern is that of the model, the same for every
shift, so everything that depends only on it -- the ordering, the band
structure, the backend itself -- is decided once per model by :func:`analyse`,
deterministically and from the pattern alone (no timing, no values): a
reduction's result never depends on what ran before on the same model object.

Backends (``backend=`` of the solver; ``"auto"`` applies :func:`choose`):

``"superlu"``
    scipy's SuperLU with a COLAMD column ordering found once, at analysis, on the
    pattern (a factorization of a matrix with the pattern's magnitudes) and applied as
    a symmetric renumbering to every shift; row pivots per shift (threshold 0.1).
    Always available; the fallback of the others.
``"banded"``
    Reverse Cuthill-McKee renumbering of the :math:`A_{11}` block (found once),
    LAPACK's banded LU with partial pivoting (``?gbtrf``) of :math:`A_{11}`, and the
    n2 constraint rows and columns as a border eliminated through the dense Schur
    complement :math:`C = -G A_{11}^{-1} G^T` (its LU by ``?getrf``). Cost
    :math:`O(n_1 k_l (k_l + k_u))` plus n2 banded solves, O(n1 (2k_l + k_u + 1)) memory;
    scipy only. Forward solve: one banded solve and a product with the stored
    :math:`A_{11}^{-1} G^T`; transposed solve: two banded solves.
    Pivoting is confined to :math:`A_{11}`: where :math:`A_{11}` is (nearly)
    singular and S is not, the solve's backward error check fails and the solver
    refactors with SuperLU (``stats.refactorizations``).
``"klu"``, ``"rslab"``, ``"pardiso"``
    Library backends (:mod:`morsuite.linalg.backends_ext`): KLU through ``nbklu`` (BSD-3) and
    rslab's supernodal LU (MIT), default dependencies; MKL PARDISO through ``mkl``, an extra.

:func:`choose` takes ``"banded"`` when the RCM bandwidth of :math:`A_{11}` and n2
are small (:data:`BAND_RULE`; the measurements behind it are in
``docs/design/backends.md``); where KLU is installed, narrow bands with a border
of more than ``max_border_klu`` rows go to KLU; wide bands go to PARDISO where it
is installed and the matrix has at least ``pardiso_min_n`` rows, else to rslab from
``rslab_min_n`` rows, else to ``"superlu"``. ``MORSUITE_LU_BACKEND`` in the environment overrides ``"auto"``.
"""

from __future__ import annotations

import ctypes
import os

import numpy as np
import scipy.linalg as sla
import scipy.linalg.lapack as lapack
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import reverse_cuthill_mckee

from ..errors import InputError, SingularShiftError
from . import kernels, backends_ext, backends_rslab

__all__ = ["BACKENDS", "BAND_RULE", "LIBRARY_BACKENDS", "BandedBorderLU", "analyse", "banded_structure", "choose",
           "factor_nnz", "permuted_pattern", "resolve_backend", "superlu_ordering"]

#: the backends a solver accepts (``"auto"``: :func:`choose`)
BACKENDS = ("auto", "superlu", "banded", "klu", "rslab", "pardiso")

#: the backends served by a library (:mod:`morsuite.linalg.backends_ext`)
LIBRARY_BACKENDS = ("klu", "rslab", "pardiso")

#: the structural rule of ``"auto"``: banded LU when the RCM half-bandwidths satisfy
#: ``kl + ku <= max_band`` and ``n2 <= max_border`` (``max_border_klu`` where KLU is
#: installed, which takes the narrow bands with a larger border); PARDISO, where
#: installed, for the wide bands from ``pardiso_min_n`` rows of S on, else rslab's supernodal LU from
#: ``rslab_min_n`` rows on (2026-11-27)
#: (docs/design/backends.md, 2026-11-25 and 2026-11-26); the banded LU runs the compiled kernels of
#: :mod:`~morsuite.linalg.kernels` up to ``kl + ku <= numba_max_band`` and LAPACK's blocked ``?gbtrf``
#: above (2026-11-26, second session: the unblocked kernel is 1.2x faster at kl + ku = 10, 1.45x
#: slower at 66)
BAND_RULE = {"max_band": 64, "max_border": 8, "max_border_klu": 1, "klu_min_n": 100_000, "pardiso_min_n": 2000,
             "rslab_min_n": 1000, "numba_max_band": 16}


def factor_nnz(lu) -> int:
    """Stored entries of a factorization made by any backend (the memory of its values).

    SuperLU: ``nnz(L) + nnz(U)``; every other backend's factorization reports its own
    ``nnz`` (banded: :attr:`BandedBorderLU.nnz`; PARDISO: the factors' entries it reports;
    KLU: the matrix's entries only, a lower bound, since kvxopt does not report the
    factors' size). Cost O(1).
    """
    nnz = getattr(lu, "nnz", None)
    return int(lu.L.nnz + lu.U.nnz) if nnz is None else int(nnz)


def resolve_backend(backend: str) -> str:
    """Validate a backend name; ``"auto"`` is replaced by ``MORSUITE_LU_BACKEND`` when that is set."""
    if backend == "auto":
        backend = os.environ.get("MORSUITE_LU_BACKEND", "auto") or "auto"
    if backend not in BACKENDS:
        raise InputError(f"backend must be one of {', '.join(map(repr, BACKENDS))}; got {backend!r}")
    if backend in LIBRARY_BACKENDS:
        backends_ext.require(backend)
    return backend


def _a11_pattern(pattern) -> sp.csr_matrix:
    """The symmetrised sparsity pattern of the (1,1) block (values 1)."""
    n1 = pattern["shape"][0]
    rows, cols = pattern["_rows"], pattern["_cols"]
    keep = (rows < n1) & (cols < n1)
    P = sp.csr_matrix((np.ones(int(keep.sum())), (rows[keep], cols[keep])), shape=(n1, n1))
    return (P + P.T).tocsr()


def _bandwidths(pattern, perm_c) -> tuple[int, int]:
    """(kl, ku) of the (1,1) block renumbered by ``perm_c`` (old -> new)."""
    n1 = pattern["shape"][0]
    rows, cols = pattern["_rows"], pattern["_cols"]
    keep = (rows < n1) & (cols < n1)
    d = perm_c[rows[keep]] - perm_c[cols[keep]]
    return (int(max(d.max(), 0)), int(max(-d.min(), 0))) if d.size else (0, 0)


def choose(kl: int, ku: int, n2: int, n: int = 0, available: dict | None = None) -> tuple[str, str]:
    """The backend of ``"auto"`` from the structure and the installed libraries: (name, reason).

    With ``B = BAND_RULE`` and ``n`` the order of S:

    - ``kl + ku <= B["max_band"]`` (a narrow band): banded if ``n2 <= B["max_border"]``
      (``B["max_border_klu"]`` where KLU is installed and ``n >= B["klu_min_n"]``), else KLU if
      so, else SuperLU. Below ``klu_min_n`` the long-standing rule stays: the banded LU is within
      1.2x of KLU there (0.264 against 0.222 of splu at tcom(2e5), 2026-11-27), and the reductions
      keep the rounding they had (so-h2 at tcom(2000), r = 30, converged on the banded LU and stopped
      at its cap on KLU's rounding, 7.547 against 7.582; an undamped random model of 32 rows led IRKA
      elsewhere);
    - a wide band (3D solids): PARDISO if installed and ``n >= B["pardiso_min_n"]``, else rslab's
      supernodal LU if installed and ``n >= B["rslab_min_n"]`` (its LDL^T at complex shifts where M, D
      and K are symmetric: :func:`~morsuite.linalg.backends_rslab.rslab_factor`), else SuperLU.

    ``available``: :func:`morsuite.linalg.backends_ext.available` by default. Decided
    from the pattern (and what is installed) alone: the banded LU costs
    O(n1 (kl + ku)^2) plus n2 banded solves for the border; KLU has no border cost and
    no supernodes; supernodes (rslab, PARDISO) win on 3D solids, whose fill grows like
    n^{4/3} and work like n^2 under nested dissection. Measurements: ``docs/design/backends.md``.
    """
    av = backends_ext.available() if available is None else available
    B = BAND_RULE
    if kl + ku <= B["max_band"]:
        klu = bool(av.get("klu")) and n >= B["klu_min_n"]
        limit = B["max_border_klu"] if klu else B["max_border"]
        if n2 <= limit:
            return "banded", f"RCM bandwidth kl + ku = {kl + ku} <= {B['max_band']} and n2 = {n2} <= {limit}"
        if klu:
            return "klu", f"RCM bandwidth kl + ku = {kl + ku} <= {B['max_band']}, n2 = {n2} > {limit}: KLU"
        return "superlu", f"n2 = {n2} above the banded border limit {limit}"
    wide = f"RCM bandwidth kl + ku = {kl + ku} > {B['max_band']}"
    if av.get("pardiso") and n >= B["pardiso_min_n"]:
        return "pardiso", f"{wide}, n = {n} >= {B['pardiso_min_n']}: PARDISO"
    if av.get("rslab") and n >= B["rslab_min_n"]:
        return "rslab", (f"{wide}, n = {n} >= {B['rslab_min_n']}: rslab's supernodal LU (its LDL^T at complex shifts "
                         "where M, D, K are symmetric)")
    return "superlu", f"{wide}, n = {n}: SuperLU"


def permuted_pattern(pattern, perm_c) -> dict:
    """The pattern's entries renumbered symmetrically, ``Ae = A[q][:, q]`` with ``q = argsort(perm_c)``.

    ``perm_c`` maps an old index to its new one. Returns a dict with ``q``, the
    CSC structure ``_indices, _indptr`` of the renumbered matrix, the block values
    ``_m, _d, _k, _g`` in that order and the old row and column indices
    ``_rows, _cols`` of each entry (the scalings use them). Read-only arrays.
    """
    N = pattern["N"]
    rows, cols = pattern["_rows"], pattern["_cols"]
    q = np.argsort(perm_c)
    new_row, new_col = perm_c[rows], perm_c[cols]
    sel = np.lexsort((new_row, new_col))
    counts = np.bincount(new_col, minlength=N)
    perm = {"q": q, "_indices": new_row[sel].astype(np.int32),
            "_indptr": np.concatenate([[0], np.cumsum(counts)]).astype(np.int32),
            "_m": pattern["_m"][sel], "_d": pattern["_d"][sel], "_k": pattern["_k"][sel],
            "_g": pattern["_g"][sel], "_rows": rows[sel], "_cols": cols[sel]}
    for v in perm.values():
        v.flags.writeable = False
    return perm


def superlu_ordering(pattern, permc_spec: str = "COLAMD") -> np.ndarray:
    """SuperLU's column ordering (old -> new) of the pattern, from values alone of the pattern.

    One real LU of the matrix whose entries are the magnitudes
    :math:`|m| + |d| + |k| + |g|` (no cancellation, so the pattern is the model's):
    SuperLU's orderings (COLAMD, MMD_*) and its elimination-tree postorder depend only
    on the pattern, so the ordering is that of any shift -- but found the same way
    whatever shift comes first.
    """
    data = np.abs(pattern["_m"]) + np.abs(pattern["_d"]) + np.abs(pattern["_k"]) + np.abs(pattern["_g"])
    N = pattern["N"]
    A = sp.csc_matrix((data, pattern["_indices"].copy(), pattern["_indptr"].copy()), shape=(N, N))
    return np.asarray(spla.splu(A, permc_spec=permc_spec, diag_pivot_thresh=0.1).perm_c)


def analyse(pattern, backend: str = "auto") -> dict:
    """The structural analysis of a saddle pattern for ``backend``, done once and stored in ``pattern``.

    Parameters
    ----------
    pattern : dict
        ``SaddlePointSolver.pattern`` (shared by the solvers of one model).
    backend : {"auto", "superlu", "banded", "klu", "rslab", "pardiso"}
        ``"auto"``: :func:`choose` from the RCM bandwidth of the (1,1) block, n2, the order of S
        and the installed libraries (KLU, rslab, PARDISO).

    Returns
    -------
    dict
        Plain data: ``backend`` (the one used), ``requested``, ``reason``, ``kl``, ``ku``
        (RCM half-bandwidths of the (1,1) block), ``n1``, ``n2``, ``nnz``, ``available``
        (the library backends installed), ``kernels`` (``"numba"``: the compiled banded LU and
        assembly of :mod:`~morsuite.linalg.kernels` are used; else ``"numpy/lapack"``). The banded renumbering is stored in
        ``pattern[("ordering", "banded")]``, PARDISO's ordering, KLU's symbolic
        analysis and rslab's in ``pattern`` too (found once, from the pattern alone); for rslab
        also ``predicted_factor_nnz`` and ``predicted_flops`` (complex) of its analysis.

    Notes
    -----
    Cost: one RCM ordering, O(nnz), and the chosen library's analysis (rslab: its ordering race,
    0.1-4 s from n1 = 4e3 to 2e4 on fem_block); deterministic (no values, no timing).
    """
    backend = resolve_backend(backend)
    key = ("analysis", backend)
    if key in pattern:
        return pattern[key]
    n1, n2 = pattern["shape"]
    if ("rcm",) not in pattern:
        rcm = np.asarray(reverse_cuthill_mckee(_a11_pattern(pattern), symmetric_mode=True), dtype=np.int64)
        perm_c = np.empty(n1 + n2, dtype=np.int64)
        perm_c[rcm] = np.arange(n1)
        perm_c[n1:] = np.arange(n1, n1 + n2)
        perm_c.flags.writeable = False
        pattern[("rcm",)] = perm_c
    perm_c = pattern[("rcm",)]
    kl, ku = _bandwidths(pattern, perm_c)
    av = backends_ext.available()
    if backend == "auto":
        name, reason = choose(kl, ku, n2, int(n1 + n2), av)
    else:
        name, reason = backend, "forced"
    if name == "banded" and ("ordering", "banded") not in pattern:
        perm = permuted_pattern(pattern, perm_c)
        perm["banded"] = banded_structure(perm, int(n1), kl, ku)
        pattern[("ordering", "banded")] = perm
    if name == "pardiso":
        backends_ext.pardiso_ordering(pattern)
    extra = {}
    if name == "rslab":  # the analysis' prediction, for the record
        try:
            sym = backends_rslab.rslab_symbolic(pattern)
            extra = {"predicted_factor_nnz": int(sym.factor_nnz),
                     "predicted_flops": float(sym.estimate_memory("complex128")["factor_flops"])}
        except (RuntimeError, ValueError) as exc:  # rslab could not analyse the pattern: SuperLU
            if backend != "auto":
                raise InputError(f"backend='rslab' cannot analyse this pattern: {exc}") from exc
            name, reason = "superlu", f"{reason}; rslab's analysis failed ({exc}): SuperLU"
    info = {"backend": name, "requested": backend, "reason": reason, "kl": kl, "ku": ku,
            "n1": int(n1), "n2": int(n2), "nnz": int(pattern["_indices"].size), "available": av,
            "kernels": _kernels_used(name, kl, ku), **extra}
    pattern[key] = info
    return info


def _kernels_used(backend: str, kl: int, ku: int) -> str:
    """What runs the assembly and (banded backend) the band LU: for ``info`` and the manifest."""
    if not kernels.use_kernels():
        return "numpy/lapack"
    if backend == "banded" and kl + ku > BAND_RULE["numba_max_band"]:
        return "numba assembly, LAPACK band LU"
    return "numba"


_GBTRS: dict = {}


def _gbtrs_nogil(prefix: str):
    """LAPACK's ``?gbtrs`` called through ctypes, which releases the GIL (SciPy's f2py wrapper
    holds it: measured, docs/design/backends.md), or None where SciPy's Cython LAPACK is not there."""
    if prefix not in _GBTRS:
        try:
            import scipy.linalg.cython_lapack as cl
            cap = cl.__pyx_capi__[prefix + "gbtrs"]
            name = ctypes.pythonapi.PyCapsule_GetName
            name.restype, name.argtypes = ctypes.c_char_p, [ctypes.py_object]
            get = ctypes.pythonapi.PyCapsule_GetPointer
            get.restype, get.argtypes = ctypes.c_void_p, [ctypes.py_object, ctypes.c_char_p]
            ip, vp = ctypes.POINTER(ctypes.c_int), ctypes.c_void_p
            _GBTRS[prefix] = ctypes.CFUNCTYPE(None, ctypes.c_char_p, ip, ip, ip, ip, vp, ip, vp, vp, ip, ip)(
                get(cap, name(cap)))
        except (ImportError, KeyError, AttributeError, ValueError):
            _GBTRS[prefix] = None
    return _GBTRS[prefix]


def banded_structure(perm: dict, n1: int, kl: int, ku: int) -> dict:
    """Where each entry of a renumbered pattern (CSC order) goes in the banded LU's arrays, found once.

    ``a11``: (entry numbers, flat positions in the (n1, 2 kl + ku + 1) transposed band
    array); ``b12``: (entry numbers, flat positions in the dense (n1, n2) block);
    ``b21`` and ``b12t``: (entry numbers in CSR order, indices, indptr) of the sparse
    (n2, n1) blocks B21 and B12^T; ``order12``, ``starts12``: the columns of B12 sorted by
    their first nonzero row, and those rows; ``w0``: (entry numbers, flat positions in the
    C-ordered (n1, n2) array ``B12[:, order12]``).
    """
    N = perm["_indptr"].size - 1
    n2 = N - n1
    rows = perm["_indices"].astype(np.int64)
    cols = np.repeat(np.arange(N), np.diff(perm["_indptr"]))
    ldab = 2 * kl + ku + 1
    in11 = np.flatnonzero((rows < n1) & (cols < n1))
    in12 = np.flatnonzero((rows < n1) & (cols >= n1))

    def csr(sel, r, c, nrows):
        order = np.lexsort((c, r))
        return (sel[order], c[order].astype(np.int32),
                np.concatenate([[0], np.cumsum(np.bincount(r, minlength=nrows))]).astype(np.int32))

    in21 = np.flatnonzero((rows >= n1) & (cols < n1))
    out = {"ldab": ldab,
           "a11": (in11, cols[in11] * ldab + (kl + ku) + rows[in11] - cols[in11]),
           "b12": (in12, rows[in12] * n2 + cols[in12] - n1),
           "b21": csr(in21, rows[in21] - n1, cols[in21], n2),
           "b12t": csr(in12, cols[in12] - n1, rows[in12], n2)}
    # each border column's first nonzero row, the columns sorted by it, and where B12's entries go in
    # the (n1, n2) C-ordered B12[:, order12] (the start of W = A11^{-1} B12 in the compiled kernel)
    first = np.full(n2, n1, dtype=np.int64)
    np.minimum.at(first, cols[in12] - n1, rows[in12])
    order = np.argsort(first, kind="stable")
    out["order12"], out["starts12"] = order, np.minimum(first[order], max(n1 - 1, 0))
    out["w0"] = (in12, rows[in12] * n2 + np.argsort(order)[cols[in12] - n1])
    return out


class BandedBorderLU:
    r"""LU of a bordered matrix ``[[A11, B12], [B21, 0]]`` (renumbered, equilibrated): banded plus Schur.

    Made from the entries ``data`` of a renumbered pattern (:func:`permuted_pattern` of the
    RCM ordering) placed by ``structure`` (:func:`banded_structure`):
    :math:`A_{11} = \tilde L U` with partial pivoting inside the band (``kl`` sub- and
    ``ku`` super-diagonals; :math:`\tilde L` holds the row swaps), and the n2 border rows
    and columns eliminated through the dense Schur complement
    :math:`C = -B_{21} A_{11}^{-1} B_{12}` (its LU by ``?getrf``). Two kernels
    (``kernel``, :func:`morsuite.linalg.kernels.use_kernels`):

    ``"numba"`` (default where ``kl + ku <= BAND_RULE["numba_max_band"]``)
        :mod:`~morsuite.linalg.kernels` (compiled ``?gbtf2`` and half-sweeps):
        :math:`W = A_{11}^{-1} B_{12}` by a forward half-sweep that starts at each
        column's first nonzero row and a full backward one.
    ``"lapack"``
        ``?gbtrf``/``?gbtrs`` (n2 full banded solves for W): wider bands, where its blocked
        algorithm wins, or without numba.

    Then :math:`C = -B_{21} W`. A solve is a banded solve and a product with W
    (transposed: two banded solves). Memory n1 (2 kl + ku + 1 + n2). The two kernels
    give the same factors (to the last bits of U's reciprocal pivots).

    :meth:`solve` has the interface of SuperLU's ``solve`` (``trans="N"`` or ``"T"``, a
    2-D right-hand side).

    Raises
    ------
    SingularShiftError
        If :math:`A_{11}` or C is exactly singular (the caller then falls back to SuperLU).
    """

    def __init__(self, data, n1: int, n2: int, kl: int, ku: int, structure: dict):
        self.n1, self.n2 = n1, n2
        self.kl, self.ku = kl, ku
        self.dtype = np.result_type(data.dtype, np.float64)
        self.shape = (n1 + n2, n1 + n2)
        ldab = structure["ldab"]
        # the transpose of LAPACK's (ldab, n1) band array
        ab = kernels.scatter(data, structure["a11"], np.zeros((n1, ldab), dtype=self.dtype))
        self.kernel = "numba" if kernels.use_kernels() and kl + ku <= BAND_RULE["numba_max_band"] else "lapack"
        if self.kernel == "numba":  # compiled ?gbtf2 and half-sweeps (kernels): measured in docs/design/backends.md
            piv, self._dinv, info = kernels.gbtrf(ab, kl, ku)
            lu = ab.T
        else:
            pfx = "z" if self.dtype == np.complex128 else "d"
            self._gbtrs, self._gbtrs_c = getattr(lapack, pfx + "gbtrs"), _gbtrs_nogil(pfx)
            lu, piv, info = getattr(lapack, pfx + "gbtrf")(ab.T, kl, ku, overwrite_ab=1)
            self._piv1 = (piv + 1).astype(np.intc)  # LAPACK's 1-based pivots (SciPy's wrappers shift them)
        if info > 0:
            raise SingularShiftError(f"banded LU: the (1,1) block is exactly singular (pivot {info})")
        self._lu, self._piv = lu, piv
        if not n2:
            return
        sel, ind, ptr = structure["b21"]
        self.B21 = sp.csr_matrix((data[sel], ind, ptr), shape=(n2, n1))
        sel, ind, ptr = structure["b12t"]
        self.B12T = sp.csr_matrix((data[sel], ind, ptr), shape=(n2, n1))
        if self.kernel == "numba":
            # W's columns in the order of their first nonzero row: the forward half-sweep skips the rows above
            self._o12 = structure["order12"]
            W = kernels.scatter(data, structure["w0"], np.zeros((n1, n2), dtype=self.dtype))
            self._sweep(W, kernels.L_FORWARD, structure["starts12"])
            self.W = self._sweep(W, kernels.U_BACKWARD)  # A11^{-1} B12[:, o12]
        else:
            self._o12 = np.arange(n2)
            sel, pos = structure["b12"]
            B12 = np.zeros((n1, n2), dtype=self.dtype)
            B12.ravel()[pos] = data[sel]
            self.W = self._band(B12, False)
        C = -(self.B21 @ self.W)  # C[:, o12]
        self._schur = sla.lu_factor(C, check_finite=False)
        if not np.all(np.abs(np.diag(self._schur[0])) > 0):
            raise SingularShiftError("banded LU: the Schur complement of the border is exactly singular")

    @property
    def nnz(self) -> int:
        """Stored factor entries: the band LU (n1 (2 kl + ku + 1)), W = A11^{-1} B12 (n1 n2), the Schur LU (n2^2)."""
        border = self.n1 * self.n2 + self.n2 * self.n2
        return int(self._lu.size + (border if self.n2 else 0))

    def u_diagonal(self) -> np.ndarray:
        """The pivots of U (banded part and Schur complement), for the pivot-ratio check."""
        d = self._lu[self.kl + self.ku, :]
        return np.concatenate([d, np.diag(self._schur[0])]) if self.n2 else d

    def _sweep(self, b, part, starts=None):
        """A half-sweep of the compiled kernel in place on the C-ordered b of the LU's type."""
        return kernels.sweep(self._lu.T, self.kl, self.ku, self._piv, self._dinv, b, part, starts)

    def _band(self, b, trans: bool):
        """A11^{-1} b (``trans``: A11^{-T} b), b overwritten where it already is an array of the LU's type and layout."""
        if self.kernel == "numba":
            return kernels.gbtrs(self._lu.T, self.kl, self.ku, self._piv, self._dinv,
                                      np.asarray(b, dtype=self.dtype, order="C"), trans)
        b = np.asarray(b, dtype=self.dtype, order="F")
        f = self._gbtrs_c
        if f is None:
            x, info = self._gbtrs(self._lu, self.kl, self.ku, b, self._piv, trans=1 if trans else 0, overwrite_b=1)
            return x
        c = ctypes.c_int
        info = c(0)
        f(b"T" if trans else b"N", c(self.n1), c(self.kl), c(self.ku), c(b.shape[1]), self._lu.ctypes.data,
          c(self._lu.shape[0]), self._piv1.ctypes.data, b.ctypes.data, c(max(b.shape[0], 1)), ctypes.byref(info))
        return b

    def _band_into(self, x, trans: bool):
        """x <- A11^{-1} x (``trans``: A11^{-T} x) in place (through a copy where x's layout needs one)."""
        y = self._band(x, trans)
        if y is not x:
            x[...] = y

    def solve(self, b, trans: str = "N"):
        """Solve ``A x = b`` (``trans="N"``) or ``A^T x = b`` (``"T"``); b of shape (N, k) or (N,)."""
        b = np.asarray(b)
        vec = b.ndim == 1
        b = b.reshape(b.shape[0], -1)
        if np.iscomplexobj(b) and self.dtype != np.complex128:
            x = self.solve(b.real, trans) + 1j * self.solve(b.imag, trans)
            return x[:, 0] if vec else x
        n1 = self.n1
        b1, b2 = b[:n1], b[n1:]
        x = np.empty((n1 + self.n2, b.shape[1]), dtype=self.dtype, order="F" if self.kernel == "lapack" else "C")
        x1 = x[:n1]
        x1[...] = b1
        if trans == "N":
            self._band_into(x1, False)
            if self.n2:
                x2p = sla.lu_solve(self._schur, b2 - self.B21 @ x1, check_finite=False)
                x[n1:][self._o12] = x2p
                x1 -= self.W @ x2p
        else:
            self._band_into(x1, True)
            if self.n2:
                x2 = sla.lu_solve(self._schur, (b2 - self.B12T @ x1)[self._o12], trans=1, check_finite=False)
                x[n1:] = x2
                x1[...] = b1 - self.B21.T @ x2
                self._band_into(x1, True)
        return x[:, 0] if vec else x
