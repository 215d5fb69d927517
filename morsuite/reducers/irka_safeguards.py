r"""IRKA's safeguards: from raw solutions to a well-posed projection.

The raw bases of an IRKA iteration can be numerically rank deficient (shifts
beyond the model's numerical order), ill-conditioned (localised solutions of
chain-like models), or give an ill-conditioned oblique projection. These
functions make the projection well posed; :class:`~.irka_engine.IRKABase`
applies them (options of its table, defaults in brackets):

* Orthonormalisation (``orthonormalization`` ["auto"], ``rank_tol`` [1e-14],
  ``ill_cond_tol`` [1e-8], :func:`orthonormal_basis`): Householder QR + SVD
  (:func:`~morsuite.linalg.dense.orth`), or column-pivoted Gram-Schmidt
  (:func:`~morsuite.linalg.orthonormal.gram_schmidt`), which keeps the rounding
  of each entry relative to the entries combined; ``"auto"`` uses Householder
  and redoes a basis by Gram-Schmidt when its smallest kept relative singular
  value is below ``ill_cond_tol`` (:func:`ill_conditioned`), or when the
  previous iteration's was. Directions of relative singular value below
  ``rank_tol`` are dropped.
* Oblique selection (``oblique_tol`` [1e-4], :func:`oblique_selection`): with
  the SVD :math:`W^T V = U \Sigma Z^T`, only the directions
  :math:`V Z_{:,1:k}`, :math:`W U_{:,1:k}` with
  :math:`\sigma_i > \mathrm{oblique\_tol}\,\sigma_1` are kept; the others give a
  near-singular reduced mass matrix and spurious poles of negligible residue.
* Singular shifts (``shift_perturbation`` [1e-6], :func:`perturb_shifts`): a
  shift at a pole of the full model (singular saddle matrix) and its conjugate
  are multiplied by 1 + ``shift_perturbation`` and the solves retried.
* A transfer function that vanishes in the tangential directions (zero bases,
  :math:`W^T V = 0`, no finite pole) leaves nothing to reduce and raises
  :class:`~morsuite.errors.ModelError` (:func:`zero_transfer_error`).

Cost: one QR + SVD (or Gram-Schmidt) of each n1 x k basis, :math:`O(n_1 k^2)`
flops, and a k x k SVD; no sparse LU. Measurements: ``docs/design/irka.md``.
"""

from __future__ import annotations

import numpy as np

from ..errors import ModelError
from ..linalg.dense import orth
from ..linalg.orthonormal import gram_schmidt

__all__ = ["orthonormal_basis", "ill_conditioned", "oblique_selection", "perturb_shifts", "zero_transfer_error"]

_ZERO_MSG = ("{name}: {what}: the transfer function vanishes in the tangential directions (a zero input or "
             "output matrix, or inputs acting only on constrained coordinates); nothing to reduce")


def zero_transfer_error(name, what) -> ModelError:
    """The error raised when reducer ``name`` finds ``what`` (nothing to reduce)."""
    return ModelError(_ZERO_MSG.format(name=name, what=what))


def orthonormal_basis(X, how, rank_tol, ill_cond_tol, previous_ill=False):
    """(Q, s, gram_schmidt_used): an orthonormal basis of the numerical range of X.

    ``how``: ``"gram-schmidt"``, ``"householder"`` or ``"auto"`` (Householder, redone by
    Gram-Schmidt when the kept singular values ``s`` fall below ``ill_cond_tol`` relative,
    and straight away when ``previous_ill``: the previous bases were ill-conditioned, these
    will be too). ``s`` are singular values (Householder) or residual norms (Gram-Schmidt).
    """
    if how == "gram-schmidt":
        return (*gram_schmidt(X, rank_tol), True)
    if how == "auto" and previous_ill:
        return (*gram_schmidt(X, rank_tol), True)
    Q, s = orth(X, rank_tol)
    if how == "auto" and Q.shape[1] and s[Q.shape[1] - 1] < ill_cond_tol * s[0]:
        return (*gram_schmidt(X, rank_tol), True)
    return Q, s, False


def ill_conditioned(s, k, ill_cond_tol) -> bool:
    """Whether the k-th of the singular values s (of a basis with k kept columns) is below
    ``ill_cond_tol`` relative to the largest."""
    return bool(s.size > 0 and s[min(k, s.size) - 1] < ill_cond_tol * s[0])


def oblique_selection(V, W, oblique_tol, name):
    """Orthonormal V, W cut to a common order and to a well-conditioned W^T V.

    Returns (V, W, k, k_rank): k_rank = min of the column counts, k <= k_rank the order
    kept by the selection (``oblique_tol`` 0: k = k_rank, no SVD). Raises ModelError when
    nothing is left (``name``: the reducer, for the message).
    """
    k = min(V.shape[1], W.shape[1])
    if k == 0:
        raise zero_transfer_error(name, "the projection bases have rank 0")
    V, W = V[:, :k], W[:, :k]
    k_rank = k
    if oblique_tol > 0:
        U_, s_, Zt_ = np.linalg.svd(W.T @ V)
        k = int(np.sum(s_ > oblique_tol * s_[0])) if s_.size and s_[0] > 0 else 0
        if k == 0:
            raise zero_transfer_error(name, "W^T V = 0")
        V, W = V @ Zt_[:k].T, W @ U_[:, :k]
    return V, W, k, k_rank


def perturb_shifts(alpha, bad, eps):
    """(alpha', count): the shifts equal to ``bad`` or its conjugate (all when ``bad`` is None)
    multiplied by 1 + eps."""
    idx = (np.arange(alpha.size) if bad is None
           else np.flatnonzero(np.isclose(alpha, bad) | np.isclose(alpha, np.conj(bad))))
    alpha = alpha.copy()
    alpha[idx] = alpha[idx] * (1 + eps)
    return alpha, idx.size
