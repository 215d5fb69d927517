r"""The IRKA iteration shared by every IRKA variant (:class:`IRKABase`).

One iteration, from interpolation data :math:`(\alpha_i, b_i, c_i)` (shifts
closed under conjugation in the open right half-plane, tangential directions):

1. raw bases :math:`V = [\ldots, \mathrm{Re}\,v_i, \mathrm{Im}\,v_i, \ldots]`,
   :math:`v_i = P(\alpha_i)^{-1} F b_i`, and (``projection="petrov"``)
   :math:`W` from :math:`w_i = P(\alpha_i)^{-T} L^T c_i`, one factorization per
   real shift or conjugate pair (hooks :meth:`~IRKABase._factor`,
   :meth:`~IRKABase._solve`; the variant says what :math:`P` is);
2. orthonormal bases, the projection made well posed (:mod:`~morsuite.reducers.irka.safeguards`)
   and the reduced model :math:`\hat M = W^T M V`, ..., :math:`\hat L = L V`
   (hook :meth:`~IRKABase._project`);
3. new interpolation data from the reduced model's poles and residues
   (:mod:`~morsuite.reducers.irka.shift_update`, option ``update``).

Convergence (option ``criterion``): ``"shifts"``, the largest relative change
of the optimally matched shifts (:func:`~morsuite.linalg.dense.shift_distance`),
below ``tol``; ``"response"``, the relative change
:math:`\max_\omega \sigma_{\max}(\hat H_j - \hat H_{j-1}) / \max_\omega \sigma_{\max}(\hat H_j)`
of the reduced transfer function on ``n_check`` log-spaced frequencies of the
model's band; ``"auto"`` (default), shifts while the bases have full rank, the
response once they have lost it or once it changes by less than
``response_tol`` (shifts beyond the numerical order are set by rounding and
never settle). Only a stable iterate counts as converged.

Numerical order: once the bases at the iteration's own shifts (from the second iteration on) have rank below the
shift count, the shift count is capped for good at that rank, so the iteration cannot cycle between orders; the
returned order ``info["r"]`` is then below ``info["r_requested"]`` with a :class:`~morsuite.errors.RankWarning`.

Cycles: a new shift set within ``cycle_tol`` of one of the last ``cycle_window`` sets while more than 100
``cycle_tol`` from the current one (criterion ``"shifts"``) is a cycle: ``update="auto"`` moves to its next
stage, otherwise the safeguard engages or (safeguard off) the iteration stops. Without convergence the best
iterate (stable first) is returned with ``converged=False``, ``status`` "cap", "cycle" or "stalled" and a
:class:`~morsuite.errors.ConvergenceWarning`.

Safeguard (option ``safeguard``, :class:`~morsuite.reducers.irka.safeguards.CycleGuard`): idle while the plain
iteration may still converge, so that its fixed points and paths are kept bit for bit; engaged when it cycles in
its last stage (update='auto': a stage ends at a cycle, after half of maxit or, option ``stage_stall``, when it
stalls), settles at an unstable model or stalls in its last stage, it replaces the update by the residue rule
with matched hysteresis and a tabu list, relaxed adaptively in shifts and directions. Without convergence it
also picks the returned iterate: the stable one of smallest exact H2 error among a shortlist (option
``shortlist_score``, :mod:`~morsuite.reducers.irka.score`; :attr:`IRKABase.iterate_score` overrides).

Options and defaults: :attr:`IRKABase.OPTIONS`, the advanced ones in :attr:`IRKABase.GROUPS` (shift_update,
stopping, safeguards, bases, solves: :mod:`morsuite.reducers.options`); the loop in named phases:
:mod:`~morsuite.reducers.irka.iteration`. Cost per iteration: one factorization per real shift or
conjugate pair (``info["lu_count"]``), two solves with it (one right, one transposed), and dense work on n1 x r
bases and r x r matrices. A variant is a subclass that defines the hooks (section ``hooks`` of
:class:`IRKABase`); design notes: ``docs/design/irka.md``.
"""

from __future__ import annotations

import numpy as np

from ...errors import (ConvergenceWarning, InputError, MorsuiteWarning, RankWarning, SingularShiftError,
                       StabilityWarning)
from ...rom import SecondOrderROM
from ..base import Group, Option, Reducer
from .continuation import Continuation
from .iteration import Iteration
from .safeguards import (GUARD_OPTIONS, ill_conditioned, oblique_selection, orthonormal_basis, perturb_shifts,
                         zero_transfer_error)
