r"""References for the stress checks, independent of the solver under test.

The saddle-point matrix at a shift s is

.. math::

    S(s) = \begin{bmatrix} s^2 M + s D + K & G^T \\ G & 0 \end{bmatrix},
    \qquad T(s) = [L, 0]\, S(s)^{-1} [F; 0].

* :func:`reference_transfer`: T(s) (and :math:`T'(s) = -Y^T (2sM + D) X` from the
  transposed solve Y) by a sparse LU of the Ruiz-equilibrated :math:`D_r S D_c`
  (five sweeps of row/column max-norm scaling), without the suite's pivot check;
  also the 1-norm condition estimate :math:`\kappa` of :math:`D_r S D_c`. One sparse
  LU per shift, plus about four solves for the estimate.
* :func:`nullspace_transfer`: the dense formula
  :math:`L N (N^T P(s) N)^{-1} N^T F`, :math:`P(s) = s^2 M + s D + K`,
  N an orthonormal basis of ker G. :math:`O(n_1^3)` per point: small models only.
* :func:`equilibrated_saddle`: a context manager under which the suite's own
  saddle-point solver factors :math:`D_r S D_c` (the prototype of the K1 fix,
  used to attribute silent failures).

Tolerances are relative and scaled by conditioning:
:func:`scaled_tol` gives ``base * max(1, kappa / KAPPA_REF)``; :func:`product_tol`
gives ``base * max(1, kappa_full * kappa_rom / 1e10)`` for a reduced transfer
function built from full-order solves.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["KAPPA_REF", "reference_transfer", "equilibrated_condition", "reference_response", "sigma",
           "scaled_tol", "product_tol", "nullspace_transfer", "equilibrated_saddle"]

#: condition number up to which the base tolerances apply unscaled (eps * 1e8 ~ 1e-8)
KAPPA_REF = 1e8


def _ruiz(row, col, av, n: int, sweeps: int):
    """Ruiz row/column max-norm scaling of the COO magnitudes ``av``: (dr, dc).

    Written independently of the solver's own scaling (morsuite.linalg.saddle),
    which is what these references check.
    """
    dr, dc = np.ones(n), np.ones(n)
    for _ in range(sweeps):
        a = av * dr[row] * dc[col]
        rmax, cmax = np.zeros(n), np.zeros(n)
        np.maximum.at(rmax, row, a)
        np.maximum.at(cmax, col, a)
        rmax[rmax == 0] = 1.0
        cmax[cmax == 0] = 1.0
        dr, dc = dr / np.sqrt(rmax), dc / np.sqrt(cmax)
    return dr, dc


class _EqLU:
    """LU of the Ruiz-equilibrated saddle-point matrix Dr S Dc (no pivot check)."""

    def __init__(self, fom, s, sweeps: int = 5):
        S = sp.coo_matrix(fom.solver.matrix(s))
        n = S.shape[0]
        row, col, val = S.row, S.col, S.data
        dr, dc = _ruiz(row, col, np.abs(val), n, sweeps)
        self.A = sp.csc_matrix((val * dr[row] * dc[col], (row, col)), shape=(n, n))
        self.dr, self.dc, self.n1 = dr, dc, fom.n1
        self.complex = np.iscomplexobj(val)
        try:
            self.lu = spla.splu(self.A)
        except RuntimeError:
            self.lu = None

    def _lu_solve(self, b, trans="N"):
        b = np.asarray(b, dtype=complex)
        if self.complex:
            return self.lu.solve(np.ascontiguousarray(b), trans=trans)
        t = "T" if trans == "H" else trans  # a real matrix: A^H = A^T
        if trans == "H":
            b = np.conj(b)
        x = self.lu.solve(np.ascontiguousarray(b.real), trans=t) + 1j * self.lu.solve(np.ascontiguousarray(b.imag), trans=t)
        return np.conj(x) if trans == "H" else x

    def solve(self, b, trans=False):
        b = np.asarray(b)
        vec = b.ndim == 1
        if vec:
            b = b[:, None]
        if b.shape[0] == self.n1 and self.A.shape[0] > self.n1:
            b = np.vstack([b, np.zeros((self.A.shape[0] - self.n1, b.shape[1]), dtype=b.dtype)])
        if trans:
            y = self.dr[:, None] * self._lu_solve(self.dc[:, None] * b, "T")
        else:
            y = self.dc[:, None] * self._lu_solve(self.dr[:, None] * b)
        y = y[: self.n1]
        return y[:, 0] if vec else y

    def cond(self) -> float:
        """1-norm condition estimate of Dr S Dc (``onenormest``: a few solves with the LU)."""
        if self.lu is None:
            return math.inf
        n = self.A.shape[0]
        op = spla.LinearOperator((n, n), dtype=complex,
                                 matvec=lambda x: self._lu_solve(np.asarray(x).reshape(-1)),
                                 rmatvec=lambda x: self._lu_solve(np.asarray(x).reshape(-1), "H"))
        try:
            inv = spla.onenormest(op)
        except Exception:  # noqa: BLE001 - an estimate only
            return math.inf
        k = float(spla.norm(self.A, 1) * inv)
        return k if np.isfinite(k) else math.inf


def reference_transfer(fom, s, *, derivative: bool = False):
    """T(s) (and T'(s)) from an equilibrated sparse LU, without the suite's pivot check.

    Returns ``(T, dT_or_None, kappa)``; ``kappa`` is the equilibrated 1-norm
    condition estimate at s (inf if the matrix is exactly singular).
    """
    f = _EqLU(fom, s)
    if f.lu is None:
        return None, None, math.inf
    X = f.solve(fom.F)
    T = fom.L @ X
    dT = None
    if derivative:
        Y = f.solve(fom.L.T.astype(complex), trans=True)
        dT = -(Y.T @ ((2 * s) * (fom.M @ X) + fom.D @ X))
    return T, dT, f.cond()


def equilibrated_condition(fom, s) -> float:
    """1-norm condition estimate of the Ruiz-equilibrated saddle-point matrix at s."""
    return _EqLU(fom, s).cond()


def reference_response(fom, omega):
    """Reference frequency response (len(omega), p, m) and the largest equilibrated condition."""
    H = np.empty((len(omega), fom.p, fom.m), dtype=complex)
    kmax = 0.0
    for i, w in enumerate(omega):
        T, _, k = reference_transfer(fom, 1j * w)
        if T is None:
            H[i] = np.inf
        else:
            H[i] = T
        kmax = max(kmax, k if i % 10 == 0 else 0.0)  # the estimate is cheap but not free
    return H, kmax


def sigma(H):
    """Largest singular value of each (p, m) slice of ``H`` (see :func:`morsuite.analysis.sigma_max`)."""
    from ..analysis import sigma_max
    return np.asarray(sigma_max(H))


def scaled_tol(base, *kappas):
    """``base * max(1, max(kappas) / KAPPA_REF)``; inf if any condition number is inf."""
    k = max([1.0] + [float(x) for x in kappas if np.isfinite(x)])
    if any(not np.isfinite(x) for x in kappas):
        return math.inf
    return base * max(1.0, k / KAPPA_REF)


def product_tol(base, kappa_full, kappa_rom):
    """``base * max(1, kappa_full * kappa_rom / KAPPA_REF**2 * 1e6)``.

    A basis error of eps * kappa_full is amplified by up to kappa_rom in the
    reduced transfer function; the base tolerance holds while that product
    stays below 1e10 (eps * 1e10 ~ 1e-6).
    """
    if not (np.isfinite(kappa_full) and np.isfinite(kappa_rom)):
        return math.inf
    return base * max(1.0, kappa_full * kappa_rom / 1e10)


def nullspace_transfer(fom, s):
    """:math:`L N (N^T P(s) N)^{-1} N^T F` with N an orthonormal basis of ker G (dense).

    Returns ``(T, X, cond)``: the transfer matrix, the state :math:`X = N Y` (its
    norm sets the scale of the attainable accuracy of T), and cond(N^T P N).
    """
    N = sla.null_space(fom.G.toarray()) if fom.n2 else np.eye(fom.n1)
    P = (s * s) * fom.M + s * fom.D + fom.K
    Pn = N.T @ (P @ N)
    X = N @ np.linalg.solve(Pn, N.T @ fom.F)
    return fom.L @ X, X, np.linalg.cond(Pn)


#: the unpatched factorization (equilibrated_saddle replaces the module's spla while active)
_REAL_SPLU = spla.splu


class equilibrated_saddle:
    """Context manager: SaddlePointSolver factors the Ruiz-equilibrated matrix (prototype of the K1 fix).

    ``Dr S Dc = L U`` with Dr, Dc from five Ruiz sweeps over ``|S|``; solves are
    unscaled (``x = Dc (LU)^-1 Dr b``, transposed ``x = Dr (LU)^-T Dc b``).
    Used to attribute a silent failure to K1: a check that fails with the
    suite's solver and passes under this context failed because of K1.
    """

    class _Factor:
        def __init__(self, A, permc_spec):
            C = sp.coo_matrix(A)
            n = C.shape[0]
            row, col = C.row, C.col
            dr, dc = _ruiz(row, col, np.abs(C.data), n, 5)
            self.dr, self.dc = dr, dc
            self._lu = _REAL_SPLU(sp.csc_matrix((C.data * dr[row] * dc[col], (row, col)), shape=(n, n)),
                                  permc_spec=permc_spec)
            self.U = self._lu.U

        def solve(self, b, trans="N"):
            b = np.asarray(b)
            if b.ndim == 1:
                return self.solve(b[:, None], trans)[:, 0]
            if trans == "N":
                return self.dc[:, None] * self._lu.solve(np.ascontiguousarray(self.dr[:, None] * b))
            return self.dr[:, None] * self._lu.solve(np.ascontiguousarray(self.dc[:, None] * b), trans=trans)

    def __enter__(self):
        import types

        from ..linalg import saddle

        self._module, self._old = saddle, saddle.spla
        shim = types.SimpleNamespace(**{k: getattr(spla, k) for k in dir(spla) if not k.startswith("__")})
        shim.splu = lambda A, permc_spec=None, **kw: equilibrated_saddle._Factor(A, permc_spec)
        saddle.spla = shim
        return self

    def __exit__(self, *exc):
        self._module.spla = self._old
        return False

