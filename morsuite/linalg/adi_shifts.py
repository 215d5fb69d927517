r"""Shift strategies of low-rank ADI, one function per strategy.

The shifts :math:`p_j` (open left half-plane, closed under conjugation) make
the ADI rational function :math:`\prod_j |(\lambda - \bar p_j)/(\lambda + p_j)|`
small on the spectrum of the pencil :math:`(A, E)` of :mod:`morsuite.linalg.lradi`.

:func:`projection_shifts` (the default of ``lradi``)
    Ritz values of the quadratic pencil projected onto a block of ADI columns
    (and the current residual directions), unstable ones mirrored; the ``num``
    whose Ritz vectors carry most of the current residual
    (``selection="residual"``), or Penzl's greedy choice by
    :func:`select_shifts` (``selection="gain"``). Dense work on 2k x 2k
    matrices, no LU. ``STANDARD_RCOND`` (1e-8): the reciprocal condition of
    :math:`X^TMX` above which the Ritz values come from the standard
    eigenproblem (geev) instead of QZ.
:func:`penzl_shifts`
    Penzl's heuristic: Arnoldi Ritz values of :math:`E^{-1}A` and
    :math:`A^{-1}E` on the hidden manifold, a fixed set used cyclically.
    Cost: one sparse LU (K bordered by G) besides the projector's.
:func:`select_shifts`
    Penzl's greedy min-max choice among candidates.
:class:`LUPool`
    Kept LUs: a shift within ADI distance ``shift_reuse`` (:func:`adi_distance`) of a
    kept LU's shift is served by that LU instead of a new one; once the pool is full,
    within ``pool_full_reuse``, and the LU farthest from the current batch is dropped.

All return representatives (Im >= 0) of the shifts, a complex pair counted once.
"""

from __future__ import annotations

import warnings
from collections import OrderedDict

import numpy as np
import scipy.linalg as sla

from .backends import factor_nnz
from .manifold import ManifoldProjector

__all__ = ["projection_shifts", "penzl_shifts", "select_shifts", "adi_distance", "lu_bytes", "LUPool",
           "STANDARD_RCOND"]

IMAG_TOL = 1e-12  # relative imaginary part below which a shift counts as real
#: projection shifts: reciprocal condition of X^T M X above which the Ritz values come from the
#: standard eigenproblem (geev) instead of QZ (recorded in every result's summary)
STANDARD_RCOND = 1e-8


def as_pairs(lam) -> np.ndarray:
    """Representatives (Im >= 0) of a set closed under conjugation; near-real ones made real."""
    lam = np.asarray(lam, dtype=complex).ravel()
    real = np.abs(lam.imag) <= IMAG_TOL * np.abs(lam)
    lam = np.where(real, lam.real + 0j, lam)
    return lam[real | (lam.imag > 0)]


def _adi_gain(x, shifts) -> np.ndarray:
    r""":math:`\prod_j |x - \bar p_j| / |x + p_j|` over the closed set of ``shifts`` (representatives)."""
    x = np.asarray(x, dtype=complex)
    out = np.ones(x.shape)
    for p in shifts:
        out *= np.abs((x - np.conj(p)) / (x + p))
        if p.imag != 0:
            out *= np.abs((x - p) / (x + np.conj(p)))
    return out


def select_shifts(candidates, num, used=()) -> np.ndarray:
    r"""Greedy choice of at most ``num`` shifts (a pair counted once) among ``candidates``.

    Each pick is the candidate where the ADI rational function of the shifts
    already applied (``used``) and already picked is largest,

    .. math:: p_{k+1} = \arg\max_{x \in \mathcal{R}} \prod_j
              \left|\frac{x - \bar p_j}{x + p_j}\right|,

    Penzl's min-max heuristic (Penzl 1999, Algorithm 5.1); without history the
    first pick is the candidate whose own rational function is smallest over
    the set. Deterministic.

    Parameters
    ----------
    candidates : array_like, complex
        Shifts in the open left half-plane (a set closed under conjugation, or
        its representatives with Im >= 0).
    num : int
    used : array_like, complex
        Shifts already applied.

    Returns
    -------
    ndarray, complex
        Representatives (Im >= 0) of the chosen shifts.
    """
    cand = as_pairs(candidates)
    cand = cand[np.lexsort((cand.imag, cand.real))]
    if cand.size <= num:
        return cand
    chosen = []
    history = list(as_pairs(used))
    if not history:
        i = int(np.argmin([np.max(_adi_gain(cand, [c])) for c in cand]))
        chosen.append(cand[i])
        cand = np.delete(cand, i)
    while len(chosen) < num and cand.size:
        i = int(np.argmax(_adi_gain(cand, history + chosen)))
        chosen.append(cand[i])
        cand = np.delete(cand, i)
    return np.array(chosen, dtype=complex)


