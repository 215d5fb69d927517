r"""The H2 error through the error system's Gramian: no cancellation, no LU for the main part.

The error :math:`T - T_r` has the block-diagonal realization
:math:`E_e = \mathrm{blkdiag}(E, E_r)`, :math:`A_e = \mathrm{blkdiag}(A, A_r)`,
:math:`B_e = [B; B_r]`, :math:`C_e = [C, -C_r]` (the model's part on the hidden
manifold). LR-ADI is block-diagonal too: run on the error system with the shifts of
the model's cached controllability factor :math:`Z`, it produces
:math:`Z_e = [Z; Z_r]`, where :math:`Z_r` is the reduced model's LR-ADI factor for the
same shifts (dense, cheap), and the residual factor :math:`W_e = [W; W_r]`. With
:math:`P_e - Z_eZ_e^T` the Gramian of the residual system,

.. math::

    \|T - T_r\|_{\mathcal H_2}^2 = \|LZ_p - C_rZ_r\|_F^2 + \|G_W - G_{W_r}\|_{\mathcal H_2}^2,
    \qquad G_W(s) = C(sE-A)^{-1}W,\; G_{W_r}(s) = C_r(sE_r-A_r)^{-1}W_r,

and the tail expands as :math:`t_1 - 2\,\mathrm{Re}\,t_2 + t_3` with
:math:`t_1 = \|G_W\|^2` (the model's ADI tail, :func:`~morsuite.linalg.gramians.h2_tail`),
:math:`t_3 = \|G_{W_r}\|^2` (a dense Lyapunov equation of the reduced model) and
:math:`t_2 = \langle G_W, G_{W_r}\rangle`. Every column of :math:`LZ_p - C_rZ_r` is a
difference of two numbers of the size of :math:`T`, but the squares are summed after
the subtraction: the rounding of the columns enters the result as
:math:`2\|E\|\,\delta` (:math:`\delta` their absolute error), one power of
:math:`\|T\|/\|E\|` where the pole-residue formula loses two. :math:`t_2` is bounded by
Cauchy-Schwarz, :math:`|t_2| \le \sqrt{t_1t_3}`, which costs nothing; when that bound is
too loose, :func:`tail_cross_terms` computes it by the pole-residue formula of
:math:`G_{W_r}` (one solve at :math:`-\lambda_k` per pole pair of the reduced model,
the LUs the pole-residue route of the error makes anyway).

Cost: the product :math:`LZ_p` once per model (cached with the factors); per reduced
model an eigendecomposition (:math:`O(n_r^3)`) and one vectorized product of order
:math:`k\,n_r\,pm` for all ADI steps (or, for an ill-conditioned eigenbasis, a complex
Schur form and one triangular solve per step, :math:`O(kn_r^2)`), and a dense Lyapunov
equation (:math:`O(n_r^3)`). The measurements behind the floor and its sharpness (the
floor is 34 to 190,000 times the error, median 560, issue 25's 10x not met):
``docs/design/norms.md``, "Sharpness of the floor" and "Cost of the error-Gramian route"
(2026-11-26).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ..errors import InputError
from ..linalg.gramians import residual_factor as _iterated_residual

__all__ = ["RomADI", "rom_adi", "output_columns", "residual_factor", "ErrorGramian", "error_gramian"]

EPS = np.finfo(float).eps
#: rounding of the ADI columns, in units of eps * sqrt(columns) * ||columns||_F: the W-update's rounding
#: (the residual factor is a difference of terms of the size of B) re-enters every later column
COLUMN_ROUNDING = 4.0
#: eigenvector condition number up to which the reduced recurrence runs in closed form (rom_adi)
KAPPA_MODAL = 1e2


@dataclass
class RomADI:
    """The reduced model's LR-ADI run with a given shift sequence (plain data)."""

    CZ: np.ndarray      # (p, k): C_r Z_r, the output columns of its factor
    U: np.ndarray       # (n_r, m): E_r^{-1} W_r, its final residual factor in standard form
    schur_cond: float   # the Schur basis' reconstruction error, relative; eps kappa(X) in closed form
    As: np.ndarray      # E_r^{-1} A_r (the standard form the recurrence ran on)
    poles: np.ndarray   # its eigenvalues
    u_ratio: float      # ||U_0||_F / ||U||_F: how much the residual factor shrank (its rounding grows as this)


