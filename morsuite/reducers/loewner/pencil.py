r"""The Loewner pencil of conjugate-closed frequency samples, its real form and its truncation.

Left points :math:`\lambda_i` and right points :math:`\mu_j`, each set closed under complex
conjugation, with the samples :math:`H(\lambda_i)`, :math:`H(\mu_j)` (p x m). With the
identity as tangential directions (every input and every output at every point) the blocks are

.. math::

    \mathbb L_{ij} = \frac{H(\lambda_i) - H(\mu_j)}{\lambda_i - \mu_j},\qquad
    (\mathbb L_s)_{ij} = \frac{\lambda_iH(\lambda_i) - \mu_jH(\mu_j)}{\lambda_i - \mu_j},\qquad
    V_i = H(\lambda_i),\qquad W_j = H(\mu_j),

and :math:`E = -\mathbb L`, :math:`A = -\mathbb L_s`, :math:`B = V`, :math:`C = W` realize
:math:`C(sE - A)^{-1}B`, which interpolates every sample where the pencil is regular (Mayo and
Antoulas, "A framework for the solution of the generalized realization problem", Linear Algebra
Appl. 425, 2007). A point and its conjugate are next to each other; the unitary
:math:`J = \frac1{\sqrt2}\begin{bmatrix}I & I\\ -iI & iI\end{bmatrix}` on each such pair of block
rows and :math:`J^H` on each pair of block columns make all four matrices real (the samples of a
real system satisfy :math:`H(\bar s) = \overline{H(s)}`) without changing the transfer function.
Truncation to order r: :math:`Y_r` the r leading left singular vectors of
:math:`[\mathbb L\ \mathbb L_s]`, :math:`X_r` the right ones of
:math:`[\mathbb L;\ \mathbb L_s]`, and :math:`(-Y_r^T\mathbb LX_r, -Y_r^T\mathbb L_sX_r, Y_r^TV, WX_r)`
(Antoulas, Lefteriu and Ionita, "A tutorial introduction to the Loewner framework for model
reduction", in *Model Reduction and Approximation*, SIAM 2017, Algorithm 1; pyMOR's
``LoewnerReductor``). Dense work only: the pencil is (k p) x (q m) for k left and q right points.
"""

from __future__ import annotations

import numpy as np

__all__ = ["conjugate_points", "loewner_pencil", "real_form", "truncation_bases", "project"]


def conjugate_points(omega, H):
    r"""The points :math:`j\omega_k, -j\omega_k` (in that order) and their samples
    :math:`H_k, \overline{H_k}`, for frequencies ``omega`` (> 0) and samples ``H`` (len(omega), p, m).
    Cost: a copy."""
    omega = np.asarray(omega, dtype=float)
    pts = np.empty(2 * omega.size, dtype=complex)
    pts[0::2], pts[1::2] = 1j * omega, -1j * omega
    vals = np.empty((2 * omega.size,) + H.shape[1:], dtype=complex)
    vals[0::2], vals[1::2] = H, np.conj(H)
    return pts, vals


def loewner_pencil(lam, Hl, mu, Hr):
    r"""The complex Loewner quadruple :math:`(\mathbb L, \mathbb L_s, V, W)` of left points ``lam``
    with samples ``Hl`` (k, p, m) and right points ``mu`` with samples ``Hr`` (q, p, m); block rows
    ordered (point, output), block columns (point, input): shapes (kp, qm), (kp, qm), (kp, m),
    (p, qm). No left point may equal a right one. Cost: O(k q p m)."""
    k, p, m = Hl.shape
    q = Hr.shape[0]
    den = (lam[:, None] - mu[None, :])[:, None, :, None]                          # (k, 1, q, 1)
    Hl4, Hr4 = Hl[:, :, None, :], np.transpose(Hr, (1, 0, 2))[None, :, :, :]    # (k, p, 1, m), (1, p, q, m)
    L = (Hl4 - Hr4) / den
    Ls = (lam[:, None, None, None] * Hl4 - mu[None, None, :, None] * Hr4) / den
    V = Hl.reshape(k * p, m)
    W = np.transpose(Hr, (1, 0, 2)).reshape(p, q * m)
    return L.reshape(k * p, q * m), Ls.reshape(k * p, q * m), V, W


def _rows(X, block):
    r""":math:`J X` for the unitary :math:`J` of :func:`real_form` on pairs of ``block`` rows: each pair
    :math:`(X_a, X_b)` becomes :math:`((X_a + X_b)/\sqrt2,\ i(X_b - X_a)/\sqrt2)`."""
    Z = X.reshape(-1, 2, block, X.shape[1])
    out = np.empty_like(Z)
    out[:, 0] = (Z[:, 0] + Z[:, 1]) / np.sqrt(2.0)
    out[:, 1] = 1j * (Z[:, 1] - Z[:, 0]) / np.sqrt(2.0)
    return out.reshape(X.shape)


def _cols(X, block):
    r""":math:`X J^H` on pairs of ``block`` columns: :math:`(X_a, X_b)` becomes
    :math:`((X_a + X_b)/\sqrt2,\ i(X_a - X_b)/\sqrt2)`."""
    Z = X.reshape(X.shape[0], -1, 2, block)
    out = np.empty_like(Z)
    out[:, :, 0] = (Z[:, :, 0] + Z[:, :, 1]) / np.sqrt(2.0)
    out[:, :, 1] = 1j * (Z[:, :, 0] - Z[:, :, 1]) / np.sqrt(2.0)
    return out.reshape(X.shape)


def real_form(L, Ls, V, W, p, m):
    r"""``(L, Ls, V, W, imag)``: the real quadruple :math:`(J_l\mathbb LJ_r^H, J_l\mathbb L_sJ_r^H, J_lV,
    WJ_r^H)` and ``imag``, the largest imaginary part dropped relative to the largest entry (rounding:
    the data are conjugate-closed). Points come in conjugate pairs, each of ``p`` block rows (left) and
    ``m`` block columns (right); :math:`J = \frac1{\sqrt2}[I, I; -iI, iI]` on each pair. Cost: O(size of
    the pencil)."""
    out = [_cols(_rows(L, p), m), _cols(_rows(Ls, p), m), _rows(V, p), _cols(W, m)]
    scale = max(float(np.max(np.abs(X), initial=0.0)) for X in out) or 1.0
    imag = max(float(np.max(np.abs(X.imag), initial=0.0)) for X in out) / scale
    return (*(np.ascontiguousarray(X.real) for X in out), imag)


def truncation_bases(L, Ls):
    r"""``(Y, s_row, X, s_col)``: the left singular vectors of :math:`[\mathbb L\ \mathbb L_s]` with their
    singular values and the right ones of :math:`[\mathbb L;\ \mathbb L_s]` with theirs. Cost: two dense
    SVDs of (kp) x (2qm) and (2kp) x (qm)."""
    Y, s_row, _ = np.linalg.svd(np.hstack([L, Ls]), full_matrices=False)
    _, s_col, Xh = np.linalg.svd(np.vstack([L, Ls]), full_matrices=False)
    return Y, s_row, Xh.T, s_col


def project(L, Ls, V, W, Y, X, r):
    r"""The order-``r`` descriptor model :math:`(E, A, B, C) = (-Y_r^T\mathbb LX_r, -Y_r^T\mathbb L_sX_r,
    Y_r^TV, WX_r)`. Cost: dense products."""
    Yr, Xr = Y[:, :r], X[:, :r]
    return -(Yr.T @ L @ Xr), -(Yr.T @ Ls @ Xr), Yr.T @ V, W @ Xr
