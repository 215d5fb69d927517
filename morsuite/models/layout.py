r"""How second-order models are laid out in files: sign conventions and first-order blocks.

Shared by the loaders of :mod:`.io` (``.mat``) and :mod:`.mtx` (Matrix Market).

Sign conventions (``sign=``):

* ``"physical"``: :math:`M \ddot x + D \dot x + K x + G^T z = F u` as stored.
* ``"mess"``: D and K are stored negated, as in the M.E.S.S. files, whose
  first-order realization is :math:`A = [[0, I, 0], [K_f, D_f, -G^T], [G, 0, 0]]`,
  :math:`E = \mathrm{blkdiag}(I, M, 0)`, so :math:`D = -D_f`, :math:`K = -K_f`.

When no realization is stored to check the convention against, the stiffness
tells: a physical K has a nonnegative diagonal (:math:`e_i^T K e_i \ge 0` for
positive semidefinite K), so a K whose diagonal is nowhere positive and somewhere
negative was read with the wrong sign.

Input and output matrices come either in second-order form (F: n1 x m,
L: p x n1) or as the first-order B, C of the realization above, with
``B = [0; F; 0]`` (2 n1 or 2 n1 + n2 rows) and ``C = [L, 0, 0]``; the loaders take
the velocity block of B and the position block of C and refuse a B or C with
anything outside those blocks (a velocity output cannot be expressed as L x).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ..errors import FileFormatError, InputError

__all__ = ["SIGNS", "existing", "check_sign_option", "to_physical", "check_stiffness_sign",
           "input_matrix", "output_matrix"]

SIGNS = ("mess", "physical")


def existing(path) -> Path:
    """``path`` as a Path; FileFormatError unless it is an existing file."""
    p = Path(path)
    if not p.is_file():
        raise FileFormatError(f"model file {str(p)!r} does not exist or is not a file")
    return p


def check_sign_option(sign):
    """``sign`` if it is one of :data:`SIGNS`; InputError otherwise."""
    if sign not in SIGNS:
        raise InputError(f"sign must be 'mess' or 'physical'; got {sign!r}")
    return sign


def to_physical(D, K, sign):
    """(D, K) in the physical convention from the stored ones."""
    return (-D, -K) if sign == "mess" else (D, K)


def check_stiffness_sign(K, sign, where):
    """Refuse a K (physical convention) whose diagonal is nowhere positive and somewhere negative."""
    d = K.diagonal() if sp.issparse(K) else np.diag(np.asarray(K))
    if d.size and d.max() <= 0 and d.min() < 0:
        other = "physical" if sign == "mess" else "mess"
        raise FileFormatError(
            f"{where}: with sign={sign!r} the stiffness K has no positive diagonal entry (max {d.max():.3g}); "
            f"the file does not follow the sign={sign!r} convention (try sign={other!r}, or "
            f"check_sign=False for a deliberately unstable model)")


def _dense(X):
    return X.toarray() if sp.issparse(X) else np.atleast_2d(np.asarray(X))


def input_matrix(B, n1, where, key="B"):
    """F from a second-order F (n1 rows) or a first-order B = [0; F; 0] (at least 2 n1 rows)."""
    B = _dense(B)
    if B.shape[0] == n1:
        return B
    if B.shape[0] < 2 * n1:
        raise FileFormatError(f"{where}: {key} has {B.shape[0]} rows; expected n1 = {n1} (second-order F) "
                              f"or at least 2 n1 = {2 * n1} (first-order B = [0; F; 0])")
    if np.any(B[:n1] != 0) or np.any(B[2 * n1:] != 0):
        raise FileFormatError(f"{where}: {key} has nonzeros outside its velocity block (rows n1 = {n1} to "
                              f"2 n1 = {2 * n1}); not the first-order layout B = [0; F; 0] of a second-order model")
    return B[n1:2 * n1]


def output_matrix(C, n1, where, key="C"):
    """L from a second-order L (n1 columns) or a first-order C = [L, 0, 0] (at least 2 n1 columns)."""
    C = _dense(C)
    if C.shape[1] == n1:
        return C
    if C.shape[1] < 2 * n1:
        raise FileFormatError(f"{where}: {key} has {C.shape[1]} columns; expected n1 = {n1} (second-order L) "
                              f"or at least 2 n1 = {2 * n1} (first-order C = [L, 0, 0])")
    if np.any(C[:, n1:] != 0):
        raise FileFormatError(f"{where}: {key} has nonzeros outside its first n1 = {n1} columns (velocity "
                              "outputs); morsuite models have position outputs y = L x only")
    return C[:, :n1]
