r"""Undamped constrained modes of a second-order system by shift-invert Lanczos on saddle solves.

Solved without a null-space basis of G, without :math:`\Pi` and without
any n1 x n1 dense matrix; every operator application is one solve with one sparse LU of a
bordered (saddle-point) matrix made by :class:`~morsuite.linalg.saddle.SaddlePointSolver`.

**Undamped constrained modes** (:func:`constrained_modes`):

.. math::

    K\varphi + G^T\mu = \omega^2 M\varphi,\qquad G\varphi = 0 .

With the saddle matrix :math:`S_\sigma = [[K - \sigma M, G^T], [G, 0]]` factored once, the
operator :math:`x \mapsto [I\ 0]\,S_\sigma^{-1}[Mx; 0]` equals
:math:`Z(Z^T(K-\sigma M)Z)^{-1}Z^TMx` for any basis Z of :math:`\ker G`: it is self-adjoint
in the M-inner product, maps into :math:`\ker G`, and has the eigenvalues
:math:`1/(\omega_j^2 - \sigma)` on the constrained space and 0 on its M-complement. ARPACK's
symmetric shift-invert mode (``scipy.sparse.linalg.eigsh`` with ``M``, ``sigma`` and
``OPinv``, mode "normal") runs Lanczos on it in the M-inner product. Each Ritz vector then
gets one step of inverse iteration (one more solve: it also returns the multiplier
:math:`\mu`), and a Rayleigh-Ritz step on the refined vectors gives M-orthonormal shapes
(:math:`\Phi^TM\Phi = I`, :math:`\Phi^TK\Phi = \Omega^2` to rounding) in :math:`\ker G` to
the solves' accuracy. The residuals :math:`\|K\varphi + G^T\mu - \omega^2M\varphi\| /
(\|K\varphi\| + \omega^2\|M\varphi\|)` are computed from sparse products and reported.

The damped poles of the same system are in :mod:`morsuite.linalg.poles`.

Cost: :func:`constrained_modes`, one real LU (kept when a band needs a larger k: only the
Lanczos run is repeated) and about 3k to 5k solves. It runs with one BLAS thread (ARPACK's dense
work is small; BLAS threads beside the sparse solves only add synchronisation). Design
note: ``docs/design/modal.md``.
"""

from __future__ import annotations

import functools
import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse.linalg as spla

from ..utils import band_pair
from ..errors import ConvergenceWarning, InputError
from ..utils import blas_threads
from .system import check_system, new_solver

__all__ = ["ModesResult", "constrained_modes"]


@dataclass
class ModesResult:
    r"""Undamped constrained modes: :math:`K\varphi_j + G^T\mu_j = \omega_j^2 M\varphi_j`, :math:`G\varphi_j = 0`.

    Attributes
    ----------
    omega : ndarray (k,)
        Angular eigenfrequencies :math:`\omega_j = \sqrt{\lambda_j}` (rad/s), ascending
        (a negative :math:`\lambda_j`, from an indefinite K, gives :math:`-\sqrt{-\lambda_j}`).
    eigenvalues : ndarray (k,)
        :math:`\lambda_j = \omega_j^2`.
    shapes : ndarray (n1, k)
        Mode shapes, M-orthonormal: :math:`\Phi^TM\Phi = I`, :math:`G\Phi = 0`.
    multipliers : ndarray (n2, k)
        The Lagrange multipliers :math:`\mu_j`.
    residuals : ndarray (k,)
        Relative residuals :math:`\|K\varphi + G^T\mu - \omega^2M\varphi\| / (\|K\varphi\| + |\omega^2|\|M\varphi\|)`.
    info : dict
        Plain data: ``sigma``, ``lu_count``, ``solves``, ``k_computed``, ``covered`` (band
        selection: the band is known to hold no other mode), ``time_s``, ``max_residual``.
    """

    omega: np.ndarray
    eigenvalues: np.ndarray
    shapes: np.ndarray
    multipliers: np.ndarray
    residuals: np.ndarray
    info: dict = field(default_factory=dict)


