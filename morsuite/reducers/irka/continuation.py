r"""Continuation in r for the IRKA family (:meth:`Reducer.continue_from <morsuite.reducers.Reducer.continue_from>`).

A search for the smallest model within a tolerance (:mod:`morsuite.analysis.tolerance`) reduces
at several orders in turn. An IRKA run at order r can start from the model found at a nearby
order: its mirrored poles of largest H2 contribution with their residue directions
(:func:`continued_data`), completed by start shifts when it had fewer poles than r. Measured
in ``docs/design/tolerance.md``.
"""

from __future__ import annotations

import numpy as np

from .shift_update import residue_rule, shifts_from_poles

__all__ = ["Continuation", "continued_data"]


def continued_data(lam, bres, cres, k, band, fill):
    r"""Interpolation data (alpha, b, c) for k shifts continued from a reduced model's stable poles
    ``lam`` with residue directions ``bres``, ``cres``: the min(k, poles) of largest H2 contribution
    (:func:`~morsuite.reducers.irka.shift_update.residue_rule`), mirrored
    (:func:`~morsuite.reducers.irka.shift_update.shifts_from_poles`); when k exceeds them, the
    k - poles shifts of ``fill(n)`` (n start shifts, e.g. log-spaced over the band, real: closed under
    conjugation) farthest in relative distance from those taken. Cost: O(k^2)."""
    n = min(k, lam.size)
    if n:
        lam, bres, cres = residue_rule(lam, bres, cres, n)
        alpha, b, c, _ = shifts_from_poles(lam, bres, cres, band)
    else:
        alpha = np.zeros(0, complex)
        b = np.zeros((0, bres.shape[1]), complex)
        c = np.zeros((0, cres.shape[1]), complex)
    extra = k - alpha.size
    if extra > 0:
        fa, fb, fc = fill(max(k, extra))
        if alpha.size:
            d = np.min(np.abs(fa[:, None] - alpha[None, :]) / np.abs(alpha)[None, :], axis=1)
            keep = np.sort(np.argsort(-d, kind="stable")[:extra])
        else:
            keep = np.arange(extra)
        alpha, b, c = (np.concatenate([alpha, fa[keep]]), np.vstack([b, fb[keep]]), np.vstack([c, fc[keep]]))
    return alpha.astype(complex), b.astype(complex), c.astype(complex)


class Continuation:
    """The continuation hooks of an IRKA reducer: :meth:`continue_from` keeps the model, the engine's
    start takes it once (:meth:`_take_warm`) and makes its data (:meth:`_continued`);
    :meth:`_continued_record` is what ``info["continued_from"]`` says (None: a fresh start)."""

    def continue_from(self, rom) -> bool:
        """Start the next :meth:`reduce` from ``rom`` (an earlier result of this reducer): its mirrored
        poles of largest H2 contribution and their residue directions (:func:`continued_data`), the
        shifts it lacks for the new order from log-spaced start shifts. One-shot: the call after next
        starts as the options say. Returns True. Cost: none here."""
        self._warm = rom
        return True

    def _take_warm(self):
        """The reduced model to continue from (set by :meth:`continue_from`), forgotten once taken."""
        warm, self._warm = getattr(self, "_warm", None), None
        if warm is not None:
            self._continued_info = {"order": int(warm.order), "states": int(warm.states)}
        return warm

    def _continued_record(self):
        """``{"order", "states"}`` of the model the last start continued from (None: a fresh start); reset."""
        rec, self._continued_info = getattr(self, "_continued_info", None), None
        return rec

    def _continued(self, rom, r, fill):
        """(alpha, b, c) for order r from ``rom``'s poles and residues, completed by ``fill(k)``."""
        E, A, B, C = self._realization(rom)
        lam, bres, cres = self._poles_and_residues(rom, E, B, C)
        ok = np.isfinite(lam) & (lam.real < 0)
        return continued_data(lam[ok], bres[ok], cres[ok], r, self.fom.band, fill)
