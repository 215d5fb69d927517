r"""``adaptive``: greedy rational interpolation, each new point where the estimated band error is largest.

The reduced model is the one-sided (Galerkin) projection onto a real orthonormal basis
:math:`V \subset \ker G` of second-order Krylov subspaces at expansion points
:math:`s_1, s_2, \dots` (:mod:`.points`): at each point, ``levels`` levels of SOAR from the inputs
:math:`F` and ``levels`` from the outputs :math:`L^T`, both from the one sparse LU of
:math:`S(s_k)`, and the real and imaginary parts of the vectors (so :math:`\bar s_k` is served too):

.. math::

    \hat M = V^TMV,\quad \hat D = V^TDV,\quad \hat K = V^TKV,\quad \hat F = V^TF,\quad \hat L = LV.

For a symmetric model (M, D, K symmetric) the basis holds both the right and the left Krylov
subspaces, so :math:`\hat T` matches :math:`T` and its first :math:`2\,\text{levels} - 1`
derivatives at every point (one-sided, as a two-sided projection would, at twice the size), and
symmetric positive definite :math:`M`, :math:`K` and semidefinite :math:`D` stay so: the reduced
model is stable (``info["definite"]``, ``info["stable"]``). A non-symmetric model gets ``levels``
moments per point.

**The greedy.** It starts at one point (``start``); then, repeatedly, it estimates the error
over the band without an LU (:mod:`.estimate`: the difference to the Galerkin model of a richer
space U, V plus ``enrich_levels`` further levels at every point, on ``grid`` log-spaced
frequencies and the models' band poles) and puts the next point :math:`j\omega` at the largest peak
of the estimate not sampled yet. The first solve at the new point gives :math:`T(j\omega)`, so every
step also measures the true error of the model before it where the estimate was largest
(``info["history"]``). It stops when the basis has r columns (``tol`` None), when the estimate
meets ``tol`` (relative to the band peak of :math:`\sigma_{\max}(T)`; with ``validate`` > 0 only
once that many true samples at the estimate's next peaks are within ``tol`` too: a sample above
it becomes a point, its LU reused), or when ``max_lus`` LUs are spent.

**Compression** (``compress``, "bt" or "irka-fo"): ``reduce(r)`` then returns r first-order states:
the named reducer applied to the greedy's model as a surrogate (an Index3Model of its matrices, no
LU of the full model), the surrogate's tolerance tightened (from ``tol``, or 1e-4) until its
estimate is at most a tenth of the distance between it and the compressed model. The estimate
of the returned model is the surrogate's plus that distance (``info["compress"]``). The route to
an H2-optimal model at a few LUs of the full model: on tcom(2000) and dsms(1000) it gives
irka-fo's H2 errors at a tenth of irka-fo's LUs (``docs/design/adaptive.md``).

**Honesty.** The estimate is :math:`\sigma_{\max}(T_U - T_V)`, not a bound: it relies on U being much
better than V. ``info["validated"]`` holds, for the returned model, the true error at every
validation sample beside the estimate there, ``info["history"]`` the true error of each model at
the point chosen next; ``docs/design/adaptive.md`` records how far estimate and truth are apart on
the test models.

Options (:attr:`Adaptive.OPTIONS`): ``tol`` (None), ``max_lus`` (40), ``levels`` (6),
``enrich_levels`` (2), ``validate`` (0), ``grid`` (400), ``peak_grid`` (200), ``band`` (the model's),
``start`` ("auto": the real point :math:`\sqrt{\omega_1\omega_2}`), ``compress`` (None), ``orth_tol``,
``reorth``.

Cost: one sparse LU per point (complex, except a real start) and per validation sample, released
before the next (memory: one LU at a time); per point ``(levels + enrich_levels)`` block solves per
side (m and p columns); per greedy step the estimate: :math:`O(n_1 c^2)` to orthonormalise the
enrichment against the basis (c columns) plus three sparse products with the new columns, and two
dense eigenproblems of sizes 2r and :math:`2\dim U`. ``info``: ``status`` ("direct": r columns
reached without ``tol``; "converged": the estimate met ``tol``; "budget": ``max_lus`` reached;
"cap": order r reached first; "stalled": every peak of the estimate sampled), ``estimate_max``,
``estimate_grid``, ``estimate``, ``peak``, ``points``, ``validated``, ``samples_at_points``,
``history``, ``lu_count``, ``lu_count_shared``, ``setup_reused``, ``solves``, ``stable``,
``definite``. Design note and measurements: ``docs/design/adaptive.md``.
"""

from .reducer import Adaptive

__all__ = ["Adaptive"]
