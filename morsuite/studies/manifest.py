"""A run's ``manifest.json``: the study, the machine, every artifact and file.

Artifacts are listed with their kind (``fom_response``, ``reduction``, ``metrics``,
``model_norm``, ``norm_error``, ``simulation``, ``sim_error``, ``figure``, ``table``),
their cache or content key and ``reused``: taken from the cache (the computed kinds;
also ``cached``) or left as the last run wrote them (figures and tables,
:mod:`.outputs`). A norm's record says how it was computed (route, LUs, estimated
accuracy ``floor``/``rel_floor``, ``trusted``, warnings); a simulation's, its LUs,
solves, growth flag and output errors. The full response, the reductions and the norms
carry ``solve_backward_error`` and ``solve_accuracy``: what their checked saddle-point
solves reached (:mod:`morsuite.linalg.accuracy`; None for an entry cached before
2026-12-02). ``reused`` and ``computed`` at the
top level list the ids of each.
"""

from __future__ import annotations

import hashlib
import sys

from .. import __version__

__all__ = ["manifest"]


def _artifacts(plan, res) -> list:
    foms, reductions, metrics = res._foms, res._red, res._met
    arts = []
    for fid, f in plan.foms.items():
        e = foms[fid]
        arts.append({"id": fid, "kind": "fom_response", "model": f.model.name, "grid": list(f.bounds),
                     "aliases": sorted(map(list, f.aliases)), "key": f.key, "cached": bool(e.get("cached")),
                     "time_s": e.get("time_s"), "lu_count": e.get("lu_count"),
                     "solve_backward_error": e.get("solve_backward_error"), "solve_accuracy": e.get("solve_accuracy"),
                     "scheduler": e.get("scheduler"), "host": e.get("host"),
                     "created": e.get("created")})
    for gid, g in plan.reduces.items():
        for r in g.rs:
            e = reductions[gid].get(r, {})
            info = e.get("info", {})
            arts.append({"id": f"{gid}/r{r}", "kind": "reduction", "group": gid, "model": g.model.name,
                         "reducer": g.method.reducer, "method_aliases": sorted({a[1] for a in g.aliases}),
                         "options": g.method.full_options, "r_requested": r, "r": info.get("r"),
                         "states": info.get("states"), "key": g.keys[r], "cached": bool(e.get("cached")),
                         "time_s": e.get("time_s"), "time_standalone_s": e.get("time_standalone_s"),
                         "wall_s": e.get("wall_s"), "call_index": e.get("call_index"),
                         "converged": info.get("converged"), "status": info.get("status"),
                         "iterations": info.get("iterations"), "lu_count": info.get("lu_count"),
                         "lu_count_shared": info.get("lu_count_shared"), "lu_backend": info.get("lu_backend"),
                         "solve_backward_error": info.get("solve_backward_error"),
                         "solve_accuracy": info.get("solve_accuracy"),
                         "time_breakdown": info.get("time_breakdown"),
                         "warnings": info.get("warnings"), "error": e.get("error"), "scheduler": e.get("scheduler"),
                         "host": e.get("host"),
                         "created": e.get("created")})
    for mid, mg in plan.metrics.items():
        for r in mg.rs:
            e = metrics[mid].get(r, {})
            g = plan.reduces[mg.reduce]
            arts.append({"id": f"{mid}/r{r}", "kind": "metrics", "model": g.model.name, "reducer": g.method.reducer,
                         "r_requested": r, "grid": list(plan.foms[mg.fom].bounds), "fom": mg.fom,
                         "reduction": f"{mg.reduce}/r{r}", "key": mg.keys[r], "cached": bool(e.get("cached")),
                         "time_s": e.get("time_s"), "error": e.get("error")})
    arts += _norm_artifacts(plan, res) + _time_artifacts(plan, res) + _tolerance_artifacts(plan, res)
    for a in arts:
        a["reused"] = a["cached"]
    return arts


#: what the manifest keeps of a norm entry (the route, LUs, accuracy, warnings), and of a simulation's
_NORM_FIELDS = ("value", "route", "lu_count", "trusted", "floor", "rel_floor", "rtol_met", "nodes", "peak_frequency",
                "lower_bound", "upper_bound", "certified", "samples", "factor_rank", "adi_converged", "reason", "options", "time_s", "warnings", "error",
                "solve_backward_error", "solve_accuracy", "scheduler", "host", "created")
_SIM_FIELDS = ("integrator", "steps", "lu_count", "solves", "time_s", "growth", "unstable_poles", "growth_factor",
               "finite", "constraint_residual", "warnings", "error", "scheduler", "host", "created")
_SIM_ERRORS = ("max_output_error", "l2_output_error", "max_output_rel_error", "l2_output_rel_error", "max_output",
               "l2_output", "t_max_error")


def _norm_artifacts(plan, res) -> list:
    arts = []
    for nid, n in plan.norms.items():
        e = res._norms.get(nid, {})
        arts.append({"id": nid, "kind": "model_norm", "model": n.model.name, "reducer": None, "norm": n.kind,
                     "key": n.key, "cached": bool(e.get("cached")), **{k: e.get(k) for k in _NORM_FIELDS}})
    for gid, g in plan.norm_groups.items():
        red = plan.reduces[g.reduce]
        for r in g.rs:
            e = res._nerr.get(gid, {}).get(r, {})
            arts.append({"id": f"{gid}/r{r}", "kind": "norm_error", "model": red.model.name,
                         "reducer": red.method.reducer, "norm": g.kind, "r_requested": r,
                         "reduction": f"{g.reduce}/r{r}", "model_norm": g.norm, "key": g.keys[r],
                         "cached": bool(e.get("cached")), **{k: e.get(k) for k in _NORM_FIELDS}})
    return arts