def _modal_adi(shifts, As, U0, C):
    """The recurrence of :func:`rom_adi` in closed form in the eigenbasis of ``As`` (None when its
    eigenvector matrix is worse conditioned than KAPPA_MODAL); ``schur_cond`` then carries eps kappa."""
    lam, X = np.linalg.eig(As)
    X = X / np.linalg.norm(X, axis=0)
    with np.errstate(all="ignore"):
        kappa = float(np.linalg.cond(X))
    if not (np.all(np.isfinite(lam)) and kappa <= KAPPA_MODAL):
        return None
    b = np.linalg.solve(X, U0)  # (n, m)
    sh = np.asarray(shifts, dtype=complex)
    steps, i = [], 0
    while i < sh.size:  # a complex pair (p, conj p) is one step, as in rom_adi
        steps.append(i)
        i += 2 if sh[i].imag != 0 else 1
    P = sh[steps]
    pair = P.imag != 0
    L = lam[:, None]
    phi = (L - P.conj()) / (L + P)
    phi = np.where(pair, phi * (L - P) / (L + P.conj()), phi)  # (n, steps)
    before = np.cumprod(np.hstack([np.ones((lam.size, 1)), phi[:, :-1]]), axis=1)
    CV = np.einsum("pi,is,im->psm", C @ X, before / (L + P), b)  # C V_j, (p, steps, m)
    g = np.where(pair, 2.0 * np.sqrt(-P.real), np.sqrt(-2.0 * P.real))
    d = np.where(pair, P.real / np.where(pair, P.imag, 1.0), 0.0)
    cols = np.stack([g[:, None] * (CV.real + d[:, None] * CV.imag),
                     (g * np.sqrt(d * d + 1.0))[:, None] * CV.imag], axis=2)  # (p, steps, 2, m)
    keep = np.ones(cols.shape[1:], dtype=bool)
    keep[~pair, 1, :] = False
    CZ = cols.reshape(C.shape[0], -1)[:, keep.ravel()]
    U = (X @ (np.prod(phi, axis=1)[:, None] * b)).real
    u0 = float(np.linalg.norm(U0))
    return RomADI(CZ, U, EPS * kappa, As, lam, u0 / max(float(np.linalg.norm(U)), 1e-300 * max(u0, 1e-300)))


