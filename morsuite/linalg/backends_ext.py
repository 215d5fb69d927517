r"""Library sparse LU backends: rslab's supernodal LU, KLU (``nbklu``) and MKL PARDISO (``mkl``).

rslab (MIT, pure Rust) and nbklu (BSD-3 bindings of SuiteSparse's KLU, LGPL-2.1, linked into the
wheel) are default dependencies; PARDISO is the ``pardiso`` extra (``mkl``: Intel Simplified
Software License, not GPL). Each is imported only when used and :func:`available` says which
import here: where one does not, ``"auto"`` chooses without it and forcing it raises an error
naming its install. All factor the equilibrated saddle matrix :math:`A_e = D S(s) D` (natural
numbering; the library orders it) and solve with it or its plain transpose, with the interface
of SuperLU's ``solve``; :class:`~morsuite.linalg.saddle_lu.SaddleLU` checks every solve's
backward error and falls back to SuperLU as for the other backends.

``"rslab"``
    rslab's supernodal LU, and its LDL^T at complex-symmetric shifts: :mod:`morsuite.linalg.backends_rslab`
    (which takes the helpers here). The fast one on 3D solids.
``"klu"``
    KLU through ``nbklu``: symbolic analysis (BTF, AMD) and a reference pivot order (a
    factorization of the pattern's magnitudes) once per pattern and value type; per shift a
    refactorization with that order (no pivot search), checked by its pivot growth, else a fresh
    factorization with KLU's own pivoting. Fast on chains (no supernodes, low per-column
    overhead), slow on 3D solids. (Until 2026-11-27 served by ``kvxopt``, GPL-3, an extra.)
``"pardiso"``
    MKL PARDISO through ctypes (``libmkl_rt``): complex symmetric (matrix type 6;
    -2 for a real shift) when M, D, K are exactly symmetric, the upper triangle with
    Bunch-Kaufman pivoting (``iparm[20] = 1``), else unsymmetric (13 complex, 11 real); nested-dissection
    (METIS) ordering computed once per pattern from a matrix of the pattern's
    magnitudes and given to every factorization (``iparm[4] = 1``); per shift a
    fresh handle: analysis with that ordering and this shift's weighted matching and scaling (``iparm[10] = iparm[12] = 1``),
    numeric factorization, released when the factorization is dropped (one handle
    per live factorization). Pivot perturbation 1e-13 (1e-8 symmetric; ``iparm[9]``),
    at most two refinement steps (``iparm[7]``); PARDISO's defaults give NaN on saddle
    matrices. The factors' size is requested (``iparm[17] = -1``) and reported as ``nnz``.
    One MKL thread per call (``mkl_set_num_threads_local``), so the
    factors are the same bits whatever the machine load or the solver threads.

Measurements behind the choice (:func:`morsuite.linalg.backends.choose`):
``docs/design/backends.md`` (2026-11-26, 2026-11-27).
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

__all__ = ["INSTALL", "KLULU", "KLU_MIN_RGROWTH", "PardisoLU", "available", "klu_pool", "pardiso_ordering"]

_LOCK = threading.Lock()
_MKL: dict = {}


def _nbklu():
    try:
        import nbklu
    except ImportError:  # not installed (a default dependency: a broken or partial install)
        return None
    return nbklu


def _rslab():
    try:
        import rslab
    except ImportError:  # not installed (a default dependency: a broken or partial install)
        return None
    return rslab


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
    """Which library backends can be used here: ``{"rslab": bool, "klu": bool, "pardiso": bool}``.

    rslab and nbklu (``"klu"``) are default dependencies, PARDISO the ``pardiso`` extra; a
    library that does not import is reported missing and ``"auto"`` chooses without it.
    Cost: one import / dlopen.
    """
    return {"rslab": _rslab() is not None, "klu": _nbklu() is not None, "pardiso": _mkl_lib() is not None}


#: what installs each library backend
INSTALL = {"rslab": "pip install 'rslab>=1.7,<2'", "klu": "pip install 'nbklu>=0.3,<1'",
           "pardiso": "pip install morsuite[pardiso]"}


def require(name: str):
    """Raise :class:`~morsuite.errors.InputError` naming the install if backend ``name`` is not there."""
    if not available().get(name, True):
        raise InputError(f"backend={name!r} needs its library: {INSTALL[name]}")


def _magnitudes(pattern):
    """The pattern's CSC structure with the magnitudes |m| + |d| + |k| + |g| (no cancellation)."""
    data = np.abs(pattern["_m"]) + np.abs(pattern["_d"]) + np.abs(pattern["_k"]) + np.abs(pattern["_g"])
    return data, pattern["_indices"], pattern["_indptr"]