def _orthonormal_map(X, rank_tol=1e-12):
    r"""Columns of X scaled to unit norm, and T with :math:`(XT)^T(XT) = I` on the numerical span.

    The span is orthonormalised through the eigendecomposition of the small
    Gram matrix (eigenvalues below ``rank_tol`` times the largest dropped)
    rather than a QR of the tall X: k x k work and one tall product, accurate
    enough for Ritz values.
    """
    norms = np.sqrt(np.einsum("ij,ij->j", X, X))
    keep = norms > 0
    X = X[:, keep]  # a copy (boolean index), scaled in place: one n1 x k array, not two
    X /= norms[keep]
    if X.shape[1] == 0:
        return X, np.zeros((0, 0))
    w, U = np.linalg.eigh(X.T @ X)
    ok = w > rank_tol * w[-1]
    return X, U[:, ok] / np.sqrt(w[ok])


def projection_shifts(fom, basis, num, *, residuals=(), selection="residual", used=(),
                      standard_rcond=None) -> np.ndarray:
    r"""Projection shifts: Ritz values of the pencil on a block of ADI columns, mirrored into :math:`\mathbb{C}^-`.

    With :math:`X` an orthonormal basis of ``basis`` (n1-vectors in
    :math:`\ker G`: the latest ADI block and the residual directions), the
    pencil :math:`(A, E)` is projected onto :math:`\mathrm{blkdiag}(X, X)`,

    .. math::

        \hat E = \begin{bmatrix} I & 0 \\ 0 & X^TMX \end{bmatrix},\qquad
        \hat A = \begin{bmatrix} 0 & I \\ -X^TKX & -X^TDX \end{bmatrix},

    whose :math:`2k` eigenvalues are those of the projected quadratic pencil
    (stable whenever M, K are positive definite and D semidefinite). Ritz values
    with :math:`\mathrm{Re}\,\lambda \ge 0` are mirrored to
    :math:`-\mathrm{Re}\,\lambda + i\,\mathrm{Im}\,\lambda`.

    Parameters
    ----------
    fom : ConstrainedSystem
        Reads M, D, K.
    basis : ndarray (n1, k)
        Columns in :math:`\ker G`.
    num : int
        Shifts returned at most (a complex pair counted once).
    residuals : sequence of (equation, W1, W2)
        Current residual factors; used by ``selection="residual"``.
    selection : {"residual", "gain"}
        ``"residual"``: the Ritz values whose Ritz vectors carry the largest part
        of the current residuals. With right and left eigenvectors
        :math:`\hat x_i, \hat y_i` of :math:`(\hat A, \hat E)` and the projected
        residual :math:`\hat w = [X^TW_1; X^TW_2]`, the score of
        :math:`\lambda_i` is
        :math:`\|\hat y_i^H \hat w\|\,\|\hat x_i\| / |\hat y_i^H \hat E \hat x_i|`
        (controllability; the roles of :math:`\hat x, \hat y` swap for
        observability), each equation's scores scaled to a maximum of 1.
        ``"gain"``: :func:`select_shifts` with the history ``used``.
    used : array_like
        Shifts already applied (``selection="gain"``).
    standard_rcond : float, optional
        Default ``STANDARD_RCOND`` (1e-8). When the estimated reciprocal
        1-norm condition of :math:`X^TMX` exceeds this, it is inverted and the
        eigenproblem solved in standard form (LAPACK geev on
        :math:`\hat E^{-1}\hat A`, left vectors mapped back by
        :math:`\hat E^{-T}`); otherwise, and with 0, by QZ on the pencil. Same
        Ritz values to rounding, about half QZ's time (``docs/design/lradi.md``).

    Returns
    -------
    ndarray, complex
        Representatives (Im >= 0) of the chosen shifts, in the open left half-plane.
    """
    X, T = _orthonormal_map(np.asarray(basis, dtype=float))
    k = T.shape[1]
    if k == 0:
        return np.zeros(0, dtype=complex)
    XT = X @ T
    Mk, Dk, Kk = (XT.T @ (Y @ XT) for Y in (fom.M, fom.D, fom.K))
    I, Z0 = np.eye(k), np.zeros((k, k))
    Eh = np.block([[I, Z0], [Z0, Mk]])
    # QZ on the balanced pencil lambda = g mu, g = sqrt(|K| / |M|) (physical units,
    # M ~ 1e-6 and K ~ 1e9, made ggev fail on the raw one); vectors mapped back
    nm, nk = np.linalg.norm(Mk, 1), np.linalg.norm(Kk, 1)
    g = np.sqrt(nk / nm) if nm > 0 and nk > 0 else 1.0
    # a well-conditioned X^T M X is inverted: the standard eigenproblem of Ehs^{-1} Ahs (geev) has
    # the pencil's eigenvalues and right vectors, and its left vectors are Ehs^T times the pencil's
    mlu = None
    standard_rcond = STANDARD_RCOND if standard_rcond is None else standard_rcond
    if standard_rcond > 0 and nm > 0:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sla.LinAlgWarning)  # a singular Mk: dgecon says so
            mlu = sla.lu_factor(Mk, check_finite=False)
        rcond, info = sla.lapack.dgecon(mlu[0], nm, norm="1")
        if info != 0 or not rcond > standard_rcond:
            mlu = None
    if mlu is not None:
        B = np.block([[Z0, I], [sla.lu_solve(mlu, Kk, check_finite=False) / (-g * g),
                                 sla.lu_solve(mlu, Dk, check_finite=False) / (-g)]])
    else:
        Ehs = np.block([[I, Z0], [Z0, g * g * Mk]])
        Ahs = np.block([[Z0, I], [-Kk, -g * Dk]])
    if selection == "gain" or not residuals:
        lam = g * (sla.eigvals(B, check_finite=False) if mlu is not None else sla.eigvals(Ahs, Ehs))
        lam = lam[np.isfinite(lam)]
        shifts = np.where(lam.real > 0, -lam.real + 1j * lam.imag, lam)
        return select_shifts(shifts[shifts.real < 0], num, used)
    if mlu is not None:
        mu, yl, xr = sla.eig(B, left=True, right=True, check_finite=False)
        yl[k:] = sla.lu_solve(mlu, yl[k:], trans=1, check_finite=False) / (g * g)  # Ehs^{-T} y
    else:
        mu, yl, xr = sla.eig(Ahs, Ehs, left=True, right=True)
    ok = np.isfinite(mu)
    lam, yl, xr = g * mu[ok], yl[:, ok], xr[:, ok]
    xr[k:] *= g        # right vectors [u; mu u] -> [u; lambda u]
    yl[:k] /= g        # left vectors of (Ah, Eh): diag(I / g, I) times those of the scaled pencil
    den = np.abs(np.einsum("ij,ij->j", yl.conj(), Eh @ xr))
    den[den == 0] = np.inf
    score = np.zeros(lam.size)
    for equation, W1, W2 in residuals:
        w = np.vstack([XT.T @ W1, XT.T @ W2])
        if equation == "controllability":
            s = np.linalg.norm(yl.conj().T @ w, axis=1) * np.linalg.norm(xr, axis=0) / den
        else:
            s = np.linalg.norm(xr.T @ w, axis=1) * np.linalg.norm(yl, axis=0) / den
        if s.size and s.max() > 0:  # no finite Ritz value: nothing to score (stress suite)
            score = np.maximum(score, s / s.max())
    shifts = np.where(lam.real > 0, -lam.real + 1j * lam.imag, lam)
    real = np.abs(shifts.imag) <= IMAG_TOL * np.abs(shifts)
    keep = (real | (shifts.imag > 0)) & (shifts.real < 0)
    shifts = np.where(real, shifts.real + 0j, shifts)[keep]
    order = np.argsort(-score[keep], kind="stable")[:num]
    return shifts[order]


