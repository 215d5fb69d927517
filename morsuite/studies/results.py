"""A run's results by the study's aliases (what scenes see), and the summary table's rows.

:class:`Results` looks artifacts up by model, method, grid, r and scene; it divides an
error norm by the model's norm of the same kind for the relative errors, and takes the
time-domain errors of a reduction from the first ``time`` scene (in the spec's order)
that simulated it.

The summary has one row per reduction (and per grid it has errors on): the columns of
:data:`SUMMARY_COLUMNS`, then the exact norms' columns when the study computes any
(:data:`NORM_COLUMNS` of the kinds it computes) and the time-domain columns when it has a
``time`` scene (:data:`TIME_COLUMNS`), then ``worse_than_zero`` (the norms in which the
reduced model is no better than the zero model, :func:`morsuite.utils.worse_than_zero`),
``cached`` and ``status``.
"""

from __future__ import annotations

import numpy as np

from ..report.tables import TableData
from ..utils import worse_than_zero
from .timedomain import ERROR_COLUMNS

__all__ = ["Results", "summary", "SUMMARY_COLUMNS", "NORM_COLUMNS", "TIME_COLUMNS", "TIME_NOTE", "BAND_NOTE",
           "NORM_NOTE", "TIME_DOMAIN_NOTE", "STATUS_NOTE"]

SUMMARY_COLUMNS = ["model", "method", "reducer", "r_requested", "r", "states", "converged", "reducer_status",
                   "iterations", "stable", "time_s", "time_standalone_s", "lu_count", "lu_count_shared",
                   "lu_count_standalone", "max_abs_error", "max_rel_error", "error_bound", "grid"]
NORM_COLUMNS = {"h2": ["h2_error", "h2_rel_error", "h2_trusted"],
                "hinf": ["hinf_error", "hinf_rel_error", "hinf_upper_bound", "hinf_certified"]}
TIME_COLUMNS = list(ERROR_COLUMNS) + ["time_scene"]
TAIL = ["worse_than_zero", "cached", "status"]

TIME_NOTE = ("time_s is the reducer's own timing of reduce(r) (info['time_s']); when one reducer instance "
             "serves several r, work that does not depend on r (Gramians, a projector) is done in its first "
             "call only. time_standalone_s adds that shared work back: what reducing to this r alone costs. "
             "lu_count is the LUs this call paid, lu_count_shared those of the shared work (whoever paid "
             "them), lu_count_standalone the LUs of reducing to this r alone.")
STATUS_NOTE = ("converged is True only when the method's own optimality or fixed-point test passed on the full "
               "model; reducer_status says how the run ended (converged, direct, cap, cycle, stalled, "
               "uncertified, skipped, partial, detection-failed, stopped: morsuite.reducers.outcome.STATUS). worse_than_zero names the "
               "norms (band, h2, hinf, max_output, l2_output) in which the error is at or above the full "
               "model's own norm, the error of the zero model T_r = 0.")
BAND_NOTE = ("max_abs_error and max_rel_error are band quantities: the maximum of sigma_max(T - T_r) (over "
             "sigma_max(T)) on the frequencies of the grid named in the grid column.")
NORM_NOTE = ("h2_error is the exact H2 norm of T - T_r over the whole "
             "axis (h2_rel_error: divided by ||T||_H2); h2_trusted = False marks a value whose estimated accuracy "
             "is worse than four digits (never to be read as exact); the estimate (the H2 floor) is validated "
             "against long-double references, not a proved bound (docs/design/norms.md). "
             "hinf_error is the peak of sigma_max(T - T_r) "
             "over the whole axis that the search found: a lower bound of the Hinf norm, exact at that peak "
             "(hinf_rel_error: divided by the peak of sigma_max(T) found, a ratio of two peaks found: neither a bound "
             "nor certified). hinf_upper_bound is "
             "an upper bound certified by a level-set (Hamiltonian) test of the dense error system, computed where "
             "the model's hidden manifold is small (n1 - n2 <= certify_dim); hinf_certified = True: the Hinf norm "
             "lies between hinf_error and hinf_upper_bound; False (bound empty): only the lower bound is known. "
             "An unstable reduced model has infinite norms.")
