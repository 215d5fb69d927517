r"""The refinement residual's product :math:`S(a)x` in double-double arithmetic (compiled, numba).

Iterative refinement (:mod:`morsuite.linalg.refine`) needs :math:`S(a)x` for a saddle matrix
:math:`S(a) = a^2 M + a D + K + [0, G^T; G, 0]` to more than double precision: the residual
:math:`b - S(a)x` of an LU solution is about :math:`\varepsilon\,|S||x|`, so a product rounded at
:math:`\varepsilon` keeps none of its digits. numpy's ``np.longdouble`` (x87, 64-bit significand)
gives :math:`2^{-64}` per operation at about 70 ns per entry on the TCOM at :math:`n_1 = 10^6`
(3e6 entries: 0.24 s for the entries of :math:`S(a)` at a new shift, 0.19-0.54 s per product;
a script, 2026-11-28, load 2), which made refinement three quarters of a refined shift's cost
there (``docs/design/irka.md``, with ``morsuite bench refine-dd``). Here each number is an unevaluated sum ``hi + lo`` of two doubles
(double-double, about :math:`2^{-104}` per operation): products by the exact ``TwoProd``
(:math:`p = ab`, :math:`e = \mathrm{fma}(a, b, -p)`; LLVM's ``llvm.fma`` intrinsic, a correctly
rounded fused multiply-add in hardware or, on a CPU without one, in libm), sums by Knuth's
``TwoSum`` (Bailey's QD library's ``ieee_add``; no fast-math, so that no rounding is reassociated
away).

:func:`entries` forms :math:`S(a)`'s entries on the solver's pattern in double-double, once per
shift: :math:`((a^2) m + a d) + k + g` with :math:`a^2` itself in double-double, real and
imaginary parts apart. :func:`product` sums :math:`\sum_q S_q x_{j(q)}` per row (or column, for
:math:`S^T`) in double-double from a double-double :math:`x`. Both run with the GIL released.

Cost: :func:`entries` about 30 flops per entry, :func:`product` about 90 per complex entry; on the
TCOM at :math:`n_1 = 10^6` 0.04-0.05 s and 0.08-0.12 s (against 0.24 s and 0.19-0.54 s in long
double, the same script). Accuracy: each row's sum carries an error of a few
:math:`2^{-104} \sum_q |S_q||x_{j(q)}|` (tested against exact rational arithmetic), far below long
double's :math:`2^{-64}` per operation. Entries beyond :math:`10^{300}` in magnitude are not
supported (``TwoSum``'s intermediate sums would overflow); saddle matrices of mechanical models are
nowhere near.
"""

from __future__ import annotations

import numpy as np

from . import kernels

__all__ = ["entries", "product", "residual"]


def _kernels():
    """The compiled module :mod:`morsuite.linalg._dd_jit` (imported, so compiled or loaded from numba's cache,
    on first use)."""
    if not kernels.available():  # pragma: no cover - the callers check kernels.available() first
        raise RuntimeError("dd_kernels needs numba")
    from . import _dd_jit
    return _dd_jit


def entries(parts, a) -> tuple:
    r"""The entries of :math:`S(a)` on a pattern, in double-double: ``(sr_h, sr_l, si_h, si_l)``.

    Parameters
    ----------
    parts : tuple of four float64 arrays
        The coefficients of :math:`M, D, K` and the constraint blocks on the pattern (``m, d, k, g``;
        the pattern's order, any).
    a : complex
        The shift.

    Returns
    -------
    tuple
        Real part (hi, lo) and imaginary part (hi, lo; None for a real shift) of
        :math:`((a^2) m + a d) + k + g`, in the order of ``parts``. Cost: about 30 flops per entry.
    """
    m, d, k, g = (np.ascontiguousarray(p, dtype=float) for p in parts)
    a = complex(a)
    imag = a.imag != 0
    sr_h, sr_l = np.empty(m.size), np.empty(m.size)
    si_h, si_l = (np.empty(m.size), np.empty(m.size)) if imag else (np.empty(0), np.empty(0))
    _kernels().entries(m, d, k, g, a.real, a.imag, sr_h, sr_l, si_h, si_l, imag)
    return sr_h, sr_l, (si_h if imag else None), (si_l if imag else None)


