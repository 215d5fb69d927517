r"""IRKA's safeguards: from raw solutions to a well-posed projection.

The raw bases of an IRKA iteration can be numerically rank deficient (shifts
beyond the model's numerical order), ill-conditioned (localised solutions of
chain-like models), or give an ill-conditioned oblique projection. These
functions make the projection well posed; :class:`~morsuite.reducers.irka.engine.IRKABase`
applies them (options of its table, defaults in brackets):

* Orthonormalisation (``orthonormalization`` ["auto"], ``rank_tol`` [1e-14],
  ``ill_cond_tol`` [1e-8], :func:`orthonormal_basis`): Householder QR + SVD
  (:func:`~morsuite.linalg.dense.orth`), or column-pivoted Gram-Schmidt
  (:func:`~morsuite.linalg.orthonormal.gram_schmidt`), which keeps the rounding
  of each entry relative to the entries combined; ``"auto"`` uses Householder
  and redoes a basis by Gram-Schmidt when its smallest kept relative singular
  value is below ``ill_cond_tol`` (:func:`ill_conditioned`), or when the
  previous iteration's was. Directions of relative singular value below
  ``rank_tol`` are dropped.
* Oblique selection (``oblique_tol`` [1e-4], :func:`oblique_selection`): with
  the SVD :math:`W^T V = U \Sigma Z^T`, only the directions
  :math:`V Z_{:,1:k}`, :math:`W U_{:,1:k}` with
  :math:`\sigma_i > \mathrm{oblique\_tol}\,\sigma_1` are kept; the others give a
  near-singular reduced mass matrix and spurious poles of negligible residue.
* Singular shifts (``shift_perturbation`` [1e-6], :func:`perturb_shifts`): a
  shift at a pole of the full model (singular saddle matrix) and its conjugate
  are multiplied by 1 + ``shift_perturbation`` and the solves retried.
* A transfer function that vanishes in the tangential directions (zero bases,
  :math:`W^T V = 0`, no finite pole) leaves nothing to reduce and raises
  :class:`~morsuite.errors.ModelError` (:func:`zero_transfer_error`).

* Cycling and unstable fixed points (``safeguard`` ["auto"] and the options of
  :data:`GUARD_OPTIONS`, :class:`CycleGuard`): idle while the plain iteration can
  still converge; engaged, the residue rule with matched hysteresis and a tabu list
  (:func:`guard_weights`, :func:`instability_culprit`) and adaptive relaxation.
  Without convergence the returned iterate comes from a :class:`Shortlist` of
  stable ones.

Cost: one QR + SVD (or Gram-Schmidt) of each n1 x k basis, :math:`O(n_1 k^2)`
flops, and a k x k SVD; no sparse LU. The safeguard adds dense r-sized work per
iteration, and at a settled unstable model one projection of the raw bases per
real shift or pair left out, :math:`O(n_1 r^3)` flops in all, no sparse LU.
Measurements: ``docs/design/irka.md``.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from ...errors import ModelError
from ...linalg.dense import orth, shift_distance
from ...linalg.orthonormal import gram_schmidt
from ..base import Option

__all__ = ["ITERATE_CYCLE", "GUARD_CYCLES", "ban_culprit", "is_cycle",
           "orthonormal_basis", "ill_conditioned", "oblique_selection", "perturb_shifts", "zero_transfer_error",
           "GUARD_OPTIONS", "guard_weights", "shift_slots", "instability_culprit", "CycleGuard", "Shortlist"]

_ZERO_MSG = ("{name}: {what}: the transfer function vanishes in the tangential directions (a zero input or "
             "output matrix, or inputs acting only on constrained coordinates); nothing to reduce")


def zero_transfer_error(name, what) -> ModelError:
    """The error raised when reducer ``name`` finds ``what`` (nothing to reduce)."""
    return ModelError(_ZERO_MSG.format(name=name, what=what))


def orthonormal_basis(X, how, rank_tol, ill_cond_tol, previous_ill=False):
    """(Q, s, gram_schmidt_used): an orthonormal basis of the numerical range of X.

    ``how``: ``"gram-schmidt"``, ``"householder"`` or ``"auto"`` (Householder, redone by
    Gram-Schmidt when the kept singular values ``s`` fall below ``ill_cond_tol`` relative,
    and straight away when ``previous_ill``: the previous bases were ill-conditioned, these
    will be too). ``s`` are singular values (Householder) or residual norms (Gram-Schmidt).
    """
    if how == "gram-schmidt":
        return (*gram_schmidt(X, rank_tol), True)
    if how == "auto" and previous_ill:
        return (*gram_schmidt(X, rank_tol), True)
    # ill_tol: an ill-conditioned X's Householder basis is not formed, Gram-Schmidt replaces it
    Q, s = orth(X, rank_tol, ill_tol=ill_cond_tol if how == "auto" else None)
    if Q is None:
        return (*gram_schmidt(X, rank_tol), True)
    return Q, s, False


def ill_conditioned(s, k, ill_cond_tol) -> bool:
    """Whether the k-th of the singular values s (of a basis with k kept columns) is below
    ``ill_cond_tol`` relative to the largest."""
    return bool(s.size > 0 and s[min(k, s.size) - 1] < ill_cond_tol * s[0])


def oblique_selection(V, W, oblique_tol, name):
    """Orthonormal V, W cut to a common order and to a well-conditioned W^T V.

    Returns (V, W, k, k_rank): k_rank = min of the column counts, k <= k_rank the order
    kept by the selection (``oblique_tol`` 0: k = k_rank, no SVD). Raises ModelError when
    nothing is left (``name``: the reducer, for the message).
    """
    k = min(V.shape[1], W.shape[1])
    if k == 0:
        raise zero_transfer_error(name, "the projection bases have rank 0")
    V, W = V[:, :k], W[:, :k]
    k_rank = k
    if oblique_tol > 0:
        U_, s_, Zt_ = np.linalg.svd(W.T @ V)
        k = int(np.sum(s_ > oblique_tol * s_[0])) if s_.size and s_[0] > 0 else 0
        if k == 0:
            raise zero_transfer_error(name, "W^T V = 0")
        V, W = V @ Zt_[:k].T, W @ U_[:, :k]
    return V, W, k, k_rank


def perturb_shifts(alpha, bad, eps):
    """(alpha', count): the shifts equal to ``bad`` or its conjugate (all when ``bad`` is None)
    multiplied by 1 + eps."""
    idx = (np.arange(alpha.size) if bad is None
           else np.flatnonzero(np.isclose(alpha, bad) | np.isclose(alpha, np.conj(bad))))
    alpha = alpha.copy()
    alpha[idx] = alpha[idx] * (1 + eps)
    return alpha, idx.size


# -- the safeguard against cycling and unstable fixed points (option ``safeguard``) ------------
#: the safeguard's options, part of the option table of :class:`~morsuite.reducers.irka.engine.IRKABase`
GUARD_OPTIONS = {
    "safeguard": Option("auto", "choice", "safeguard against cycling and unstable fixed points "
                        "(irka_safeguards.CycleGuard): idle until the plain iteration cycles in its last "
                        "stage, settles at an unstable model or stalls, then the residue rule with matched "
                        "hysteresis, a tabu list and adaptive relaxation; it also picks the returned "
                        "iterate without convergence from a shortlist of stable ones. 'auto': on with "
                        "update='auto', off with an explicit update rule; 'off': the plain iteration",
                        choices=("auto", "on", "off")),
    "safeguard_window": Option(10, "int", "iterations of the last stage without a new smallest measure "
                               "that engage the safeguard", low=2),
    "safeguard_settle": Option(1e-6, "float", "measure below which an unstable iterate counts as an "
                               "unstable fixed point (the plain iteration stays there): the safeguard bans "
                               "the shift or pair whose removal leaves the most stable model",
                               low=0, high=1, open_low=True, open_high=True),
    "safeguard_hysteresis": Option(1.0, "float", "matched hysteresis of the engaged safeguard's residue "
                                   "rule (multiplied by 4 at each further cycle)", low=0),
    "safeguard_tabu_radius": Option(0.01, "float", "relative distance to a banned shift within which a "
                                    "mirrored pole is passed over", low=0, high=1, open_low=True,
                                    open_high=True),
    "safeguard_min_step": Option(0.125, "float", "smallest step of the engaged safeguard's adaptive "
                                 "relaxation (1: no relaxation)", low=0, high=1, open_low=True),
    "safeguard_stop": Option(True, "bool", "the engaged safeguard stops the iteration when a cycle of shift "
                             "sets (of the proposed sets, or of the relaxed iterates within 10 cycle_tol) forms "
                             "again after a reaction (stronger hysteresis, smaller step, recent sets forgotten) "
                             "to an earlier one (status cycle) or after safeguard_stall iterations without a new smallest "
                             "measure (status stalled), returning the best iterate, instead of running to maxit"),
    "safeguard_stall": Option(15, "int", "iterations of the engaged safeguard without progress (a measure below "
                              "1 - safeguard_progress times the smallest one at the last progress) after which "
                              "safeguard_stop stops (docs/design/irka.md, issue 33)", low=2),
    "safeguard_progress": Option(0.1, "float", "relative decrease of the smallest measure that counts as progress "
                                 "of the engaged safeguard (0: any new smallest measure); idle, any new smallest "
                                 "measure counts", low=0, high=1, open_high=True),
    "safeguard_reach": Option(True, "bool", "engaged, safeguard_stop also stops (status stalled) when the "
                              "smallest measure's decrease over the last safeguard_stall iterations, continued "
                              "geometrically, would not reach tol by maxit (CycleGuard.out_of_reach): a run that "
                              "cannot converge within its budget stops instead of paying it (docs/design/irka.md, "
                              "issue 33)"),
    "shortlist": Option(5, "int", "stable iterates kept (with their models) for the final choice "
                        "without convergence (safeguard on)", low=1),
    "shortlist_score": Option("h2", "choice", "how the shortlisted iterates are ranked without convergence: "
                              "their exact H2 error (irka.score.ExactH2Score: the model's Gramian factors once "
                              "per model, shared with bt and the norms, then about r sparse LUs per shortlisted "
                              "iterate) or their convergence measure (no cost); "
                              "a reducer's iterate_score, when set, takes precedence",
                              choices=("h2", "measure")),
}


def guard_weights(lam, current, hysteresis, radius, tabu=(), tabu_radius=0.01):
    r"""Score factors (one per pole) of the safeguard's residue selection.

    Matched hysteresis: the current shifts and the mirrored poles
    :math:`\mu_j = |\mathrm{Re}\,\lambda_j| - i\,\mathrm{Im}\,\lambda_j` are assigned one
    to one (optimal assignment on the relative distance); a pole assigned to a shift
    within relative distance ``radius`` has its score multiplied by 1 + ``hysteresis``.
    One shift favours one pole: of two poles near one shift (a near-double resonance)
    only one keeps its place, which the radius rule of
    :func:`~morsuite.reducers.irka.shift_update.select_by_residue` cannot say. Tabu: a pole whose mirror lies
    within ``tabu_radius`` (relative) of a banned shift or its conjugate has its score
    multiplied by 1e-12, so it is chosen only when nothing else is left.
    """
    lam = np.asarray(lam, dtype=complex)
    w = np.ones(lam.size)
    if lam.size == 0:
        return w
    mu = np.abs(lam.real) - 1j * lam.imag
    scale = np.maximum(np.abs(mu), np.finfo(float).tiny)
    cur = np.asarray(current if current is not None else [], dtype=complex).ravel()
    if hysteresis > 0 and cur.size:
        cost = np.abs(mu[:, None] - cur[None, :]) / np.maximum(scale[:, None], np.abs(cur)[None, :])
        i, j = linear_sum_assignment(cost)
        near = cost[i, j] < radius
        w[i[near]] *= 1.0 + hysteresis
    for t in tabu:
        d = np.minimum(np.abs(mu - t), np.abs(mu - np.conj(t))) / max(abs(t), np.finfo(float).tiny)
        w[d < tabu_radius] *= 1e-12
    return w


def shift_slots(alpha, tol):
    """The raw basis columns of each real shift or conjugate pair, in the order the bases are
    built: a list of (shift indices, column indices)."""
    slots, col = [], 0
    for i, a in enumerate(alpha):
        if abs(a.imag) > tol * abs(a):
            if a.imag < 0:
                continue
            partner = [j for j in np.flatnonzero(np.isclose(alpha, np.conj(a), rtol=1e-8, atol=0)) if j != i]
            slots.append(([i] + partner[:1], [col, col + 1]))
            col += 2
        else:
            slots.append(([i], [col]))
            col += 1
    return slots


def instability_culprit(slots, rom_without):
    """Index into ``slots`` of the real shift or conjugate pair whose removal from the bases
    leaves the most stable reduced model (smallest largest relative real part of a pole),
    and that value. ``rom_without(cols)`` projects with the raw basis columns ``cols``
    left out (no new solve) and returns the model, or None if that fails."""
    best, best_val = None, np.inf
    for s, (_, cols) in enumerate(slots):
        rom = rom_without(cols)
        if rom is None:
            continue
        lam = rom.poles()
        val = float(np.max(lam.real / np.maximum(np.abs(lam), np.finfo(float).tiny))) if lam.size else -np.inf
        if val < best_val:
            best, best_val = s, val
    return best, best_val


class CycleGuard:
    r"""State of the safeguard of :class:`~morsuite.reducers.irka.engine.IRKABase` (option ``safeguard``).

    Idle until the plain iteration shows that it will not converge; then *engaged*
    for the rest of the reduction. It engages when (the iteration's ``reason``):

    * ``"cycle"``: a cycle of shift sets is detected in the last stage of the update
      schedule (where the plain iteration stops);
    * ``"unstable fixed point"``: the shifts settle (measure below ``settle``) at an
      unstable reduced model, which the criterion never accepts;
    * ``"stall"``: in the last stage, ``window`` iterations without a new smallest
      measure.

    Engaged, the update is the residue rule with matched hysteresis and a tabu list
    (:func:`guard_weights`), and the step is relaxed adaptively: halved (down to
    ``min_step``) when the shift change grows, doubled back towards 1 when it falls.
    Relaxation keeps the fixed points (:math:`\alpha = f(\alpha)` solves
    :math:`\alpha = (1-w)\alpha + w f(\alpha)`); the hysteresis grows fourfold at each
    further cycle. At an unstable settled iterate the shift or pair whose removal
    leaves the most stable model (:func:`instability_culprit`) is banned.
    """

    @classmethod
    def from_options(cls, o):
        """The safeguard of one reduction from the reducer's options ``o`` (idle until engaged)."""
        active = o["safeguard"] == "on" or (o["safeguard"] == "auto" and o["update"] == "auto")
        return cls(active, hysteresis=o["safeguard_hysteresis"], radius=o["hysteresis_radius"],
                   settle=o["safeguard_settle"], window=o["safeguard_window"], min_step=o["safeguard_min_step"],
                   tabu_radius=o["safeguard_tabu_radius"], progress=o.get("safeguard_progress", 0.0))

    def __init__(self, active, *, hysteresis, radius, settle, window, min_step, tabu_radius, progress=0.0):
        self.active = bool(active)
        #: engaged, a new smallest measure counts as progress only below (1 - progress) times the last one that did
        self.progress = float(progress)
        self.h0, self.radius, self.settle = hysteresis, radius, settle
        self.window, self.min_step, self.tabu_radius = window, min_step, tabu_radius
        self.h = hysteresis
        self.engaged_at = None
        self.reason = None
        #: cycles met while engaged (each answered by a stronger hysteresis and a smaller step)
        self.cycles = 0
        self.tabu = []
        self.events = []
        self.step = 1.0
        self._best = np.inf
        self._since_best = 0
        #: the running minimum of the measure at each iteration of the stage (out_of_reach)
        self._mins = []

    @property
    def engaged(self) -> bool:
        """Whether the safeguard has taken over the shift update."""
        return self.engaged_at is not None

    def engage(self, it, reason):
        """Take over from iteration ``it`` on, recording ``reason`` in the event log."""
        self.engaged_at, self.reason = it, reason
        self.events.append((it, f"engaged: {reason}"))
        self.new_stage()  # its progress is counted from here

    def observe(self, measure):
        """Record this iteration's measure (progress: a new smallest one in the stage; engaged, smaller than
        ``1 - progress`` times the smallest at the last progress)."""
        if measure < (1.0 - (self.progress if self.engaged else 0.0)) * self._best:
            self._best, self._since_best = measure, 0
        else:
            self._since_best += 1
        self._mins.append(min(measure, self._mins[-1]) if self._mins else measure)

    def new_stage(self):
        """The update schedule moved on: progress is counted afresh."""
        self._best, self._since_best = np.inf, 0
        self._mins = []

    def stop_reason(self, o, it) -> str | None:
        """Why the engaged safeguard stops at iteration ``it`` (options ``o``), or None: no progress in
        ``safeguard_stall`` iterations (:meth:`stalled`), or, with ``safeguard_reach``, ``tol`` out of
        reach by ``maxit`` at the rate of the last ``safeguard_stall`` iterations (:meth:`out_of_reach`).
        The reason is logged in :attr:`events` and becomes the warning's."""
        w, why = o["safeguard_stall"], None
        if self.stalled(w):
            why = f"the safeguard made no progress (safeguard_progress {o['safeguard_progress']:g}) in {w} iterations"
        elif o["safeguard_reach"] and self.out_of_reach(w, o["tol"], o["maxit"] - it):
            why = (f"at the rate of its last {w} iterations the safeguard would not reach tol = {o['tol']:g} by "
                   f"maxit = {o['maxit']}")
        if why:
            self.events.append((it, why + ": stopped"))
        return why

    def out_of_reach(self, window: int, tol: float, left: int) -> bool:
        r"""Whether the stage's smallest measure, decreasing from now on as it did over the last ``window``
        iterations, would stay above ``tol`` after the ``left`` iterations the budget allows.

        With :math:`m_0` the smallest measure ``window`` iterations ago and :math:`m_1` the smallest now,
        the extrapolation is :math:`m_1 (m_1/m_0)^{\text{left}/\text{window}}`; it needs ``window``
        iterations of the stage (before that: False). No decrease at all is out of reach."""
        if len(self._mins) <= window:
            return False
        m0, m1 = self._mins[-1 - window], self._mins[-1]
        if not (m1 > tol):
            return False
        if m1 >= m0:
            return True
        return bool(np.log(m1) + (left / window) * np.log(m1 / m0) > np.log(tol))

    def stalled(self, window: int | None = None) -> bool:
        """Whether ``window`` (default the guard's) iterations have passed without a new smallest measure."""
        return self._since_best >= (self.window if window is None else window)

    def on_cycle(self, it):
        """A further cycle while engaged: fourfold hysteresis, half the step."""
        self.h *= 4.0
        self.cycles += 1
        self.step = max(self.min_step, self.step / 2)
        self.events.append((it, f"cycle: hysteresis {self.h:g}, step {self.step:g}"))
        self.new_stage()  # a new hysteresis and step: progress counted afresh

    def adapt_step(self, change, previous):
        """Halve the step when the shift change grew, double it (at most 1) when it fell."""
        if np.isfinite(previous) and change > previous:
            self.step = max(self.min_step, self.step / 2)
        else:
            self.step = min(1.0, self.step * 2)
        return self.step

    def ban(self, it, shift, value):
        """Put ``shift`` (stored in the upper half-plane) on the tabu list; ``value``: the largest
        relative pole real part without it, for the record."""
        a = complex(shift)
        self.tabu.append(a if a.imag >= 0 else a.conjugate())
        self.events.append((it, f"banned {self.tabu[-1]:.6g} (largest relative pole real part without it "
                                f"{value:.2e})"))

    def weights(self, lam, current):
        """Score factors of the poles ``lam`` given the ``current`` shifts (:func:`guard_weights`)."""
        return guard_weights(lam, current, self.h, self.radius, self.tabu, self.tabu_radius)

    def info(self) -> dict:
        """The record kept in ``info["safeguard"]``."""
        return {"engaged_at": self.engaged_at, "reason": self.reason, "tabu": list(self.tabu),
                "hysteresis": self.h if self.engaged else None, "events": [f"{i}: {e}" for i, e in self.events]}


class Shortlist:
    """The iterates kept for the final choice when the iteration does not converge.

    Up to ``size`` stable iterates with the smallest measure, and the iterate of
    smallest measure overall (returned only when no iterate is stable). ``choose`` scores
    the stable ones with ``score(rom)`` (smaller is better; the reducer's
    ``iterate_score``) or, without one, by their measure.
    """

    def __init__(self, size):
        self.size = size
        self.stable = []  # (measure, it, payload)
        self.any = None

    def add(self, measure, it, stable, payload):
        """Offer iterate ``it`` (its convergence ``measure``, stability and reduced model ``payload``)."""
        if self.any is None or measure < self.any[0]:
            self.any = (measure, it, payload)
        if stable:
            self.stable.append((measure, it, payload))
            self.stable.sort(key=lambda t: (t[0], t[1]))  # ties: the earlier iterate first
            del self.stable[self.size:]

    def choose(self, score=None):
        """(it, payload, scores): the chosen iterate and the score of each shortlisted one."""
        if not self.stable:
            return self.any[1], self.any[2], {}
        if score is None:
            return self.stable[0][1], self.stable[0][2], {}
        scores = {it: float(score(payload[0])) for _, it, payload in self.stable}
        # iterates without a finite score rank last, among themselves by measure (the list's order)
        rank = {it: j for j, (_, it, _) in enumerate(self.stable)}
        it = min(scores, key=lambda k: (scores[k] if np.isfinite(scores[k]) else np.inf, rank[k]))
        return it, next(p for _, i, p in self.stable if i == it), scores


#: engaged (option safeguard_stop), a relaxed iterate within ITERATE_CYCLE * cycle_tol of a recent one is a
#: cycle too (measured on fem_block(1000), r = 6: its period-4 cycle closes to 1e-3 only after 25 iterations)
ITERATE_CYCLE = 10.0
#: engaged (option safeguard_stop), the iteration stops when a cycle forms again after this many reactions
#: (stronger hysteresis, half the step; the recent sets forgotten) to earlier ones
GUARD_CYCLES = 1


def is_cycle(new_alpha, d_shift, recent, options, loose: float = 1.0) -> bool:
    """Back to an earlier shift set of ``recent`` (within ``loose`` times ``cycle_tol``) while still far from
    the current one (slow oscillating convergence has d_shift near tol instead). ``options``: the engine's
    (``cycle_window``, ``cycle_tol``). Cost O(len(recent) r^2)."""
    o = options
    return bool(o["cycle_window"]) and d_shift > 100 * o["cycle_tol"] and any(
        new_alpha.size == a.size and shift_distance(new_alpha, a) < loose * o["cycle_tol"] for a in recent)


def ban_culprit(guard, it, alpha, rom_from_raw, Vraw, Wraw, left):
    """Ban the shift or pair whose removal from this iteration's raw bases leaves the most
    stable model (:func:`instability_culprit`; projections by ``rom_from_raw``, the engine's, no solve)."""
    from .shift_update import COMPLEX_TOL  # it imports this module

    def rom_without(cols):
        keep = np.setdiff1d(np.arange(Vraw.shape[1]), cols)
        try:
            return rom_from_raw(Vraw[:, keep], Wraw[:, keep] if left else None, left)[0]
        except (ArithmeticError, ValueError, np.linalg.LinAlgError):
            return None
    slots = shift_slots(alpha, COMPLEX_TOL)
    s, val = instability_culprit(slots, rom_without) if len(slots) > 1 else (None, None)
    if s is not None:
        guard.ban(it, alpha[slots[s][0][0]], val)

