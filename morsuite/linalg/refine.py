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
double): the entries of :math:`S(a)` are formed once per shift. The extended
product is computed in double-double by compiled kernels
(:mod:`morsuite.linalg.dd_kernels`, about 2^-104 per operation, five times faster
than numpy's long double on the TCOM at n1 = 1e6) and handed back in
``np.longdouble``; without numba, by numpy in ``np.longdouble`` (a gather, a
multiply and a segmented sum).
"""

from __future__ import annotations

import numpy as np

from . import dd_kernels, kernels

__all__ = ["SaddleOperator", "refined_solve", "refine_columns", "refined_unit"]

EPS = np.finfo(float).eps
EPS_LD = float(np.finfo(np.longdouble).eps)


def refined_unit(rho: float, steps: int) -> float:
    r"""Estimated relative error of a solution after ``steps`` refinement steps.

    ``rho`` is the relative size of the first correction, i.e. the LU
    solution's own error (about :math:`\kappa\varepsilon`). Each step
    multiplies the error by about :math:`\rho` and cannot go below the
    long-double residual's :math:`\varepsilon_{ld}\kappa \approx
    \varepsilon_{ld}\rho/\varepsilon`; factor 4 for margin. Without
    refinement: :math:`16\varepsilon` (the LU's error is then unknown).
    """
    if steps <= 0:
        return 16.0 * EPS
    return 4.0 * (rho ** (steps + 1) + EPS_LD * max(1.0, rho / EPS))


class SaddleOperator:
    """S(a) x and S(a)^T x in working or extended precision on a solver's fixed pattern.

    Parameters
    ----------
    pattern : dict
        ``SaddlePointSolver.pattern``: the coefficient arrays ``_m, _d, _k, _g`` of
        M, D, K and the G blocks on the pattern (CSC order), its row and column
        indices ``_rows, _cols``, pointers ``_rowptr, _indptr`` and the CSC -> CSR
        permutation ``_csr_perm``.
    double_double : bool or None
        The extended product in double-double (:mod:`~morsuite.linalg.dd_kernels`) or in
        numpy's ``np.longdouble``; None (default): double-double where numba is available.

    Notes
    -----
    ``cache`` holds the pattern's coefficients in the precision last used, the CSR and
    CSC segment structure, and the entries of S(a) for the shift last used (both
    solves at a shift share them).
    """

    def __init__(self, pattern, double_double: bool | None = None):
        self.pattern = pattern
        self.cache = {}
        #: the extended product in double-double (None: where numba is available)
        self.double_double = kernels.available() if double_double is None else bool(double_double)

    def at(self, a, trans, ext):
        """(xr, xi) -> S(a) x (``trans``: S(a)^T x) in the refinement precision, one sparse product;
        its attribute ``residual(br, bi, xr, xi)`` gives b - S(a) x rounded to double (complex
        where any part is; ``bi``, ``xi`` None for real ones), formed in the same precision.

        x = xr + i xi is held as two real arrays (xi None: a real vector), and so is the
        result; ``ext``: np.longdouble, else float. The real operations and their order are
        those of numpy's complex arithmetic on the complex entries, so the result is that of
        the complex product to a few long-double ulps (tested; bit for bit where numpy's complex
        multiply uses no fused multiply-add); real vectors of a real shift stay real. With numba
        (:func:`~morsuite.linalg.kernels.available`) the extended product is the double-double one of
        :mod:`~morsuite.linalg.dd_kernels` instead, rounded to ``np.longdouble`` once per entry of the
        result (more accurate than the long double sums: tested against exact rational arithmetic)."""
        if ext and self.double_double:
            return self._at_dd(a, trans)
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
            cache.update(a=complex(a), data={True: (dre, dim)})
        if bool(trans) not in cache["data"]:  # the CSR order of the entries, made when first needed
            perm = cache["perm"]
            dre, dim = cache["data"][True]
            cache["data"][False] = (dre[perm], None if dim is None else dim[perm])
        dre, dim = cache["data"][bool(trans)]
        idx, starts, nonempty = cache["structure"][bool(trans)]

        def segsum(v, n):
            if nonempty.size == n:  # every row (column) has an entry
                return np.add.reduceat(v, starts)
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

        def residual(br, bi, xr, xi=None):
            yr, yi = apply(xr, xi)
            r = (br - yr).astype(float)
            if bi is None and yi is None:
                return r
            return r + 1j * ((0 if bi is None else bi) - (0 if yi is None else yi)).astype(float)

        apply.residual = residual
        return apply

    def _at_dd(self, a, trans):
        """:meth:`at` in double-double (:mod:`~morsuite.linalg.dd_kernels`): the same contract."""
        cache, P = self.cache, self.pattern
        if cache.get("ext") != "dd":  # the pattern's segment structures, in int64: once
            perm = np.asarray(P["_csr_perm"], dtype=np.int64)
            cache.clear()
            cache.update(ext="dd", parts=tuple(P[k] for k in ("_m", "_d", "_k", "_g")), structure={
                False: (np.asarray(P["_rowptr"], dtype=np.int64), np.asarray(P["_cols"], dtype=np.int64)[perm], perm),
                True: (np.asarray(P["_indptr"], dtype=np.int64), np.asarray(P["_rows"], dtype=np.int64),
                       np.arange(perm.size, dtype=np.int64))})
        if cache.get("a") != complex(a):  # the entries of S(a): once per shift, for both orientations
            cache.update(a=complex(a), data=dd_kernels.entries(cache["parts"], a))
        structure, data = cache["structure"][bool(trans)], cache["data"]

        def apply(xr, xi=None):
            x = _split(xr) + ((None, None) if xi is None else _split(xi))
            yr_h, yr_l, yi_h, yi_l = dd_kernels.product(structure, data, x)
            return _join(yr_h, yr_l), (None if yi_h is None else _join(yi_h, yi_l))

        def residual(br, bi, xr, xi=None):
            x = _split(xr) + ((None, None) if xi is None else _split(xi))
            b = _split(br) + ((None, None) if bi is None else _split(bi))
            rr, _, ri, _ = dd_kernels.product(structure, data, x, b)  # rounded once, from double-double
            return rr if ri is None else rr + 1j * ri

        apply.residual = residual
        return apply


_NO_LOW = np.empty(0)  # the low part of a double: zero


def _split(v) -> tuple:
    """(hi, lo) float64 arrays with hi + lo = v exactly (v in long double; a double's lo is empty)."""
    v = np.asarray(v)
    hi = np.ascontiguousarray(v, dtype=float)
    return hi, ((v - hi).astype(float) if v.dtype == np.longdouble and v.dtype != hi.dtype else _NO_LOW)


def _join(hi, lo):
    """hi + lo rounded once to ``np.longdouble``."""
    out = hi.astype(np.longdouble)
    out += lo
    return out


def refine_columns(lu, rhs, x, trans, a, operator: SaddleOperator, *, steps: int, ext: bool = True,
                   tol: float | None = None, max_steps: int = 6, record: dict | None = None):
    r"""``steps`` refinements of the LU's solution of :math:`S(a)[x; z] = [\mathrm{rhs}; 0]` (``trans``: :math:`S(a)^T`),
    and with ``tol`` more until the estimated error is below it.

    Parameters
    ----------
    lu : SaddleLU
        The LU of S(a).
    rhs : ndarray, shape (n1, k) or (n1,)
        The first block of the right-hand side (the second is zero).
    x : ndarray, shape (n1 + n2, k) or (n1 + n2,)
        The LU's solution (``lu.solve(rhs, trans=trans, full=True)``).
    trans : bool
    a : complex
        The shift of ``lu``.
    operator : SaddleOperator
        S(a) on the pattern of the solver that made ``lu``.
    steps : int
        Refinement steps (>= 1), all made.
    ext : bool
        Residual in np.longdouble (equals float where longdouble is double), else float.
    tol : float, optional
        After ``steps``, continue (at most ``max_steps`` in all) while a column's estimated relative
        error :math:`\rho_j c` is above ``tol``: :math:`\rho_j` its last correction relative to its
        first block (max-norm), :math:`c` the contraction per step, the largest of the LU solution's
        error :math:`\rho_1`, ``lu.contraction`` (what the LU's own refinement measured,
        :class:`~morsuite.linalg.saddle_lu.SaddleLU`) and the ratio of the last two corrections; a
        column stops when that ratio exceeds 1/2 (a correction that grew is not applied). None
        (default): exactly ``steps``.
    max_steps : int
        Most steps with ``tol`` (6).
    record : dict, optional
        Filled with ``steps`` (the most a column took) and ``estimate`` (the largest estimated
        relative error after them).

    Returns
    -------
    (xr, xi, rho)
        Real and imaginary parts of the refined whole solution, (n1 + n2, k), in the
        refinement precision (``xi`` None when matrix, shift and right-hand side are
        real); ``rho``, the largest first correction relative to its column's first
        block (max-norm): the LU solution's forward error, the argument of
        :func:`refined_unit`.

    Notes
    -----
    Cost per step and column: one product with :math:`S(a)` in the refinement
    precision and one pair of triangular solves; no factorization.
    """
    ft = np.longdouble if ext else float
    x = np.asarray(x)
    b = np.asarray(rhs)
    vector = x.ndim == 1
    if vector:
        x, b = x[:, None], b.reshape(-1, 1)
    n1 = lu.n1
    cplx = np.iscomplexobj(x) or np.iscomplexobj(b) or complex(a).imag != 0
    apply = operator.at(a, trans, ext)
    xr = x.real.astype(ft)
    xi = x.imag.astype(ft) if cplx else None
    rho = 0.0
    most = steps if tol is None else max(steps, int(max_steps))
    taken, estimate = 0, 0.0
    for j in range(x.shape[1]):
        # real and imaginary parts held apart (see SaddleOperator.at: the same bits, faster); b and the
        # LU's solution are doubles (their long double copies would give the same residual, slower)
        br = np.zeros(x.shape[0])
        br[:n1] = b[:, j].real
        bi = None
        if cplx:
            bi = np.zeros(x.shape[0])
            bi[:n1] = np.imag(b[:, j])
        size = float(np.max(np.abs(x[:n1, j]))) if n1 else 0.0
        first = prev = est = 0.0
        for step in range(most):
            if step == 0:  # the LU's solution, in double
                cur = (x[:, j].real, x[:, j].imag if cplx else None)
            else:
                cur = (xr[:, j], xi[:, j] if cplx else None)
            r = apply.residual(br, bi, *cur)  # b - S x, rounded to double once
            # the correction needs no accuracy check of its own: the refined solution is judged
            d = lu._raw_solve(r[:, None], trans)[:, 0]
            rel = float(np.max(np.abs(d[:n1]))) / size if size > 0 else 0.0
            if step == 0:
                first = rel
                rho = max(rho, rel)
            ratio = rel / prev if prev > 0 else 0.0
            if step >= steps and ratio > 1.0:  # a correction that grew: not applied
                taken = max(taken, step)
                break
            xr[:, j] += d.real.astype(ft)
            if cplx:
                xi[:, j] += d.imag.astype(ft)
            prev = rel
            est = rel * max(first, getattr(lu, "contraction", 0.0), ratio)
            if step + 1 >= steps and (tol is None or est <= tol or ratio > 0.5):
                taken = max(taken, step + 1)
                break
        else:
            taken = max(taken, most)
        estimate = max(estimate, est)
    if record is not None:
        record.update(steps=taken, estimate=estimate)
    if vector:
        xr, xi = xr[:, 0], (xi[:, 0] if cplx else None)
    return xr, xi, rho


def refined_solve(lu, rhs, trans, a, operator: SaddleOperator, *, steps: int, ext: bool):
    """x of S(a) [x; z] = [rhs; 0] (``trans``: S(a)^T), refined ``steps`` times with the same LU.

    Parameters
    ----------
    lu, trans, a, operator, steps, ext
        As in :func:`refine_columns`.
    rhs : ndarray, shape (n1,)
        The first block of the right-hand side (the second is zero).

    Returns
    -------
    ndarray, shape (n1,), complex
        The refined first block x (the multiplier z is dropped), rounded to double.
    """
    x = lu.solve(rhs, trans=trans, full=True).reshape(-1)
    xr, xi, _ = refine_columns(lu, np.asarray(rhs).reshape(-1), x, trans, a, operator, steps=steps, ext=ext)
    n1 = lu.n1
    out = xr[:n1].astype(float)
    return out + 1j * xi[:n1].astype(float) if xi is not None else out.astype(complex)
