"""A run's ``manifest.json``: the study, the machine, every artifact and file.

Artifacts are listed with their kind (``fom_response``, ``reduction``, ``metrics``,
``figure``, ``table``), their cache or content key and ``reused``: taken from the
cache (the three computed kinds; also ``cached``) or left as the last run wrote
them (figures and tables, :mod:`.outputs`). ``reused`` and ``computed`` at the
top level list the ids of each.
"""

from __future__ import annotations

import hashlib
import sys

from .. import __version__

__all__ = ["manifest"]


def _artifacts(plan, foms, reductions, metrics) -> list:
    arts = []
    for fid, f in plan.foms.items():
        e = foms[fid]
        arts.append({"id": fid, "kind": "fom_response", "model": f.model.name, "grid": list(f.bounds),
                     "aliases": sorted(map(list, f.aliases)), "key": f.key, "cached": bool(e.get("cached")),
                     "time_s": e.get("time_s"), "lu_count": e.get("lu_count"), "scheduler": e.get("scheduler"),
                     "host": e.get("host"),
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
                         "converged": info.get("converged"), "iterations": info.get("iterations"),
                         "lu_count": info.get("lu_count"), "time_breakdown": info.get("time_breakdown"),
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
    for a in arts:
        a["reused"] = a["cached"]
    return arts


def manifest(study, plan, choice, cache, foms, reductions, metrics, outputs, files, outdir, notes, started,
             timing, rerender) -> dict:
    """The manifest of one run (plain data; ``outputs`` are the records of :func:`.outputs.realize`)."""
    from .environment import environment
    from .runner import H2_NOTE, TIME_NOTE

    spec_text = study.path.read_text() if study.path is not None else None
    for rec in outputs:  # a scene's model, for readers who look artifacts up by model
        scene = next((s for s in study.scenes if s.name == rec["scene"]), None)
        rec["model"] = study.models[scene.model].name if scene is not None else None
        rec.setdefault("reducer", None)
    arts = _artifacts(plan, foms, reductions, metrics) + list(outputs)
    return {
        "study": study.name, "title": study.title, "description": study.description,
        "spec": str(study.path) if study.path else None,
        "spec_sha256": hashlib.sha256(spec_text.encode()).hexdigest() if spec_text else None,
        "config_hash": study.config_hash, "morsuite": __version__, "started": started, "argv": sys.argv,
        **environment(),
        "scheduler": choice.describe(),
        "cache": {"dir": str(cache.root), "read": cache.read, "write": cache.write},
        "models": {a: {"spec": m.spec, "source": m.source, "model_id": m.model_id, "name": m.name,
                       "n1": m.n1, "n2": m.n2, "band": list(m.band)} for a, m in study.models.items()},
        "grids": {g.name: {"band": g.band, "n": g.n} for g in study.grids.values()},
        "methods": {a: {"reducer": m.reducer, "label": m.label, "options_given": m.options,
                        "options": m.full_options} for a, m in study.methods.items()},
        "seeds": {a: m.full_options["seed"] for a, m in study.methods.items() if "seed" in m.full_options},
        "scenes": [{"name": s.name, "kind": s.kind, "model": s.model, "methods": list(s.methods),
                    "r": list(s.rs), "grid": s.grid, "params": s.params,
                    "paper_csv": {k: str(v) for k, v in s.paper.items()}} for s in study.scenes],
        "artifacts": arts,
        "reused": [a["id"] for a in arts if a["reused"]],
        "computed": [a["id"] for a in arts if not a["reused"]],
        "rerender": bool(rerender),
        "files": sorted(str(p.relative_to(outdir)) for p in files),
        "notes": notes, "definitions": {"h2_error_grid": H2_NOTE, "time": TIME_NOTE},
        "timing": timing,
    }