def penzl_shifts(fom, solver, num, *, kp=None, km=None, projector=None) -> np.ndarray:
    r"""Penzl's heuristic shifts on the hidden manifold (Penzl 1999, Algorithm 5.1).

    ``kp`` Arnoldi steps with :math:`E^{-1}A` and ``km`` with :math:`A^{-1}E`,
    both restricted to :math:`\ker G \times \ker G` by saddle-point solves with
    M and with K, from :math:`[0; M^{-1}\Pi F]`, give Ritz values
    :math:`\mathcal{R}_+ \cup 1/\mathcal{R}_-`; the stable ones are reduced to
    ``num`` shifts by :func:`select_shifts`. Ritz values of :math:`A^{-1}E` at
    rounding level (a Krylov space that closed early) are discarded: they would
    give shifts of modulus 1e13 that wreck the iteration.

    Parameters
    ----------
    fom : ConstrainedSystem
        Reads M, D, K, G, F, n1, n2.
    solver : SaddlePointSolver
    num : int
        Shifts returned (a complex pair counted once).
    kp, km : int, optional
        Arnoldi steps; default ``2 num + 10`` and ``num + 5``.
    projector : ManifoldProjector, optional

    Returns
    -------
    ndarray, complex
        Representatives (Im >= 0) of the shifts.
    """
    n1 = fom.n1
    kp = 2 * num + 10 if kp is None else int(kp)
    km = num + 5 if km is None else int(km)
    proj = projector or ManifoldProjector(fom, solver)
    v0 = np.concatenate([np.zeros(n1), proj(fom.F[:, 0])[1]])
    K_lu = solver.factor(coeffs=(0.0, 0.0, 1.0))

    def e_inv_a(v):
        return np.concatenate([v[n1:], proj(-(fom.K @ v[:n1]) - fom.D @ v[n1:])[1]])

    def a_inv_e(v):  # the shifted solve with mu = 0
        return np.concatenate([K_lu.solve(-(fom.D @ v[:n1]) - fom.M @ v[n1:]), v[:n1]])

    rp = _arnoldi_ritz(e_inv_a, v0, kp)
    rm = _arnoldi_ritz(a_inv_e, v0, km)
    rm = rm[np.abs(rm) > 1e-8 * np.abs(rm).max()]
    cand = np.concatenate([rp, 1.0 / rm])
    return select_shifts(cand[np.isfinite(cand) & (cand.real < 0)], num)


