r"""Solves at the reduced model's mirrored poles: the pole-residue value and the tail cross term :math:`t_2`.

One sparse LU per real pole or conjugate pair :math:`-\lambda_k` serves two right-hand
sides: :math:`Fb_k` (the pole-residue cross term :math:`\langle T, T_r\rangle`) and
:math:`W\tilde b_k` (the error-Gramian route's :math:`t_2 = \langle G_W, G_{W_r}\rangle`,
:mod:`morsuite.norms.error_gramian`). Each solve is refined in long double where its
unrefined error could matter: where the caller gives a ``budget`` (the absolute error of
:math:`\|T - T_r\|^2` that the unrefined solves may add, a hundredth of ``rtol`` times
the square in :func:`~morsuite.norms.h2.h2_error`), a solve whose contribution to
:math:`t_2`, estimated with :data:`~morsuite.linalg.h2.UNREFINED_UNIT` (a measured unit), fits its share
of it is not refined. The refinement's long-double residual cost about 1.5 times the
LU and its solve on tcom(2000) (``docs/design/norms.md``, "Cost", 2026-11-26); the
pole-residue value of unrefined solves keeps the unrefined unit in its floor, so that
it stays an honest (wider) second route.
"""

from __future__ import annotations

import numpy as np

from ..linalg.h2 import EPS, UNREFINED_UNIT, modal_form, pole_residue_squared
from ._fom import FomResponse
from .error_gramian import residual_factor

__all__ = ["mirrored_solves"]

LD = np.longdouble
CLD = np.clongdouble


def mirrored_solves(fom, arrays, rom, norm2, floor2, refine, eg=None, factors=None, budget=None):
    """Solves at the mirrored poles -lambda_k (one LU per real pole or conjugate pair): the pole-residue
    value of ||T - Tr||^2 with its floor, and, given the error-Gramian parts ``eg``, the tail cross term t2
    with its error (the same LUs serve both). ``budget``: None refines every solve ``refine`` times; a
    float skips the refinement of a solve whose unrefined t2 contribution's error is within
    ``budget / solves`` (module docstring). Returns (e2, floor of e2, record, (t2, t2 error) or None)."""
    E, A, B, C, D = arrays
    m = B.shape[1]
    Wr = None
    if eg is not None:
        W1, W2 = residual_factor(fom, factors)
        Wr = E @ eg.rom_adi.U
        Bx = np.hstack([B, Wr])
    else:
        Bx = B
    modal = modal_form(E, A, Bx, C, D, rom=rom)
    if not np.isfinite(modal.kappa):
        return None, np.inf, {"kappa": np.inf, "lu_count": 0, "reason": "defective reduced model"}, None
    Bw = modal.B[:, m:]
    modal.B = modal.B[:, :m]
    idx, weight, paired = modal.pairs()
    # refined: an unrefined solve next to a slow or lightly damped pole of the model is off by about
    # kappa eps, 1e-12 of T(-lambda_k) on the TCOM, which the cancellation of the three terms amplifies
    ev = FomResponse(fom, refine=refine)
    L = np.asarray(fom.L, dtype=LD)
    n1 = fom.n1
    share = None if budget is None or Wr is None else budget / max(idx.size, 1)
    cross = t2 = 0.0 + 0.0j
    cross_abs = cross_err = t2_abs = t2_err = 0.0
    refined = 0
    for k, wk in zip(idx, weight):
        s = -modal.poles[k]
        rhs = [fom.F @ modal.B[k]]
        if Wr is not None:
            w1, w2 = W1 @ Bw[k], W2 @ Bw[k]
            rhs.append(w2 + s * (fom.M @ w1) + fom.D @ w1)
        rhs = np.column_stack(rhs)
        lu, x = ev._first(s, rhs)
        X = np.asarray(x[:n1], dtype=complex)
        LX = fom.L @ X.real + 1j * (fom.L @ X.imag)
        unit = UNREFINED_UNIT
        if refine and (share is None or 2.0 * wk * abs(np.sum(modal.C[:, k] * LX[:, 1])) * unit > share):
            X = ev._refined(s, lu, rhs, x)
            LX = (L @ X.real) + 1j * (L @ X.imag).astype(CLD)
            unit = ev.last_unit
            refined += 1
        t = complex(np.sum(modal.C[:, k] * LX[:, 0]))  # in long double where refined, then rounded
        cross += wk * (t.real if paired else t)
        cross_abs += wk * abs(t)
        cross_err += wk * abs(t) * unit
        if Wr is not None:
            tau = complex(np.sum(modal.C[:, k] * LX[:, 1]))
            t2 += wk * (tau.real if paired else tau)
            t2_abs += wk * abs(tau)
            t2_err += wk * abs(tau) * (unit + 4.0 * EPS)
    cross = complex(cross)
    e2, floor, parts = pole_residue_squared(norm2, floor2, cross, cross_abs, modal, cross_err)
    e_est, tr = np.sqrt(max(e2, 0.0)), parts["rom_norm"]
    rec = {"value": float(e_est), "squared": float(e2), "cross": cross.real, "cross_imag": cross.imag,
           "rom_norm": float(tr), "kappa": modal.kappa, "poles": int(modal.poles.size),
           "solves": int(idx.size), "refined_solves": refined, "lu_count": ev.lu_count,
           "lu_shifts": list(ev.shifts), "floor_squared": float(floor), "cross_error": float(cross_err)}
    tail = None
    if Wr is not None:
        # the modal form's rounding perturbs G_Wr by about eps kappa relative
        t2_err += 2.0 * EPS * modal.kappa * np.sqrt(max(eg.t1, 0.0) * eg.t3) + 2.0 * EPS * t2_abs
        t2_err += eg.t2_rounding(t2_abs)
        tail = (float(complex(t2).real), float(t2_err))
    return e2, floor, rec, tail
