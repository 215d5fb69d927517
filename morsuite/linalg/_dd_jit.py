r"""The compiled double-double kernels behind :mod:`morsuite.linalg.dd_kernels` (numba, imported on first use).

Every function is module-level and compiled with ``cache=True`` from its own bytecode alone, so a
later process loads the machine code from numba's on-disk cache instead of compiling it again
(about 2 s per process): a function made inside a closure is keyed by its closure's pickle too,
which differs in every process, and its cache only grew (18 entries for one kernel before
2026-12-02; ``docs/design/backends.md``). Imported by :func:`morsuite.linalg.dd_kernels._kernels`
only, so that importing morsuite does not import numba.

``fma`` is LLVM's ``llvm.fma`` intrinsic: a correctly rounded fused multiply-add, in hardware or in
libm. ``two_sum`` is Knuth's TwoSum, ``quick`` Dekker's FastTwoSum (:math:`|a| \ge |b|`), ``add``
and ``mul`` the double-double sum and product of Bailey's QD library (``ieee_add``, ``mul``).
"""

from __future__ import annotations

from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic


@intrinsic
def fma(typingctx, a, b, c):
    """The correctly rounded :math:`ab + c` (``llvm.fma``), for float64 arguments."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        dbl = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [dbl], ir.FunctionType(dbl, [dbl, dbl, dbl]))
        return builder.call(fn, args)
    return sig, codegen


@njit(inline="always")
def two_sum(a, b):
    """``(s, e)`` with :math:`s = \\mathrm{fl}(a + b)` and :math:`s + e = a + b` exactly."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


@njit(inline="always")
def quick(a, b):
    """``two_sum`` for :math:`|a| \\ge |b|` (three flops)."""
    s = a + b
    return s, b - (s - a)


@njit(inline="always")
def add(ah, al, bh, bl):
    """The double-double sum :math:`(a_h + a_l) + (b_h + b_l)`."""
    s, e = two_sum(ah, bh)
    t, f = two_sum(al, bl)
    s, e = quick(s, e + t)
    return quick(s, e + f)


@njit(inline="always")
def mul(ah, al, bh, bl):
    """The double-double product :math:`(a_h + a_l)(b_h + b_l)`."""
    p = ah * bh
    return quick(p, fma(ah, bh, -p) + (ah * bl + al * bh))


@njit(cache=True, nogil=True)
def entries(m, d, k, g, ar, ai, sr_h, sr_l, si_h, si_l, imag):
    """:func:`morsuite.linalg.dd_kernels.entries`' loop: writes the parts of :math:`((a^2) m + a d) + k + g`."""
    p, q = ar * ar, ai * ai
    a2r_h, a2r_l = add(p, fma(ar, ar, -p), -q, -fma(ai, ai, -q))
    p = ar * ai
    a2i_h, a2i_l = 2.0 * p, 2.0 * fma(ar, ai, -p)  # exact: a doubling
    for t in range(m.size):
        h, l = mul(a2r_h, a2r_l, m[t], 0.0)
        p = ar * d[t]
        h, l = add(h, l, p, fma(ar, d[t], -p))
        h, l = add(h, l, k[t], 0.0)
        sr_h[t], sr_l[t] = add(h, l, g[t], 0.0)
        if imag:
            h, l = mul(a2i_h, a2i_l, m[t], 0.0)
            p = ai * d[t]
            si_h[t], si_l[t] = add(h, l, p, fma(ai, d[t], -p))


@njit(cache=True, nogil=True)
def product(ptr, idx, order, sr_h, sr_l, si_h, si_l, xr_h, xr_l, xi_h, xi_l, yr_h, yr_l, yi_h, yi_l,
            s_imag, x_imag, br_h, br_l, bi_h, bi_l, sign):
    """:func:`morsuite.linalg.dd_kernels.product`' loop: writes :math:`y = b + \\mathrm{sign}\\,Sx` row by row."""
    # an empty b part is zero, an empty low part of x or b is zero
    x_lo, b_lo = xr_l.size > 0, br_l.size > 0
    for row in range(ptr.size - 1):
        rh = rl = ih = il = 0.0
        if br_h.size:
            rh, rl = br_h[row], (br_l[row] if b_lo else 0.0)
        if bi_h.size:
            ih, il = bi_h[row], (bi_l[row] if b_lo else 0.0)
        for u in range(ptr[row], ptr[row + 1]):
            t, j = order[u], idx[u]
            xrh, xrl = xr_h[j], (xr_l[j] if x_lo else 0.0)
            h, l = mul(sr_h[t], sr_l[t], xrh, xrl)
            rh, rl = add(rh, rl, sign * h, sign * l)
            if x_imag:
                xih, xil = xi_h[j], (xi_l[j] if x_lo else 0.0)
                h, l = mul(sr_h[t], sr_l[t], xih, xil)
                ih, il = add(ih, il, sign * h, sign * l)
            if s_imag:
                h, l = mul(si_h[t], si_l[t], xrh, xrl)
                ih, il = add(ih, il, sign * h, sign * l)
                if x_imag:
                    h, l = mul(si_h[t], si_l[t], xih, xil)
                    rh, rl = add(rh, rl, -sign * h, -sign * l)
        yr_h[row], yr_l[row] = rh, rl
        if yi_h.size:
            yi_h[row], yi_l[row] = ih, il


@njit(inline="always")
def dot2(s, c, a, x, sign):
    """One step of Ogita, Rump and Oishi's Dot2: ``(s', c')`` with :math:`s' + c'` carrying
    :math:`s + \\mathrm{sign}\\,ax`, the product exact (TwoProd by ``fma``), the sum by ``two_sum``, both
    errors into ``c``."""
    p = a * x
    s, q = two_sum(s, sign * p)
    return s, c + (q + sign * fma(a, x, -p))


@njit(cache=True, nogil=True)
def residual(ptr, idx, order, ar, ai, xr, xi, br, bi, rr, ri, a_imag, x_imag, b_imag):
    """``r = b - A x`` per row by Dot2 (:func:`morsuite.linalg.dd_kernels.residual`), the errors summed in
    double and added once."""
    for row in range(ptr.size - 1):
        sr, cr = br[row], 0.0
        si, ci = (bi[row] if b_imag else 0.0), 0.0
        for u in range(ptr[row], ptr[row + 1]):
            t, j = order[u], idx[u]
            sr, cr = dot2(sr, cr, ar[t], xr[j], -1.0)
            if x_imag:
                si, ci = dot2(si, ci, ar[t], xi[j], -1.0)
            if a_imag:
                si, ci = dot2(si, ci, ai[t], xr[j], -1.0)
                if x_imag:
                    sr, cr = dot2(sr, cr, ai[t], xi[j], 1.0)
        rr[row] = sr + cr
        ri[row] = si + ci
