r"""The second-order Arnoldi process (SOAR) through saddle-point solves, and the real basis.

At an expansion point :math:`s_0` with :math:`A_0 = s_0^2M + s_0D + K` and
:math:`A_1 = 2s_0M + D`, the Taylor coefficients of :math:`X(s_0+\sigma) =
\sum_j \sigma^j X_j` (the positions of :math:`S(s)[X; Z] = [F; 0]`) obey

.. math::

    S(s_0)\begin{bmatrix} X_j \\ Z_j \end{bmatrix}
    = -\begin{bmatrix} A_1 X_{j-1} + M X_{j-2} \\ 0 \end{bmatrix},\qquad
    S(s_0)\begin{bmatrix} X_0 \\ Z_0 \end{bmatrix} = \begin{bmatrix} F \\ 0 \end{bmatrix},

so :math:`X_j = \mathcal A X_{j-1} + \mathcal B X_{j-2}` with the (never formed)
operators :math:`\mathcal A = -A_0^{-1}A_1`, :math:`\mathcal B = -A_0^{-1}M` on
:math:`\ker G`, each application one pair of triangular solves with the one LU of
:math:`S(s_0)`. The :math:`X_j` span the second-order Krylov subspace
:math:`\mathcal G_k(\mathcal A, \mathcal B; X_0)` and are, like the power
iteration, numerically dependent after a few steps; SOAR (Bai and Su, "SOAR: a
second-order Arnoldi method for the solution of the quadratic eigenvalue
problem", SIAM J. Matrix Anal. Appl. 26(3), 2005) builds an orthonormal basis
:math:`Q` of the same subspace from the Arnoldi process of the linearisation
:math:`[\mathcal A\ \mathcal B; I\ 0]` started at :math:`[X_0; 0]`, orthogonalising
only the top halves: a pair :math:`(q, p)` gives :math:`r = \mathcal A q + \mathcal
B p`, :math:`t = q`; the coefficients :math:`h = Q^H r` remove :math:`Qh` from
:math:`r` and :math:`Ph` from :math:`t` (``reorth`` passes), and the new pair is
:math:`(r, t)/\|r\|`. A column whose top half falls to at most ``orth_tol`` of
its norm before orthogonalisation is deflated (Bai and Su's case
:math:`r = 0`): it adds no column to :math:`Q`, and its pair :math:`(0, t)` stays
in the recurrence (its continuation :math:`\mathcal B t` need not lie in the
subspace); a pair whose both halves vanish ends that direction (an invariant
subspace), and so do :data:`MAX_EMPTY_LEVELS` levels in a row without a new
column. The block form runs the columns of the starting block one by one.
A complex point is run in complex arithmetic (one complex LU), its conjugate
served by the conjugate basis; :class:`RealBasis` takes real and imaginary parts.

Every :math:`X_j` and so every column lies in :math:`\ker G` (to the solve's
accuracy, amplified by at most ``1/orth_tol`` through the orthogonalisation); the
reducer reports :math:`\|GV\|_F / (\|G\|_F \sqrt{r})`.

Cost per level and column: one saddle solve (two triangular solves with the
LU), two sparse products (:math:`A_1q`, :math:`Mp`), and ``reorth`` passes of
:math:`O(n_1 k)` flops against the k columns so far.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SOAR", "RealBasis", "MAX_EMPTY_LEVELS", "taylor_radius", "KernelProjector"]

#: a point whose recurrence adds no column for this many levels in a row is taken as exhausted
#: (only deflated pairs left: their continuations lie in the subspace to ``orth_tol``)
MAX_EMPTY_LEVELS = 3


class SOAR:
    r"""Block second-order Krylov recurrence at one expansion point, grown one level at a time.

    Parameters
    ----------
    solve : callable
        ``solve(rhs) -> x``: the positions of :math:`S(s_0)[x; z] = [rhs; 0]` (or of
        the transposed system for a left basis), for an (n1, k) block.
    A1, M, K : sparse (n1, n1)
        :math:`2s_0M + D`, :math:`M` and :math:`K` (their transposes for a left basis).
    D : sparse (n1, n1)
        The damping (for the scale's Rayleigh quotient).
    s0 : complex
        The expansion point.
    start : ndarray (n1, b)
        The input block (F, F b, L^T or L^T c).
    orth_tol : float
        Deflation tolerance (relative to a pair's norm before orthogonalisation).
    reorth : int
        Orthogonalisation passes (2: classical Gram-Schmidt twice).

    Attributes
    ----------
    levels : list of ndarray
        ``levels[j]``: the top halves that level j added (n1 x c_j, c_j <= b; complex
        for a complex point); together they span the moments :math:`X_0, \dots, X_j`.
    gamma : float
        The scale :math:`\gamma` (:func:`taylor_radius`).
    exhausted : bool
        True when every direction ended (the subspace is invariant).
    """

    def __init__(self, solve, A1, M, K, D, s0, start, orth_tol, reorth):
        self._solve, self._A1, self._M, self._K, self._D = solve, A1, M, K, D
        self.s0 = complex(s0)
        self._start = np.asarray(start)
        self.orth_tol, self.reorth = orth_tol, reorth
        self._W = None  # the orthonormal pairs [q; p] (2 n1 x k)
        self._front = None  # the pairs of the last level, (2 n1, c)
        self.levels: list[np.ndarray] = []
        self.gamma = 1.0
        self.exhausted = False
        self.deflated = 0
        self.solves = 0
        self._empty = 0  # levels in a row that added no column

    def step(self) -> np.ndarray:
        """Add one level: the top halves of its new pairs (possibly none)."""
        n1 = self._start.shape[0]
        if self.exhausted:
            return np.zeros((n1, 0))
        if self._front is None:  # level 0: X_0 = A_0^{-1} F, the pair [X_0; 0]
            R = self._solve(self._start)
            self.gamma = taylor_radius(R, self._M, self._D, self._K, self.s0)
            C = np.vstack([R, np.zeros_like(R)])
            self._W = np.zeros((2 * n1, 0), dtype=R.dtype)
        else:  # [q; p] -> [gamma A q + gamma^2 B p; q]
            g, F = self.gamma, self._front
            q, p = F[:n1], F[n1:]
            R = self._solve(-(g * (self._A1 @ q) + (g * g) * (self._M @ p)))
            C = np.vstack([R, q])
        self.solves += R.shape[1]
        tops = []
        front = []
        for c in range(C.shape[1]):
            w = C[:, c].copy()
            before = np.linalg.norm(w)
            for _ in range(self.reorth):
                w -= self._W @ (self._W.conj().T @ w)
            nw = np.linalg.norm(w)
            if before == 0 or nw <= self.orth_tol * before:
                self.deflated += 1
                continue
            w /= nw
            self._W = np.column_stack([self._W, w])
            front.append(w)
            if np.linalg.norm(w[:n1]) > 0:
                tops.append(w[:n1])
        self._empty = 0 if tops else self._empty + 1
        if not front or self._empty >= MAX_EMPTY_LEVELS:
            self.exhausted = True
            self._front = None
        else:
            self._front = np.column_stack(front)
        block = np.column_stack(tops) if tops else np.zeros((n1, 0), dtype=C.dtype)
        self.levels.append(block)
        return block


def taylor_radius(X, M, D, K, s0) -> float:
    r"""A scale for the Taylor variable: the distance from :math:`s_0` to the nearest
    root of the pencil's Rayleigh quotient on the leading moment.

    With :math:`x` the first column of :math:`X_0` (the response at :math:`s_0`,
    dominated by the modes nearest to it, as in Rayleigh's method) and
    :math:`m = x^HMx`, :math:`d = x^HDx`, :math:`k = x^HKx`, the roots
    :math:`\lambda_\pm` of :math:`m\lambda^2 + d\lambda + k` estimate the nearest
    poles and :math:`\gamma = \min|s_0 - \lambda_\pm|` the radius of convergence of
    the Taylor series. The recurrence then runs on :math:`\gamma^jX_j` (the same
    spans): the linearisation :math:`[\gamma\mathcal A\ \gamma^2\mathcal B; I\ 0]`
    has both blocks of order one instead of :math:`\|\mathcal B\| \approx
    1/\omega_1^2`, so its Arnoldi pairs keep both halves in proportion. Returns 1
    where the quotient gives no finite positive scale. Cost: three sparse products.
    """
    x = X[:, 0]
    m, d, k = (np.vdot(x, A @ x) for A in (M, D, K))
    try:
        lam = np.roots([m, d, k])
        g = float(np.min(np.abs(s0 - lam))) if lam.size else 0.0
    except (np.linalg.LinAlgError, ValueError):
        g = 0.0
    return g if np.isfinite(g) and g > 0 else 1.0


class RealBasis:
    r"""A real orthonormal basis in :math:`\ker G`, grown by blocks (Gram-Schmidt, ``reorth`` passes, deflation).

    ``add(X)`` appends the part of the columns of X (real, or complex: real and
    imaginary parts) not yet in the span: each column is projected onto
    :math:`\ker G` (``project``; the raw columns are there only to the solves'
    accuracy, and near-dependent columns magnify that error when normalised),
    orthogonalised against the basis, and dropped when what is left is at most
    ``orth_tol`` of its norm. ``V[:, :k]`` is nested: the first k columns never
    change. Cost: :math:`O(n_1 k c)` per block of c columns plus the projections.
    """

    def __init__(self, n1, orth_tol, reorth, project=None):
        self._V = np.zeros((n1, 16))
        self.cols = 0
        self.orth_tol, self.reorth = orth_tol, reorth
        self._project = project

    @property
    def V(self) -> np.ndarray:
        """The orthonormal columns so far, (n1, cols)."""
        return self._V[:, :self.cols]

    def add(self, X) -> int:
        """Append the new directions of X's columns; returns how many were kept."""
        X = np.asarray(X)
        if np.iscomplexobj(X):
            X = np.column_stack([X.real, X.imag]) if X.shape[1] else X.real
        kept = 0
        for c in range(X.shape[1]):
            v = X[:, c].astype(float, copy=True)
            before = np.linalg.norm(v)
            if before == 0:
                continue
            V = self.V
            for _ in range(self.reorth):
                v -= V @ (V.T @ v)
                if self._project is not None:
                    v = self._project(v)
            nv = np.linalg.norm(v)
            if nv <= self.orth_tol * before:
                continue
            v /= nv
            v -= V @ (V.T @ v)  # the projection's rounding, against the basis once more
            v /= np.linalg.norm(v)
            if self.cols == self._V.shape[1]:
                self._V = np.column_stack([self._V, np.zeros_like(self._V)])
            self._V[:, self.cols] = v
            self.cols += 1
            kept += 1
        return kept


class KernelProjector:
    r"""The orthogonal projection :math:`v - G^T(GG^T)^{-1}Gv` onto :math:`\ker G`.

    One sparse LU of :math:`GG^T` (n2 x n2; not a saddle LU), made on creation;
    each application one product with G and :math:`G^T` and a pair of triangular
    solves, on the rows G touches only.
    """

    def __init__(self, G):
        import scipy.sparse.linalg as spla

        G = G.tocsr()
        self._support = np.unique(G.indices)
        self._Gs = G[:, self._support].tocsr()
        self._lu = spla.splu((self._Gs @ self._Gs.T).tocsc())

    def __call__(self, v):
        sup = self._support
        vs = v[sup]
        v = v.copy()
        v[sup] = vs - self._Gs.T @ self._lu.solve(self._Gs @ vs)
        return v
