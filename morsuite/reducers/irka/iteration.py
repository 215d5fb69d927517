r"""The IRKA iteration of :class:`~morsuite.reducers.irka.engine.IRKABase`, in named phases on its state.

:class:`Iteration` holds what one ``reduce(r)`` call carries from iteration to iteration (the
interpolation data, the history, the cycle window, the shortlist, the safeguard, the update
schedule, the timings) and runs it in phases:

1. :meth:`~Iteration.start`: the reducer's r-independent setup and the initial data;
2. per iteration, :meth:`~Iteration.step`: the bases (one factorization per real shift or
   conjugate pair), the reduced model, the proposed update, the convergence measures and the
   iteration's record;
3. :meth:`~Iteration.decide`: converged, or a cycle, a stage's end, an unstable fixed point, a
   stall, the engaged safeguard's stop; returns whether the iteration stops;
4. :meth:`~Iteration.advance`: the next data (the safeguard's update where it took over, the
   relaxed step);
5. :meth:`~Iteration.finish`: the returned iterate (converged, else the shortlist's best, scored),
   the record and the status.

The module docstring of :mod:`~morsuite.reducers.irka.engine` states the mathematics and the
rules; the phases compute exactly what the single loop did before (2026-12-02, issue 47), in the
same order. Cost: the iteration's (engine docstring).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ...linalg.dense import shift_distance, sigma_max
from .safeguards import GUARD_CYCLES, ITERATE_CYCLE, CycleGuard, Shortlist, ban_culprit, is_cycle
from .score import iterate_scorer, score_cost
from .shift_update import UpdateSchedule, resolve_stage_stall

__all__ = ["Iteration", "Step"]


@dataclass
class Step:
    """What one iteration computed: its reduced model and raw bases, the proposed next data, the measures."""

    rom: object
    Vraw: np.ndarray
    Wraw: np.ndarray
    stable: bool
    proposed: tuple        # (alpha, b, c) of the update
    uinfo: dict
    d_shift: float
    crit: str
    measure: float
    reason: str | None = None


class Iteration:
    """One run of the IRKA iteration of reducer ``red`` at order ``r`` (module docstring)."""

    def __init__(self, red, r):
        self.red, self.r, self.o = red, r, red.options
        self.start()

    # -- 1. the start ----------------------------------------------------------
    def start(self):
        """The reducer's setup (timed), the initial data, and the state of the iteration."""
        red, o = self.red, self.o
        t0 = time.perf_counter()
        self.setup_times = red._setup()
        self.t_setup = time.perf_counter() - t0
        self.alpha, self.bdir, self.cdir = red._initial(self.r)
        self.left = o["projection"] == "petrov"
        self.history, self.recent = [], []
        self.shortlist = Shortlist(o["shortlist"])
        self.guard = CycleGuard.from_options(o)
        self.chosen = None
        self.converged = self.cycled = False
        self.stalled = self.forget = self.out_of_time = False
        self.t_proj = self.t_upd = 0.0
        self.cap = self.r
        self.schedule = UpdateSchedule(o["update"], o["relaxation"], o["maxit"],
                                       resolve_stage_stall(o["stage_stall"], red.fom.n1))
        self.how, self.relax = self.schedule.rule
        self.lost_rank = False
        self.check_grid = np.logspace(np.log10(red.fom.band[0]), np.log10(red.fom.band[1]), o["n_check"])
        self.H_prev = None
        self.it = self.perturbed = 0
        self.prev_change = np.inf
        red._ill_conditioned = False  # read by the solves of the next iteration (IRKA: refine_when)

    def run(self):
        """Iterate to convergence, a stop or ``maxit``; then :meth:`finish`. Returns ``(rom, info)``."""
        for it in range(1, self.o["maxit"] + 1):
            self.it = it
            step = self.step(it)
            if self.decide(it, step):
                break
            if self.red.deadline is not None and time.perf_counter() >= self.red.deadline:
                self.out_of_time = True  # a caller's time budget (Reducer.deadline): the best iterate so far
                break  # _outcome's warning says why
            self.advance(it, step)
        return self.finish()

    # -- 2. one iteration's computation ---------------------------------------------------
    def step(self, it) -> Step:
        """Bases, reduced model, proposed update, measures; the iteration's record and shortlist entry."""
        red, o, guard = self.red, self.o, self.guard
        refined = red._refining()
        self.alpha, Vraw, Wraw, npert = red._bases_safe(self.alpha, self.bdir, self.cdir, self.left)
        self.perturbed += npert
        t0 = time.perf_counter()
        rom, k, k_rank, ill, gs = red._rom_from_raw(Vraw, Wraw, self.left)
        poles = rom.poles()
        stable = bool(np.all(poles.real < 0))
        max_pole_real = float(poles.real.max()) if poles.size else -np.inf
        t1 = time.perf_counter()
        rank_short = it > 1 and k_rank < self.alpha.size
        if rank_short:
            # the shifts of this iteration ask for more than the model holds:
            # shrink the shift count for good (it never grows back)
            self.cap = min(self.cap, k_rank)
        # the guard is passed only when engaged: an override of _update without it still works
        extra = {"guard": guard} if guard.engaged else {}
        new_alpha, new_b, new_c, uinfo = red._update(rom, min(self.cap, rom.states),
                                                     "guarded" if guard.engaged else self.how, current=self.alpha,
                                                     **extra)
        t2 = time.perf_counter()
        self.t_proj += t1 - t0
        self.t_upd += t2 - t1
        d_shift = shift_distance(new_alpha, self.alpha)
        H = rom.freqresp(self.check_grid)
        d_resp = (float(np.max(sigma_max(H - self.H_prev)) / max(np.max(sigma_max(H)), np.finfo(float).tiny))
                  if self.H_prev is not None else np.inf)
        self.H_prev = H
        self.lost_rank = self.lost_rank or rank_short
        crit = red._criterion(self.lost_rank, d_resp)
        measure = d_resp if crit == "response" else d_shift
        red._ill_conditioned = bool(ill)
        alpha = self.alpha
        self.history.append({"iteration": it, "shifts": alpha.copy(), "n_shifts": int(alpha.size), "rank": int(k),
                             "ill_conditioned": bool(ill), "refined": bool(refined), "gram_schmidt": gs,
                             "measure": measure, "shift_change": d_shift, "response_change": d_resp,
                             "criterion": crit, "stable": stable, "max_pole_real": max_pole_real,
                             "update": uinfo["update"], "mirrored": uinfo["mirrored"], "step": 1.0})
        self.shortlist.add(measure, it, stable, (rom, alpha.copy(), self.bdir.copy(), self.cdir.copy()))
        return Step(rom, Vraw, Wraw, stable, (new_alpha, new_b, new_c), uinfo, d_shift, crit, measure)

    # -- 3. the decision -------------------------------------------------------------
    def decide(self, it, step: Step) -> bool:
        """True when the iteration stops here: converged (a stable iterate below ``tol``), a cycle with the
        safeguard off or engaged past its reactions, or the engaged safeguard's stop. Otherwise it may
        switch the update's stage, engage the safeguard (``step.reason``) or react to a cycle."""
        o, guard, schedule = self.o, self.guard, self.schedule
        alpha = self.alpha
        if step.measure < o["tol"] and step.stable:
            # an unstable iterate is not a fixed point worth returning: iterate on
            self.converged = True
            self.chosen = (it, (step.rom, alpha.copy(), self.bdir.copy(), self.cdir.copy()), {})
            return True
        new_alpha, d_shift = step.proposed[0], step.d_shift
        guard.observe(step.measure)
        if guard.active and not step.stable and step.measure < guard.settle:
            step.reason = "unstable fixed point"  # the criterion never accepts it: move away
        elif step.crit == "shifts" and (is_cycle(new_alpha, d_shift, self.recent, o)
                                        or (guard.engaged and o["safeguard_stop"]
                                            and is_cycle(alpha, d_shift, self.recent, o, ITERATE_CYCLE))):
            # engaged, the relaxed iterates can cycle while no proposed set repeats: both are watched
            if guard.engaged and o["safeguard_stop"] and guard.cycles >= GUARD_CYCLES:
                self.cycled = True  # it cycles on through its stronger hysteresis and smaller steps: stop
                guard.events.append((it, f"cycle after {guard.cycles} reactions: stopped"))
                return True
            if guard.engaged:
                guard.on_cycle(it)
                # stopping: the answer is judged on the iterates that follow it, not on the old cycle
                self.forget = bool(o["safeguard_stop"])
                self.prev_change = np.inf  # the step was just halved: no second adaptation
            elif schedule.can_switch():
                schedule.switch(it)
                guard.new_stage()
            elif guard.active:
                step.reason = "cycle"
            else:
                self.cycled = True
                return True
        elif why := schedule.stage_over(it, guard):  # its share of maxit used up, or stalled
            schedule.switch(it, why)
            guard.new_stage()
        elif guard.active and not guard.engaged and not schedule.can_switch() and guard.stalled():
            step.reason = "stall"
        elif guard.engaged and o["safeguard_stop"] and (stalled := guard.stop_reason(o, it)):
            self.stalled = stalled
            return True  # engaged: no progress in a window, or tol out of reach at its rate
        return False

    # -- 4. the next data -------------------------------------------------------------
    def advance(self, it, step: Step):
        """The next interpolation data: the safeguard's update where it engages or reacts, else the proposed
        one, relaxed by the schedule's or the engaged safeguard's step."""
        red, o, guard = self.red, self.o, self.guard
        alpha = self.alpha
        new_alpha, new_b, new_c = step.proposed
        self.how, relax = self.schedule.rule
        if step.reason is not None:
            if step.reason == "unstable fixed point":
                ban_culprit(guard, it, alpha, red._rom_from_raw, step.Vraw, step.Wraw, self.left)
                guard.step = 1.0  # jump off the banned shift, do not creep away from it
            if not guard.engaged:
                guard.engage(it, step.reason)
            new_alpha, new_b, new_c, uinfo = red._update(step.rom, min(self.cap, step.rom.states), "guarded",
                                                         current=alpha, guard=guard)
            self.history[-1]["update"] = uinfo["update"]
        elif guard.engaged:
            relax = guard.adapt_step(step.d_shift, self.prev_change) if np.isfinite(self.prev_change) else guard.step
        self.relax = relax
        self.prev_change = step.d_shift
        self.history[-1]["step"] = relax
        self.recent = ((self.recent + [alpha.copy()])[-o["cycle_window"]:] if o["cycle_window"] and not self.forget
                       else [])
        self.forget = False
        self.alpha, self.bdir, self.cdir = red._next_data(it, (alpha, self.bdir, self.cdir),
                                                          (new_alpha, new_b, new_c), relax, blend=guard.engaged)

    # -- 5. the result -------------------------------------------------------------------
    def finish(self):
        """``(rom, info)``: the returned iterate (scored from the shortlist without convergence), the
        reducer's record (:meth:`~morsuite.reducers.irka.engine.IRKABase._outcome`), the safeguard's record,
        the scores' LUs and the status."""
        red, guard, schedule = self.red, self.guard, self.schedule
        chosen, score = self.chosen, None
        if chosen is None:
            # out of time: the iterates are chosen by the measure (scoring them may need the Gramian factors)
            score = iterate_scorer(red) if guard.active and not self.out_of_time else None
            chosen = self.shortlist.choose(None if score is None else (lambda m: score(red.fom, m)))
        times = {"setup": self.t_setup, **self.setup_times, **red._phase_times(), "projection": self.t_proj,
                 "shift_update": self.t_upd}
        red._stalled = self.stalled  # read by _outcome (its signature is shared with the variants)
        red._out_of_time = self.out_of_time
        rom, info = red._outcome(self.r, chosen, self.history, self.it, self.converged, self.cycled, times=times,
                                 perturbed=self.perturbed, switched=schedule.switched_at)
        info.update(update_switch_reasons=list(schedule.switch_reasons), stage_stall=schedule.stall)
        info["safeguard"] = {**guard.info(), "active": guard.active,
                             "scored_by": "iterate_score" if chosen[2] else "measure",
                             "scores": {str(i): v for i, v in chosen[2].items()}, **score_cost(score)}
        sg = info["safeguard"]
        info["lu_count"] += sg["score_lu_count"] + sg["score_gramian_lu_count"]
        if "lu_count_shared" not in info:  # a variant may overrule
            # the scores' r-independent Gramian factors, whoever paid them (reducers.outcome): the same
            # count whatever ran before on the model; a call that found them cached reused them
            info["lu_count_shared"] = sg["score_gramian_lu_relied"]
            if sg["score_gramian_lu_relied"] and not sg["score_gramian_lu_count"]:
                info["setup_reused"] = True
                info["setup_cost"] = {"score_gramians": sg["score_gramian_time_relied"]}
        info.setdefault("status", "converged" if info["converged"] else "cycle" if self.cycled  # a variant may
                        else "stalled" if self.stalled else "uncertified" if self.converged  # overrule
                        else "budget" if self.out_of_time else "cap")
        return rom, info
