r"""Undamped constrained modes of a second-order system by shift-invert Lanczos on saddle solves.

Solved without a null-space basis of G, without :math:`\Pi` and without
any n1 x n1 dense matrix (except the dense route below, on small models only); every operator
application is one solve with one sparse LU of a bordered (saddle-point) matrix made by
:class:`~morsuite.linalg.saddle.SaddlePointSolver`.

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

Where Lanczos cannot serve (k above about half of :math:`n_1 - n_2`: ARPACK's basis does not
fit, and at :math:`k = n_1 - n_2 - 1` its restarts fail) a small model (:math:`n_1 \le`
:data:`DENSE_MAX`) gets its modes densely from a null-space basis of G
(:func:`null_space_modes`, also the reference of the tests); a run that ARPACK converges
only in part says so (``info["status"]`` "partial", a warning), never returns fewer modes silently.

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

__all__ = ["ModesResult", "constrained_modes", "null_space_modes", "DENSE_MAX", "MODES_STATUS"]

#: largest n1 for which :func:`constrained_modes` computes modes densely (:func:`null_space_modes`) where
#: Lanczos cannot serve: k above about half of n1 - n2, or ARPACK failing outright
DENSE_MAX = 2000

#: the values of a :class:`ModesResult`'s ``info["status"]``
MODES_STATUS = {
    "converged": "every mode asked for converged (and, for a band, the modes found reach past both of its ends)",
    "partial": "ARPACK converged only some of the modes asked for (maxiter restarts): those are returned, "
               "fewer than asked and not necessarily the nearest sigma; modes may be missing",
    "cap": "a band's search reached k_max modes before covering the band: modes in the band may be missing",
}


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
        Plain data: ``method`` ("lanczos" or "dense"), ``sigma``, ``lu_count``, ``solves``,
        ``k_computed`` (modes asked of the last Lanczos run, or computed densely), ``k_converged``,
        ``covered`` (every mode asked for converged and, for a band, the band is known to hold no
        other mode), ``status`` (one of :data:`MODES_STATUS`) with its ``reason`` (None when
        converged), ``fallback`` (why the dense route replaced a failed Lanczos run, else None),
        ``time_s``, ``max_residual``.
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


def _residuals(system, lam, Phi, mu):
    r"""Relative residuals :math:`\|K\varphi + G^T\mu - \lambda M\varphi\| / (\|K\varphi\| + |\lambda|\|M\varphi\|)`."""
    KP, MP = system.K @ Phi, system.M @ Phi
    R = KP - MP * lam[None, :]
    if system.n2:
        R = R + system.G.T @ mu
    scale = np.linalg.norm(KP, axis=0) + np.abs(lam) * np.linalg.norm(MP, axis=0)
    return np.linalg.norm(R, axis=0) / np.where(scale > 0, scale, 1.0)


def _modes_at(system, lu, sigma, k, tol, maxiter):
    """Lanczos run for the k eigenvalues nearest sigma: (lam, shapes, multipliers, residuals, solves, shortfall).

    ``shortfall`` is None when ARPACK converged all k, else a sentence saying how many it did (its
    converged pairs are returned: fewer than k, and not necessarily the nearest sigma)."""
    n1, n2 = system.n1, system.n2
    count = [0]

    def opinv(b):
        count[0] += 1
        return lu.solve(np.asarray(b, dtype=float).ravel())

    OP = spla.LinearOperator((n1, n1), matvec=opinv, dtype=float)
    ncv = _ncv(n1 - n2, k)
    shortfall = None
    try:
        lam, X = spla.eigsh(system.K, k=k, M=system.M, sigma=sigma, which="LM", OPinv=OP, mode="normal",
                            v0=_start_vector(n1), ncv=ncv, tol=tol, maxiter=maxiter)
    except spla.ArpackNoConvergence as exc:
        lam, X = exc.eigenvalues, exc.eigenvectors
        shortfall = (f"ARPACK converged {lam.size} of {k} modes at sigma = {sigma:g} within maxiter = {maxiter} "
                     "restarts")
    if lam.size == 0:
        return np.zeros(0), np.zeros((n1, 0)), np.zeros((n2, 0)), np.zeros(0), count[0], shortfall
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
    return lam, Phi, mu, _residuals(system, lam, Phi, mu), count[0], shortfall


def _ncv(dim, k):
    """ARPACK's Lanczos basis size for k modes of a space of dimension ``dim``: 2k + 1 (at least k + 20),
    at most ``dim``."""
    return min(dim, max(2 * k + 1, k + 20))


def _lanczos_fits(dim, k):
    """Whether k modes leave ARPACK its basis (:func:`_ncv` uncapped): else its restarts have too few
    shifts to apply (ARPACK error 3 at k = dim - 1 with a shift far from the spectrum, measured)."""
    return _ncv(dim, k) >= max(2 * k + 1, k + 20)


@_one_blas_thread
def null_space_modes(system) -> ModesResult:
    r"""Every undamped constrained mode, densely: a null-space basis Z of G and ``eigh`` on it.

    .. math::

        Z^TKZ\,c = \lambda\,Z^TMZ\,c,\qquad \varphi = Zc,\qquad
        G^T\mu = -(K\varphi - \lambda M\varphi)\ \text{(least squares)} .

    The reference route for small models, and the one :func:`constrained_modes` takes where
    Lanczos cannot serve (k above about half of :math:`n_1 - n_2`) on a model with
    :math:`n_1 \le` :data:`DENSE_MAX`. Forms dense n1 x n1 matrices: small models only.

    Parameters
    ----------
    system : ConstrainedSystem
        The model (M, K, G, n1, n2 are used).

    Returns
    -------
    ModesResult
        All :math:`n_1 - \operatorname{rank} G` modes ascending, M-orthonormal shapes, multipliers
        and residuals; ``info``: ``method`` "dense", ``lu_count`` 0, ``solves`` 0, ``covered`` True,
        ``status`` "converged", ``time_s``, ``max_residual``.

    Cost: an SVD of the dense G (O(n1^2 n2 + n1^3) for the basis), a dense generalized symmetric
    eigenproblem of order :math:`n_1 - n_2` (O(n1^3)) and a least-squares solve with the dense
    :math:`G^T`; O(n1^2) memory.
    """
    check_system(system, "system")
    t0 = time.perf_counter()
    n1, n2 = system.n1, system.n2
    Gd = system.G.toarray() if n2 else np.zeros((0, n1))
    Z = sla.null_space(Gd) if n2 else np.eye(n1)
    Kz, Mz = Z.T @ (system.K @ Z), Z.T @ (system.M @ Z)
    lam, C = sla.eigh(0.5 * (Kz + Kz.T), 0.5 * (Mz + Mz.T))
    Phi = Z @ C
    if n2:
        R0 = system.K @ Phi - (system.M @ Phi) * lam[None, :]
        mu = -sla.lstsq(Gd.T, R0)[0]
    else:
        mu = np.zeros((0, lam.size))
    res = _residuals(system, lam, Phi, mu)
    omega = np.sign(lam) * np.sqrt(np.abs(lam))
    info = {"method": "dense", "sigma": None, "lu_count": 0, "solves": 0, "k_computed": int(lam.size),
            "k_converged": int(lam.size), "covered": True, "status": "converged", "reason": None,
            "time_s": time.perf_counter() - t0, "max_residual": float(res.max()) if res.size else 0.0}
    return ModesResult(omega=omega, eigenvalues=lam, shapes=Phi, multipliers=mu, residuals=res, info=info)


@_one_blas_thread
def constrained_modes(system, k=None, band=None, *, sigma=None, tol: float = 0.0, maxiter: int | None = None,
                      solver=None, factorization=None, k_max: int | None = None, within_band: bool = True,
                      dense_max: int = DENSE_MAX):
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
        Cap of k when covering a band (default :math:`n_1 - n_2 - 1`; :math:`n_1 - n_2 - 2` above
        ``dense_max``, where ARPACK needs two spare basis vectors).
    within_band : bool
        With ``band``: return only the modes in the band (default), or every mode computed
        (those in the band and at least ``k`` nearest :math:`\sigma`, for a caller that wants
        the band's neighbours too).
    dense_max : int
        Models with :math:`n_1 \le` ``dense_max`` (default :data:`DENSE_MAX` = 2000) get their modes
        from :func:`null_space_modes` where Lanczos cannot serve them: k (or a band's doubling k)
        above about half of :math:`n_1 - n_2` (ARPACK's basis of 2k + 1 vectors would not fit;
        at k = n1 - n2 - 1 its restarts fail), or ARPACK failing outright (``info["fallback"]``).

    Returns
    -------
    ModesResult
        Frequencies ascending, M-orthonormal shapes, multipliers, residuals and ``info``
        (``lu_count``: LUs this call made; ``solves``; ``sigma``; ``covered``; ``status`` and
        ``reason``). A run that ARPACK converged only in part (``maxiter``) returns the pairs it
        converged with ``status`` "partial", ``covered`` False and a
        :class:`~morsuite.errors.ConvergenceWarning` naming the shortfall; a band not covered within
        ``k_max``, ``status`` "cap".

    Raises
    ------
    InputError
        If neither or both of k and band are given, k exceeds :math:`n_1 - n_2 - 1` (or
        :math:`n_1 - n_2 - 2` above ``dense_max``), the band is empty (:math:`w_2 \le w_1`) or holds
        no mode (a complete search; an incomplete one says so), or sigma is not finite.
    SingularShiftError
        If :math:`\sigma` is an eigenvalue (e.g. 0 for a free-floating model) and Lanczos runs.
    scipy.sparse.linalg.ArpackError
        If ARPACK fails outright on a model above ``dense_max``.

    Cost: one sparse LU of order :math:`n_1 + n_2` (none when ``factorization`` is given or
    only the dense route runs), the Lanczos solves (about 2k to 4k), k more for the refinement,
    and O(n1 k^2) dense work; the dense route, :func:`null_space_modes`'s O(n1^3).
    """
    check_system(system, "system")
    t0 = time.perf_counter()
    k = _positive_int("k", k)
    if k is None and band is None:
        raise InputError("constrained_modes needs k (the lowest k modes) or band (every mode in the band)")
    dim = system.n1 - system.n2
    limit = dim - 1
    if limit < 1:
        raise InputError(f"the constrained space has dimension n1 - n2 = {dim}: too small "
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
    dense_max = _positive_int("dense_max", dense_max, allow_none=False)
    dense_ok = system.n1 <= dense_max
    # Lanczos needs ncv >= k + 2 at least; without the dense route, k stops there
    k_max = (limit if dense_ok else dim - 2) if k_max is None else min(limit, _positive_int("k_max", k_max))
    if k is not None and k > k_max and not dense_ok:
        raise InputError(f"k = {k} leaves ARPACK no room (ncv <= n1 - n2 = {dim}) and the model (n1 = {system.n1}) "
                         f"is above dense_max = {dense_max}: ask for at most {k_max} modes")
    lus, lu = 0, factorization
    if factorization is not None and tuple(complex(c) for c in factorization.coeffs) != (complex(-sigma), 0j, 1 + 0j):
        raise InputError(f"factorization is of the coefficients {factorization.coeffs}, not of K - sigma M "
                         f"with sigma = {sigma:g} (coeffs (-sigma, 0, 1))")

    def factor():  # the one LU, made when Lanczos first runs
        nonlocal lu, lus, solver
        if lu is None:
            solver = new_solver(system) if solver is None else solver
            before = solver.stats.copy()
            lu = solver.factor(coeffs=(-sigma, 0.0, 1.0))  # K - sigma M bordered: the one LU
            lus = solver.stats.since(before)["factorizations"]
        return lu

    solves, covered, shortfall, method, fallback = 0, True, None, "lanczos", None
    kk = min(k_max, k) if k is not None else min(8, k_max)
    while True:
        if dense_ok and not _lanczos_fits(dim, kk):
            method = "dense"
        else:
            mi = maxiter if maxiter is not None else max(1000, 10 * kk)
            try:
                lam, Phi, mu, res, n, shortfall = _modes_at(system, factor(), sigma, kk, tol, mi)
            except spla.ArpackError as exc:  # not a partial convergence (ArpackNoConvergence is caught there)
                if not dense_ok:
                    raise
                method, fallback = "dense", f"ARPACK failed at k = {kk}: {exc}"
            else:
                solves += n
        if method == "dense":
            lam, Phi, mu, res = _dense_nearest(system, sigma, kk if band is None else None)
            break
        if band is None or shortfall is not None:
            break
        reach = np.max(np.abs(lam - sigma)) if lam.size else 0.0
        need = max(abs(sigma - w1 * w1), abs(w2 * w2 - sigma))
        if (reach > need and (k is None or lam.size >= k)) or lam.size >= limit:
            break
        if kk >= k_max:
            covered = False
            break
        kk = min(k_max, 2 * kk)
    status, reason = "converged", None
    if shortfall is not None:
        status, covered = "partial", False
        reason = (f"{shortfall}: modes nearer sigma may be missing" if band is None else
                  f"{shortfall} while covering the band {tuple(band)}: modes in the band may be missing")
    elif not covered:
        status = "cap"
        reason = (f"k_max = {k_max} modes nearest sigma = {sigma:g} do not reach past the band {tuple(band)}; modes "
                  "in the band may be missing")
    if reason is not None:
        warnings.warn(f"constrained_modes: {reason}", ConvergenceWarning, stacklevel=2)
    k_converged = int(lam.size)
    omega = np.sign(lam) * np.sqrt(np.abs(lam))
    if band is not None and within_band:
        keep = (omega >= w1) & (omega <= w2)
        if not np.any(keep):
            if status != "converged":  # nothing converged in the band: not a statement about the model
                raise InputError(f"band {tuple(band)}: no mode found in it and the search is incomplete ({reason})")
            raise InputError(f"band {tuple(band)} holds no mode of the model (nearest: "
                             f"{omega[np.argmin(np.abs(omega - w1))]:.6g} rad/s)")
        lam, Phi, mu, res, omega = lam[keep], Phi[:, keep], mu[:, keep], res[keep], omega[keep]
    info = {"method": method, "sigma": sigma, "lu_count": int(lus), "solves": int(solves),
            "k_computed": int(kk if method == "lanczos" else k_converged), "k_converged": k_converged,
            "covered": bool(covered), "status": status, "reason": reason, "fallback": fallback,
            "time_s": time.perf_counter() - t0, "max_residual": float(res.max()) if res.size else 0.0}
    return ModesResult(omega=omega, eigenvalues=lam, shapes=Phi, multipliers=mu, residuals=res, info=info)


def _dense_nearest(system, sigma, k):
    """The k modes nearest sigma (every mode for k None) of :func:`null_space_modes`, ascending."""
    d = null_space_modes.__wrapped__(system)
    lam = d.eigenvalues
    idx = np.arange(lam.size) if k is None else np.sort(np.argsort(np.abs(lam - sigma), kind="stable")[:k])
    return lam[idx], d.shapes[:, idx], d.multipliers[:, idx], d.residuals[idx]
