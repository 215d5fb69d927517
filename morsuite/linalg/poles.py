r"""Poles of a constrained second-order system by shift-invert Arnoldi on saddle solves, or from its
undamped modes under Rayleigh damping.

**Damped poles** (:func:`damped_poles`): the finite eigenvalues of the constrained quadratic
problem

.. math::

    (\lambda^2 M + \lambda D + K)x + G^Tz = 0,\qquad Gx = 0,

from the first-order pencil :math:`(A, E)` of size :math:`2n_1+n_2` (``E = blkdiag(I, M,
0)``, ``A = [[0, I, 0], [-K, -D, -G^T], [G, 0, 0]]``). A solve with :math:`A - \sigma E`
reduces to one saddle solve with :math:`S(\sigma) = [[\sigma^2M + \sigma D + K, G^T], [G,
0]]`: for :math:`(A-\sigma E)[x; v; z] = [b_1; b_2; 0]`,
:math:`S(\sigma)[x; z] = [-b_2 - (D + \sigma M)b_1; 0]` and :math:`v = b_1 + \sigma x`. So
shift-invert Arnoldi (``scipy.sparse.linalg.eigs``) on
:math:`(A-\sigma E)^{-1}E` (eigenvalues :math:`1/(\lambda - \sigma)`, infinite eigenvalues
mapped to 0) costs one complex LU per shift :math:`\sigma = j\omega` in the band.

Rayleigh damping :math:`D = \alpha M + \beta K` (:func:`proportional_damping`) gives every pole from an
undamped mode of :func:`~morsuite.linalg.eigen.constrained_modes` (symmetric Lanczos, one real LU):
:math:`\lambda^2 + (\alpha + \beta\omega^2)\lambda + \omega^2 = 0`.

Cost: :func:`damped_poles`, one complex LU per shift (a few) and the solves of Arnoldi, or one real
LU and the Lanczos solves (Rayleigh damping). Design note: ``docs/design/modal.md``.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse.linalg as spla

from ..errors import ConvergenceWarning, InputError
from .eigen import _band, _one_blas_thread, _positive_int, _start_vector, constrained_modes
from .system import check_system, new_solver

__all__ = ["PolesResult", "proportional_damping", "damped_poles"]


@dataclass
class PolesResult:
    r"""Poles of the constrained quadratic problem :math:`(\lambda^2M + \lambda D + K)x + G^Tz = 0`, :math:`Gx = 0`.

    One entry per conjugate pair (the member with :math:`\operatorname{Im}\lambda \ge 0`), sorted
    by natural frequency.

    Attributes
    ----------
    poles : ndarray (k,) complex
    shapes : ndarray (n1, k) complex
        Right mode shapes x, unit 2-norm.
    frequencies : ndarray (k,)
        Natural frequencies :math:`|\lambda|` (rad/s).
    damping : ndarray (k,)
        Damping ratios :math:`-\operatorname{Re}\lambda / |\lambda|`.
    in_band : ndarray (k,) of bool
        :math:`w_1 \le |\lambda| \le w_2`.
    residuals : ndarray (k,)
        :math:`\|(\lambda^2M + \lambda D + K)x + G^Tz\| / ((|\lambda|^2\|M\|_1 + |\lambda|\|D\|_1 + \|K\|_1)\|x\|)`.
    info : dict
        Plain data: ``band``, ``shifts``, ``lu_count``, ``solves``, ``covered`` (every shift's disk
        reached past its part of the band), ``time_s``, ``max_residual``.
    """

    poles: np.ndarray
    shapes: np.ndarray
    frequencies: np.ndarray
    damping: np.ndarray
    in_band: np.ndarray
    residuals: np.ndarray
    info: dict = field(default_factory=dict)


def _first_order_op(system, lu, sigma, count):
    r"""(A - sigma E)^{-1} E on [x; v] (2 n1): one saddle solve with S(sigma) per application (counted)."""
    n1 = system.n1
    M, D = system.M, system.D

    def matvec(w):
        count[0] += 1
        w = np.asarray(w).ravel()
        v1, v2 = w[:n1], w[n1:]
        rhs = -(M @ v2) - (D @ v1) - sigma * (M @ v1)
        x = lu.solve(rhs)
        return np.concatenate([x, v1 + sigma * x])

    return spla.LinearOperator((2 * n1, 2 * n1), matvec=matvec, dtype=complex)


def _default_shifts(w1, w2, n_shifts):
    lo = max(w1, w2 * 1e-6)
    edges = np.geomspace(lo, w2, n_shifts + 1)
    centres = np.sqrt(edges[:-1] * edges[1:])
    return 1j * centres, edges


def _distinct(lam, X, rtol=1e-8, stol=1e-6):
    """Indices of the distinct eigenpairs: a pair is dropped when its pole is within ``rtol`` of kept
    ones and its (unit) shape lies in the span of theirs to ``stol`` (a multiple pole keeps as many
    pairs as its eigenspace has dimensions; the same pole from two shifts is kept once)."""
    keep = []
    for i, li in enumerate(lam):
        near = [j for j in keep if abs(li - lam[j]) <= rtol * max(abs(li), 1e-300)]
        if near:
            Q, _ = np.linalg.qr(X[:, near])
            if np.linalg.norm(X[:, i] - Q @ (Q.conj().T @ X[:, i])) <= stol:
                continue
        keep.append(i)
    return keep


def proportional_damping(system, rtol: float = 1e-12):
    r"""The coefficients :math:`(\alpha, \beta)` of Rayleigh damping :math:`D = \alpha M + \beta K`, or None.

    Least squares in the Frobenius inner product (a 2 x 2 normal system of sparse element-wise
    products, solved by ``lstsq``: M proportional to K is handled), accepted when
    :math:`\|D - \alpha M - \beta K\|_F \le` ``rtol`` :math:`(|\alpha|\|M\|_F + |\beta|\|K\|_F
    + \|D\|_F)`; D = 0 gives (0, 0). Memoised in ``system.cache`` where the system has one.

    Parameters
    ----------
    system : ConstrainedSystem
    rtol : float
        Acceptance tolerance relative to the norms (default 1e-12: rounding of assembled
        matrices, not an approximation).

    Returns
    -------
    (alpha, beta) or None

    Cost: O(nnz(M) + nnz(D) + nnz(K)).
    """
    cache = getattr(system, "cache", None)
    key = ("proportional_damping", float(rtol))
    if cache is not None and key in cache:
        return cache[key]
    M, D, K = system.M, system.D, system.K
    inner = lambda X, Y: float(X.multiply(Y).sum()) if hasattr(X, "multiply") else float(np.sum(X * Y))
    A = np.array([[inner(M, M), inner(M, K)], [inner(K, M), inner(K, K)]])
    b = np.array([inner(M, D), inner(K, D)])
    nM, nK, nD = math.sqrt(A[0, 0]), math.sqrt(A[1, 1]), math.sqrt(max(inner(D, D), 0.0))
    out = None
    if nD == 0.0:
        out = (0.0, 0.0)
    elif nM > 0 and nK > 0:
        S = np.diag([1.0 / nM, 1.0 / nK])  # scaled normal equations
        c = S @ np.linalg.lstsq(S @ A @ S, S @ b, rcond=1e-12)[0]
        R = D - c[0] * M - c[1] * K
        nR = math.sqrt(max(inner(R, R), 0.0))
        if nR <= rtol * (abs(c[0]) * nM + abs(c[1]) * nK + nD):
            out = (float(c[0]), float(c[1]))
    if cache is not None:
        cache[key] = out
    return out


def _proportional_poles(system, w1, w2, coeffs, k, max_poles, n_shifts, tol, solver):
    """Poles from the undamped modes under Rayleigh damping: (lam, X, Z, lus, solves, covered, sigma)."""
    alpha, beta = coeffs
    lo = max(w1, w2 * 1e-6)  # as the Arnoldi's shifts: never sigma = 0 (a free-floating model's pole)
    m = constrained_modes(system, band=(w1, w2), k=min(k, system.n1 - system.n2 - 1), sigma=lo * lo, tol=tol,
                          solver=solver, k_max=max_poles * n_shifts, within_band=False)
    lam2 = m.eigenvalues
    c = alpha + beta * lam2  # lambda^2 + c lambda + omega^2 = 0 for each undamped mode
    disc = np.sqrt((c * c - 4 * lam2).astype(complex))
    upper = (-c + disc) / 2  # Im >= 0 of a complex pair; the larger real root of an overdamped mode
    lower = (-c - disc) / 2
    real = np.abs(disc.imag) <= 1e-14 * np.maximum(np.abs(c), 1e-300)  # overdamped: two real poles
    lam = np.concatenate([upper, lower[real].real.astype(complex)])
    idx = np.concatenate([np.arange(lam2.size), np.flatnonzero(real)])
    X = m.shapes[:, idx].astype(complex)
    Z = m.multipliers[:, idx] * (1 + beta * lam)[None, :]  # z = (1 + lambda beta) mu
    return lam, X, Z, m.info["lu_count"], m.info["solves"], m.info["covered"], m.info["sigma"]


@_one_blas_thread
def damped_poles(system, band, *, k: int | None = None, shifts=None, n_shifts: int | None = None,
                 max_poles: int = 40, tol: float = 0.0, maxiter: int = 60, solver=None,
                 proportional: bool | None = None):
    r"""Poles of the full constrained model in and near a band, by shift-invert Arnoldi (module docstring).

    Parameters
    ----------
    system : ConstrainedSystem
        The model.
    band : (w1, w2)
        Frequencies in rad/s, :math:`0 \le w_1 < w_2`.
    k : int, optional
        Poles requested per shift at the start (default 10); if the disk of the poles found
        around the shift does not reach past the shift's part of the band
        (:math:`[e_i, e_{i+1}]` of a geometric split of the band), one more run computes
        ``max_poles``.
    shifts : sequence of complex, optional
        The shifts :math:`\sigma_i`; default ``n_shifts`` points :math:`j\omega` at the
        geometric centres of equal log-parts of the band.
    n_shifts : int, optional
        Default ``max(1, ceil(log10(w2 / w1)))`` (one shift per decade), at most 6.
    max_poles : int
        Cap of the poles computed per shift (default 40). A band holding more poles than that
        near a shift gets the nearest ones, ``covered`` False and a warning (the cost grows
        quickly with it: ``docs/design/modal.md``).
    tol : float
        ARPACK's relative accuracy (default 0: machine precision).
    maxiter : int
        ARPACK's restart cap per run (default 60): clustered poles (dsms) converge slowly; at the
        cap the converged poles are kept, ``covered`` is False and a warning says so.
    solver : SaddlePointSolver, optional
        Solver to use (default a fresh one of the system).
    proportional : bool, optional
        Rayleigh damping path. Default None: taken when :func:`proportional_damping` finds
        :math:`D = \alpha M + \beta K` and ``shifts`` is not given. Then every pole comes from
        an undamped mode (:func:`constrained_modes`: one real LU at :math:`\sigma = w_1^2`,
        symmetric Lanczos, the lowest modes from :math:`w_1` up, at most ``max_poles *
        n_shifts``): :math:`\lambda^2 + (\alpha + \beta\omega^2)\lambda + \omega^2 = 0`, the
        same shape, the multiplier :math:`(1 + \beta\lambda)\mu`; residuals are computed as
        on the general path. On the DSMS g = 600 this took 420 solves for 72 modes against
        1966 solves of Arnoldi for 24 poles (about 20x less time, 2026-11-27). False: always
        Arnoldi; True: require Rayleigh damping (InputError otherwise).

    Returns
    -------
    PolesResult
        Every distinct pole found (one per conjugate pair), with shapes, natural frequencies,
        damping ratios, ``in_band`` flags, residuals and ``info`` (``lu_count``: one per shift;
        ``method``: ``"arnoldi"`` or ``"proportional"`` with ``rayleigh`` = [alpha, beta]).

    Raises
    ------
    InputError
        If the band is empty or a shift is not finite.

    Cost: one complex sparse LU per shift, and per shift the Arnoldi solves (about 2k per
    run, a run per doubling of k) and one more solve per pole (its multiplier, for the residual).
    """
    check_system(system, "system")
    t0 = time.perf_counter()
    w1, w2 = _band(band)
    k = _positive_int("k", k) or 10
    max_poles = _positive_int("max_poles", max_poles, allow_none=False)
    maxiter = _positive_int("maxiter", maxiter, allow_none=False)
    n1 = system.n1
    limit = 2 * (n1 - system.n2) - 1
    shifts_given = shifts is not None
    if shifts is None:
        ns = _positive_int("n_shifts", n_shifts) or min(6, max(1, math.ceil(math.log10(w2 / max(w1, w2 * 1e-6)))))
        shifts, edges = _default_shifts(w1, w2, ns)
        parts = [(edges[i], edges[i + 1]) for i in range(ns)]
    else:
        shifts = np.atleast_1d(np.asarray(shifts, dtype=complex))
        if shifts.size == 0 or not np.all(np.isfinite(shifts)):
            raise InputError(f"shifts must be finite complex numbers; got {shifts!r}")
        parts = [(w1, w2)] * shifts.size
    solver = new_solver(system) if solver is None else solver
    before = solver.stats.copy()
    found, covered, count = [], True, [0]
    coeffs = None
    if proportional is None or proportional:
        coeffs = proportional_damping(system) if shifts_given is False else None
        if proportional and coeffs is None:
            raise InputError("proportional=True: D is not alpha M + beta K to rounding (or shifts were given)")
    if coeffs is not None:
        lam, X, Z, _, nsolves, covered, sig = _proportional_poles(system, w1, w2, coeffs, k, max_poles, len(shifts),
                                                                 tol, solver)
        count[0] += nsolves
        found.append((lam, X, Z))
        shifts = np.array([math.sqrt(max(sig, 0.0)) * 1j])
    for sigma, (a, b) in zip(shifts if coeffs is None else [], parts):
        sigma = complex(sigma)
        lu = solver.factor(sigma)
        OP = _first_order_op(system, lu, sigma, count)
        need = max(abs(1j * a - sigma), abs(1j * b - sigma))
        kk = min(k, limit, max_poles)
        while True:
            ncv = min(2 * n1, max(2 * kk + 1, kk + 40))
            try:
                theta, W = spla.eigs(OP, k=kk, which="LM", v0=_start_vector(2 * n1, complex), ncv=ncv, tol=tol,
                                     maxiter=maxiter)
            except spla.ArpackNoConvergence as exc:
                theta, W = exc.eigenvalues, exc.eigenvectors
                covered = False
                warnings.warn(f"damped_poles: ARPACK converged {theta.size} of {kk} poles at shift {sigma}",
                              ConvergenceWarning, stacklevel=2)
            ok = np.abs(theta) > 0
            lam = sigma + 1.0 / theta[ok]
            W = W[:, ok]
            reach = np.max(np.abs(lam - sigma)) if lam.size else 0.0
            if reach > need or kk >= limit:
                break
            if kk >= max_poles:
                covered = False
                warnings.warn(f"damped_poles: max_poles = {max_poles} poles nearest the shift {sigma:.4g} do not "
                              f"reach past its part of the band ({a:.4g}, {b:.4g}); poles may be missing",
                              ConvergenceWarning, stacklevel=2)
                break
            kk = min(limit, max_poles)  # one rerun at the cap: each Arnoldi run starts afresh
        X = W[:n1]
        # multipliers for the residual: S(sigma)[x'; z'] = [-(lam M + D + sigma M) x; 0], z = (lam - sigma) z'
        rhs = -(system.M @ X) * (lam + sigma)[None, :] - system.D @ X
        Z = (lu.solve(rhs, full=True)[n1:] * (lam - sigma)[None, :] if lam.size
             else np.zeros((system.n2, 0), dtype=complex))
        count[0] += X.shape[1]
        found.append((lam, X, Z))
    lam = np.concatenate([f[0] for f in found])
    X = np.hstack([f[1] for f in found])
    Z = np.hstack([f[2] for f in found])
    # one per conjugate pair (real data: the conjugate of a pole is a pole with the conjugate
    # shape), then merge the duplicates that two shifts, or both members of a pair, gave
    lower = lam.imag < 0
    lam, X, Z = np.where(lower, lam.conj(), lam), np.where(lower, X.conj(), X), np.where(lower, Z.conj(), Z)
    order = np.argsort(np.abs(lam), kind="stable")
    lam, X, Z = lam[order], X[:, order], Z[:, order]
    nx = np.linalg.norm(X, axis=0)
    X, Z = X / nx, Z / nx
    keep = _distinct(lam, X)
    lam, X, Z = lam[keep], X[:, keep], Z[:, keep]
    R = system.K @ X + (system.D @ X) * lam + (system.M @ X) * lam ** 2
    if system.n2:
        R = R + system.G.T @ Z
    norms = [spla.norm(A, 1) for A in (system.M, system.D, system.K)]
    scale = np.abs(lam) ** 2 * norms[0] + np.abs(lam) * norms[1] + norms[2]
    res = np.linalg.norm(R, axis=0) / scale
    freq = np.abs(lam)
    damping = -lam.real / np.where(freq > 0, freq, 1.0)
    lus = solver.stats.since(before)["factorizations"]
    info = {"band": [w1, w2], "shifts": [complex(s) for s in shifts], "lu_count": int(lus),
            "solves": int(count[0]), "covered": bool(covered), "time_s": time.perf_counter() - t0,
            "max_residual": float(res.max()) if res.size else 0.0,
            "method": "arnoldi" if coeffs is None else "proportional",
            "rayleigh": None if coeffs is None else [float(coeffs[0]), float(coeffs[1])]}
    return PolesResult(poles=lam, shapes=X, frequencies=freq, damping=damping,
                       in_band=(freq >= w1) & (freq <= w2), residuals=res, info=info)