from .shift_solves import raw_bases
from .shift_update import bt_rule, initial_shifts, relaxed_update, residue_rule, shifts_from_poles

__all__ = ["IRKABase"]

#: per-iteration records copied into info["history"], in this order
_HISTORY_KEYS = ("measure", "shift_change", "response_change", "criterion", "n_shifts", "rank", "ill_conditioned",
                 "refined", "gram_schmidt", "stable", "max_pole_real", "update", "mirrored", "step", "shifts")


class IRKABase(Continuation, Reducer):
    """Shared IRKA iteration; subclasses say how V and W are computed and projected."""
    costly_orders = True
    OPTIONS = {
        "tol": Option(1e-6, "float", "relative change of the matched shifts that counts as converged",
                      low=0, high=1, open_low=True, open_high=True),
        "maxit": Option(100, "int", "maximum number of iterations", low=1),
        "init": Option("logspace", "choice", "initial shifts: real log-spaced over the model's band, "
                       "seeded random, or given", choices=("logspace", "random", "given")),
        "init_shifts": Option(None, "array", "initial shifts for init='given'", nullable=True),
        "init_b": Option(None, "array", "initial right directions (k x m) for init='given'", nullable=True),
        "init_c": Option(None, "array", "initial left directions (k x p) for init='given'", nullable=True),
        "seed": Option(0, "int", "seed of init='random'", low=0),
        "update": Option("auto", "choice", "shift update: dense BT of the 2r realization (paper), "
                         "r QEP poles by H2 residue, or auto (bt, switching to residue on a cycle or "
                         "after half of maxit)",
                         choices=("auto", "bt", "residue")),
        "residue_hysteresis": Option(0.3, "float", "update='residue' (and its stage of 'auto'): the score of a "
                                     "pole whose mirror lies within hysteresis_radius of a current shift is "
                                     "multiplied by 1 + this, so that near-equal scores do not swap poles in "
                                     "and out of the chosen r from one iteration to the next (0: off)", low=0),
        "hysteresis_radius": Option(0.05, "float", "relative distance of a mirrored pole to the nearest current "
                                    "shift within which residue_hysteresis applies", low=0, high=1,
                                    open_low=True, open_high=True),
        "relaxation": Option(1.0, "float", "step of the relaxed shift update alpha <- (1-w) alpha + w f(alpha) "
                             "(matched shifts; 1 = plain IRKA)", low=0, high=1, open_low=True),
        "projection": Option("petrov", "choice", "two-sided (W from left solves) or Galerkin (W = V)",
                             choices=("petrov", "galerkin")),
        "orthonormalization": Option("auto", "choice", "orthonormal bases by column-pivoted "
                                     "Gram-Schmidt with reorthogonalisation (keeps the rounding of each "
                                     "entry relative to the entries combined), by Householder QR + SVD "
                                     "(BLAS-3, 2-3x faster), or auto: Householder, redone by Gram-Schmidt "
                                     "when a kept singular value is below ill_cond_tol",
                                     choices=("auto", "gram-schmidt", "householder")),
        "ill_cond_tol": Option(1e-8, "float", "a basis whose smallest kept relative singular value is below "
                               "this counts as ill-conditioned: orthonormalization='auto' uses Gram-Schmidt and "
                               "refine_when='ill-conditioned' refines the next iteration's solves",
                               low=0, high=1, open_high=True),
        "rank_tol": Option(1e-14, "float", "relative singular value below which a basis direction is dropped",
                           low=0, high=1, open_high=True),
        "oblique_tol": Option(1e-4, "float", "relative singular value of W^T V below which a direction "
                              "pair is dropped (0: keep all)", low=0, high=1, open_high=True),
        "hsv_tol": Option(1e-13, "float", "relative Hankel singular value below which the update's BT "
                          "order is capped", low=0, high=1, open_high=True),
        "criterion": Option("auto", "choice", "convergence measure: matched relative shift change, relative "
                            "change of the reduced transfer function on the band, or auto (shifts while the "
                            "bases have full rank, response once they lose rank)",
                            choices=("auto", "shifts", "response")),
        "response_tol": Option(1e-9, "float", "criterion='auto' also stops when the reduced transfer "
                               "function changes by less than this (relative, on the band; 0: never)",
                               low=0, high=1, open_high=True),
        "n_check": Option(64, "int", "frequencies on the band used by the response criterion", low=4),
        "cycle_tol": Option(1e-3, "float", "a shift set within this relative distance of one of the last "
                            "cycle_window sets, while 100 times farther from the current one, is a cycle",
                            low=0, high=1, open_low=True, open_high=True),
        "cycle_window": Option(6, "int", "number of earlier shift sets checked for a cycle", low=0),
        "stage_stall": Option(None, "int", "update='auto': a stage but the last ends after this many iterations "
                              "without a new smallest measure (0: never; None: shift_update.resolve_stage_stall)",
                              low=0, nullable=True),
        **GUARD_OPTIONS,
        "pivot_tol": Option(0.0, "float", "smallest relative LU pivot before a shift counts as a pole "
                            "(0: only exact singularity and non-finite solves count)", low=0, high=1),
        "shift_perturbation": Option(1e-6, "float", "relative perturbation applied to a shift whose "
                                     "saddle matrix is singular", low=0, high=1, open_low=True),
    }

    #: the advanced options, in groups (:mod:`morsuite.reducers.options`); the rest are top-level
    GROUPS = {
        "shift_update": Group("how the next shifts follow from the reduced model's poles (update='residue' and "
                              "the stages of 'auto')",
                              ("residue_hysteresis", "hysteresis_radius", "relaxation", "stage_stall")),
        "stopping": Group("the convergence measure and the cycle test",
                          ("criterion", "response_tol", "n_check", "cycle_tol", "cycle_window")),
        "safeguards": Group("the safeguard against cycles and unstable fixed points (option safeguard) and the "
                            "shortlist it returns from", tuple(k for k in GUARD_OPTIONS if k != "safeguard"),
                            prefix="safeguard_"),
        "bases": Group("the orthonormal bases, their rank and the oblique projection",
                       ("projection", "orthonormalization", "ill_cond_tol", "rank_tol", "oblique_tol", "hsv_tol")),
        "solves": Group("the shifted solves: poles hit by a shift", ("pivot_tol", "shift_perturbation")),
    }

    #: Score of the shortlisted stable iterates when the iteration does not converge (safeguard
    #: on): a callable ``(fom, rom) -> float``, smaller is better, or None: option
    #: ``shortlist_score`` decides (default the exact H2 error, :class:`~morsuite.reducers.irka.score.ExactH2Score`).
    #: On a reducer, ``red.iterate_score = f``; for every IRKA variant,
    #: ``IRKABase.iterate_score = staticmethod(f)``. Cost: one call per shortlisted iterate, at the end only.
    iterate_score = None

    # -- hooks -------------------------------------------------------------
    def _setup(self) -> dict:
        """Work done once per reducer (timings dict)."""
        return {}

    def _system(self):
        """(M, D, K, F, L) of the model the bases are built for (sparse or dense)."""
        raise TypeError(f"{type(self).__name__} must define the hook _system")  # pragma: no cover

    def _factor(self, a):
        """A factorization of a^2 M + a D + K (bordered by G for the index-3 model)."""
        raise TypeError(f"{type(self).__name__} must define the hook _factor")  # pragma: no cover

    def _solve(self, lu, rhs, trans, a):
        """The solve with the factorization ``lu`` at shift ``a`` (``trans``: transposed)."""
        return lu.solve(rhs, trans=trans)

    def _second(self, lu):
        """The factorization as used by the second (transposed) solve with it."""
        return lu

    def _begin_bases(self):
        """Called once per iteration before the solves."""

    def _refining(self) -> bool:
        """Whether this iteration's solves are refined (IRKA: ``refine_when``)."""
        return False

    def _basis_vector(self, x, a, left: bool):
        """The basis vector made from the solution x of the (``left``: transposed) solve at
        shift a: x itself (a first-order variant stacks it with its derivative part)."""
        return x

    def _restrict(self, X):
        """An orthonormal basis X moved back onto the model's state space
        (the index-3 model: null(G)); the column order is kept."""
        return X

    def _project(self, V, W) -> SecondOrderROM:
        """The reduced model W^T (M, D, K) V, W^T F, L V, with its lift (:meth:`_lift`)."""
        M, D, K, F, L = self._system()
        return SecondOrderROM(W.T @ (M @ V), W.T @ (D @ V), W.T @ (K @ V), W.T @ F, L @ V, basis=self._lift(V))

    def _lift(self, V):
        """The right basis in the index-3 model's positions (``rom.basis``); projected IRKA maps it back."""
        return V

    def _realization(self, rom):
        """(E, A, B, C): the first-order realization of the reduced model the update reduces."""
        return rom.first_order()

    def _poles_and_residues(self, rom, E, B, C):
        """(lam, b, c): the reduced model's finite poles and residue directions, the rows of
        (E Z)^-1 B and of (C Z)^T, Z the eigenvectors of the realization ``_realization``."""
        lam, Z = rom.eig()
        bres = np.linalg.solve(E @ Z, B) if Z.shape[1] == E.shape[0] else np.linalg.lstsq(E @ Z, B, rcond=None)[0]
        return lam, bres, (C @ Z).T

    def _next_data(self, it, current, proposed, relax, blend=False):
        """The interpolation data of iteration ``it + 1``: the ``proposed`` update (alpha, b, c)
        of the ``current`` data, relaxed when ``relax`` < 1 (:func:`~morsuite.reducers.irka.shift_update.relaxed_update`;
        ``blend``: the directions too, phase-aligned, as the engaged safeguard asks).
        A variant may take another step here (the first-order IRKA: Newton's)."""
        if relax < 1:
            return relaxed_update(*current, *proposed, relax, blend_directions=blend)
        return proposed

    def _lu_count(self) -> int:
        return 0

    def _phase_times(self) -> dict:
        return {}

    # -- one iteration -----------------------------------------------------
    def _bases(self, alpha, bdir, cdir, left: bool):
        """Raw real bases: per real shift or conjugate pair one factorization, its solve
        with F b_i and (two-sided) its transposed solve with L^T c_i; complex solutions
        give their real and imaginary parts (:func:`~morsuite.reducers.irka.shift_solves.raw_bases`)."""
        return raw_bases(self, alpha, bdir, cdir, left)

    def _map_shifts(self, fn, jobs) -> list:
        """``[fn(job) for job in jobs]``, in order; a variant may run them concurrently."""
        return [fn(job) for job in jobs]

    def _map_bases(self, fn, bases) -> list:
        """``[fn(X) for X in bases]``: the right and left bases made orthonormal, in order;
        a variant may run them concurrently (``fn`` then must be thread-safe)."""
        return [fn(X) for X in bases]

    def _bases_safe(self, alpha, bdir, cdir, left):
        """Bases; a shift at a pole (singular saddle matrix) is perturbed and retried."""
        npert = 0
        for _ in range(5):
            try:
                Vraw, Wraw = self._bases(alpha, bdir, cdir, left)
                return alpha, Vraw, Wraw, npert
            except SingularShiftError as exc:
                bad = getattr(exc, "shift", None)
                eps = self.options["shift_perturbation"]
                alpha, n = perturb_shifts(alpha, bad, eps)
                npert += n
                self.warn(f"{self.name}: shift(s) {bad} hit a pole of the full model; perturbed by a relative {eps:g}",
                          MorsuiteWarning)
        raise SingularShiftError(f"{self.name}: shifts stay singular after 5 perturbations")

    def _orthonormal(self, X):
        """(Q, s, gram_schmidt_used) per the option ``orthonormalization``."""
        o = self.options
        return orthonormal_basis(X, o["orthonormalization"], o["rank_tol"], o["ill_cond_tol"],
                                 getattr(self, "_ill_conditioned", False))

    def _rom_from_raw(self, Vraw, Wraw, left):
        """Orthonormal bases, the model's state space, the oblique selection and the projection.

        Returns (rom, k, k_rank, ill, gram_schmidt_used): k the order kept, k_rank
        the numerical rank of the bases before the oblique selection, ill whether
        a kept basis direction has relative singular value below ``ill_cond_tol``."""
        o = self.options

        def basis(X):  # orthonormal, ill-conditioned or not, moved onto the state space
            Q, s, used_gs = self._orthonormal(X)
            return self._restrict(Q), ill_conditioned(s, Q.shape[1], o["ill_cond_tol"]), used_gs
        if left:
            (V, ill, gs), (W, ill_w, gs_w) = self._map_bases(basis, [Vraw, Wraw])
            gs, ill = gs or gs_w, ill or ill_w
            V, W, k, k_rank = oblique_selection(V, W, o["oblique_tol"], self.name)
        else:
            V, ill, gs = basis(Vraw)
            W, k = V, V.shape[1]
            k_rank = k
            if k == 0:
                raise zero_transfer_error(self.name, "the projection basis has rank 0")
        return self._project(V, W), k, k_rank, bool(ill), bool(gs)

    def _update(self, rom, k, how, current=None, guard=None):
        """New shifts and directions from the current reduced model (k of them at most);
        ``current``: the shifts of this iteration (the residue update's hysteresis);
        ``how="guarded"``: the residue rule weighted by the engaged safeguard ``guard``."""
        o = self.options
        E, A, B, C = self._realization(rom)
        lam = hsv = None
        if how == "bt":
            lam, bdir, cdir, hsv = bt_rule(E, A, B, C, k, o["hsv_tol"])
            if lam is None:
                how = "residue-fallback"
        if lam is None:
            lam, bres, cres = self._poles_and_residues(rom, E, B, C)
            weights = guard.weights(lam, current) if how == "guarded" else None
            lam, bdir, cdir = residue_rule(lam, bres, cres, k, current=current, hysteresis=o["residue_hysteresis"],
                                           radius=o["hysteresis_radius"], weights=weights)
        if lam.size == 0:
            raise zero_transfer_error(self.name, "the reduced model has no finite pole")
        alpha, bdir, cdir, mirrored = shifts_from_poles(lam, bdir, cdir, self.fom.band)
        return alpha, bdir, cdir, {"update": how, "mirrored": mirrored, "hsv": hsv}

    # -- the iteration -----------------------------------------------------
    def _check_options(self):
        o = self.options
        if o["init"] == "given":
            if o["init_shifts"] is None:
                raise InputError("init='given' needs the option init_shifts")
        elif any(o[k] is not None for k in ("init_shifts", "init_b", "init_c")):
            raise InputError(f"init_shifts/init_b/init_c are only used with init='given' (init={o['init']!r})")

    def _initial(self, r):
        o, fom = self.options, self.fom
        if (warm := self._take_warm()) is not None:
            return self._continued(warm, r, lambda k: initial_shifts(k, fom.band, fom.m, fom.p))
        return initial_shifts(r, fom.band, fom.m, fom.p, init=o["init"], seed=o["seed"], shifts=o["init_shifts"],
                              b=o["init_b"], c=o["init_c"])

    def _criterion(self, lost_rank, d_resp) -> str:
        """The convergence measure in force: option ``criterion``, resolved when "auto"."""
        crit = self.options["criterion"]
        if crit == "auto":
            crit = "response" if lost_rank else "shifts"
            if crit == "shifts" and d_resp < self.options["response_tol"]:
                # the model is a fixed point although some shifts still move:
                # those beyond the numerical order are set by rounding
                crit = "response"
        return crit

    def _reduce(self, r):
        """The iteration in its named phases (:class:`~morsuite.reducers.irka.iteration.Iteration`: start, per
        iteration step, decide and advance, then finish); ``(rom, info)``."""
        return Iteration(self, r).run()

    def _outcome(self, r, best, history, it, converged, cycled, *, times, perturbed, switched):
        """The best iterate, the warnings its state calls for, and the info record."""
        o = self.options
        best_it, (rom, alpha_used, b_used, c_used), _ = best
        # stacklevel 4: the warnings point at the caller of _reduce, as when they were issued there
        if rom.order < r:
            self.warn(f"{self.name}: the projection bases lost numerical rank; the reduced order was capped "
                      f"from r = {r} to r = {rom.order} ({rom.states} first-order states), which is all "
                      f"the model supports to rank_tol = {o['rank_tol']:g}, hsv_tol = {o['hsv_tol']:g}",
                      RankWarning, stacklevel=4)
        if not converged:
            why = ("a cycle of shift sets was detected" if cycled else getattr(self, "_stalled", False)
                   or ("the time budget ran out (deadline)" if getattr(self, "_out_of_time", False)
                       else f"maxit = {o['maxit']} was reached"))
            what = (f"iteration {best_it} (shift change {history[best_it - 1]['measure']:.2e}, tol {o['tol']:g})"
                    if best_it else "its start")
            self.warn(f"{self.name} did not converge at r = {r}: {why}; returning {what}",
                      ConvergenceWarning, stacklevel=4)
        stable = bool(rom.is_stable())
        if not stable:
            self.warn(f"{self.name}: the returned reduced model at r = {rom.order} has unstable poles",
                      StabilityWarning, stacklevel=4)
        info = {"converged": converged, "iterations": it, "best_iteration": best_it, "cycle_detected": cycled,
                "lu_count": self._lu_count(), "time_breakdown": times, "stable": stable,
                "rank_capped": bool(rom.order < r), "shifts": alpha_used, "b": b_used, "c": c_used,
                "perturbed_shifts": perturbed, "update_switched_at": switched,
                "history": {key: [h[key] for h in history] for key in _HISTORY_KEYS}}
        return rom, info