def _arnoldi_ritz(op, v0, k) -> np.ndarray:
    n = v0.size
    k = min(k, n - 1)
    Q = np.zeros((n, k + 1))
    H = np.zeros((k + 1, k))
    Q[:, 0] = v0 / np.linalg.norm(v0)
    for j in range(k):
        w = op(Q[:, j])
        for _ in range(2):  # classical Gram-Schmidt, twice
            h = Q[:, : j + 1].T @ w
            w = w - Q[:, : j + 1] @ h
            H[: j + 1, j] += h
        H[j + 1, j] = np.linalg.norm(w)
        if H[j + 1, j] <= 1e-14 * np.abs(H[: j + 2, j]).max():
            k = j + 1
            break
        Q[:, j + 1] = w / H[j + 1, j]
    return np.linalg.eigvals(H[:k, :k])


# -- kept factorizations: shifts served by an LU made for a nearby one ----------------
def adi_distance(p, q) -> float:
    r"""How far shift q is from p for ADI: :math:`|p - q| / |p + \bar q|`.

    This is the factor :math:`|(\lambda - q)/(\lambda + \bar q)|` (:func:`select_shifts`) of shift q at
    :math:`\lambda = p`, the point its own factor would have annihilated: q in place of p leaves at
    most that factor where p was aimed. It is 0 for q = p and below 1 for two shifts in the open
    left half-plane.
    """
    return float(abs(p - q) / abs(p + np.conj(q)))


