r"""The Jacobian of the SISO first-order IRKA map against a modal surrogate, in closed form.

For one input and one output the interpolant of the surrogate
:math:`T_s(s) = \sum_n g_n/(s - \mu_n)` (:math:`g = C_s^T\circ B_s`) at shifts
:math:`\sigma_1, \dots, \sigma_k` has, in the basis of the columns
:math:`R_{ni} = (\sigma_i - \mu_n)^{-1}` (unit directions: in the SISO case they only
scale rows and columns of the pencil and leave its eigenvalues alone), the complex
symmetric pencil

.. math::

    E_c = R^T\mathrm{diag}(g)R,\qquad A_c = R^T\mathrm{diag}(g\mu)R,

congruent to the real interpolant of :meth:`~.irka_surrogate.ModalSurrogate.interpolant`,
so with the same eigenvalues :math:`\lambda_k`. As :math:`\partial R_{:,j}/\partial\sigma_j = -R_{:,j}^2`,
:math:`\partial E_c/\partial\sigma_j = e_jd_j^T + d_je_j^T` with :math:`d_j^T` the row j of
:math:`D_E = -(R\circ R)^T\mathrm{diag}(g)R` (likewise :math:`D_A` with :math:`g\mu`), and
for a symmetric pencil the left eigenvectors are the right ones :math:`x_k`, so
(first-order perturbation of a simple eigenvalue)

.. math::

    \frac{\partial\lambda_k}{\partial\sigma_j}
    = \frac{x_k^T(\partial A_c - \lambda_k\partial E_c)x_k}{x_k^TE_cx_k}
    = \frac{2x_{jk}\,[(D_A - \lambda_kD_E)x_k]_j}{x_k^TE_cx_k}.

The map sends :math:`\sigma` to the mirrored poles :math:`-\lambda`; in the real chart
coordinates of :class:`~.irka_surrogate.Chart` (a real shift, or the real and imaginary
part of a pair's upper member) a pair :math:`(\sigma, \bar\sigma) = (u + iv, u - iv)` gives
:math:`\partial/\partial u = \partial/\partial\sigma + \partial/\partial\bar\sigma` and
:math:`\partial/\partial v = i(\partial/\partial\sigma - \partial/\partial\bar\sigma)`.
Cost: one complex QZ of the k x k pencil and :math:`O(Nk^2 + k^3)` flops, against k + 1
map evaluations for forward differences. Checked against forward differences in
``tests/test_irka_fo.py``; measurements in ``docs/design/irka_fo.md`` (2026-11-26).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

__all__ = ["siso_jacobian"]


def siso_jacobian(mu, g, chart, x, y):
    r"""The map's Jacobian :math:`f'(x)` in ``chart`` coordinates (SISO, module docstring).

    Parameters
    ----------
    mu, g : ndarray
        The surrogate's poles and residues :math:`g_n = C_{s,n}B_{s,n}`.
    chart : Chart
        Coordinates with one input and one output (only shifts are coordinates).
    x, y : ndarray
        The point and its image :math:`f(x)` in chart coordinates.

    Returns
    -------
    ndarray or None
        The real Jacobian, or None where the closed form does not apply (an image shift that
        is not a mirrored pole, a pole that is not simple, a singular :math:`x_k^TE_cx_k`):
        the caller falls back to differences. Cost: module docstring.
    """
    alpha = chart.decode(x)[0]
    R = 1.0 / (alpha[None, :] - mu[:, None])
    gR, gmR = g[:, None] * R, (g * mu)[:, None] * R
    Ec, Ac = R.T @ gR, R.T @ gmR
    R2 = R * R
    De, Da = -(R2.T @ gR), -(R2.T @ gmR)
    # eigenvectors of the diagonally scaled pencil (unit diagonal of |E_c|-like size: better
    # conditioned QZ), mapped back: X = S X_s
    sc = 1.0 / np.sqrt(np.maximum(np.sqrt(np.abs(g)) @ np.abs(R) ** 2, np.finfo(float).tiny))
    try:
        lam, Xs = sla.eig(Ac * sc[:, None] * sc[None, :], Ec * sc[:, None] * sc[None, :])
    except (np.linalg.LinAlgError, ValueError):
        return None
    if not np.all(np.isfinite(lam)):
        return None
    X = sc[:, None] * Xs
    den = np.sum(X * (Ec @ X), axis=0)
    if np.any(np.abs(den) <= 1e-13 * np.linalg.norm(X, axis=0) ** 2 * np.linalg.norm(Ec, 2)):
        return None
    # J[k, j] = d lambda_k / d sigma_j
    J = (2.0 * X * (Da @ X - (De @ X) * lam[None, :])).T / den[:, None]
    # columns: chart coordinates of the input
    cols = []
    i = 0
    for s in range(chart.shifts.size):
        if s < chart.n_real:
            cols.append(J[:, i])
            i += 1
        else:
            a, b = J[:, i], J[:, i + 1]
            cols.extend([a + b, 1j * (a - b)])
            i += 2
    Jx = np.column_stack(cols) if cols else np.zeros((lam.size, 0))
    # rows: the image's chart coordinates, each from the pole it mirrors
    out = chart.decode(y)[0]
    rows = []
    i = 0
    scale = np.abs(out)
    for s in range(chart.shifts.size):
        dist = np.abs(-lam - out[i])
        k = int(np.argmin(dist))
        second = np.partition(dist, 1)[1] if dist.size > 1 else np.inf
        if dist[k] > 1e-3 * scale[i] or dist[k] > 0.1 * second:
            return None  # a mirrored unstable pole, a nudged one: not -lambda
        if s < chart.n_real:
            rows.append(-Jx[k].real)
            i += 1
        else:
            rows.extend([-Jx[k].real, -Jx[k].imag])
            i += 2
    return np.vstack(rows)