def rom_adi(shifts, E, A, B, C) -> RomADI:
    r"""LR-ADI of the dense :math:`(E_r, A_r, B_r, C_r)` with the shifts of a model's factor.

    Reproduces :class:`~morsuite.linalg.adi_iteration.ADIIteration`'s update exactly
    (a real shift :math:`p`: columns :math:`\sqrt{-2p}V`, :math:`W \mathrel{+}= -2pEV`; a
    complex pair: columns :math:`gR`, :math:`c\,\mathrm{Im}V` with
    :math:`R = \mathrm{Re}V + (\mathrm{Re}p/\mathrm{Im}p)\,\mathrm{Im}V`,
    :math:`g = 2\sqrt{-\mathrm{Re}p}`, :math:`c = g\sqrt{1 + (\mathrm{Re}p/\mathrm{Im}p)^2}`,
    :math:`W \mathrel{+}= g^2ER`), so that column :math:`j` of the result pairs with
    column :math:`j` of the model's factor. Works in standard form
    :math:`U = E_r^{-1}W`, :math:`V = (E_r^{-1}A_r + pI)^{-1}U`, through the complex
    Schur form :math:`E_r^{-1}A_r = QTQ^H` (one triangular solve a step), or, when the
    eigenvector matrix :math:`X` (unit columns) of :math:`E_r^{-1}A_r` has
    :math:`\kappa(X) \le` :data:`KAPPA_MODAL`, in closed form in its eigenbasis: the ADI
    residual after the steps before :math:`j` is :math:`\prod_i \phi_i(\lambda)` times
    :math:`X^{-1}U_0` (:math:`\phi_i(\lambda) = (\lambda - \bar p_i)/(\lambda + p_i)`, the
    product of both for a pair), so every :math:`C_rV_j` is one vectorized product
    (:func:`_modal_adi`; 15 to 20 times faster at 1,200 shifts, and 1.5 to 3 times more
    accurate against a long-double recurrence: ``docs/design/norms.md``, 2026-11-26).

    Returns only :math:`C_rZ_r` (the factor itself is never needed) and :math:`U`.
    """
    n, p_out = A.shape[0], C.shape[0]
    As = np.linalg.solve(E, A)
    modal = _modal_adi(shifts, As, np.linalg.solve(E, B), C)
    if modal is not None:
        return modal
    T, Q = sla.schur(As.astype(complex), output="complex")
    QH = np.ascontiguousarray(Q.conj().T)
    schur_cond = float(np.linalg.norm(Q @ T @ QH - As) / max(np.linalg.norm(As), 1e-300))
    U = np.linalg.solve(E, B).astype(float)
    u0 = float(np.linalg.norm(U))
    m = U.shape[1]
    QC = np.vstack([Q, C @ Q])  # one product a step gives V = Q Vt and C V
    # LAPACK's triangular solve called directly: scipy's wrapper (validation, lookup) cost 8x the solve at
    # these sizes, and the recurrence makes one per step (docs/design/norms.md, "Cost", 2026-11-26)
    trtrs = sla.get_lapack_funcs("trtrs", (T,))
    Tp = np.asfortranarray(T)
    dview = Tp.T.reshape(-1)[:: n + 1]  # the diagonal of Tp, as a view (Tp.T is C-contiguous)
    Td = np.diag(T).copy()
    sh = np.asarray(shifts, dtype=complex)
    CZ = np.empty((p_out, sh.size * m))
    i = j = 0
    while i < sh.size:
        p = sh[i]
        np.add(Td, p, out=dview)
        Vt, info = trtrs(Tp, QH @ U)
        VC = QC @ Vt
        if p.imag != 0:
            g = 2.0 * np.sqrt(-p.real)
            d = p.real / p.imag
            # [Re, Im] of V and C V, mixed at once: columns g (Re + d Im) = g R and c Im (C is real)
            K = np.array([[g, 0.0], [g * d, g * np.sqrt(d * d + 1.0)]])
            G = VC.view(float).reshape(n + p_out, m, 2) @ K
            CZ[:, j:j + m] = G[n:, :, 0]
            CZ[:, j + m:j + 2 * m] = G[n:, :, 1]
            U += g * G[:n, :, 0]  # g^2 R
            i += 2
            j += 2 * m
        else:
            w = -2.0 * p.real
            CZ[:, j:j + m] = np.sqrt(w) * VC[n:].real
            U += w * VC[:n].real
            i += 1
            j += m
    CZ = CZ[:, :j]
    return RomADI(CZ, U, schur_cond, As, Td, u0 / max(float(np.linalg.norm(U)), 1e-300 * max(u0, 1e-300)))


def _per_model(fom, factors, name, make):
    """``make()`` once per model and ADI options: kept in ``fom.cache`` beside the factors."""
    cache = getattr(fom, "cache", None)
    key = (name, tuple(sorted(factors.options.items())))
    if cache is not None and key in cache and not factors.computed:
        return cache[key]
    value = make()
    if cache is not None:
        cache[key] = value
    return value


def output_columns(fom, factors) -> np.ndarray:
    r""":math:`LZ_p` (p x k) of the model's cached controllability factor, computed once per model and options."""
    return _per_model(fom, factors, "h2_output_columns",
                      lambda: np.asarray(fom.L @ factors.controllability.position))


def residual_factor(fom, factors):
    r"""The model's final controllability residual factor :math:`W = W_0 + EZS` as its blocks (W1, W2).

    :math:`W_0 = [0; F]` (``F`` and :math:`\Pi F` differ by a vector of
    :math:`\mathrm{range}(G^T)`, which the saddle-point solves absorb), as iterated
    (:func:`~morsuite.linalg.gramians.residual_factor`; a compressed factor has no column
    layout to rebuild it from). Cost: none (older results: two products with the factor's
    blocks), once per model and options (kept beside the factors).
    """
    def make():
        return _iterated_residual(factors.controllability, fom)

    return _per_model(fom, factors, "h2_residual_factor", make)