def lu_bytes(lu) -> int:
    """Estimated memory of one saddle-point factorization: its stored entries (values and, at
    half their size, indices) plus the kept matrix of the accuracy check."""
    item = 16 if lu.complex_lu else 8
    entries = factor_nnz(lu.lu) + (lu.matrix.nnz if lu.matrix is not None else 0)
    return int(1.5 * item * entries)


class LUPool:
    r"""Factorizations kept for reuse, within a memory budget.

    :meth:`get` serves a shift p with the kept factorization of the shift q nearest to it
    (:func:`adi_distance`) if that distance is at most ``radius``, otherwise factors at p and
    keeps the new LU. A shift from a later projection batch often lies next to one already
    applied (the same lightly damped modes keep most of the residual): the step with q costs a
    solve instead of an LU and reduces the residual at p by the factor :math:`\le` ``radius``
    instead of annihilating it. ``radius = 0`` reuses exact repeats only (cyclic shift sets).

    When the kept LUs exceed ``budget_mib``, the least recently used are dropped; with
    ``full_radius`` > ``radius`` the pool is *full* once it has dropped one, and from then on

    * a shift is served by the nearest kept LU within ADI distance ``full_radius`` (instead of
      ``radius``): a small pool keeps too few LUs for a later batch's shift to find its
      neighbour within ``radius``, so it would pay an LU for most shifts;
    * the LU dropped is the kept one whose shift is farthest, in ADI distance, from every shift
      of the current batch (:meth:`expect`; the least recently used among equals, and without a
      batch): the LUs next to what the iteration is about to ask for stay.

    A pool that never exceeds its budget is unchanged by ``full_radius``.

    Cost: one LU per served shift that no kept one is near; memory at most ``budget_mib``
    (:func:`lu_bytes`; at least the LU in use is kept); the eviction compares each kept shift
    with the batch's (a few hundred distances).
    """

    def __init__(self, solver, radius: float, budget_mib: float, full_radius: float | None = None):
        self.solver, self.radius, self.budget = solver, float(radius), float(budget_mib) * 2.0 ** 20
        self.full_radius = self.radius if full_radius is None else float(full_radius)
        self._kept = OrderedDict()  # shift -> (lu, bytes), least recently used first
        self._batch = ()
        self.reused = 0
        self.dropped = 0
        self.peak_bytes = 0

    @property
    def full(self) -> bool:
        """True once an LU was dropped and the full-pool rule (``full_radius`` > ``radius``) applies."""
        return self.dropped > 0 and self.full_radius > self.radius

    def expect(self, shifts):
        """The shifts of the current batch (what the eviction of a full pool keeps LUs near)."""
        self._batch = tuple(complex(p) for p in shifts)

    def get(self, p):
        """(shift actually used, its LU)."""
        best = min(self._kept, key=lambda q: adi_distance(p, q), default=None)
        if best is not None and adi_distance(p, best) <= (self.full_radius if self.full else self.radius):
            self._kept.move_to_end(best)
            self.reused += 1
            return best, self._kept[best][0]
        lu = self.solver.factor(-p if p.imag else -p.real)
        if self.budget > 0:
            self._kept[p] = (lu, lu_bytes(lu))
            while len(self._kept) > 1 and self.bytes > self.budget:
                self._drop(p)
            self.peak_bytes = max(self.peak_bytes, self.bytes)
        return p, lu

    def _drop(self, p):
        """Drop one kept LU other than p's: the least recently used, or when full the farthest from the batch."""
        self.dropped += 1
        if not (self.full and self._batch):
            self._kept.popitem(last=False)
            return
        far = max((q for q in self._kept if q != p),
                  key=lambda q: min(adi_distance(b, q) for b in self._batch))
        del self._kept[far]

    @property
    def bytes(self) -> int:
        """Estimated memory of the kept LUs."""
        return sum(b for _, b in self._kept.values())

    def clear(self):
        """Drop every kept LU (the memory is freed once no step holds one)."""
        self._kept.clear()
