r"""Compiled kernels (numba): the narrow-band LU (LAPACK's ``?gbtf2`` / ``?gbtrs`` algorithms) and the
one-pass assembly of the equilibrated saddle matrix.

LAPACK's banded routines are bound, for the half-bandwidths of the chain models
(:math:`k_l = k_u = 2`), by one BLAS call per column rather than by flops: at
n = 2e5, ``zgbtrf`` costs about 40 ms and ``zgbtrs`` with six right-hand sides
about 80 ms for some 1e7 flops (``docs/design/backends.md``, 2026-11-26). The
kernels here are the same algorithms -- Gaussian elimination with partial pivoting
inside the band, the unblocked ``?gbtf2``, and the forward/back substitutions of
``?gbtrs`` for ``A x = b`` and ``A^T x = b`` (plain transpose) -- written as loops
that numba compiles once per dtype (``cache=True``: the compiled code is kept on
disk) and run with the GIL released (``nogil=True``), so that shift-parallel
threads run them concurrently.

Storage is LAPACK's: the factor array is the C-ordered ``(n, 2 k_l + k_u + 1)``
transpose of LAPACK's ``(ldab, n)`` band array, ``ab[j, k_l + k_u + i - j] = A[i, j]``,
so that the factors of either implementation are interchangeable; pivots are
0-based (``piv[j]`` is the row swapped with row j).

Cost: :math:`O(n k_l (k_l + k_u))` for the factorization, :math:`O(n (2 k_l + k_u))`
per right-hand side for a solve; no allocation.

:func:`assemble_scaled` forms the entries of :math:`D (a M + b D + c K + [G^T; G]) D`
and the matrix's 1-norm in one pass over the pattern (numpy needs about ten: the
products, the gathers of the scaling, the absolute values); on the chain models at
n1 = 2e5 the passes are memory-bound (about 4.5 GB/s on one core here). ``numba`` is a default dependency
(BSD-2), imported on first use; where it cannot be imported :func:`available` is False and
:class:`~morsuite.linalg.backends.BandedBorderLU` uses LAPACK's routines instead
(``MORSUITE_BAND_KERNEL=lapack`` forces that, for comparison and tests).
"""

from __future__ import annotations

import math
import os

import numpy as np

__all__ = ["LT_BACKWARD", "L_FORWARD", "UT_FORWARD", "U_BACKWARD", "assemble_scaled", "available", "compiled",
           "dense_pencil", "gbtrf", "gbtrs", "scatter", "sweep", "use_kernels"]

_NUMBA: dict = {}  # "module": numba or None (not importable), imported on first use
_JIT: dict = {}  # python function -> its compiled dispatcher


def available() -> bool:
    """True when numba can be imported (imported on the first call: about 1 s, so that a command that
    factors nothing, e.g. a cached study run, does not pay it)."""
    if "module" not in _NUMBA:
        try:
            import numba
        except Exception:  # pragma: no cover - a missing or broken numba: the numpy/LAPACK paths
            numba = None
        _NUMBA["module"] = numba
    return _NUMBA["module"] is not None


def use_kernels() -> bool:
    """True when the compiled kernels are used: numba importable and ``MORSUITE_BAND_KERNEL`` not ``"lapack"``."""
    return os.environ.get("MORSUITE_BAND_KERNEL", "numba").lower() != "lapack" and available()


def compiled(fn):
    """``numba.njit(nogil=True, cache=True)(fn)``, made once per function (requires :func:`available`).

    ``nogil``: threads run it concurrently; ``cache``: the machine code is kept on disk next to the
    module (or in numba's user cache where that is not writable) and loaded by later processes.
    """
    f = _JIT.get(fn)
    if f is None:
        available()
        f = _JIT[fn] = _NUMBA["module"].njit(nogil=True, cache=True)(fn)
    return f