# -- helpers of the libraries; KLU (nbklu) ---------------------------------------------------------------
#: a :class:`_Local`'s value after unpickling: made again on first use
_LOST = object()


class _Local:
    """A value kept with the pattern but not pickled (the libraries' handles are not picklable; a Dask
    worker's copy of the pattern recomputes it). Any value may be kept, None included."""

    def __init__(self, value):
        self.value = value

    def __getstate__(self):
        return {}

    def __setstate__(self, state):
        self.value = _LOST


def _stored(pattern, key, make):
    """``pattern[key]``'s value, made by ``make()`` once per pattern (and process) under the lock."""
    with _LOCK:
        if key not in pattern or pattern[key].value is _LOST:
            pattern[key] = _Local(make())
    return pattern[key].value


class _KLUPool:
    """Idle nbklu solvers of one pattern and value type, each analysed (BTF, AMD) and factored once
    with the pattern's magnitudes: their pivot order is the reference one, found from the pattern alone."""

    def __init__(self, pattern, complex_: bool):
        self._pattern, self._complex = pattern, complex_
        self._idle: list = []
        self._lock = threading.Lock()

    def fresh(self, data=None):
        """A new nbklu solver of the pattern: analysed, factored with ``data`` (default the magnitudes)."""
        nbklu = _nbklu()
        mag, ind, ptr = _magnitudes(self._pattern)
        # singular_as_error: a zero pivot raises (nbklu 0.3.0's default only warns, and a solve with
        # such factors crashed the process, 2026-11-27)
        kls = (nbklu.KLUSolver64Complex if self._complex else nbklu.KLUSolver64Real)(singular_as_error=True)
        kls.analyze(ptr.size - 1, ptr.astype(np.int64), ind.astype(np.int64))
        kls.factor(np.asarray(mag if data is None else data, dtype=complex if self._complex else float))
        return kls

    def take(self):
        with self._lock:
            if self._idle:
                return self._idle.pop()
        return self.fresh()

    def give(self, kls):
        with self._lock:
            self._idle.append(kls)


def klu_pool(pattern, complex_: bool) -> _KLUPool:
    """The pool of nbklu solvers of the pattern for real or complex values (made once per pattern and type).

    Every pooled solver holds KLU's symbolic analysis of the pattern and the pivot order of one
    factorization of the pattern's magnitudes :math:`|m| + |d| + |k| + |g|` (deterministic: BTF, AMD
    and KLU's pivoting of that matrix depend on the pattern only); :class:`KLULU` refactors new values
    with that order. Cost of a new member: one symbolic analysis and one numeric factorization.
    """
    return _stored(pattern, ("klu", bool(complex_)), lambda: _KLUPool(pattern, complex_))


#: smallest reciprocal pivot growth (KLU's ``rgrowth``) accepted from a refactorization with the
#: reference pivot order; below it the matrix is factored afresh with its own pivoting
KLU_MIN_RGROWTH = 1e-6


