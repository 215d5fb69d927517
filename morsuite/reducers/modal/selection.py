r"""Which computed modes a modal reduced model keeps: the orderings of the ``selection`` option.

Each function returns the indices of the computed modes in the order they are taken, so
``order[:k]`` are the k modes of a reduced model with k modes (a sweep over r takes prefixes).

- ``"lowest"``: ascending frequency.
- ``"band"``: the modes in the band ascending, then the others by their distance
  :math:`|\omega^2 - \sigma|` to the shift (the order shift-invert Lanczos finds them in).
- ``"dominance"``: descending dominance (:func:`dominance`), ties by frequency.

Cost: O(k log k) for the orderings; :func:`dominance` O(nnz(D) k + (m + p) n1 k).
"""

from __future__ import annotations

import numpy as np

__all__ = ["band_order", "dominance", "dominance_order", "lowest_order"]


def lowest_order(omega) -> np.ndarray:
    """Indices of the modes by ascending frequency."""
    return np.argsort(np.asarray(omega), kind="stable")


def band_order(omega, band, sigma) -> np.ndarray:
    r"""Indices: the modes with :math:`w_1 \le \omega \le w_2` ascending, then the rest by
    :math:`|\omega^2 - \sigma|`."""
    omega = np.asarray(omega)
    w1, w2 = band
    inside = (omega >= w1) & (omega <= w2)
    first = np.flatnonzero(inside)[np.argsort(omega[inside], kind="stable")]
    rest = np.flatnonzero(~inside)
    rest = rest[np.argsort(np.abs(omega[rest] ** 2 - sigma), kind="stable")]
    return np.concatenate([first, rest]).astype(int)


def dominance(omega, Phi, D, F, L, band) -> np.ndarray:
    r"""Dominance of each mode: the largest gain of its modal term over the band.

    With M-normalised shapes and modal damping :math:`\zeta_i = \varphi_i^TD\varphi_i / (2\omega_i)`
    (exact for proportional damping) the transfer function is approximately
    :math:`\sum_i R_i / (s^2 + 2\zeta_i\omega_i s + \omega_i^2)` with the rank-one residues
    :math:`R_i = (L\varphi_i)(F^T\varphi_i)^T`, :math:`\|R_i\|_2 = \|L\varphi_i\|\,\|F^T\varphi_i\|`.
    The dominance is that term's gain at the band frequency nearest :math:`\omega_i`,
    :math:`w_i = \min(\max(\omega_i, w_1), w_2)`:

    .. math::

        d_i = \frac{\|L\varphi_i\|\,\|F^T\varphi_i\|}
                   {\max\bigl(|\omega_i^2 - w_i^2 + 2j\zeta_i\omega_i w_i|,\ 10^{-12}\omega_i^2\bigr)} ,

    the resonance peak :math:`\|R_i\| / (2\zeta_i\omega_i^2)` for a mode in the band, the
    static or high-frequency gain for one outside (the floor keeps undamped in-band modes finite).

    Parameters
    ----------
    omega : ndarray (k,)
    Phi : ndarray (n1, k)
        M-normalised shapes.
    D : sparse (n1, n1)
    F : ndarray (n1, m)
    L : ndarray (p, n1)
    band : (w1, w2)

    Returns
    -------
    ndarray (k,)
    """
    omega = np.abs(np.asarray(omega, dtype=float))
    zeta = np.einsum("ij,ij->j", Phi, D @ Phi) / (2.0 * np.where(omega > 0, omega, 1.0))
    gain = np.linalg.norm(L @ Phi, axis=0) * np.linalg.norm(F.T @ Phi, axis=0)
    w = np.clip(omega, band[0], band[1])
    den = np.abs(omega ** 2 - w ** 2 + 2j * zeta * omega * w)
    return gain / np.maximum(den, 1e-12 * np.maximum(omega ** 2, np.finfo(float).tiny))


def dominance_order(omega, dom) -> np.ndarray:
    """Indices by descending dominance, ties by ascending frequency."""
    return np.lexsort((np.asarray(omega), -np.asarray(dom))).astype(int)