TIME_DOMAIN_NOTE = ("max_output_error and l2_output_error are max_t and the L2 norm over the horizon of "
                    "||y(t) - y_r(t)||_2 for the input of the time scene named in time_scene (full and reduced "
                    "model by the same time-stepping scheme); the relative versions divide by max_t ||y(t)||_2 "
                    "and ||y||_L2. growth = True: the reduced model is unstable and its output grows.")


class Results:
    """Read access to a run's artifacts by the study's aliases (what scenes see)."""

    def __init__(self, study, plan, foms, reductions, metrics, norms=None, norm_errors=None, sims=None,
                 sim_errors=None, modes=None, tolerances=None):
        self.study, self.plan = study, plan
        #: the study's modes and poles as the page shows them (``{"rows", "poles", "note"}``, see
        #: docs/design/reports.md "Modes and poles"), or None: no modes section on the page
        self.modes = modes
        #: each ``modes`` scene's data by scene name (:func:`morsuite.studies.modes.compute_modes`)
        self.modes_of: dict = {}
        self._foms, self._red, self._met = foms, reductions, metrics
        self._norms, self._nerr = norms or {}, norm_errors or {}
        self._sims, self._serr = sims or {}, sim_errors or {}
        self._tol = tolerances or {}

    def tolerance(self, scene, method):
        """The tolerance search entry of ``method`` in tolerance scene ``scene`` (names), or None."""
        return self._tol.get(self.plan.tolerance_of.get((scene, method)))

    def fom(self, model, grid):
        """The full-order response entry of ``model`` on ``grid`` (aliases), or None."""
        fid = self.plan.fom_of.get((model, grid))
        return self._foms.get(fid)

    def reduction(self, model, method, r):
        """The reduction entry (ROM payload, info, timings) of ``method`` at ``r``, or None."""
        gid = self.plan.reduce_of.get((model, method))
        return self._red.get(gid, {}).get(r)

    def metrics(self, model, grid, method, r):
        """The band errors of that reduction on ``grid``, or None."""
        mid = self.plan.metrics_of.get((model, grid, method))
        return self._met.get(mid, {}).get(r) if mid else None

    def norm(self, model, kind):
        """The model's norm entry of ``kind`` (``value``, route, LUs) or None."""
        return self._norms.get(self.plan.norm_of.get((model, kind)))

    def norm_error(self, model, method, r, kind):
        """The exact error norm entry (``kind``: 'h2' or 'hinf') of that reduction, or None."""
        gid = self.plan.norm_group_of.get((model, method, kind))
        return self._nerr.get(gid, {}).get(r) if gid else None

    def norm_columns(self, model, method, r) -> dict:
        """``K_error``, ``K_rel_error`` (and ``h2_trusted``; ``hinf_upper_bound``, ``hinf_certified``) of
        each norm kind computed for this reduction; ``K_failed`` says why one is missing."""
        out = {}
        for kind in ("h2", "hinf"):
            if (model, method, kind) not in self.plan.norm_group_of:
                continue
            e, n = self.norm_error(model, method, r, kind), self.norm(model, kind)
            if e is None or "error" in e:
                out[f"{kind}_failed"] = e["error"] if e else "not computed"
                continue
            value = float(e["value"])
            out[f"{kind}_error"] = value
            ok = n is not None and "error" not in n and n["value"] > 0
            out[f"{kind}_rel_error"] = value / float(n["value"]) if ok else None
            if kind == "h2":
                out["h2_trusted"] = bool(e["trusted"] and (n is None or n.get("trusted", True)))
            else:  # the value is a lower bound; the level-set test's upper bound where it ran
                out["hinf_upper_bound"] = e.get("upper_bound")
                out["hinf_certified"] = bool(e.get("certified", False))
        return out

    def simulation(self, scene):
        """The full model's simulation entry of time scene ``scene``, or None."""
        return self._sims.get(self.plan.sim_of.get(scene))

    def sim_error(self, scene, method, r):
        """The time-domain error entry of ``method`` at ``r`` in time scene ``scene``, or None."""
        gid = self.plan.sim_group_of.get((scene, method))
        return self._serr.get(gid, {}).get(r) if gid else None

    def time_columns(self, model, method, r) -> dict:
        """The time-domain errors of the first time scene that simulated this reduction (or {})."""
        for s in self.study.scenes:
            if s.kind == "time" and s.model == model and method in s.methods and r in s.rs_of(method):
                e = self.sim_error(s.name, method, r)
                if e is not None and "error" not in e:
                    return {**{c: e.get(c) for c in ERROR_COLUMNS}, "time_scene": s.name}
        return {}

    def summary_columns(self) -> list:
        """The summary's columns: the base ones, norm columns if norms were computed, time-domain
        columns if a time scene ran."""
        kinds = {g.kind for g in self.plan.norm_groups.values()}
        cols = list(SUMMARY_COLUMNS)
        for kind in ("h2", "hinf"):
            if kind in kinds:
                cols += NORM_COLUMNS[kind]
        if self.plan.sim_groups:
            cols += TIME_COLUMNS
        return cols + TAIL

    def summary_row(self, model, method, r, grid=None) -> dict:
        """One row of the summary for that reduction (band errors from ``grid`` if given)."""
        red = self.reduction(model, method, r)
        met = self.metrics(model, grid, method, r) if grid else None
        m = self.study.methods[method]
        row = dict.fromkeys(self.summary_columns())
        row.update(model=self.study.models[model].name, method=method, reducer=m.reducer, r_requested=int(r),
                   grid=grid if met else None)
        if red is None:
            row["status"] = "not computed"
            return row
        row["cached"] = bool(red.get("cached", False))
        if "error" in red:
            row["status"] = "failed: " + red["error"]
            return row
        info = red["info"]
        row.update(r=int(info["r"]), states=int(info["states"]), converged=bool(info.get("converged")),
                   reducer_status=info.get("status"),
                   iterations=int(info.get("iterations", 0)), stable=bool(info.get("stable")),
                   time_s=float(red["time_s"]), time_standalone_s=float(red["time_standalone_s"]),
                   lu_count=info.get("lu_count"), lu_count_shared=info.get("lu_count_shared"),
                   lu_count_standalone=red.get("lu_count_standalone"), status="ok")
        bound = info.get("error_bound")
        if isinstance(bound, (int, float)) and not isinstance(bound, bool):
            row["error_bound"] = float(bound)  # the reducer's own a-priori bound (BT), when it has one
        if met is not None and "error" not in met:
            row.update(max_abs_error=met["max_abs_error"], max_rel_error=met["max_rel_error"])
        row.update({k: v for k, v in self.norm_columns(model, method, r).items() if k in row})
        row.update({k: v for k, v in self.time_columns(model, method, r).items() if k in row})
        row["worse_than_zero"] = ",".join(self._worse_than_zero(row, model, met, grid))
        return row

    def _worse_than_zero(self, row, model, met, grid) -> list:
        """The norms of this row whose error is at or above the full model's (utils.worse_than_zero)."""
        fom = self.fom(model, grid) if met is not None and "error" not in met else None
        peak = float(np.max(fom["sigma_full"])) if fom is not None and "sigma_full" in fom else None
        rel = {k: (row.get(f"{k}_rel_error"), 1.0) for k in ("h2", "hinf", "max_output", "l2_output")}
        return worse_than_zero(band=(row.get("max_abs_error"), peak), **rel)


def summary(study, plan, res, name) -> TableData:
    """The summary table: every reduction of the run (one row per grid with errors, or one)."""
    rows = []
    grids_of = {}
    for (model, grid, method) in plan.metrics_of:
        grids_of.setdefault((model, method), []).append(grid)
    for (model, method), gid in sorted(plan.reduce_of.items()):
        for r in plan.reduces[gid].rs:
            grids = [g for g in sorted(grids_of.get((model, method), [])) if res.metrics(model, g, method, r)]
            for grid in grids or [None]:
                rows.append(res.summary_row(model, method, r, grid))
    note = "\n\n".join([BAND_NOTE] + ([NORM_NOTE] if plan.norm_groups else []) + [TIME_NOTE, STATUS_NOTE] +
                       ([TIME_DOMAIN_NOTE] if plan.sim_groups else []))
    return TableData(name, f"{study.title}: every reduction of this run", rows, columns=res.summary_columns(),
                     int_columns=("r", "states", "iterations", "lu_count", "lu_count_shared",
                                  "lu_count_standalone"), note=note)
