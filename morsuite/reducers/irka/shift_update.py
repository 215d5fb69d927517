r"""IRKA's shift-update rules: initial shifts, new shifts from the reduced model, relaxation.

Each IRKA iteration maps the reduced model to new interpolation data
:math:`(\alpha_i, b_i, c_i)`: poles :math:`\lambda_i` of (a reduction of) the
reduced model give :math:`\alpha_i = -\lambda_i` (mirrored into the open right
half-plane if needed), its residue directions give :math:`b_i, c_i` (rows
normalised to unit length). Option ``update`` of :class:`~morsuite.reducers.irka.engine.IRKABase`:

``"bt"`` (the paper's choice, :func:`bt_rule`)
    The reduced model's first-order realization (for a second-order model of
    order r, :math:`E = \mathrm{blkdiag}(I, \hat M)`,
    :math:`A = [[0, I], [-\hat K, -\hat D]]`, :math:`B = [0; \hat F]`,
    :math:`C = [\hat L, 0]`: 2r states; the paper prints a singular E, a typo)
    is reduced to k states by dense balanced truncation (``hsv_tol`` caps k);
    the poles and residue directions of the result are used.
``"residue"`` (:func:`residue_rule`)
    k of the reduced model's poles with the largest H2 contribution
    :math:`\|c_i\|\|b_i\| / \sqrt{2|\mathrm{Re}\,\lambda_i|}`, conjugate pairs
    kept whole; a pole in use (its mirror within ``hysteresis_radius`` of a
    current shift) has its score raised by the factor 1 + ``residue_hysteresis``.
``"auto"`` (default, :class:`UpdateSchedule`)
    ``"bt"``, switching to ``"residue"`` when a cycle is detected or after half
    of ``maxit``.

``relaxation`` w < 1 moves each shift only the fraction w towards its matched
new value (:func:`relaxed_update`). Initial shifts (:func:`initial_shifts`, option
``init``): r real shifts log-spaced over the model's band with unit directions
(default), seeded random ones, or given ones.

Cost: dense work on the 2r-state realization only, :math:`O(r^3)` flops (two
Lyapunov equations and an SVD for ``"bt"``, a QZ for ``"residue"``); no sparse
LU. Measurements behind the rules: ``docs/design/irka.md``.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from ...errors import InputError
from ...linalg.dense import UnstableError, dense_bt, shift_distance

__all__ = ["COMPLEX_TOL", "UpdateSchedule", "resolve_stage_stall", "initial_shifts", "bt_rule", "residue_rule",
           "select_by_residue", "fill_odd_slot", "shifts_from_poles", "normalize_rows", "relaxed_update"]

#: relative imaginary part below which a shift or pole counts as real
COMPLEX_TOL = 1e-12


def initial_shifts(r, band, m, p, *, init="logspace", seed=0, shifts=None, b=None, c=None):
    """Initial shifts (closed under conjugation, in the open right half-plane) and directions.

    ``init``: ``"logspace"``, r real shifts log-spaced over ``band`` = (lo, hi) with all-one
    directions; ``"random"``, r real shifts log-uniform on the band with standard normal
    directions (``seed``); ``"given"``, ``shifts`` with directions ``b`` (k x m) and ``c``
    (k x p), all-one where None. Returns (alpha, b, c), complex.
    """
    rng = np.random.default_rng(seed)
    lo, hi = band
    if init == "given":
        alpha = np.asarray(shifts, dtype=complex).ravel()
        if np.any(alpha.real <= 0):
            raise InputError("init_shifts must lie in the open right half-plane")
        pos = alpha[alpha.imag > COMPLEX_TOL * np.abs(alpha)]
        neg = alpha[alpha.imag < -COMPLEX_TOL * np.abs(alpha)]
        if pos.size != neg.size or (
                pos.size and shift_distance(np.sort_complex(pos), np.sort_complex(np.conj(neg))) > 1e-12):
            raise InputError("init_shifts must be closed under complex conjugation")
        k = alpha.size
        bdir = np.ones((k, m)) if b is None else np.asarray(b, dtype=complex).reshape(k, m)
        cdir = np.ones((k, p)) if c is None else np.asarray(c, dtype=complex).reshape(k, p)
        return alpha, bdir.astype(complex), cdir.astype(complex)
    if init == "logspace":
        alpha = np.logspace(np.log10(lo), np.log10(hi), r).astype(complex)
        return alpha, np.ones((r, m), dtype=complex), np.ones((r, p), dtype=complex)
    alpha = 10 ** rng.uniform(np.log10(lo), np.log10(hi), r)
    return (alpha.astype(complex), rng.standard_normal((r, m)).astype(complex),
            rng.standard_normal((r, p)).astype(complex))


#: option stage_stall=None: a stall window of STAGE_STALL iterations from STAGE_STALL_MIN_N1 positions on
STAGE_STALL, STAGE_STALL_MIN_N1 = 10, 50_000


def resolve_stage_stall(option, n1) -> int:
    """The stall window of the stages of update="auto": the option ``stage_stall``, or when None,
    :data:`STAGE_STALL` from :data:`STAGE_STALL_MIN_N1` positions on and 0 (off) below.

    The BT update can wander without cycling on long lightly damped chains (tcom at n1 = 1e5:
    no new smallest shift change from iteration 5 to 15 and on to its 50th; with the window,
    44 iterations and 759 LUs instead of 87 and 1369, docs/design/irka.md). Below the size,
    where an iteration is cheap, the rule would move converged answers (tcom(2000) at r = 20
    and 30 reaches other fixed points, H2 errors 5e-8 and 2e-6 relative apart, beyond
    their floors): it is off there."""
    return int(option) if option is not None else (STAGE_STALL if n1 >= STAGE_STALL_MIN_N1 else 0)


class UpdateSchedule:
    """The update rule and relaxation in force: option ``update``, or the stages of ``"auto"``.

    ``"auto"`` runs the stages in turn: the next one after a cycle (:meth:`switch`),
    after ``stage_stall`` iterations without a new smallest measure (the engine's option),
    or once its share of ``maxit`` is used up (:meth:`stage_expired`); ``switched_at`` lists
    the iterations at which it moved on, ``switch_reasons`` why ("cycle", "stall", "maxit").
    """

    #: the stages of update="auto": (update, relaxation)
    STAGES = (("bt", 1.0), ("residue", 1.0))

    def __init__(self, update, relaxation, maxit, stall=0):
        self.update, self.relaxation, self.maxit = update, relaxation, maxit
        self.stall = int(stall)  # stall window of a stage (0: off), resolve_stage_stall
        self.stage = 0
        self.switched_at = []
        self.switch_reasons = []

    @property
    def rule(self):
        """(update, relaxation) of the current stage."""
        return self.STAGES[self.stage] if self.update == "auto" else (self.update, self.relaxation)

    def can_switch(self) -> bool:
        """Whether a cycle may move ``update="auto"`` on to a next stage (there is one left)."""
        return self.update == "auto" and self.stage < len(self.STAGES) - 1

    def switch(self, it, reason="cycle"):
        """Move to the next stage at iteration ``it`` (recorded in ``switched_at`` and ``switch_reasons``)."""
        self.stage += 1
        self.switched_at.append(it)
        self.switch_reasons.append(reason)

    def stage_expired(self, it) -> bool:
        """Whether iteration ``it`` ends the current stage's share of maxit (and a next stage exists)."""
        return self.can_switch() and it >= (self.stage + 1) * self.maxit // len(self.STAGES)

    def stage_over(self, it, guard):
        """Why iteration ``it`` ends the current stage (a next one exists): "maxit" (its share of maxit
        used up), "stall" (``guard`` saw no new smallest measure for ``stall`` iterations), else None."""
        if self.stage_expired(it):
            return "maxit"
        return "stall" if self.can_switch() and self.stall and guard.stalled(self.stall) else None


def bt_rule(E, A, B, C, k, hsv_tol):
    """Poles and residue directions of the dense balanced truncation of (E, A, B, C) to k states.

    Returns (lam, b, c, hsv): b the rows of Z^-1 B, c those of (C Z)^T, Z the eigenvectors
    of the truncated A. lam is None when the truncation fails (an unstable or singular
    realization, or no state kept), and the caller falls back to :func:`residue_rule`;
    hsv is None when it failed before the Hankel singular values were known.
    """
    hsv = None
    try:
        bt = dense_bt(E, A, B, C, order=k, hsv_tol=hsv_tol)
        hsv = bt.hsv
        if bt.order == 0:
            raise ValueError("balanced truncation kept no state")
        lam, Z = np.linalg.eig(bt.A)
        bdir = np.linalg.solve(Z, bt.B)
        cdir = (bt.C @ Z).T
    except (UnstableError, np.linalg.LinAlgError, ValueError):
        return None, None, None, hsv
    return lam, bdir, cdir, hsv


def residue_rule(lam, bres, cres, k, current=None, hysteresis=0.0, radius=0.05, weights=None):
    """The k poles of largest H2 contribution (:func:`select_by_residue`), one slot left by
    conjugate pairs filled by a real pole (:func:`fill_odd_slot`). Returns (lam, b, c)."""
    sel = select_by_residue(lam, bres, cres, k, current=current, hysteresis=hysteresis, radius=radius,
                            weights=weights)
    return fill_odd_slot(lam, bres, cres, sel, k)


def select_by_residue(lam, bres, cres, k, current=None, hysteresis=0.0, radius=0.05, weights=None):
    r"""Indices of k poles with the largest H2 contribution, keeping conjugate pairs whole.

    The score of pole :math:`\lambda_i` is
    :math:`\|b_i\|\|c_i\| / \sqrt{2|\mathrm{Re}\,\lambda_i|}`. With ``hysteresis``
    h > 0, a pole whose mirror image lies within relative distance ``radius`` of one
    of the ``current`` shifts has its score multiplied by 1 + h: a pole already in use
    is only replaced by one that scores clearly higher. A pair that does not fit in
    the slots left is skipped, not split. ``weights`` (one per pole) multiply the scores
    instead of the hysteresis (the safeguard's matched hysteresis and tabu list,
    :func:`~morsuite.reducers.irka.safeguards.guard_weights`).
    """
    score = (np.linalg.norm(bres, axis=1) * np.linalg.norm(cres, axis=1)
             / np.sqrt(2 * np.maximum(np.abs(lam.real), 1e-300)))
    if weights is not None:
        score = score * weights
    elif hysteresis > 0 and current is not None and np.size(current) and lam.size:
        cur = np.asarray(current, dtype=complex).ravel()
        dist = np.min(np.abs(-lam[:, None] - cur[None, :]) / np.maximum(np.abs(cur), 1e-300)[None, :], axis=1)
        score = score * np.where(dist < radius, 1.0 + hysteresis, 1.0)
    order = np.argsort(-score)
    chosen, used = [], np.zeros(lam.size, bool)
    for i in order:
        if used[i] or len(chosen) >= k:
            continue
        if abs(lam[i].imag) > COMPLEX_TOL * abs(lam[i]):
            j = np.flatnonzero(~used & np.isclose(lam, np.conj(lam[i]), rtol=1e-8, atol=0))
            j = [x for x in j if x != i]
            if not j or len(chosen) + 2 > k:
                continue
            chosen += [i, j[0]]
            used[[i, j[0]]] = True
        else:
            chosen.append(i)
            used[i] = True
    return np.array(chosen, dtype=int)


def fill_odd_slot(lam, bres, cres, sel, k):
    """(lam, b, c) of the selection ``sel``; if one slot is left and only pairs remain, the
    best remaining pair's modulus is added as a real pole (directions from the real parts),
    so that k shifts are returned and the order does not drift down."""
    if sel.size >= k or sel.size + 1 < k:
        return lam[sel], bres[sel], cres[sel]
    rest = np.setdiff1d(np.arange(lam.size), sel)
    if rest.size == 0:
        return lam[sel], bres[sel], cres[sel]
    score = np.linalg.norm(bres[rest], axis=1) * np.linalg.norm(cres[rest], axis=1)
    j = rest[np.argmax(score)]
    extra = -abs(lam[j])
    return (np.append(lam[sel], extra), np.vstack([bres[sel], bres[j].real]),
            np.vstack([cres[sel], cres[j].real]))


def shifts_from_poles(lam, bdir, cdir, band):
    """Shifts alpha = -lam made usable, unit directions, sorted by (real, imaginary) part.

    Non-finite poles give the band's upper end, zero poles its lower end (a reduced model
    can produce both: stress suite K5); shifts in the closed left half-plane are mirrored
    (their count is returned), undamped ones nudged to a real part ``1e-8 |alpha|`` (at
    least ``1e-8 lo``). Returns (alpha, b, c, mirrored).
    """
    alpha = -lam
    lo, hi = band
    alpha[~np.isfinite(alpha)] = hi
    alpha[np.abs(alpha) == 0] = lo
    bad = alpha.real <= 0
    mirrored = int(np.sum(bad))
    alpha[bad] = -alpha[bad].real + 1j * alpha[bad].imag
    tiny = alpha.real <= 0
    alpha[tiny] = np.maximum(np.abs(alpha[tiny]) * 1e-8, lo * 1e-8) + 1j * alpha[tiny].imag  # undamped: nudge
    bdir = normalize_rows(np.asarray(bdir, dtype=complex))
    cdir = normalize_rows(np.asarray(cdir, dtype=complex))
    order = np.lexsort((alpha.imag, alpha.real))
    return alpha[order], bdir[order], cdir[order], mirrored


def normalize_rows(X):
    """X with its nonzero rows scaled to unit Euclidean norm."""
    n = np.linalg.norm(X, axis=1, keepdims=True)
    n[n == 0] = 1.0
    return X / n


def relaxed_update(alpha, bdir, cdir, new_alpha, new_b, new_c, w, blend_directions=False):
    r"""Relaxed update: each new shift moved only a fraction w from its matched old one.

    Real shifts are matched with real ones and upper-half-plane shifts with
    upper-half-plane ones (optimal assignment by distance), so the set stays closed
    under conjugation; the directions are those of the new shifts, or with
    ``blend_directions`` (the safeguard) :math:`(1-w) b + w\,e^{i\phi} b'`,
    normalised, :math:`\phi` the phase that aligns the new direction :math:`b'` with
    its matched old one :math:`b` (a direction is defined up to a complex factor); a
    fixed point of the plain update is one of this. If the two sets do not split alike
    (different counts), the plain update is returned.
    """
    def split(a):
        cplx = np.abs(a.imag) > COMPLEX_TOL * np.abs(a)
        return np.flatnonzero(~cplx), np.flatnonzero(cplx & (a.imag > 0))
    r_old, u_old = split(alpha)
    r_new, u_new = split(new_alpha)
    if r_old.size != r_new.size or u_old.size != u_new.size:
        return new_alpha, new_b, new_c
    out_a, out_b, out_c = [], [], []
    for io, inew in ((r_old, r_new), (u_old, u_new)):
        if io.size == 0:
            continue
        cost = np.abs(new_alpha[inew][:, None] - alpha[io][None, :])
        i, j = linear_sum_assignment(cost)
        a = (1 - w) * alpha[io][j] + w * new_alpha[inew][i]
        out_a.append(a)
        if blend_directions:
            out_b.append(_blend(bdir[io][j], new_b[inew][i], w))
            out_c.append(_blend(cdir[io][j], new_c[inew][i], w))
        else:
            out_b.append(new_b[inew][i])
            out_c.append(new_c[inew][i])
    a = np.concatenate(out_a)
    b = np.vstack(out_b)
    c = np.vstack(out_c)
    cplx = np.abs(a.imag) > COMPLEX_TOL * np.abs(a)
    a = np.concatenate([a, np.conj(a[cplx])])
    b = np.vstack([b, np.conj(b[cplx])])
    c = np.vstack([c, np.conj(c[cplx])])
    order = np.lexsort((a.imag, a.real))
    return a[order], b[order], c[order]


def _blend(old, new, w):
    """Rows (1-w) old + w new, new turned by the phase of <new, old> first, normalised."""
    ph = np.sum(np.conj(new) * old, axis=1)
    ph = np.where(np.abs(ph) > 0, ph / np.maximum(np.abs(ph), np.finfo(float).tiny), 1.0)
    return normalize_rows((1 - w) * old + w * new * ph[:, None])