def _gbtrf(ab, kl, ku, piv, dinv):
    """In-place banded LU with partial pivoting (``?gbtf2``), ``dinv`` the reciprocal pivots (0 where a pivot is 0);
    returns 0 or the 1-based first zero pivot."""
    n = ab.shape[0]
    kv = kl + ku
    info = 0
    ju = 0
    for j in range(n):
        km = min(kl, n - 1 - j)
        # pivot: the entry of largest |re| + |im| in A[j:j+km+1, j] (LAPACK's i?amax)
        jp = 0
        best = -1.0
        for i in range(km + 1):
            v = ab[j, kv + i]
            a = abs(v.real) + abs(v.imag)
            if a > best:
                best = a
                jp = i
        piv[j] = j + jp
        dinv[j] = 0
        if ab[j, kv + jp] == 0:
            if info == 0:
                info = j + 1
            continue
        ju = max(ju, min(j + ku + jp, n - 1))
        if jp != 0:  # swap rows j and j + jp in columns j..ju
            for c in range(j, ju + 1):
                p, q = kv + j - c, kv + j + jp - c
                t = ab[c, p]
                ab[c, p] = ab[c, q]
                ab[c, q] = t
        r = 1.0 / ab[j, kv]
        dinv[j] = r
        if km > 0:
            for i in range(1, km + 1):
                ab[j, kv + i] *= r
            for c in range(j + 1, ju + 1):  # rank-1 update of the trailing band
                a = ab[c, kv + j - c]
                if a != 0:
                    base = kv + j - c
                    for i in range(1, km + 1):
                        ab[c, base + i] -= ab[j, kv + i] * a
    return info


#: the four half-sweeps of a banded solve (``part`` of :func:`sweep`)
L_FORWARD, U_BACKWARD, UT_FORWARD, LT_BACKWARD = 0, 1, 2, 3


def _sweep(ab, kl, ku, piv, dinv, b, part, starts):
    """One half-sweep in place on b (n, k), columns sorted by their first nonzero row ``starts``.

    part 0: b <- L^{-1} P b (row swaps and eliminations); 1: b <- U^{-1} b; 2: b <- U^{-T} b;
    3: b <- P^T L^{-T} b. Parts 0 and 2 skip the rows above each column's first nonzero
    (those rows stay zero: a swap at row j reaches row j + kl at most).
    """
    n = ab.shape[0]
    k = b.shape[1]
    kv = kl + ku
    if part == 0:
        a = 0
        for j in range(max(0, starts[0] - kl) if k else n, n - 1):
            while a < k and starts[a] <= j + kl:
                a += 1
            p = piv[j]
            if p != j:
                for c in range(a):
                    t = b[p, c]
                    b[p, c] = b[j, c]
                    b[j, c] = t
            for i in range(1, min(kl, n - 1 - j) + 1):
                l = ab[j, kv + i]
                for c in range(a):
                    b[j + i, c] -= l * b[j, c]
    elif part == 1:
        for j in range(n - 1, -1, -1):
            d = dinv[j]
            for c in range(k):
                b[j, c] *= d
            for i in range(1, min(kv, j) + 1):
                u = ab[j, kv - i]
                for c in range(k):
                    b[j - i, c] -= u * b[j, c]
    elif part == 2:
        a = 0
        for j in range(starts[0] if k else n, n):
            while a < k and starts[a] <= j:
                a += 1
            for i in range(1, min(kv, j) + 1):
                u = ab[j, kv - i]
                for c in range(a):
                    b[j, c] -= u * b[j - i, c]
            d = dinv[j]
            for c in range(a):
                b[j, c] *= d
    else:
        for j in range(n - 2, -1, -1):
            for i in range(1, min(kl, n - 1 - j) + 1):
                l = ab[j, kv + i]
                for c in range(k):
                    b[j, c] -= l * b[j + i, c]
            p = piv[j]
            if p != j:
                for c in range(k):
                    t = b[p, c]
                    b[p, c] = b[j, c]
                    b[j, c] = t