class KLULU:
    """KLU factorization (SuiteSparse KLU through ``nbklu``, BSD-3 wrapper) of an equilibrated saddle matrix.

    ``As`` is CSC with the pattern's structure. First a refactorization with the pattern's reference
    pivot order (:func:`klu_pool`: no pivot search, about half a factorization); its reciprocal pivot
    growth is checked (``rgrowth`` >= :data:`KLU_MIN_RGROWTH`) and, where it is too small or a pivot
    vanishes, the matrix is factored afresh with KLU's own pivoting (``fresh``; ``refactored``
    False). The reference order makes the factors depend on the values only, never on which shift
    was factored before. ``solve(b, trans)`` as SuperLU's; the backward-error check of
    :class:`~morsuite.linalg.saddle_lu.SaddleLU` follows every solve. KLU holds the GIL (one solver
    thread, :func:`morsuite.reducers.irka.shift_solves.default_threads`).
    """

    def __init__(self, As, pattern):
        nbklu = _nbklu()
        self.dtype = np.complex128 if np.iscomplexobj(As.data) else np.float64
        self.shape = As.shape
        self._pool = klu_pool(pattern, self.dtype == np.complex128)
        data = np.asarray(As.data, dtype=self.dtype)
        kls, self.refactored, self.rgrowth = None, True, 0.0
        try:
            kls = self._pool.take()
            kls.refactor(data)
            self.rgrowth = float(kls.rgrowth(data))
        except nbklu.KLUException:  # a zero pivot (magnitudes or reference order): the member is dropped
            kls = None
        if not self.rgrowth >= KLU_MIN_RGROWTH:  # the reference pivots do not suit these values
            if kls is not None:  # its pivot order is unchanged (a refactorization keeps it)
                self._pool.give(kls)
            try:
                kls = self._pool.fresh(data)
            except nbklu.KLUException as exc:
                raise SingularShiftError(f"KLU: the matrix is singular ({exc!r})") from exc
            self.refactored = False
        self._kls = kls
        self.nnz = int(As.nnz)  # nbklu does not report its factors' size cheaply: the matrix's (a lower bound)

    def __reduce__(self):
        raise TypeError("a KLU factorization is a handle of this process; it cannot be pickled")

    def __del__(self):
        kls = getattr(self, "_kls", None)
        if kls is not None and self.refactored:  # its pivot order is still the reference one
            self._pool.give(kls)
            self._kls = None

    def solve(self, b, trans: str = "N"):
        """Solve ``A x = b`` (``trans="N"``) or ``A^T x = b`` (``"T"``); b of shape (N, k) or (N,)."""
        b = np.asarray(b)
        vec = b.ndim == 1
        B = np.array(b.reshape(b.shape[0], -1).T, dtype=self.dtype, order="C")  # nbklu: (nrhs, n) rows
        X = self._kls.solve_(B) if trans == "N" else self._kls.tsolve_(B, 0)
        X = np.asarray(X).reshape(B.shape).T
        return X[:, 0] if vec else X


# -- PARDISO ----------------------------------------------------------------------------------
def _iparm(symmetric: bool = False) -> np.ndarray:
    """PARDISO's parameters (0-based, MKL's C numbering); with ``iparm[0] = 1`` every entry left 0 is 0,
    not MKL's default, hence the explicit pivoting (``iparm[20]``) and factor-size report (``iparm[17]``)."""
    ip = np.zeros(64, dtype=np.int32)
    ip[0] = 1    # iparm given (not defaults)
    ip[1] = 2    # nested dissection (METIS)
    ip[7] = 2    # at most two iterative refinement steps
    ip[9] = 8 if symmetric else 13   # pivot perturbation 1e-8 (symmetric, PARDISO's default) / 1e-13
    ip[10] = 1   # scaling
    ip[12] = 1   # weighted matching (saddle matrices: the defaults give NaN)
    ip[17] = -1  # report the factors' entries (reported only when requested: iparm[17] < 0 on input)
    ip[20] = 1   # symmetric types: Bunch-Kaufman 1 x 1 and 2 x 2 pivots (0, left by iparm[0] = 1: 1 x 1 only)
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