def product(structure, data, x, b=None) -> tuple:
    r"""Row sums :math:`y_i = \sum_{u} S_{o(u)} x_{j(u)}` over a segment structure, in double-double;
    with ``b``, the residual :math:`b - y` instead.

    Parameters
    ----------
    structure : tuple (ptr, idx, order)
        int64 arrays: row i's terms are ``u`` in ``ptr[i]:ptr[i+1]``, with entry ``order[u]`` of
        ``data`` and column ``idx[u]`` of x (CSR order of S for :math:`Sx`, CSC order for :math:`S^Tx`).
    data : tuple
        :func:`entries`' result.
    x : tuple (xr_h, xr_l, xi_h, xi_l)
        float64 arrays, x = (xr_h + xr_l) + i (xi_h + xi_l); ``xi_h`` None for a real x; the low
        parts may be empty arrays (both, for a double x).
    b : tuple (br_h, br_l, bi_h, bi_l) or None
        The same for b (``bi_h`` None for a real b); None (default): the product alone.

    Returns
    -------
    tuple (yr_h, yr_l, yi_h, yi_l)
        The product (or the residual), ``yi_*`` None where S(a), x and b are real. ``yr_h`` is the
        double nearest to the double-double result (its sum is renormalised). Cost: about 90 flops
        per entry of S for complex S and x, a quarter of that for real ones.
    """
    ptr, idx, order = structure
    sr_h, sr_l, si_h, si_l = data
    xr_h, xr_l, xi_h, xi_l = x
    br_h, br_l, bi_h, bi_l = b if b is not None else (None, None, None, None)
    empty = np.empty(0)
    s_imag, x_imag = si_h is not None, xi_h is not None
    imag = s_imag or x_imag or bi_h is not None
    n = ptr.size - 1
    yr_h, yr_l = np.empty(n), np.empty(n)
    yi_h, yi_l = (np.empty(n), np.empty(n)) if imag else (empty, empty)

    def arg(v):
        return empty if v is None else v

    _kernels().product(ptr, idx, order, sr_h, sr_l, arg(si_h), arg(si_l), xr_h, xr_l, arg(xi_h), arg(xi_l),
                          yr_h, yr_l, yi_h, yi_l, s_imag, x_imag, arg(br_h), arg(br_l), arg(bi_h), arg(bi_l),
                          1.0 if b is None else -1.0)
    return yr_h, yr_l, (yi_h if imag else None), (yi_l if imag else None)


def residual(structure, a, x, b) -> np.ndarray:
    r"""The residual :math:`b - Ax` of a matrix of doubles and vectors of doubles, each row summed by
    Ogita, Rump and Oishi's Dot2 (exact products by ``TwoProd``, the sum by ``TwoSum``, the errors
    added once) and rounded to double: as if computed in twice the working precision,
    :math:`|\hat r_i - r_i| \le u|r_i| + \gamma_{2k}^2(|b_i| + \sum_q|a_q||x_{j(q)}|)` for k terms
    (Ogita, Rump, Oishi, SIAM J. Sci. Comput. 26 (2005), Prop. 5.5).

    Parameters
    ----------
    structure : tuple (ptr, idx, order)
        As in :func:`product`.
    a : ndarray or tuple
        The matrix's entries (float64 or complex128), in the order ``order`` indexes, or their real and
        imaginary parts as contiguous float64 arrays ``(ar, ai)`` (``ai`` None for a real matrix).
    x, b : ndarray
        1-D, float64 or complex128.

    Returns
    -------
    ndarray
        ``b - A x``, complex where anything is. Cost: about 10 flops per real term (a third of
        :func:`product`'s double-double arithmetic, which takes double-double inputs).
    """
    ptr, idx, order = structure
    empty = np.empty(0)
    if isinstance(a, tuple):
        ar, ai = a
        a_imag = ai is not None
        ai = empty if ai is None else ai
    else:
        a_imag = np.iscomplexobj(a)
        ar = np.ascontiguousarray(a.real, dtype=float)
        ai = np.ascontiguousarray(a.imag, dtype=float) if a_imag else empty
    x_imag, b_imag = np.iscomplexobj(x), np.iscomplexobj(b)
    xr = np.ascontiguousarray(x.real, dtype=float)
    xi = np.ascontiguousarray(x.imag, dtype=float) if x_imag else empty
    br = np.ascontiguousarray(b.real, dtype=float)
    bi = np.ascontiguousarray(b.imag, dtype=float) if b_imag else empty
    n = ptr.size - 1
    rr, ri = np.empty(n), np.empty(n)
    _kernels().residual(ptr, idx, order, ar, ai, xr, xi, br, bi, rr, ri, a_imag, x_imag, b_imag)
    return rr + 1j * ri if (a_imag or x_imag or b_imag) else rr
