r"""Level-set test of the H-infinity norm: the Hamiltonian matrix of a dense realization.

For a stable :math:`G(s) = C(sI - A)^{-1}B + D` and a level :math:`\gamma > \sigma_{\max}(D)`
(Boyd, Balakrishnan and Kabamba 1989; Boyd and Balakrishnan 1990; Bruinsma and Steinbuch
1990), :math:`\gamma` is a singular value of :math:`G(j\omega)` if and only if
:math:`j\omega` is an eigenvalue of

.. math::

    H(\gamma) = \begin{bmatrix} A_\gamma & -\gamma B R^{-1} B^T \\
                                \gamma C^T S^{-1} C & -A_\gamma^T \end{bmatrix},\qquad
    A_\gamma = A - B R^{-1} D^T C,

:math:`R = D^TD - \gamma^2 I`, :math:`S = DD^T - \gamma^2 I`. As
:math:`\sigma_{\max}(G(j\omega))` is continuous and tends to :math:`\sigma_{\max}(D) < \gamma`,
no purely imaginary eigenvalue means :math:`\|G\|_{\mathcal H_\infty} < \gamma`; the
imaginary eigenvalues :math:`j\omega_i` are the frequencies where some singular value
crosses :math:`\gamma`.

Rounding: the eigenvalues are those of :math:`H` after a diagonal balancing
(:func:`scipy.linalg.matrix_balance`), computed by the unstructured QR algorithm, so an
imaginary eigenvalue comes back with a real part of about
:math:`\varepsilon\,\|H_b\|\,\kappa(\lambda)`. An eigenvalue counts as imaginary when
:math:`|\mathrm{Re}\,\lambda| \le` ``rel_tol`` :math:`\cdot\|H_b\|_1` (default
:math:`\sqrt\varepsilon`, which covers condition numbers up to
:math:`10^{-2}/\sqrt\varepsilon`, i.e. all but nearly coalescing crossings, whose
peak exceeds :math:`\gamma` by a relative amount of the order of the rounding). The test
is thus generous: it may report eigenvalues near the axis that are not on it (near a
local maximum of a singular value just below :math:`\gamma`, near a lightly damped
pole); the caller checks each reported frequency (:mod:`morsuite.analysis.hinf`).

Cost: one dense nonsymmetric eigenvalue problem of order :math:`2n` (about
:math:`25 n^3` flops; measured in ``docs/design/norms.md``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

from ..errors import InputError

__all__ = ["hamiltonian", "level_set", "LevelSet"]

EPS = np.finfo(float).eps


def hamiltonian(A, B, C, D, gamma: float) -> np.ndarray:
    r"""The Hamiltonian matrix :math:`H(\gamma)` of :math:`(A, B, C, D)` (module docstring), order 2n.

    Raises
    ------
    InputError
        ``gamma`` is not above :math:`\sigma_{\max}(D)` (then :math:`R` or :math:`S` is singular),
        or the shapes do not match.
    """
    A, B, C, D = (np.asarray(X, dtype=float) for X in (A, B, C, D))
    n, m, p = A.shape[0], B.shape[1], C.shape[0]
    if A.shape != (n, n) or B.shape[0] != n or C.shape[1] != n or D.shape != (p, m):
        raise InputError(f"hamiltonian: shapes A {A.shape}, B {B.shape}, C {C.shape}, D {D.shape} do not match")
    dmax = float(np.linalg.norm(D, 2)) if D.size else 0.0
    if not (np.isfinite(gamma) and gamma > dmax):
        raise InputError(f"gamma must exceed sigma_max(D) = {dmax:.6e}; got {gamma!r}")
    g2 = gamma * gamma
    if dmax == 0.0:
        Ag, BRB, CSC = A, B @ B.T / gamma, C.T @ C / gamma  # R = S = -gamma^2 I
        return np.block([[Ag, BRB], [-CSC, -Ag.T]])
    R = D.T @ D - g2 * np.eye(m)
    S = D @ D.T - g2 * np.eye(p)
    Ri = np.linalg.inv(R)
    Ag = A - B @ Ri @ D.T @ C
    return np.block([[Ag, -gamma * B @ Ri @ B.T], [gamma * C.T @ np.linalg.solve(S, C), -Ag.T]])


@dataclass
class LevelSet:
    """Result of :func:`level_set`.

    ``frequencies``: :math:`|\\mathrm{Im}\\,\\lambda| \\ge 0` of the eigenvalues counted imaginary
    (sorted, each once); ``real_parts``: their :math:`|\\mathrm{Re}\\,\\lambda|`; ``threshold``: the
    absolute tolerance used; ``norm``: :math:`\\|H_b\\|_1`; ``order``: 2n; ``closest``: the smallest
    :math:`|\\mathrm{Re}\\,\\lambda| / \\|H_b\\|_1` over all eigenvalues (how near the test came).
    """

    gamma: float
    frequencies: np.ndarray
    real_parts: np.ndarray
    threshold: float
    norm: float
    order: int
    closest: float
    extra: dict = field(default_factory=dict)

    @property
    def crossed(self) -> bool:
        """Whether some eigenvalue counted as imaginary (no certificate at this level)."""
        return bool(self.frequencies.size)


def level_set(A, B, C, D, gamma: float, *, rel_tol: float | None = None) -> LevelSet:
    r"""Eigenvalues of :math:`H(\gamma)` on or near the imaginary axis (module docstring).

    Parameters
    ----------
    A, B, C, D : ndarray
        A standard realization (``A`` stable; not checked here).
    gamma : float
        The level, above :math:`\sigma_{\max}(D)`.
    rel_tol : float, optional
        :math:`|\mathrm{Re}\,\lambda| \le` ``rel_tol`` :math:`\|H_b\|_1` counts as imaginary
        (default :math:`\sqrt\varepsilon`).

    Returns
    -------
    LevelSet
        No frequency: :math:`\|G\|_{\mathcal H_\infty} < \gamma` (up to the rounding stated in the
        module docstring).

    Notes
    -----
    Cost: one balanced dense eigenvalue computation of order 2n, no eigenvectors.
    """
    rel_tol = np.sqrt(EPS) if rel_tol is None else float(rel_tol)
    H = hamiltonian(A, B, C, D, gamma)
    Hb, _ = sla.matrix_balance(H, permute=False, separate=False)
    nrm = float(np.linalg.norm(Hb, 1))
    lam = sla.eigvals(Hb, overwrite_a=True, check_finite=False)
    re = np.abs(lam.real)
    thr = rel_tol * nrm
    near = re <= thr
    w, rp = np.abs(lam.imag[near]), re[near]
    order = np.argsort(w)
    w, rp = w[order], rp[order]
    # a conjugate pair +-j w, and the pair -conj(lambda), lambda split off the axis by rounding, give one
    # frequency each; distinct crossings closer than 1e-9 relative are one frequency too
    keep = np.ones(w.size, dtype=bool)
    keep[1:] = np.diff(w) > 1e-9 * w[1:]
    return LevelSet(float(gamma), w[keep], rp[keep], float(thr), nrm, int(H.shape[0]),
                    float(re.min() / nrm) if re.size and nrm > 0 else np.inf)