def _sweep1(ab, kl, ku, piv, dinv, b, part, start):
    """:func:`_sweep` for one right-hand side (b 1-D, first nonzero at ``start``): the scalar recurrences,
    about 2x the (n, 1) loop's speed."""
    n = ab.shape[0]
    kv = kl + ku
    if part == 0:
        for j in range(max(0, start - kl), n - 1):
            p = piv[j]
            if p != j:
                t = b[p]
                b[p] = b[j]
                b[j] = t
            bj = b[j]
            for i in range(1, min(kl, n - 1 - j) + 1):
                b[j + i] -= ab[j, kv + i] * bj
    elif part == 1:
        for j in range(n - 1, -1, -1):
            bj = b[j] * dinv[j]
            b[j] = bj
            for i in range(1, min(kv, j) + 1):
                b[j - i] -= ab[j, kv - i] * bj
    elif part == 2:
        for j in range(start, n):
            bj = b[j]
            for i in range(1, min(kv, j) + 1):
                bj -= ab[j, kv - i] * b[j - i]
            b[j] = bj * dinv[j]
    else:
        for j in range(n - 2, -1, -1):
            bj = b[j]
            for i in range(1, min(kl, n - 1 - j) + 1):
                bj -= ab[j, kv + i] * b[j + i]
            b[j] = bj
            p = piv[j]
            if p != j:
                t = b[p]
                b[p] = b[j]
                b[j] = t


def _scatter(data, sel, pos, out):
    """out.flat[pos[t]] = data[sel[t]] (out zeroed by the caller)."""
    flat = out.reshape(-1)
    for t in range(sel.size):
        flat[pos[t]] = data[sel[t]]


def _assemble(m, d, k, g, rows, cols, indptr, dvec, a, b, c, out):
    """out[i] = (a m_i + b d_i + c k_i + g_i) dvec[rows_i] dvec[cols_i]; returns max over columns of sum |out|."""
    norm = 0.0
    for j in range(indptr.size - 1):
        colsum = 0.0
        for i in range(indptr[j], indptr[j + 1]):
            v = (a * m[i] + b * d[i] + c * k[i] + g[i]) * (dvec[rows[i]] * dvec[cols[i]])
            out[i] = v
            colsum += math.sqrt(v.real * v.real + v.imag * v.imag)  # |v| without hypot's scaling (entries are O(1))
        if colsum > norm:
            norm = colsum
    return norm


def _pencil(K, M, D, s2, s, out):
    n, m = out.shape
    for j in range(m):
        for i in range(n):
            out[i, j] = K[i, j] + s2 * M[i, j] + s * D[i, j]


def dense_pencil(K: np.ndarray, M: np.ndarray, D: np.ndarray, s, out: np.ndarray) -> np.ndarray:
    r"""``out`` :math:`= K + s^2 M + s D` in one pass (dense, Fortran-ordered ``out`` and inputs for
    contiguous access; ``out`` complex, or real for a real ``s``); returns ``out``.

    The explicitly projected IRKA's pencil at each shift: numpy needs three passes over ``out``
    and, blockwise, temporaries (measured 2026-11-26 at k = 1000 on a loaded machine: 25.6 ms
    against 3.6 ms). Cost: one read of each input and one write of ``out``.
    """
    compiled(_pencil)(K, M, D, out.dtype.type(s * s), out.dtype.type(s), out)
    return out


