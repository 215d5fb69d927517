r"""Optional sparse LU backends: KLU (``kvxopt``, GPL-3) and MKL PARDISO (``mkl``, Intel's ISSL).

Neither is in the default install (``mkl`` is under the Intel Simplified Software
License, not GPL; ``kvxopt`` is GPL-3, so never a default dependency); each is an extra (``pip install morsuite[klu]``,
``pip install morsuite[pardiso]``), imported only when used, and
:func:`available` says which are there. Both factor the equilibrated saddle matrix
:math:`A_e = D S(s) D` (natural numbering; the backend orders it) and solve with
it or its plain transpose, with the interface of SuperLU's ``solve``;
:class:`~morsuite.linalg.saddle_lu.SaddleLU` checks every solve's backward error
and falls back to SuperLU as for the other backends.

``"klu"``
    KLU's symbolic analysis (BTF, AMD ordering) once per pattern and value type,
    from the pattern alone; per shift one numeric factorization. Fast on chains
    (no supernodes, low per-column overhead), slow on 3D solids.
``"pardiso"``
    MKL PARDISO through ctypes (``libmkl_rt``): complex symmetric (matrix type 6;
    -2 for a real shift) when M, D, K are exactly symmetric, the upper triangle with
    Bunch-Kaufman pivoting, else unsymmetric (13 complex, 11 real); nested-dissection
    (METIS) ordering computed once per pattern from a matrix of the pattern's
    magnitudes and given to every factorization (``iparm[4] = 1``); per shift a
    fresh handle: analysis with that ordering and this shift's weighted matching and scaling (``iparm[10] = iparm[12] = 1``),
    numeric factorization, released when the factorization is dropped (one handle
    per live factorization). Pivot perturbation 1e-13 (1e-8 symmetric; ``iparm[9]``),
    at most two refinement steps (``iparm[7]``); PARDISO's defaults give NaN on saddle
    matrices. One MKL thread per call (``mkl_set_num_threads_local``), so the
    factors are the same bits whatever the machine load or the solver threads.

Measurements behind the choice (:func:`morsuite.linalg.backends.choose`):
``docs/design/backends.md`` (2026-11-26).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import glob
import os
import sys
import threading

import numpy as np
import scipy.sparse as sp

from ..errors import InputError, SingularShiftError

__all__ = ["KLULU", "PardisoLU", "available", "klu_symbolic", "pardiso_ordering"]

_LOCK = threading.Lock()
_MKL: dict = {}


def _klu():
    try:
        import kvxopt
        from kvxopt import klu
    except ImportError:  # the optional extra is not installed
        return None
    return kvxopt, klu


def _mkl_lib():
    """``libmkl_rt`` (from PyPI's ``mkl`` wheel or the system), or None."""
    if "lib" not in _MKL:
        lib = None
        names = [os.path.join(sys.prefix, "lib", n) for n in ("libmkl_rt.so.3", "libmkl_rt.so.2", "libmkl_rt.so")]
        names += sorted(glob.glob(os.path.join(sys.prefix, "lib", "libmkl_rt.so*")))
        found = ctypes.util.find_library("mkl_rt")
        names += [found] if found else []
        for n in names:
            try:
                lib = ctypes.CDLL(n)
                lib.pardiso.restype = None
                lib.MKL_Set_Num_Threads_Local.restype = ctypes.c_int
                break
            except (OSError, AttributeError):
                lib = None
        _MKL["lib"] = lib
    return _MKL["lib"]


def available() -> dict:
    """Which optional backends can be used here: ``{"klu": bool, "pardiso": bool}``. Cost: one import / dlopen."""
    return {"klu": _klu() is not None, "pardiso": _mkl_lib() is not None}


def require(name: str):
    """Raise :class:`~morsuite.errors.InputError` naming the extra if backend ``name`` is not installed."""
    if not available().get(name, True):
        raise InputError(f"backend={name!r} needs the optional extra: pip install morsuite[{name}]")


def _magnitudes(pattern):
    """The pattern's CSC structure with the magnitudes |m| + |d| + |k| + |g| (no cancellation)."""
    data = np.abs(pattern["_m"]) + np.abs(pattern["_d"]) + np.abs(pattern["_k"]) + np.abs(pattern["_g"])
    return data, pattern["_indices"], pattern["_indptr"]


# -- KLU --------------------------------------------------------------------------------------
class _Local:
    """A value kept with the pattern but not pickled (kvxopt's objects are not picklable; a Dask
    worker's copy of the pattern recomputes it)."""

    def __init__(self, value=None):
        self.value = value

    def __getstate__(self):
        return {}

    def __setstate__(self, state):
        self.value = None


def klu_symbolic(pattern, complex_: bool):
    """KLU's symbolic analysis of the pattern for real or complex values (once per pattern and type).

    Returns ``(template, symbolic)``: a kvxopt sparse matrix with the pattern (values
    replaced per factorization under a lock) and the analysis. Deterministic: KLU's
    BTF and AMD orderings depend on the pattern only.
    """
    key = ("klu", bool(complex_))
    with _LOCK:
        if key not in pattern or pattern[key].value is None:
            kvxopt, klu = _klu()
            data, ind, ptr = _magnitudes(pattern)
            N = ptr.size - 1
            cols = np.repeat(np.arange(N), np.diff(ptr))
            tc = "z" if complex_ else "d"
            A = kvxopt.spmatrix(data.astype(complex if complex_ else float).tolist(), ind.tolist(), cols.tolist(),
                                (N, N), tc)
            pattern[key] = _Local((A, klu.symbolic(A)))
    return pattern[key].value


class KLULU:
    """KLU factorization of an equilibrated saddle matrix ``As`` (CSC, the pattern's structure).

    ``solve(b, trans)`` as SuperLU's. Cost: one KLU numeric factorization (the symbolic
    analysis is shared by the pattern), a copy of the values into kvxopt's storage.
    """

    def __init__(self, As, pattern):
        kvxopt, klu = _klu()
        self._kv, self._klu = kvxopt, klu
        self.dtype = np.complex128 if np.iscomplexobj(As.data) else np.float64
        self.shape = As.shape
        self._A, self._sym = klu_symbolic(pattern, self.dtype == np.complex128)
        with _LOCK:  # the template's values are this factorization's only while numeric runs
            self._A.V = kvxopt.matrix(np.asarray(As.data, dtype=self.dtype))
            try:
                self._num = klu.numeric(self._A, self._sym)
            except ArithmeticError as exc:
                raise SingularShiftError(f"KLU: the matrix is singular ({exc})") from exc
        self.nnz = int(As.nnz)  # KLU does not report its factors' size through kvxopt: the matrix's

    def solve(self, b, trans: str = "N"):
        """Solve ``A x = b`` (``trans="N"``) or ``A^T x = b`` (``"T"``); b of shape (N, k) or (N,)."""
        b = np.asarray(b)
        vec = b.ndim == 1
        B = self._kv.matrix(np.asarray(b.reshape(b.shape[0], -1), dtype=self.dtype))
        self._klu.solve(self._A, self._sym, self._num, B, trans=trans)
        x = np.array(B, dtype=self.dtype)
        return x[:, 0] if vec else x


# -- PARDISO ----------------------------------------------------------------------------------
def _iparm(symmetric: bool = False) -> np.ndarray:
    ip = np.zeros(64, dtype=np.int32)
    ip[0] = 1    # iparm given (not defaults)
    ip[1] = 2    # nested dissection (METIS)
    ip[7] = 2    # at most two iterative refinement steps
    ip[9] = 8 if symmetric else 13   # pivot perturbation 1e-8 (symmetric, PARDISO's default) / 1e-13
    ip[10] = 1   # scaling
    ip[12] = 1   # weighted matching (saddle matrices: the defaults give NaN)
    ip[34] = 1   # zero-based indices
    return ip


def _pardiso(pt, phase, mtype, n, data, ptr, ind, perm, iparm, b=None, x=None):
    lib = _mkl_lib()
    I = ctypes.c_int
    err = I(0)
    dummy = np.zeros(1, dtype=complex)
    b = dummy if b is None else b
    x = dummy if x is None else x
    vp = ctypes.c_void_p
    old = lib.MKL_Set_Num_Threads_Local(1)
    try:
        lib.pardiso(vp(pt.ctypes.data), ctypes.byref(I(1)), ctypes.byref(I(1)), ctypes.byref(I(mtype)),
                    ctypes.byref(I(phase)), ctypes.byref(I(n)), vp(data.ctypes.data), vp(ptr.ctypes.data),
                    vp(ind.ctypes.data), vp(perm.ctypes.data), ctypes.byref(I(b.shape[1] if b.ndim == 2 else 1)),
                    vp(iparm.ctypes.data), ctypes.byref(I(0)), vp(b.ctypes.data), vp(x.ctypes.data),
                    ctypes.byref(err))
    finally:
        lib.MKL_Set_Num_Threads_Local(old)
    return err.value


def _symmetric_blocks(pattern) -> bool:
    """Whether M, D and K are exactly symmetric (then S(s) is complex symmetric)."""
    ind, ptr = pattern["_indices"], pattern["_indptr"]
    N = ptr.size - 1
    for key in ("_m", "_d", "_k"):
        A = sp.csc_matrix((pattern[key], ind, ptr), shape=(N, N))
        if (A - A.T).count_nonzero():
            return False
    return True


def _upper_structure(pattern):
    """CSR of the upper triangle with every diagonal entry stored (PARDISO's symmetric input).

    For a symmetric matrix, the entries of CSC column c with row >= c are the upper
    row c in CSR order. Returns (sel: the pattern entries taken, pos: where they go,
    size, ptr, ind), zero diagonals added where the pattern has none (the multipliers).
    """
    ind, ptr = pattern["_indices"].astype(np.int64), pattern["_indptr"].astype(np.int64)
    N = ptr.size - 1
    cols = np.repeat(np.arange(N), np.diff(ptr))
    sel = np.flatnonzero(ind >= cols)
    has_diag = np.zeros(N, dtype=bool)
    has_diag[cols[sel][ind[sel] == cols[sel]]] = True
    r = np.concatenate([cols[sel], np.flatnonzero(~has_diag)])  # CSR rows of the upper entries
    c = np.concatenate([ind[sel], np.flatnonzero(~has_diag)])
    order = np.lexsort((c, r))
    where = np.empty(order.size, dtype=np.int64)
    where[order] = np.arange(order.size)
    rowptr = np.concatenate([[0], np.cumsum(np.bincount(r, minlength=N))]).astype(np.int32)
    return sel, where[:sel.size], int(order.size), rowptr, c[order].astype(np.int32)


def pardiso_ordering(pattern) -> dict:
    """PARDISO's fill-reducing ordering (METIS) of the pattern, found once from its magnitudes.

    Complex symmetric input (matrix type 6, upper triangle, Bunch-Kaufman pivoting)
    where M, D and K are exactly symmetric, else unsymmetric (types 13/11; the
    pattern's CSC arrays passed as CSR, so PARDISO analyses the transpose, whose
    pattern is the same). Stored in ``pattern``: ``perm`` (int32), ``symmetric`` and
    the structure passed to PARDISO.
    """
    with _LOCK:
        if ("pardiso", "perm") not in pattern:
            data, ind, ptr = _magnitudes(pattern)
            N = ptr.size - 1
            sym = _symmetric_blocks(pattern)
            if sym:
                sel, pos, size, ptr32, ind32 = _upper_structure(pattern)
                vals = np.zeros(size)
                vals[pos] = data[sel]
            else:
                sel = pos = None
                ptr32, ind32, vals = ptr.astype(np.int32), ind.astype(np.int32), np.asarray(data, dtype=float)
            ip = _iparm(sym)
            ip[4] = 2  # return the ordering
            pt = np.zeros(64, dtype=np.int64)
            perm = np.zeros(N, dtype=np.int32)
            mtype = -2 if sym else 11  # real symmetric indefinite / unsymmetric: the pattern's analysis
            err = _pardiso(pt, 11, mtype, N, vals, ptr32, ind32, perm, ip)
            _pardiso(pt, -1, mtype, N, vals, ptr32, ind32, perm, ip)
            if err:
                raise SingularShiftError(f"PARDISO analysis of the pattern failed (error {err})")
            for a in (perm, ptr32, ind32):
                a.flags.writeable = False
            pattern[("pardiso", "perm")] = {"perm": perm, "symmetric": sym, "ptr": ptr32, "ind": ind32,
                                            "sel": sel, "pos": pos, "size": int(vals.size)}
    return pattern[("pardiso", "perm")]


class PardisoLU:
    """MKL PARDISO factorization of an equilibrated saddle matrix ``As`` (CSC, the pattern's structure).

    PARDISO is given the CSC arrays as CSR, i.e. it factors :math:`A_s^T`; a solve with
    :math:`A_s` is its transposed solve (``iparm[11] = 2``). Cost: PARDISO's analysis with
    the stored ordering, one numeric factorization; the handle is released with the object.
    """

    def __init__(self, As, pattern):
        o = pardiso_ordering(pattern)
        self._perm, self._ptr, self._ind, self.symmetric = o["perm"], o["ptr"], o["ind"], o["symmetric"]
        self.dtype = np.complex128 if np.iscomplexobj(As.data) else np.float64
        cplx = self.dtype == np.complex128
        self.mtype = (6 if cplx else -2) if self.symmetric else (13 if cplx else 11)
        self.shape = As.shape
        if self.symmetric:
            self._data = np.zeros(o["size"], dtype=self.dtype)
            self._data[o["pos"]] = As.data[o["sel"]]
        else:
            self._data = np.ascontiguousarray(As.data, dtype=self.dtype)
        self._pt = np.zeros(64, dtype=np.int64)
        self._iparm = _iparm(self.symmetric)
        self._iparm[4] = 1  # the stored ordering
        self._lock = threading.Lock()
        err = _pardiso(self._pt, 12, self.mtype, self.shape[0], self._data, self._ptr, self._ind,
                       np.array(self._perm), self._iparm)
        if err:
            self._release()
            raise SingularShiftError(f"PARDISO factorization failed (error {err})")
        self.nnz = int(self._iparm[17])  # entries of the factors (reported by PARDISO)
        self.perturbed_pivots = int(self._iparm[13])

    def __reduce__(self):
        raise TypeError("a PARDISO factorization is a handle of this process; it cannot be pickled")

    def _release(self):
        if getattr(self, "_pt", None) is not None and self._pt.any() and _mkl_lib() is not None:
            _pardiso(self._pt, -1, self.mtype, self.shape[0], self._data, self._ptr, self._ind,
                     np.array(self._perm), self._iparm)
            self._pt[:] = 0

    def __del__(self):
        try:
            self._release()
        except Exception:  # noqa: BLE001 -- interpreter shutdown: nothing to release into
            pass

    def solve(self, b, trans: str = "N"):
        """Solve ``A x = b`` (``trans="N"``) or ``A^T x = b`` (``"T"``); b of shape (N, k) or (N,)."""
        b = np.asarray(b)
        vec = b.ndim == 1
        B = np.array(b.reshape(b.shape[0], -1), dtype=self.dtype, order="F")
        X = np.empty_like(B)
        with self._lock:  # iparm and the handle's work arrays are per factorization
            self._iparm[11] = 2 if trans == "N" and not self.symmetric else 0
            err = _pardiso(self._pt, 33, self.mtype, self.shape[0], self._data, self._ptr, self._ind,
                           np.array(self._perm), self._iparm, B, X)
        if err:
            raise SingularShiftError(f"PARDISO solve failed (error {err})")
        return X[:, 0] if vec else X
