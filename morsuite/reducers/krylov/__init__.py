r"""``krylov``: second-order Krylov moment matching (SOAR) through saddle-point solves.

At an expansion point :math:`s_0` the transfer function :math:`T(s) = LX(s)`,
:math:`S(s)[X; Z] = [F; 0]`, has the Taylor expansion
:math:`T(s_0+\sigma) = \sum_j \sigma^j LX_j` with, for
:math:`A_0 = s_0^2M + s_0D + K` and :math:`A_1 = 2s_0M + D`,

.. math::

    S(s_0)\begin{bmatrix} X_0 \\ * \end{bmatrix} = \begin{bmatrix} F \\ 0 \end{bmatrix},\qquad
    S(s_0)\begin{bmatrix} X_j \\ * \end{bmatrix}
    = -\begin{bmatrix} A_1X_{j-1} + MX_{j-2} \\ 0 \end{bmatrix}\quad (j \ge 1,\ X_{-1} = 0),

every solve one pair of triangular solves with the one sparse LU of
:math:`S(s_0) = [A_0\ G^T; G\ 0]`; :math:`\Pi` is never formed. The :math:`X_j`
lie in :math:`\ker G` and span the second-order Krylov subspace, of which SOAR
(Bai and Su, "SOAR: a second-order Arnoldi method for the solution of the
quadratic eigenvalue problem", SIAM J. Matrix Anal. Appl. 26(3):640-659, 2005;
its use for reducing second-order systems: Bai and Su, "Dimension reduction of
large-scale second-order dynamical systems via a second-order Arnoldi method",
SIAM J. Sci. Comput. 26(5), 2005) builds an orthonormal basis without the
numerical dependence of the raw moments (:mod:`.soar`). Several points give one
basis (:class:`~.soar.RealBasis`: real and imaginary parts of a complex point's
vectors, so it serves the conjugate point too), grown level by level, one point
after the other.

With :math:`V` (n1 x r, orthonormal, in :math:`\ker G`):

``sided="one"`` (default)
    :math:`\hat M = V^TMV`, :math:`\hat D = V^TDV`, :math:`\hat K = V^TKV`,
    :math:`\hat F = V^TF`, :math:`\hat L = LV` (congruence): with :math:`V`
    spanning :math:`X_0, \dots, X_{k-1}` at a point, the first k moments
    :math:`T^{(j)}(s_0)/j!` are matched; symmetric positive definite M, K and
    semidefinite D stay so and the reduced model is stable
    (``info["definite"]``, ``info["stable"]``).
``sided="two"``
    :math:`W` from the transposed solves (same LUs) started at :math:`L^T`, and
    :math:`\hat M = W^TMV` etc. (Petrov-Galerkin): k right and l left levels
    match k + l moments; stability is not guaranteed: checked, a
    :class:`~morsuite.errors.StabilityWarning` and ``info["stable"] = False``.

``directions="block"`` (default) takes all m inputs (p outputs) at every level,
so r columns hold about r/m levels; ``"tangential"`` one direction per point,
:math:`Fb` (:math:`L^Tc`), matching :math:`T^{(j)}(s_0)b` (:math:`c^TT^{(j)}(s_0)`),
the directions given or random unit vectors from ``seed`` (``info["directions"]``).

Options (:attr:`Krylov.OPTIONS`, recorded in ``info["options"]``): ``points``
("auto": the real point :math:`s_0 = \sqrt{\omega_1\omega_2}`, the band's geometric
mean; "band":
``npoints`` (3) points :math:`i\omega_k` log-uniform over the band; or a list),
``sided`` ("one"), ``directions`` ("block"), ``right_directions`` /
``left_directions`` (None), ``seed`` (0), ``orth_tol`` (1e-10, deflation),
``reorth`` (2 Gram-Schmidt passes), ``check_moments`` (True), ``moment_tol`` (1e-8).

**What is matched, measured.** A basis spanning k levels matches k moments (k + l
two-sided) in exact arithmetic; in floating point the reduced model's moments come from
solves with :math:`A_r(s_0) = s_0^2\hat M + s_0\hat D + \hat K`, whose condition can reach
1e15 (two-sided: :math:`W^TA(s_0)V` nearly singular). So each moment the basis spans is
measured: the full model's Taylor recurrence with the point's LU (one solve per moment and
column, kept across ``reduce`` calls) against the reduced model's (dense), relative error
per moment; ``info["moments"][i]`` holds ``moments_spanned`` (the levels' count),
``moment_errors``, ``moments`` (the leading moments within ``moment_tol``: what is claimed)
and ``moment_error`` (their largest error: the accuracy claimed). Fewer than spanned: an
:class:`~morsuite.errors.AccuracyWarning`. ``check_moments=False`` skips the measurement
(``moments`` is then the count spanned, ``moment_error`` None).

Cost: one sparse LU per distinct point (a conjugate pair shares one; complex
points factor in complex arithmetic), made on the first ``reduce`` and kept
with the basis, so a sweep over r pays the LUs once; then one saddle solve per
basis column and side (``info["solves"]``) and :math:`O(n_1 r^2)` of
orthogonalisation; the projection three sparse products with r columns; the
moment check one solve per moment and column (``info["moment_check_solves"]``; 1.2x
and 1.4x the time of r = 30 without it on tcom(2000) and fem_block(4000),
``docs/design/krylov.md``).
``info`` holds ``points``, ``moments`` (per point: levels in the basis,
moments spanned, matched and their measured errors), ``lu_count`` (LUs paid by this call), ``lu_count_shared``
(the points' LUs), ``setup_reused``, ``setup_cost`` / ``time_breakdown``
(``lu``, ``basis``), ``solves``, ``kernel_residual``
(:math:`\|GV\|_F/(\|G\|_F\sqrt r)`), ``definite`` (one-sided), ``stable``,
``deflated``. Design note and measurements: ``docs/design/krylov.md``.
"""

from .reducer import Krylov, expansion_points
from .soar import SOAR, RealBasis

__all__ = ["Krylov", "SOAR", "RealBasis", "expansion_points"]
