r"""The relative gradient of a SISO reduced model in an orthonormal basis of its tangent space.

The tangent space, at :math:`T_r = p/q` (McMillan degree n, distinct poles, relative degree 2:
the second-order models with :math:`\hat M = I`, :mod:`morsuite.reducers.h2.poles`), of the reduced
models is :math:`V = \{u/q^2 : \deg u \le 2n - 2\}`: the span of :math:`1/(s - \lambda_k)` and
:math:`1/(s - \lambda_k)^2` with the constraint that :math:`s\,f(s) \to 0`. The pole-residue form
of :math:`\rho = \|\Pi E\|/\|E\|` (:func:`~morsuite.reducers.h2.stationarity.relative_gradient_rank_one`)
inverts the Gram matrix of that partial-fraction basis, which is singular to working precision
where poles cluster (the residues grow as the inverse of the gaps and cancel): its eigenvalues
below 1e-13 of the largest are dropped, and :math:`\rho` can be underestimated there (measured:
0.089 against 0.200 at a stall of the descent on tcom(2000), r = 30; ``docs/design/so_h2.md``).

Here the basis is orthonormal by construction, whatever the gaps: the Takenaka-Malmquist functions
of the pole sequence :math:`a = (\lambda_1, \lambda_1, \lambda_2, \lambda_2, \dots)` (every pole
twice), :math:`x(s) = (sI - A)^{-1}\beta` with

.. math::

    A = \mathrm{diag}(a) - \mathrm{tril}(\beta\beta^T, -1),\qquad \beta_k = (-2\,\mathrm{Re}\,a_k)^{1/2},

whose controllability Gramian is the identity (:math:`A + A^H + \beta\beta^T = 0`), so
:math:`\langle x_k, x_l\rangle = \delta_{kl}`; :math:`s\,x(s) \to \beta`, so
:math:`V = \{w^Tx : \beta^Tw = 0\}`. With :math:`v = E(-A)\beta` (the matrix function;
:math:`\bar v_k = \langle x_k, E\rangle` for a real E, by the residue theorem),

.. math::

    \rho = \frac{\|(I - \hat\beta\hat\beta^T)v\|}{\|E\|_{\mathcal H_2}},\qquad \hat\beta = \beta/\|\beta\| .

:math:`T(-A)\beta` of a realization :math:`C(sE - \mathcal A)^{-1}B` is :math:`CZ` with
:math:`\mathcal AZ + EZA^T + B\beta^T = 0`, solved column by column (A is lower triangular):
:math:`Z_k = \beta_k(\sigma_kE - \mathcal A)^{-1}(B - EW_k)`, :math:`\sigma_k = -a_k`,
:math:`W_k = \sum_{j<k}\beta_jZ_j`. For the index-3 model (:class:`TMRecursion`), with
:math:`Z = [x; v]`, :math:`(\sigma E - \mathcal A)^{-1}[f_1; f_2]` is
:math:`x = P(\sigma)^{-1}(f_2 + (\sigma M + D)f_1)` (the saddle-point solve with :math:`Gx = 0`),
:math:`v = \sigma x - f_1`: one LU per real pole or conjugate pair (the same LU as the other solves
at that pole), two solves with it per pole. Every step is bounded: the all-pass factors have
modulus at most one in the right half-plane. Cost: dense :math:`O(n^2N)` for a reduced or modal
model of order N; against the index-3 model two refined saddle-point solves per pole.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

__all__ = ["tm_realization", "tm_rho", "realization_tm_values", "modal_tm_values", "projection_value",
           "TMRecursion"]


def tm_realization(sequence):
    r"""``(A, beta)`` of the orthonormal Takenaka-Malmquist basis :math:`x = (sI - A)^{-1}\beta` of the
    pole sequence (each entry a pole in the open left half-plane; repeats allowed) (module docstring).
    Cost: :math:`O(n^2)`."""
    a = np.asarray(sequence, dtype=complex)
    beta = np.sqrt(-2.0 * a.real)
    return np.diag(a) - np.tril(np.outer(beta, beta), -1), beta


def tm_rho(v, beta, J) -> float:
    r""":math:`\rho = \|(I - \hat\beta\hat\beta^T)v\|/\sqrt J` from :math:`v = E(-A)\beta`; ``inf`` for
    :math:`J \le 0`."""
    if not J > 0:
        return np.inf
    bh = beta / np.linalg.norm(beta)
    w = v - bh * (bh @ v)
    return float(np.linalg.norm(w) / np.sqrt(J))


def realization_tm_values(A_tm, beta, A, B, C):
    r""":math:`T(-A_{tm})\beta` of a SISO :math:`T = C(sI - A)^{-1}B` (dense): :math:`CZ` with
    :math:`AZ + ZA_{tm}^T + B\beta^T = 0` (one Sylvester solve, Bartels-Stewart)."""
    A = np.asarray(A, dtype=complex)
    Z = sla.solve_sylvester(A, np.asarray(A_tm, dtype=complex).T,
                            -np.outer(np.asarray(B, dtype=complex).reshape(-1), beta.astype(complex)))
    return (np.asarray(C, dtype=complex).reshape(1, -1) @ Z)[0]


def modal_tm_values(A_tm, beta, mu, psi):
    r""":math:`T(-A_{tm})\beta = \sum_j\psi_j(-\mu_jI - A_{tm})^{-1}\beta` of a modal
    :math:`T = \sum_j\psi_j/(s - \mu_j)`: one triangular solve per target pole."""
    n = A_tm.shape[0]
    out = np.zeros(n, dtype=complex)
    I = np.eye(n)
    for m, p in zip(np.asarray(mu), np.asarray(psi)):
        out += p * sla.solve_triangular(-m * I - A_tm, beta.astype(complex), lower=True)
    return out


def projection_value(poles, mu, b, c, qfactor):
    r"""The H2 error of the best model with the given poles, :math:`J = \|T - \Pi_{V_0}T\|^2`
    (:math:`V_0 = \{p/q: \deg p \le n - 2\}`, :math:`q` the poles' polynomial: the variable projection value
    of :mod:`morsuite.reducers.h2.clusters`), for a modal target :math:`T = \sum_j c_jb_j/(s - \mu_j)`
    with observability Gramian :math:`Q = FF^H` (``qfactor`` F), without the cancellation of
    :math:`\|T\|^2 - \|\Pi_{V_0}T\|^2`.

    In the Takenaka-Malmquist realization of the poles (controllability Gramian I, so :math:`V = X`) the
    cancellation-free residual form (``docs/design/so_h2.md``) has closed-form residuals:
    :math:`R_B = b\odot\overline{\mathcal B(-\bar\mu)}` with the Blaschke product
    :math:`\mathcal B(s) = \prod_k(s + \bar a_k)/(s - a_k) = 1 - \beta^Tx(s)`, and
    :math:`R_C = \hat\beta(\hat\beta^T\bar v)`, :math:`\beta^T\bar v = \overline{\sum_jc_jb_j(1 - \mathcal B(-\mu_j))}`:

    .. math::

        J = \|F^HR_B\|^2 + \frac{|\sum_jc_jb_j(1 - \mathcal B(-\mu_j))|^2}{\|\beta\|^2} .

    The Blaschke factors have modulus below one in the right half-plane and vanish at target poles equal
    to reduced ones, so nothing of the size of :math:`\|T\|^2` is formed. Requires target poles and
    ``poles`` closed under conjugation (a real T and real models). Returns ``(J, floor)``, the floor a
    bound on the rounding of the sums. Cost: :math:`O(nN + Nk)`, k the rank of F (no Schur form, no
    Lyapunov solve).

    Several outputs and one input (``c`` of shape (p, N), ``qfactor`` that of the Gramian of all outputs):
    :math:`R_B` does not depend on the output and the outputs' Gramians sum, so the first term is the
    same with :math:`Q = \sum_iQ_i`, the second the sum of the outputs' (each output's residues sum to
    zero; :mod:`morsuite.reducers.h2.simo`)."""
    a = np.asarray(poles, dtype=complex)[:, None]
    mu = np.asarray(mu, dtype=complex)
    eps = np.finfo(float).eps
    sr = -np.conj(mu)[None, :]
    rb = np.asarray(b) * np.conj(np.prod((sr + np.conj(a)) / (sr - a), axis=0))
    s = -mu[None, :]
    one_minus = 1.0 - np.prod((s + np.conj(a)) / (s - a), axis=0)
    psi = np.atleast_2d(c) * np.asarray(b)[None, :]         # (p, N): several outputs, one input
    nb = np.sqrt(np.sum(-2.0 * a.real))
    fr = qfactor.conj().T @ rb
    j1 = float(np.sum(np.abs(fr) ** 2))
    rc = np.sum(psi * one_minus[None, :], axis=1) / nb
    j2s = np.abs(rc) ** 2                                      # per output
    j2 = float(np.sum(j2s))
    n, N = a.shape[0], mu.size
    e1 = 4.0 * eps * (n + np.sqrt(N)) * float(np.linalg.norm(np.abs(qfactor).T @ np.abs(rb)))
    e2 = 4.0 * eps * (n + np.sqrt(N)) * np.sum(np.abs(psi) * (1.0 + np.abs(one_minus))[None, :], axis=1) / nb
    floor = 2.0 * np.sqrt(j1) * e1 + e1 * e1 + float(np.sum(2.0 * np.sqrt(j2s) * e2 + e2 * e2))
    return j1 + j2, float(floor)


class TMRecursion:
    r""":math:`T(-A_{tm})\beta` of the index-3 model :math:`T = LP(s)^{-1}F` (SISO), one pole of the
    sequence at a time, in the sequence's order (module docstring).

    ``step(solve, sigma, beta_k)`` takes the column of the next entry (:math:`\sigma = -a_k`) with
    ``solve(rhs)`` :math:`= P(\sigma)^{-1}\mathrm{rhs}` (the saddle-point solve with :math:`Gx = 0`)
    and returns :math:`LZ_k`."""

    def __init__(self, system):
        self.sys = system
        n1 = system.M.shape[0]
        self.wx = np.zeros(n1, dtype=complex)
        self.wv = np.zeros(n1, dtype=complex)
        self.f = np.asarray(system.F[:, 0], dtype=complex)

    def step(self, solve, sigma, beta_k):
        """L Z_k for the next entry of the sequence (class docstring)."""
        s = self.sys
        f1 = -self.wx
        f2 = self.f - s.M @ self.wv
        x = solve(f2 + sigma * (s.M @ f1) + s.D @ f1)
        v = sigma * x - f1
        x, v = beta_k * x, beta_k * v
        self.wx += beta_k * x
        self.wv += beta_k * v
        return complex(s.L[0] @ x)
