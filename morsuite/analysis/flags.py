r"""Flags on a reduced model's reported errors: is it worse than the zero model?

The zero model :math:`T_r = 0` has error :math:`\|T - 0\| = \|T\|` in every norm, at no
cost. A reduced model whose error is at or above that, :math:`\|T - T_r\| \ge \|T\|`,
is no approximation in that norm, whatever its other merits (e.g. the paper's IRKA at
r = 2 on a 3x3 MIMO chain in the band norm): the study tables, the CLI's JSON and the
verdict texts say so (:func:`worse_than_zero`). The norms compared are the ones
reported, by the values reported (the H-infinity values are the largest peaks found,
lower bounds; the comparison is of those values): ``band``,
:math:`\max_\omega \sigma_{\max}(T - T_r)` against :math:`\max_\omega \sigma_{\max}(T)` over the
frequencies of a grid (``max_abs_error`` against the full model's peak there); ``h2``
and ``hinf`` (``h2_rel_error >= 1``, ``hinf_rel_error >= 1``); for a simulation
``max_output`` and ``l2_output`` (the output error against the output itself).
"""

from __future__ import annotations

import math
from numbers import Real

__all__ = ["worse_than_zero"]


def _finite_pair(pair):
    if pair is None:
        return None
    err, ref = pair
    if not all(isinstance(x, Real) and not isinstance(x, bool) for x in (err, ref)):
        return None
    err, ref = float(err), float(ref)
    if math.isnan(err) or math.isnan(ref) or math.isinf(ref):
        return None
    return err, ref


def worse_than_zero(**pairs) -> list[str]:
    r"""The norms in which a reduced model's error is at or above the zero model's.

    Parameters
    ----------
    **pairs : (float, float) or None
        ``name=(error, reference)`` per norm: :math:`\|T - T_r\|` and :math:`\|T\|` in that
        norm (the reference is the zero model's error). The names used by morsuite:
        ``band`` (:math:`\max_\omega \sigma_{\max}(T - T_r)` and
        :math:`\max_\omega \sigma_{\max}(T)` on one grid), ``h2``, ``hinf``, and for a
        simulation ``max_output`` (:math:`\max_t \|y - y_r\|_2` against
        :math:`\max_t \|y\|_2`) and ``l2_output`` (the same in :math:`L_2` over the horizon).
        A relative error may be passed as ``(rel, 1.0)``. A norm given as None, or with a
        None or NaN value or an infinite reference, is not judged.

    Returns
    -------
    list of str
        The names with ``error >= reference`` (an infinite error, of an unstable reduced
        model, counts), in the order given; empty when the reduced model beats the zero
        model in every norm judged. Cost: none.
    """
    out = []
    for name, pair in pairs.items():
        p = _finite_pair(pair)
        if p is not None and p[0] >= p[1]:
            out.append(name)
    return out