def _tolerance_artifacts(plan, res) -> list:
    """A record per tolerance search: its settings, every order it evaluated, one outcome per tolerance."""
    arts = []
    for tid, t in plan.tolerances.items():
        e = res._tol.get(tid, {})
        search = e.get("search") or {}
        arts.append({"id": tid, "kind": "tolerance", "model": t.model.name, "reducer": t.method.reducer,
                     "options": t.method.full_options, "settings": t.settings, "norm_options": t.norm_options,
                     "fom": t.fom, "scenes": t.scenes, "key": t.key, "cached": bool(e.get("cached")),
                     "time_s": e.get("time_s"), "lus": search.get("lus"), "scale": search.get("scale"),
                     "outcomes": search.get("outcomes"), "candidates": search.get("candidates"),
                     "warnings": e.get("warnings"), "error": e.get("error"), "scheduler": e.get("scheduler"),
                     "host": e.get("host"), "created": e.get("created")})
    return arts


def _time_artifacts(plan, res) -> list:
    arts = []
    for sid, sim in plan.sims.items():
        e = res._sims.get(sid, {})
        arts.append({"id": sid, "kind": "simulation", "model": sim.model.name, "reducer": None,
                     "settings": sim.settings, "scenes": sim.scenes, "key": sim.key, "cached": bool(e.get("cached")),
                     **{k: e.get(k) for k in _SIM_FIELDS}})
    for gid, g in plan.sim_groups.items():
        red = plan.reduces[g.reduce]
        for r in g.rs:
            e = res._serr.get(gid, {}).get(r, {})
            arts.append({"id": f"{gid}/r{r}", "kind": "sim_error", "model": red.model.name,
                         "reducer": red.method.reducer, "r_requested": r, "simulation": g.sim,
                         "reduction": f"{g.reduce}/r{r}", "rom_method": g.rom_method, "scenes": g.scenes,
                         "key": g.keys[r], "cached": bool(e.get("cached")),
                         **{k: e.get(k) for k in _SIM_FIELDS + _SIM_ERRORS}})
    return arts


def manifest(study, plan, choice, cache, res, outputs, files, outdir, notes, started, timing, rerender) -> dict:
    """The manifest of one run (plain data; ``res`` the :class:`~.results.Results`, ``outputs``
    the records of :func:`.outputs.realize`)."""
    from .environment import environment
    from .results import BAND_NOTE, NORM_NOTE, TIME_DOMAIN_NOTE, TIME_NOTE

    spec_text = study.path.read_text() if study.path is not None else None
    for rec in outputs:  # a scene's model, for readers who look artifacts up by model
        scene = next((s for s in study.scenes if s.name == rec["scene"]), None)
        rec["model"] = study.models[scene.model].name if scene is not None else None
        rec.setdefault("reducer", None)
    arts = _artifacts(plan, res) + list(outputs)
    return {
        "study": study.name, "title": study.title, "description": study.description,
        "spec": str(study.path) if study.path else None,
        "spec_sha256": hashlib.sha256(spec_text.encode()).hexdigest() if spec_text else None,
        "config_hash": study.config_hash, "morsuite": __version__, "started": started, "argv": sys.argv,
        **environment(),
        "scheduler": choice.describe(),
        "cache": {"dir": str(cache.root), "read": cache.read, "write": cache.write},
        "models": {a: {"spec": m.spec, "source": m.source, "model_id": m.model_id, "name": m.name,
                       "n1": m.n1, "n2": m.n2, "m": m.m, "p": m.p, "band": list(m.band)}
                   for a, m in study.models.items()},
        "grids": {g.name: {"band": g.band, "n": g.n} for g in study.grids.values()},
        "methods": {a: {"reducer": m.reducer, "label": m.label, "options_given": m.options,
                        "options": m.full_options} for a, m in study.methods.items()},
        "seeds": {a: m.full_options["seed"] for a, m in study.methods.items() if "seed" in m.full_options},
        "scenes": [{"name": s.name, "kind": s.kind, "model": s.model, "methods": list(s.methods),
                    "r": list(s.rs), "grid": s.grid, "params": s.params,
                    "paper_csv": {k: str(v) for k, v in s.paper.items()},
                    **({"r_by_method": {k: list(v) for k, v in s.r_by_method.items()}} if s.r_by_method else {})}
                   for s in study.scenes],
        "artifacts": arts,
        "reused": [a["id"] for a in arts if a["reused"]],
        "computed": [a["id"] for a in arts if not a["reused"]],
        "rerender": bool(rerender),
        "files": sorted(str(p.relative_to(outdir)) for p in files),
        "norms": {"summary": list(study.norms), "options": study.norm_options},
        "notes": notes, "definitions": {"band_errors": BAND_NOTE, "norms": NORM_NOTE, "time": TIME_NOTE,
                                        "time_domain": TIME_DOMAIN_NOTE},
        "timing": timing,
    }
