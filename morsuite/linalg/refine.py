r"""Iterative refinement of saddle-point solves with a residual in extended precision.

For the saddle-point matrix

.. math::

    S(a) = \begin{bmatrix} a^2 M + a D + K & G^T \\ G & 0 \end{bmatrix}

and an LU of :math:`S(a)` (:class:`~morsuite.linalg.saddle.SaddleLU`),
:func:`refined_solve` computes :math:`x_0 = S(a)^{-1} [f; 0]` (or with
:math:`S(a)^T`) and then ``steps`` times

.. math::

    r_j = [f; 0] - S(a) x_j \ \text{(in extended precision)}, \qquad
    x_{j+1} = x_j + S(a)^{-1} r_j \ \text{(the same LU)}.

A residual formed in working precision does not reduce the forward error of
the LU's solution; one formed in ``np.longdouble`` does (numbers in
``docs/design/irka.md``). Cost per step: one sparse product with :math:`S(a)`
in the refinement precision and one pair of triangular solves; no
factorization.

:class:`SaddleOperator` applies :math:`S(a)` or :math:`S(a)^T` in that
precision on the fixed sparsity pattern of a
:class:`~morsuite.linalg.saddle.SaddlePointSolver` (scipy.sparse has no long
double): the entries of :math:`S(a)` are formed once per shift, the product is
a gather, a multiply and a segmented sum.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SaddleOperator", "refined_solve"]


class SaddleOperator:
    """S(a) x and S(a)^T x in working or extended precision on a solver's fixed pattern.

    Parameters
    ----------
    pattern : dict
        ``SaddlePointSolver.pattern``: the coefficient arrays ``_m, _d, _k, _g`` of
        M, D, K and the G blocks on the pattern (CSC order), its row and column
        indices ``_rows, _cols``, pointers ``_rowptr, _indptr`` and the CSC -> CSR
        permutation ``_csr_perm``.

    Notes
    -----
    ``cache`` holds the pattern's coefficients in the precision last used, the CSR and
    CSC segment structure, and the entries of S(a) for the shift last used (both
    solves at a shift share them).
    """

    def __init__(self, pattern):
        self.pattern = pattern
        self.cache = {}

    def at(self, a, trans, ext):
        """(xr, xi) -> S(a) x (``trans``: S(a)^T x) in the refinement precision, one sparse product.

        x = xr + i xi is held as two real arrays (xi None: a real vector), and so is the
        result; ``ext``: np.longdouble, else float. The real operations and their order are
        those of numpy's complex arithmetic on the complex entries, so the result is that of
        the complex product to a few long-double ulps (tested; bit for bit where numpy's complex
        multiply uses no fused multiply-add); real vectors of a real shift stay real."""
        cache = self.cache
        P = self.pattern
        ft = np.longdouble if ext else float
        if cache.get("ext") is not ext:  # the pattern's entries in this precision, its CSR view: once
            perm = P["_csr_perm"]
            rowptr, colptr = np.asarray(P["_rowptr"]), np.asarray(P["_indptr"])
            rows_ne, cols_ne = np.flatnonzero(np.diff(rowptr) > 0), np.flatnonzero(np.diff(colptr) > 0)
            cache.clear()
            cache.update(ext=ext, parts=tuple(P[k].astype(ft) for k in ("_m", "_d", "_k", "_g")), perm=perm,
                         structure={False: (P["_cols"][perm], rowptr[rows_ne], rows_ne),  # row sums (CSR)
                                    True: (P["_rows"], colptr[cols_ne], cols_ne)})  # column sums (CSC)
        if cache.get("a") != complex(a):  # the entries of S(a): once per shift, for both solves
            m, d, k, g = cache["parts"]
            ar, ai = ft(complex(a).real), ft(complex(a).imag)
            # (a a) m + a d + k + g, with a a = (ar ar - ai ai) + i (ar ai + ai ar)
            dre = (((ar * ar - ai * ai) * m + ar * d) + k) + g
            dim = (ar * ai + ai * ar) * m + ai * d if ai != 0 else None
            perm = cache["perm"]
            cache.update(a=complex(a), data={True: (dre, dim),
                                             False: (dre[perm], None if dim is None else dim[perm])})
        dre, dim = cache["data"][bool(trans)]
        idx, starts, nonempty = cache["structure"][bool(trans)]

        def segsum(v, n):
            y = np.zeros(n, dtype=ft)
            y[nonempty] = np.add.reduceat(v, starts)
            return y

        def apply(xr, xi=None):
            n = xr.shape[0]
            gr = xr[idx]
            if xi is None:
                return segsum(dre * gr, n), (None if dim is None else segsum(dim * gr, n))
            gi = xi[idx]
            if dim is None:
                return segsum(dre * gr, n), segsum(dre * gi, n)
            return segsum(dre * gr - dim * gi, n), segsum(dre * gi + dim * gr, n)

        return apply


def refined_solve(lu, rhs, trans, a, operator: SaddleOperator, *, steps: int, ext: bool):
    """x of S(a) [x; z] = [rhs; 0] (``trans``: S(a)^T), refined ``steps`` times with the same LU.

    Parameters
    ----------
    lu : SaddleLU
        The LU of S(a).
    rhs : ndarray, shape (n1,)
        The first block of the right-hand side (the second is zero).
    trans : bool
    a : complex
        The shift of ``lu``.
    operator : SaddleOperator
        S(a) on the pattern of the solver that made ``lu``.
    steps : int
        Refinement steps (>= 1).
    ext : bool
        Residual in np.longdouble (equals float where longdouble is double), else float.

    Returns
    -------
    ndarray, shape (n1,), complex
        The refined first block x (the multiplier z is dropped).
    """
    x = lu.solve(rhs, trans=trans, full=True).reshape(-1)
    ft = np.longdouble if ext else float
    apply = operator.at(a, trans, ext)
    # real and imaginary parts held apart (see SaddleOperator.at: the same bits, faster)
    b = np.asarray(rhs).reshape(-1)
    n1 = lu.n1
    cplx = np.iscomplexobj(x) or np.iscomplexobj(b) or complex(a).imag != 0
    br = np.zeros(x.size, dtype=ft)
    br[:n1] = b.real
    bi = None
    if cplx:
        bi = np.zeros(x.size, dtype=ft)
        bi[:n1] = b.imag
    xr, xi = x.real.astype(ft), (x.imag.astype(ft) if cplx else None)
    for _ in range(steps):
        yr, yi = apply(xr, xi)
        r = (br - yr).astype(float)
        if cplx:
            r = r + 1j * (bi - yi).astype(float)
        # the correction needs no accuracy check of its own: the refined solution is judged
        d = lu._raw_solve(r[:, None], trans)[:, 0]
        xr = xr + d.real.astype(ft)
        if cplx:
            xi = xi + d.imag.astype(ft)
    out = xr[:n1].astype(float)
    return out + 1j * xi[:n1].astype(float) if cplx else out.astype(complex)
