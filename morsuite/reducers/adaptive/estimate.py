r"""The adaptive reducer's error estimate over the band: a reduced model against a richer one, no LU.

With V (n1 x r, orthonormal, in :math:`\ker G`) the reduced model's basis and :math:`U \supset V` a
richer one (V, the rest of the primary columns and every point's enrichment levels,
:mod:`.points`), the Galerkin models :math:`T_V`, :math:`T_U` give

.. math::

    \Delta(\omega) = \sigma_{\max}\bigl(T_U(j\omega) - T_V(j\omega)\bigr) / \max_\omega \sigma_{\max}(T_U(j\omega)).

This is the dual-weighted residual with the dual solved in the richer space: for the residual
:math:`R(s) = F - A(s)VX_r(s)` of the reduced solution (:math:`A(s) = s^2M + sD + K` on
:math:`\ker G`) and the Galerkin dual :math:`Y_U(s) = U(U^TA(s)^TU)^{-1}U^TL^T`,
:math:`Y_U^TR = T_U - T_V` because :math:`U \supset V`; the plain dual weight (a dual in V) gives 0
whenever V holds the dual moments, as the one-sided basis does. The true error is
:math:`T - T_V = (T - T_U) + \Delta`: the estimate is accurate where U is much better than V (the
saturation assumption :math:`\|T - T_U\| \le \theta\|T - T_V\|`, :math:`\theta < 1`, gives
:math:`\Delta/(1+\theta) \le \|T - T_V\| \le \Delta/(1-\theta)`); it is not a bound, and the reducer
checks it against true samples (``docs/design/adaptive.md``).

The frequencies: ``n`` log-spaced over the band and the imaginary parts of the poles of both models
in the band (where a lightly damped error peaks, narrower than any grid). :class:`ReducedResponse`
evaluates a model at all of them from its pole-residue form, checked against direct solves.

Cost: two dense eigenvalue problems of size 2r and :math:`2\dim U` (the first-order form of each
model), :math:`O((n + k) \dim U)` for the curves, and a few dense solves for the check.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from ...linalg.dense import sigma_max

__all__ = ["ReducedResponse", "BandEstimate", "band_estimate", "band_option", "local_maxima", "order_at_tol"]

#: the pole-residue values must agree with direct solves to this, relative to the largest response
#: at the check frequencies, or every frequency is solved directly
CHECK_TOL = 1e-9


class ReducedResponse:
    r""":math:`T_r(s) = L_r(s^2M_r + sD_r + K_r)^{-1}F_r` at many s, from the pole-residue form.

    With :math:`M_r = R^TR` (Cholesky; the generalized eigenproblem of the first-order pencil if
    :math:`M_r` is not positive definite), the first-order matrix
    :math:`A = [[0, I], [-R^{-T}K_rR^{-1}, -R^{-T}D_rR^{-1}]]` is diagonalised once,
    :math:`A = X\Lambda X^{-1}`, and :math:`T_r(s) = \sum_k c_k b_k^T / (s - \lambda_k)`. The values
    at ``check`` frequencies are compared with dense solves of the second-order system; if they differ
    by more than :data:`CHECK_TOL` (relative to the largest value; an ill-conditioned eigenvector
    basis), every later evaluation solves directly (``method`` says which).

    Parameters
    ----------
    Mr, Dr, Kr : ndarray (r, r)
    Fr : ndarray (r, m)
    Lr : ndarray (p, r)
    check : array_like of complex
        Points of the accuracy check (a few, in the band).

    Cost: one eigenvalue problem of size 2r (:math:`O(r^3)`), ``len(check)`` dense solves.
    """

    def __init__(self, Mr, Dr, Kr, Fr, Lr, check=()):
        self.M, self.D, self.K, self.F, self.L = Mr, Dr, Kr, Fr, Lr
        r = Mr.shape[0]
        self.method = "modal"
        try:
            R = sla.cholesky(0.5 * (Mr + Mr.T))
            Ri = sla.solve_triangular(R, np.eye(r))
            Kt, Dt = Ri.T @ Kr @ Ri, Ri.T @ Dr @ Ri
            A = np.block([[np.zeros((r, r)), np.eye(r)], [-Kt, -Dt]])
            lam, X = sla.eig(A)
            B = np.vstack([np.zeros_like(Fr), Ri.T @ Fr])
            C = np.hstack([Lr @ Ri, np.zeros_like(Lr)])
        except (sla.LinAlgError, ValueError):
            A = np.block([[np.zeros((r, r)), np.eye(r)], [-Kr, -Dr]])
            E = sla.block_diag(np.eye(r), Mr)
            lam, X = sla.eig(A, E)
            keep = np.isfinite(lam)
            lam, X = lam[keep], X[:, keep]
            B = sla.lstsq(E @ X, np.vstack([np.zeros_like(Fr), Fr]))[0]
            C = np.hstack([Lr, np.zeros_like(Lr)])
            self._set(lam, C @ X, B)
            self._check(check)
            return
        try:
            XiB = np.linalg.solve(X, B)
        except np.linalg.LinAlgError:
            XiB = sla.lstsq(X, B)[0]
        self._set(lam, C @ X, XiB)
        self._check(check)

    def _set(self, lam, CX, XiB):
        self.poles = lam
        self._CX, self._XiB = CX, XiB

    def _check(self, check):
        s = np.atleast_1d(np.asarray(check, dtype=complex))
        if not s.size:
            return
        want, got = self.direct(s), self._modal(s)
        scale = max(float(np.abs(want).max()), np.finfo(float).tiny)
        self.check_error = float(np.abs(want - got).max() / scale)
        if not self.check_error <= CHECK_TOL:
            self.method = "solve"

    def _modal(self, s):
        w = 1.0 / (s[:, None] - self.poles[None, :])
        return np.einsum("pk,fk,km->fpm", self._CX, w, self._XiB, optimize=True)

    def direct(self, s) -> np.ndarray:
        """Dense solves of the second-order system, one per point: complex (len(s), p, m)."""
        s = np.atleast_1d(np.asarray(s, dtype=complex))
        out = np.empty((s.size,) + (self.L.shape[0], self.F.shape[1]), dtype=complex)
        step = max(1, int(2 ** 24 // max(self.M.size, 1)))  # about 256 MB of matrices at a time
        for i in range(0, s.size, step):
            z = s[i:i + step, None, None]
            P = z ** 2 * self.M + z * self.D + self.K
            out[i:i + step] = self.L @ np.linalg.solve(P, np.broadcast_to(self.F, (z.shape[0],) + self.F.shape))
        return out

    def __call__(self, s) -> np.ndarray:
        """:math:`T_r(s)`: complex (len(s), p, m)."""
        s = np.atleast_1d(np.asarray(s, dtype=complex))
        return self._modal(s) if self.method == "modal" else self.direct(s)

    def band_poles(self, band) -> np.ndarray:
        """The frequencies :math:`|\\operatorname{Im}\\lambda|` of the poles that lie in ``band``."""
        w = np.abs(self.poles.imag)
        return np.unique(w[(w >= band[0]) & (w <= band[1])])


class BandEstimate:
    """The estimate over the band of one reduced model (plain data and its two responses).

    Attributes
    ----------
    grid : ndarray
        Frequencies (rad/s), sorted.
    estimate : ndarray
        :math:`\\Delta(\\omega)` relative to ``peak``.
    peak : float
        :math:`\\max \\sigma_{\\max}(T_U)` over the peak's frequencies (:func:`band_estimate`).
    rom, rich : ReducedResponse
        The reduced model and the richer one.
    """

    def __init__(self, grid, estimate, peak, rom, rich):
        self.grid, self.estimate, self.peak, self.rom, self.rich = grid, estimate, peak, rom, rich

    @property
    def max(self) -> float:
        """The estimated band error: the largest value of ``estimate``."""
        return float(self.estimate.max())

    def at(self, omega) -> float:
        r"""The estimate at ``omega`` (not necessarily on the grid): :math:`\sigma_{\max}(T_U - T_V)/\text{peak}`."""
        s = np.array([1j * float(omega)])
        return float(sigma_max(self.rich(s) - self.rom(s))[0] / self.peak)


def band_estimate(rom: ReducedResponse, rich: ReducedResponse, band, n: int, n_peak: int) -> BandEstimate:
    """:math:`\\Delta` on ``n`` log-spaced frequencies of ``band``, the ``n_peak`` of the peak, and the band poles
    of both models.

    The peak is :math:`\\max\\sigma_{\\max}(T_U)` over ``n_peak`` log-spaced frequencies (the convention of
    the suite's sampled band errors, 200), or with ``n_peak`` 0 over every frequency of the estimate, the
    band poles included (the supremum, which a lightly damped resonance between samples makes several
    times larger than a sampled peak). The error is taken at every frequency. Cost: the two responses at
    ``n + n_peak`` plus the number of band poles frequencies.
    """
    lo, hi = band
    peaks = np.geomspace(lo, hi, n_peak) if n_peak else np.zeros(0)
    grid = np.unique(np.concatenate([np.geomspace(lo, hi, n), peaks, rom.band_poles(band), rich.band_poles(band)]))
    s = 1j * grid
    TU, TV = rich(s), rom(s)
    on_peak = np.isin(grid, peaks) if n_peak else np.ones(grid.size, dtype=bool)
    peak = max(float(sigma_max(TU[on_peak]).max()), np.finfo(float).tiny)
    return BandEstimate(grid, sigma_max(TU - TV) / peak, peak, rom, rich)


def band_option(value, owner: str):
    """The ``band`` option of a reducer checked: None, or a float array (w1, w2) with 0 < w1 < w2.

    Raises
    ------
    OptionError
        Naming ``band`` and ``owner``. Cost: none.
    """
    from ...errors import OptionError

    if value is None:
        return None
    arr = np.ravel(value).astype(float)
    if arr.size != 2 or not (0 < arr[0] < arr[1]):
        raise OptionError(f"The 'band' parameter of {owner} must be (w1, w2) with 0 < w1 < w2. "
                          f"Got {np.ravel(value).tolist()!r} instead.")
    return arr


def local_maxima(values) -> np.ndarray:
    """Indices of the local maxima of a sampled curve (ends included), by decreasing value."""
    v = np.asarray(values, dtype=float)
    if v.size == 1:
        return np.array([0])
    left = np.concatenate([[True], v[1:] >= v[:-1]])
    right = np.concatenate([v[:-1] >= v[1:], [True]])
    idx = np.flatnonzero(left & right)
    return idx[np.argsort(-v[idx], kind="stable")]


def order_at_tol(reducer, tol: float, measure: str) -> int | None:
    """The order at which ``reducer`` (adaptive or dominant, ``tol`` option None) stops by its own band
    estimate at ``tol``: it runs ``reducer.reduce`` with the option ``tol`` set (the greedy's points, or
    the Newton steps, are kept for the calls that follow: they pay no LU again) and returns the order
    of that model. The hook :meth:`~morsuite.reducers.Reducer.order_guess` of both reducers, for a band
    tolerance only (the estimate is of the band error relative to the band peak: ``measure="band"``;
    None for "h2", "hinf", or when ``tol`` or ``compress`` is set already). A guess: the tolerance search
    verifies it against the true band error. Cost: the LUs of the greedy up to ``tol``, which the
    next calls report as shared work (``lu_count_shared``)."""
    import warnings

    o = reducer.options
    if measure != "band" or o.get("tol") is not None or o.get("compress"):
        return None
    o["tol"] = float(tol)
    try:
        with warnings.catch_warnings():  # a budget or a cap is the search's to report, at its own orders
            warnings.simplefilter("ignore")
            res = reducer.reduce(reducer.max_order())
    finally:
        o["tol"] = None
    return int(res.rom.order)
