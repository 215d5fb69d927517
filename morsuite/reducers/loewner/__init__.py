r"""``loewner``: data-driven reduction in the Loewner framework, from samples of :math:`T(j\omega)`.

The method needs the full model only through its transfer function on a band,
:math:`H_k = T(j\omega_k)` (p x m) at ``samples`` log-spaced frequencies (or the frequencies of
``omega``): the response a comparison already computes (:func:`morsuite.analysis.band_response`
keeps it in the model's memo of :math:`T(j\omega)`, which serves these samples without an LU;
on its own, one sparse LU of :math:`S(j\omega_k)` per frequency). The real system's samples at
:math:`-j\omega_k` are :math:`\overline{H_k}`, so the data are closed under conjugation.

The frequencies are split into left and right points (``partition``: alternating, or lower and
upper half), each with its conjugate, and the Loewner pencil of the data (:mod:`.pencil`)

.. math::

    \mathbb L_{ij} = \frac{H(\lambda_i) - H(\mu_j)}{\lambda_i - \mu_j},\qquad
    (\mathbb L_s)_{ij} = \frac{\lambda_iH(\lambda_i) - \mu_jH(\mu_j)}{\lambda_i - \mu_j}

is brought to real form by a unitary transformation of each conjugate pair. Where it is regular,
:math:`(E, A, B, C) = (-\mathbb L, -\mathbb L_s, V, W)` interpolates every sample; its rank is the
McMillan degree of the data. The model of order r projects it on the r leading singular vectors of
:math:`[\mathbb L\ \mathbb L_s]` and :math:`[\mathbb L;\ \mathbb L_s]` (Antoulas, Lefteriu and Ionita
2017, Algorithm 1), so r is chosen by the pencil's singular values (``info["singular_values"]``,
normalised), and r above its numerical rank (``rank_tol``) is capped with a
:class:`~morsuite.errors.RankWarning`. The result is a first-order descriptor model with r states;
it is real, not guaranteed stable (checked: a :class:`~morsuite.errors.StabilityWarning` and
``info["stable"] = False``), and it matches :math:`T` where the data do: the band.

Options (:attr:`Loewner.OPTIONS`): ``band`` (the model's), ``samples`` (200, the grid of a
comparison's band response), ``omega`` (given frequencies instead), ``partition``
("alternating"), ``rank_tol`` (1e-12), ``refined`` (True: the samples refined in extended
precision, as the memo keeps them), ``solver_threads`` (0: automatic).

Cost: one sparse LU per sample not in the model's memo (``info["lu_count"]``; every sample is in
``lu_count_shared``, ``samples_from_memo`` says how many were served), then dense work on the
pencil of size (2 p k) x (2 m q) for k left and q right frequencies: two SVDs (once per reducer:
every r reuses them) and a projection per r. ``info`` also holds ``rank`` (numerical rank at
``rank_tol``), ``imag_dropped`` (the imaginary part the real form discarded, relative: rounding)
and ``setup_cost`` / ``setup_paid`` by parts (samples, pencil, svd). Design note, measurements and
the comparison with pyMOR's ``LoewnerReductor``: ``docs/design/loewner.md``.
"""

from .pencil import conjugate_points, loewner_pencil, project, real_form, truncation_bases
from .reducer import Loewner, sample_frequencies

__all__ = ["Loewner", "sample_frequencies", "conjugate_points", "loewner_pencil", "real_form", "truncation_bases",
           "project"]