def _one_blas_thread(fn):
    """Run ``fn`` with one BLAS thread (measured in docs/design/modal.md)."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with blas_threads(1):
            return fn(*args, **kwargs)
    return wrapper


def _positive_int(name, value, allow_none=True):
    if value is None and allow_none:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < 1:
        raise InputError(f"{name} must be a positive integer; got {value!r}")
    return int(value)


def _band(band, name="band"):
    return band_pair(band, name=name, allow_zero=True)


def _start_vector(n, dtype=float):
    """A fixed, deterministic start vector (no random seed in the result)."""
    v = 1.0 + 0.5 * np.cos(np.arange(n) * 0.7)
    return v.astype(dtype)


def _modes_at(system, lu, sigma, k, tol, maxiter):
    """Lanczos run for the k eigenvalues nearest sigma: (lam, shapes, multipliers, residuals, solves)."""
    n1, n2 = system.n1, system.n2
    count = [0]

    def opinv(b):
        count[0] += 1
        return lu.solve(np.asarray(b, dtype=float).ravel())

    OP = spla.LinearOperator((n1, n1), matvec=opinv, dtype=float)
    ncv = min(n1 - n2, max(2 * k + 1, k + 20))
    try:
        lam, X = spla.eigsh(system.K, k=k, M=system.M, sigma=sigma, which="LM", OPinv=OP, mode="normal",
                            v0=_start_vector(n1), ncv=ncv, tol=tol, maxiter=maxiter)
    except spla.ArpackNoConvergence as exc:
        lam, X = exc.eigenvalues, exc.eigenvectors
        warnings.warn(f"constrained_modes: ARPACK converged {lam.size} of {k} modes at sigma = {sigma:g}",
                      ConvergenceWarning, stacklevel=3)
    # one step of inverse iteration: (K - sigma M) Y + G^T N = M X, G Y = 0
    W = lu.solve(system.M @ X, full=True)
    count[0] += X.shape[1]
    Y, N = W[:n1], W[n1:]
    # Rayleigh-Ritz on the refined vectors: M-orthonormal shapes, Phi^T K Phi diagonal
    Kr, Mr = Y.T @ (system.K @ Y), Y.T @ (system.M @ Y)
    lam, C = sla.eigh(0.5 * (Kr + Kr.T), 0.5 * (Mr + Mr.T))
    Phi = Y @ C
    # multipliers: (K - sigma M) y + G^T n = M x with y = x / (lam - sigma) gives K y + G^T n = lam M y,
    # so n is y's multiplier (to the accuracy of the pair; the residual below is measured, not assumed)
    mu = N @ C
    R = system.K @ Phi - (system.M @ Phi) * lam[None, :]
    if n2:
        R = R + system.G.T @ mu
    scale = np.linalg.norm(system.K @ Phi, axis=0) + np.abs(lam) * np.linalg.norm(system.M @ Phi, axis=0)
    res = np.linalg.norm(R, axis=0) / np.where(scale > 0, scale, 1.0)
    return lam, Phi, mu, res, count[0]


@_one_blas_thread
def constrained_modes(system, k=None, band=None, *, sigma=None, tol: float = 0.0, maxiter: int | None = None,
                      solver=None, factorization=None, k_max: int | None = None, within_band: bool = True):
    r"""Undamped constrained modes by shift-invert Lanczos with one saddle-point LU (module docstring).

    Parameters
    ----------
    system : ConstrainedSystem
        The model (``Index3Model`` or anything with M, D, K, G, F, L, n1, n2, m, p); only
        M, K and G are used (D is not: the bordered matrix is :math:`K - \sigma M`).
    k : int, optional
        Number of modes: the k eigenvalues nearest :math:`\sigma` (with the default
        :math:`\sigma`, the lowest k). At most :math:`n_1 - n_2 - 1` (Lanczos cannot return
        every mode of the constrained space).
    band : (w1, w2), optional
        Return every mode with :math:`w_1 \le \omega \le w_2` instead: k starts at ``k`` (or 8)
        and doubles until the modes found reach past both ends of the band (every mode
        nearer :math:`\sigma` has then been found), capped at ``k_max``.
    sigma : float, optional
        Shift (rad²/s²), a point of :math:`\omega^2` where K - sigma M is nonsingular on
        :math:`\ker G`. Default 0 for ``k`` (the lowest modes; a free-floating model
        needs a negative shift) and :math:`w_1^2` for ``band``.
    tol : float
        ARPACK's relative accuracy of the Ritz values (default 0: machine precision).
    maxiter : int, optional
        ARPACK's restart cap (default ``max(1000, 10 k)``).
    solver : SaddlePointSolver, optional
        The solver that factors :math:`K - \sigma M` bordered (its counters count the LU);
        default a fresh one of the system (``new_solver``).
    factorization : SaddleLU, optional
        That factorization, made earlier (``solver.factor(coeffs=(-sigma, 0, 1))``, e.g. kept by a
        reducer across calls): no LU is made here.
    k_max : int, optional
        Cap of k when covering a band (default :math:`n_1 - n_2 - 1`).
    within_band : bool
        With ``band``: return only the modes in the band (default), or every mode computed
        (those in the band and at least ``k`` nearest :math:`\sigma`, for a caller that wants
        the band's neighbours too).

    Returns
    -------
    ModesResult
        Frequencies ascending, M-orthonormal shapes, multipliers, residuals and ``info``
        (``lu_count``: LUs this call made; ``solves``; ``sigma``; ``covered``).

    Raises
    ------
    InputError
        If neither or both of k and band are given, k exceeds :math:`n_1 - n_2 - 1`, the band
        is empty (:math:`w_2 \le w_1`) or holds no mode, or sigma is not finite.
    SingularShiftError
        If :math:`\sigma` is an eigenvalue (e.g. 0 for a free-floating model).

    Cost: one sparse LU of order :math:`n_1 + n_2` (none when ``solver`` holds it), the
    Lanczos solves (about 2k to 4k), k more for the refinement, and O(n1 k^2) dense work.
    """
    check_system(system, "system")
    t0 = time.perf_counter()
    k = _positive_int("k", k)
    if k is None and band is None:
        raise InputError("constrained_modes needs k (the lowest k modes) or band (every mode in the band)")
    limit = system.n1 - system.n2 - 1
    if limit < 1:
        raise InputError(f"the constrained space has dimension n1 - n2 = {system.n1 - system.n2}: too small "
                         "for shift-invert Lanczos")
    if band is not None:
        w1, w2 = _band(band)
    if sigma is None:
        sigma = 0.0 if band is None else w1 * w1
    sigma = float(sigma)
    if not math.isfinite(sigma):
        raise InputError(f"sigma must be finite; got {sigma}")
    if k is not None and k > limit:
        raise InputError(f"k = {k} exceeds n1 - n2 - 1 = {limit}, the most modes shift-invert Lanczos can "
                         f"return for this model")
    k_max = limit if k_max is None else min(limit, _positive_int("k_max", k_max))
    maxiter_ = maxiter
    if factorization is not None:
        if tuple(complex(c) for c in factorization.coeffs) != (complex(-sigma), 0j, 1 + 0j):
            raise InputError(f"factorization is of the coefficients {factorization.coeffs}, not of K - sigma M "
                             f"with sigma = {sigma:g} (coeffs (-sigma, 0, 1))")
        lu, lus = factorization, 0
    else:
        solver = new_solver(system) if solver is None else solver
        before = solver.stats.copy()
        lu = solver.factor(coeffs=(-sigma, 0.0, 1.0))  # K - sigma M bordered: the one LU
        lus = solver.stats.since(before)["factorizations"]
    solves = 0
    covered = True
    kk = min(k_max, k) if k is not None else min(8, k_max)
    while True:
        mi = maxiter_ if maxiter_ is not None else max(1000, 10 * kk)
        lam, Phi, mu, res, n = _modes_at(system, lu, sigma, kk, tol, mi)
        solves += n
        if band is None:
            break
        reach = np.max(np.abs(lam - sigma)) if lam.size else 0.0
        need = max(abs(sigma - w1 * w1), abs(w2 * w2 - sigma))
        if (reach > need and (k is None or lam.size >= k)) or lam.size >= limit:
            break
        if kk >= k_max:
            covered = False
            warnings.warn(f"constrained_modes: k_max = {k_max} modes nearest sigma = {sigma:g} do not reach past "
                          f"the band {band}; modes in the band may be missing", ConvergenceWarning, stacklevel=2)
            break
        kk = min(k_max, 2 * kk)
    omega = np.sign(lam) * np.sqrt(np.abs(lam))
    if band is not None and within_band:
        keep = (omega >= w1) & (omega <= w2)
        if not np.any(keep):
            raise InputError(f"band {tuple(band)} holds no mode of the model (nearest: "
                             f"{omega[np.argmin(np.abs(omega - w1))]:.6g} rad/s)")
        lam, Phi, mu, res, omega = lam[keep], Phi[:, keep], mu[:, keep], res[keep], omega[keep]
    info = {"sigma": sigma, "lu_count": int(lus), "solves": int(solves), "k_computed": int(kk),
            "covered": bool(covered), "time_s": time.perf_counter() - t0,
            "max_residual": float(res.max()) if res.size else 0.0}
    return ModesResult(omega=omega, eigenvalues=lam, shapes=Phi, multipliers=mu, residuals=res, info=info)