@dataclass
class ErrorGramian:
    """The parts of :math:`\\|T - T_r\\|^2` by the error system's Gramian (see the module docstring)."""

    columns: float        # ||L Z_p - C_r Z_r||_F^2
    t1: float             # the model's ADI tail (estimate)
    t1_error: float       # its own error bound
    t3: float             # ||G_{W_r}||^2, exact (dense)
    t3_error: float       # its rounding: eps ||A_s|| / min|Re lambda| (Bartels-Stewart), with margin
    column_error: float   # absolute error of the columns' difference (Frobenius)
    rom_adi: RomADI
    rank: int
    rho_w: float = 0.0    # relative rounding of the model's residual factor W (a difference of terms of size W_0)
    rho_wr: float = 0.0   # the same for the reduced model's W_r

    def t2_rounding(self, t2_abs: float) -> float:
        """Absolute rounding of the cross term :math:`t_2` from the residual factors' own rounding."""
        return (self.rho_w + self.rho_wr) * t2_abs

    def squared(self, t2: float | None = None, t2_error: float = 0.0):
        """(value, absolute floor) of :math:`\\|T-T_r\\|^2`; ``t2`` None: bounded by Cauchy-Schwarz."""
        value = self.columns + self.t1 + self.t3
        dc = self.column_error
        floor = 2.0 * np.sqrt(self.columns) * dc + dc * dc + self.t1_error + 4.0 * EPS * value
        # the residual factors are differences of terms of the size of B: their relative rounding
        # rho grows as the residual shrinks, and t1, t3 are quadratic in them
        floor += self.t3_error + 2.0 * self.rho_w * self.t1 + 2.0 * self.rho_wr * self.t3
        if t2 is None:
            floor += 2.0 * np.sqrt(max(self.t1, 0.0) * max(self.t3, 0.0))
        else:
            value -= 2.0 * t2
            floor += 2.0 * t2_error
        return float(value), float(floor)


def error_gramian(fom, arrays, factors, norm_record, unit: float) -> ErrorGramian:
    r"""The cancellation-free parts of :math:`\|T - T_r\|^2` (module docstring).

    Parameters
    ----------
    fom : Index3Model
    arrays : tuple
        The reduced model's first-order :math:`(E_r, A_r, B_r, C_r, D_r)`.
    factors : GramianFactors
        The model's cached LR-ADI factors.
    norm_record : dict
        :func:`~morsuite.linalg.h2.norm_squared`'s record (its ``tail``).
    unit : float
        Relative forward error of the factor's shifted solves (``solve_error``).
    """
    E, A, B, C, _ = arrays
    c, o = factors.controllability, factors.observability
    if c.rank != c.columns:
        raise InputError(f"the error-Gramian route replays the factor's columns, but it was compressed "
                         f"(compress_tol = {c.compress_tol:g}: {c.columns} columns to {c.rank}); use "
                         "compress_tol=0 for the exact H2 error")
    LZ = output_columns(fom, factors)
    run = rom_adi(c.shifts, E, A, B, C)
    d = LZ - run.CZ
    columns = float(np.sum(d * d))
    As = run.As
    Qs = sla.solve_continuous_lyapunov(As.T, -(C.T @ C))
    Qs = 0.5 * (Qs + Qs.T)
    t3 = float(max(np.sum(run.U * (Qs @ run.U)), 0.0))
    lam = run.poles
    sep = float(np.min(np.abs(lam.real))) if lam.size else 1.0
    t3_error = 10.0 * EPS * As.shape[0] * np.linalg.norm(As, "fro") / max(sep, 1e-300) * t3
    t1 = float(norm_record["tail"])
    t1_error = 10.0 * t1 * max(o.residual, EPS) if factors.converged else max(t1, 0.0)
    k = max(c.rank, 1)
    size = np.sqrt(float(np.sum(LZ * LZ)) + float(np.sum(run.CZ * run.CZ)))
    dc = (unit + COLUMN_ROUNDING * EPS * np.sqrt(k) + run.schur_cond) * size
    rho_w = COLUMN_ROUNDING * EPS * np.sqrt(k) / np.sqrt(max(c.residual, EPS * EPS))
    rho_wr = COLUMN_ROUNDING * EPS * np.sqrt(k) * run.u_ratio
    return ErrorGramian(columns, t1, t1_error, t3, float(t3_error), float(dc), run, k, float(rho_w), float(rho_wr))
