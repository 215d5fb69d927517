r"""The pole-residue core of exact H2 norms, shared by the norms and the H2-optimal reducers.

For a stable, strictly proper, real :math:`T` with Gramian factor
:math:`P \approx ZZ^T` and a reduced model with simple poles,
:math:`T_r(s) = \sum_k c_kb_k^T/(s-\lambda_k)` (Gugercin, Antoulas, Beattie 2008),

.. math::

    \|T - T_r\|_{\mathcal H_2}^2 = \|T\|_{\mathcal H_2}^2
        - 2\,\mathrm{Re}\sum_k c_k^T\,T(-\lambda_k)\,b_k
        + \sum_{k,l}\frac{(c_k^Tc_l)(b_l^Tb_k)}{-\lambda_k-\lambda_l}.

- :func:`norm_squared`: :math:`\|T\|^2 = \|LZ_p\|_F^2` plus the ADI tail
  (:func:`~morsuite.linalg.gramians.h2_tail`) from the model's cached factors,
  its absolute floor, and a record; cached per model and ADI options.
- :func:`modal_form` / :class:`Modal`: the pole-residue form of a dense
  realization, with the condition number :math:`\kappa` of its normalised
  eigenvector matrix.
- :func:`pole_residue_squared`: the three terms combined, with the absolute
  rounding floor of the result.

The cross term :math:`\sum_k c_k^TT(-\lambda_k)b_k` needs one saddle-point solve
per real pole or conjugate pair; who makes those solves is the caller's
business (:func:`morsuite.analysis.h2_error` makes them itself; the first-order
IRKA takes them from its next iteration). The three terms are of size
:math:`\|T\|^2` and cancel: relative accuracy is lost as
:math:`(\|T\|/\|T-T_r\|)^2` (``docs/design/norms.md``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ..errors import InputError
from .gramians import gramian_factors, h2_tail

__all__ = ["Modal", "modal_form", "norm_squared", "pole_residue_squared", "EPS", "UNREFINED_UNIT"]

EPS = np.finfo(float).eps
#: relative forward error assumed for solves that were not refined (their error is not measured): the
#: largest measured, 7.9e-12 (||T||^2 from unrefined LR-ADI solves on tcom(2000)), with margin; a
#: measured constant, so the floors that use it are estimates validated on those models, not bounds
UNREFINED_UNIT = 1e-10


@dataclass
class Modal:
    """Pole-residue form :math:`T_r(s) = \\sum_k c_k b_k^T / (s - \\lambda_k) + D` (see :func:`modal_form`)."""

    poles: np.ndarray     # (n,) complex
    C: np.ndarray         # (p, n) complex, columns c_k
    B: np.ndarray         # (n, m) complex, rows b_k^T
    D: np.ndarray         # (p, m)
    kappa: float          # condition number of the column-normalised eigenvector matrix

    def pairs(self):
        """Indices of the poles with Im >= 0 and their weights: 2 for one of a conjugate pair, 1 for a real pole.

        Falls back to every pole with weight 1 (and complex sums) when the set is not closed under
        conjugation to rounding.
        """
        lam = self.poles
        up = np.flatnonzero(lam.imag > 0)
        down = np.flatnonzero(lam.imag < 0)
        real = np.flatnonzero(lam.imag == 0)
        if up.size == down.size and np.allclose(np.sort_complex(lam[up]), np.sort_complex(np.conj(lam[down])),
                                                rtol=1e-12, atol=0):
            idx = np.concatenate([real, up])
            return idx, np.concatenate([np.ones(real.size), 2.0 * np.ones(up.size)]), True
        return np.arange(lam.size), np.ones(lam.size), False

    def self_inner(self):
        r""":math:`\|T_r - D\|_{\mathcal H_2}^2 = \sum_{k,l} (c_k^Tc_l)(b_l^Tb_k)/(-\lambda_k-\lambda_l)`
        and the sum of the moduli of its terms (for the rounding estimate)."""
        lam = self.poles
        terms = (self.C.T @ self.C) * (self.B @ self.B.T).T / (-(lam[:, None] + lam[None, :]))
        return float(np.sum(terms).real), float(np.sum(np.abs(terms)))


def modal_form(E, A, B, C, D, rom=None) -> Modal:
    r"""Pole-residue form of the realization :math:`(E, A, B, C, D)`, E nonsingular.

    With the eigenvalues :math:`\lambda_k` and right eigenvectors :math:`X` of
    :math:`(A, E)` (for a second-order ``rom``, those of ``rom.eig()``, computed
    on the balanced pencil), normalised to unit columns :math:`X_n`:
    :math:`[c_1, \dots] = CX_n`, :math:`[b_1, \dots]^T = X_n^{-1}E^{-1}B`.
    Its rounding perturbs the model by about :math:`\varepsilon\kappa(X_n)`.
    Cost: one QZ of the pencil, :math:`O(n^3)`.
    """
    if rom is not None and rom.kind == "second-order":
        lam, X = rom.eig()
    else:
        lam, X = sla.eig(A, E)
    if lam.size != A.shape[0] or not np.all(np.isfinite(lam)):
        raise InputError("rom: the pencil (A, E) has infinite eigenvalues; E is singular")
    Xn = X / np.linalg.norm(X, axis=0)
    with np.errstate(all="ignore"):
        kappa = float(np.linalg.cond(Xn))
    if not np.isfinite(kappa):
        kappa = np.inf
        Bm = np.full((lam.size, B.shape[1]), np.nan, dtype=complex)
    else:
        Bm = np.linalg.solve(Xn, np.linalg.solve(E, B))
    return Modal(lam, C @ Xn, Bm, np.asarray(D, dtype=float), kappa)


def norm_squared(fom, adi: dict):
    r""":math:`\|T\|_{\mathcal H_2}^2` of the index-3 model, its absolute floor, a record and the factors.

    :math:`\|LZ_p\|_F^2 + \mathrm{tr}(W^TQW)` from the model's cached Gramian
    factors (:func:`~morsuite.linalg.gramians.gramian_factors` with the LR-ADI
    options ``adi``). Returns ``(value, floor, record, factors)``; the value is
    cached in ``fom.cache`` next to the factors. Cost: the factors' LR-ADI run
    on the first call per model and options (``record["gramian_lu_count"]``),
    then products with the factors once, then nothing.

    The floor is an estimate of the error, validated against long-double
    quadratures, not a proved bound (``docs/design/norms.md``); it adds three
    measured parts with margins: the tail estimate's own error (the tail times
    the observability residual, factor 10), the rounding of the factor
    (:math:`2\varepsilon\sqrt{\mathrm{rank}}`, measured 2e-16 to 7e-16 relative),
    and the forward error of the shifted solves, :math:`2u` relative with
    :math:`u` the refined solves' estimated error (``solve_error`` of the
    controllability factor, whose solves are the refined ones; the observability
    factor enters only the tail, about ``tol`` of the value;
    :data:`UNREFINED_UNIT` for factors computed with ``refine=0``,
    whose solves are off by up to :math:`\kappa\varepsilon`: 7.9e-12 of
    :math:`\|T\|^2` on tcom(2000), ``docs/design/norms.md``).
    """
    t0 = time.perf_counter()
    gf = gramian_factors(fom, **adi)
    cache = getattr(fom, "cache", None)
    key = ("h2_norm_squared", tuple(sorted(gf.options.items())))
    if cache is not None and key in cache and not gf.computed:
        value, floor, rec = cache[key]
        return value, floor, {**rec, "gramian_cached": True, "gramian_lu_count": 0, "gramian_time_s": 0.0,
                              "time_s": time.perf_counter() - t0}, gf
    c, o = gf.controllability, gf.observability
    raw = float(np.sum((fom.L @ c.position) ** 2))
    tail = h2_tail(gf, fom)
    value = raw + tail
    # the tail estimate misses about tail * (observability residual); the factor's rounding, measured
    # against long-double quadratures of |T(jw)|^2 (dsms(60), random MIMO models: 2e-16 .. 7e-16 relative,
    # factor ranks 28 .. 258), is estimated with margin by 2 eps sqrt(rank) (measured, not proved)
    unit = c.solve_error if c.refine else UNREFINED_UNIT
    floor = 10.0 * tail * max(o.residual, EPS) + 2.0 * EPS * np.sqrt(max(c.rank, 1)) * value + 2.0 * unit * value
    if not gf.converged:
        floor = max(floor, tail)
    rec = {"method": "gramian", "uncorrected": float(np.sqrt(raw)), "tail": tail,
           "factor_rank": c.rank, "adi_converged": gf.converged, "adi_refine": c.refine,
           "adi_solve_error": float(unit),
           "adi_residuals": {"controllability": c.residual, "observability": o.residual},
           "gramian_cached": not gf.computed, "gramian_lu_count": gf.lu_count if gf.computed else 0,
           "gramian_time_s": gf.time_s if gf.computed else 0.0, "adi_options": dict(gf.options),
           "time_s": time.perf_counter() - t0}
    if cache is not None:  # products with the whole factors: once per model (230 MB of them on tcom(2000))
        cache[key] = (value, floor, rec)
    return value, floor, rec, gf


def pole_residue_squared(norm2: float, floor2: float, cross: complex, cross_abs: float, modal: Modal,
                         cross_err: float = 0.0):
    r""":math:`\|T - T_r\|^2 = \|T\|^2 - 2\,\mathrm{Re}\langle T, T_r\rangle + \|T_r\|^2` and its absolute floor.

    Parameters
    ----------
    norm2, floor2 : float
        :math:`\|T\|^2` and its absolute floor (:func:`norm_squared`).
    cross : complex
        :math:`\langle T, T_r\rangle = \sum_k c_k^TT(-\lambda_k)b_k` over the poles of ``modal``
        (a conjugate pair as twice the real part of one of them).
    cross_abs : float
        The sum of the moduli of its terms (for the rounding estimate).
    modal : Modal
        The reduced model's pole-residue form, whose residues the cross term used.
    cross_err : float
        Absolute error bound of the cross term beyond its rounding: the solves'
        forward errors, :math:`\sum_k w_k|t_k|u_k` with :math:`u_k` the relative
        error of the solve at :math:`-\lambda_k` (default 0: exact solves).

    Returns
    -------
    (e2, floor, parts)
        ``parts``: ``rom_norm`` (:math:`\|T_r\|`), ``self_inner``, ``cross``.
    """
    self2, self_abs = modal.self_inner()
    e2 = norm2 - 2.0 * float(np.real(cross)) + self2
    e_est = np.sqrt(max(e2, 0.0))
    tr = np.sqrt(max(self2, 0.0))
    # rounding of the three sums (measured errors are 30-160x below this on dsms(60) and random models),
    # and the modal form's perturbation of the reduced model, seen through both of its terms alike
    floor = (floor2 + 2.0 * EPS * (norm2 + 2.0 * cross_abs + self_abs) + 2.0 * cross_err
             + 2.0 * EPS * modal.kappa * tr * max(e_est, 1e-300))
    return float(e2), float(floor), {"rom_norm": float(tr), "self_inner": float(self2), "cross": float(np.real(cross))}