def gbtrf(ab: np.ndarray, kl: int, ku: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Factor the band array ``ab`` (C-ordered ``(n, 2 kl + ku + 1)``, overwritten) in place.

    Returns ``(piv, dinv, info)``: 0-based pivots, the reciprocals of U's diagonal (the
    solves multiply by them; LAPACK divides, so results differ from LAPACK's in the
    last bits) and LAPACK's ``info`` (0, or the 1-based index of the first exactly zero
    pivot; the factorization is then finished but singular). Requires :func:`available`.
    Cost :math:`O(n k_l (k_l + k_u))`.
    """
    if not (ab.flags.c_contiguous and ab.ndim == 2 and ab.shape[1] == 2 * kl + ku + 1):
        raise ValueError(f"ab: a C-ordered (n, 2 kl + ku + 1) array is needed, got shape {ab.shape}")
    piv = np.empty(ab.shape[0], dtype=np.int64)
    dinv = np.empty(ab.shape[0], dtype=ab.dtype)
    info = compiled(_gbtrf)(ab, int(kl), int(ku), piv, dinv)
    return piv, dinv, int(info)


def sweep(ab: np.ndarray, kl: int, ku: int, piv: np.ndarray, dinv: np.ndarray, b: np.ndarray, part: int,
          starts: np.ndarray | None = None) -> np.ndarray:
    r"""One half of a banded solve with factors of :func:`gbtrf`, in place on b (n, k) C-ordered; returns b.

    With :math:`A = \tilde L U` (:math:`\tilde L` holding the row swaps), ``part``:
    :data:`L_FORWARD` :math:`b \leftarrow \tilde L^{-1} b`, :data:`U_BACKWARD`
    :math:`U^{-1} b`, :data:`UT_FORWARD` :math:`U^{-T} b`, :data:`LT_BACKWARD`
    :math:`\tilde L^{-T} b`. ``starts`` (the forward parts): each column's first nonzero
    row, ascending -- the rows above it are skipped (default: all zero). b must have the
    dtype of ``ab``. One right-hand side takes the scalar kernel (about 2x faster per
    column than the (n, k) loop, which is 2-3x faster per column than one call per
    column at k = 6). Cost :math:`O(k_l)` or :math:`O(k_l + k_u)` per row and column.
    """
    if not (b.flags.c_contiguous and b.ndim == 2 and b.dtype == ab.dtype):
        raise ValueError("b: a C-ordered 2-D array of the factors' dtype is needed")
    k = b.shape[1]
    if starts is None:
        starts = np.zeros(k, dtype=np.int64)
    starts = np.asarray(starts, dtype=np.int64)
    if starts.shape != (k,) or (k > 1 and np.any(np.diff(starts) < 0)):
        raise ValueError(f"starts: {k} ascending row indices are needed")
    if k == 1:
        compiled(_sweep1)(ab, int(kl), int(ku), piv, dinv, b[:, 0], int(part), int(starts[0]))
    elif k:
        compiled(_sweep)(ab, int(kl), int(ku), piv, dinv, b, int(part), starts)
    return b


def gbtrs(ab: np.ndarray, kl: int, ku: int, piv: np.ndarray, dinv: np.ndarray, b: np.ndarray,
          trans: bool = False) -> np.ndarray:
    """Solve ``A x = b`` (``A^T x = b`` when ``trans``) with factors of :func:`gbtrf`; b (n, k) C-ordered, overwritten.

    Two :func:`sweep` calls; returns b.
    """
    parts = (UT_FORWARD, LT_BACKWARD) if trans else (L_FORWARD, U_BACKWARD)
    for part in parts:
        sweep(ab, kl, ku, piv, dinv, b, part)
    return b


def assemble_scaled(P: dict, dvec: np.ndarray, a, b, c, real: bool) -> tuple[np.ndarray, float]:
    r"""Entries of the equilibrated saddle matrix on a pattern, and its 1-norm, in one pass.

    ``P``: a pattern dict (``_m, _d, _k, _g`` values, ``_rows, _cols`` the indices into
    ``dvec``, ``_indptr`` its CSC columns); ``dvec``: the symmetric scaling. Returns
    ``(data, norm1)`` with ``data[i] = (a m_i + b d_i + c k_i + g_i) dvec[rows_i] dvec[cols_i]``
    (float when ``real``, the coefficients then taken as real; complex otherwise) and
    ``norm1`` the largest column sum of ``|data|``. Cost: one pass over the entries.
    """
    dt = np.float64 if real else np.complex128
    a, b, c = (dt(x.real) if real else dt(x) for x in (complex(a), complex(b), complex(c)))
    out = np.empty(P["_m"].size, dtype=dt)
    norm = compiled(_assemble)(P["_m"], P["_d"], P["_k"], P["_g"], P["_rows"], P["_cols"], P["_indptr"], dvec,
                         a, b, c, out)
    return out, float(norm)


def scatter(data: np.ndarray, where: tuple, out: np.ndarray) -> np.ndarray:
    """``out.flat[pos] = data[sel]`` for ``where = (sel, pos)`` in one pass (numpy's fancy indexing makes a
    temporary and two passes); out C-contiguous and zeroed where nothing lands. Returns out."""
    sel, pos = where
    if out.flags.c_contiguous and use_kernels():
        compiled(_scatter)(data, sel, pos, out)
    else:
        out.ravel()[pos] = data[sel]
    return out
