r"""``dominant``: modal truncation by dominance over the band, the poles from SAQDPA, with the static correction.

The dominant poles of the damped constrained quadratic problem come from the subspace-accelerated
quadratic dominant pole algorithm (:mod:`.qdpa`: Newton's method on :math:`1/T` with one sparse LU
per step, Rommes and Martins 2008), ranked by their dominance over the band
(:math:`\sigma_{\max}(R_i) / \operatorname{dist}(\lambda_i, j[\omega_1, \omega_2])`), not only among
the lowest undamped modes. The basis (:class:`~.reducer.Dominant`) is

.. math::

    V = \operatorname{orth}\bigl[X_0,\ \operatorname{Re}x_1,\ \operatorname{Im}x_1,\ \operatorname{Re}x_2, \dots\bigr],
    \qquad X_0 = [I\ 0]\,S(0)^{-1}[F; 0],

the static response first (``static_correction``, from the iteration's first step at
:math:`s = 0`, so it costs no extra LU) and the shapes by decreasing dominance, phase-normalised (a
proportionally damped mode is real: one column); the model is the Galerkin projection
:math:`\hat M = V^TMV` etc., so symmetric positive definite M, K and semidefinite D stay so (stable)
and :math:`\hat T(0) = T(0)`. For a proportionally damped model :math:`\hat T` keeps each chosen pole
exactly.

``reduce(r)``: with ``tol`` None, Newton steps until the converged poles fill r columns; with
``tol``, until the band error estimate (:mod:`morsuite.reducers.adaptive.estimate`: the modal model
against the Galerkin model of the whole search space, which holds it) meets ``tol``; both within
``max_lus``. The search space, shifts and poles are kept across calls.

Options (:attr:`Dominant.OPTIONS`): ``tol`` (None), ``max_lus`` (40), ``eig_tol`` (1e-8),
``static_correction`` (True), ``band``, ``grid`` (400), ``peak_grid`` (200), ``orth_tol``.
Symmetric M, D, K only (the residues use right eigenvectors as left ones).

Cost: one sparse LU per Newton step (the first real), m + p solves each, the Ritz problem of twice
the search space's size per step (:math:`O(k^3)`, k its columns), the residuals of the candidate Ritz
pairs (three sparse products each). ``info``: ``poles``, ``dominance``, ``pole_residuals``,
``poles_converged``, ``points`` (the shifts), ``estimate_max``, ``estimate_grid``, ``estimate``,
``history``, ``lu_count``, ``status`` ("direct", "converged", "budget", "cap", "stalled").
Design note and measurements: ``docs/design/adaptive.md``.
"""

from .reducer import Dominant

__all__ = ["Dominant"]
