"""The study runner: spec -> plan -> cache lookup -> Dask graph -> results folder.

``run("studies/paper_dsms.toml")`` validates the spec (nothing is computed if it
is wrong), plans the artifacts its scenes need, takes what the cache holds,
computes the rest as a Dask graph (synchronous by default), and writes
``OUT/NAME/``: a CSV per curve, PNG, PDF and pgfplots per figure, tables,
``summary.csv``/``summary.md`` (every reduction computed), ``manifest.json`` and the
study's page ``index.html`` (:mod:`.pages`); ``OUT/index.html`` links every study's page.

Nothing is done twice: computed artifacts come from the cache when their key is
there (a fully cached study builds no Dask graph and no model: see
:mod:`.memo`), and a figure or table whose content did not change is neither
drawn nor written (:mod:`.outputs`); matplotlib, pandas and dask are imported
only when something needs them.
"""

from __future__ import annotations

import datetime
import functools
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..report.tables import TableData
from ..utils import atomic_write_text, strict_json
from . import tasks as T
from .cache import Cache
from .execute import choose, compute, progress_enabled
from .memo import SpecMemo
from .outputs import previous_records, realize_many
from .pages import PAGE, realize_page, study_page, write_index
from .plan import SUMMARY, build_plan
from .results import SUMMARY_COLUMNS, Results, summary as make_summary
from .scenes import build
from .spec import Study, load_spec, plain

__all__ = ["run", "RunResult", "SUMMARY_COLUMNS"]

FIGURE_FORMATS = ("png", "pdf", "svg")

#: Full-order responses with at least this many frequencies get their own progress bar.
LONG_RESPONSE = 200


@dataclass
class RunResult:
    """What :func:`run` made: ``summary`` is the summary table as a DataFrame (built on first use)."""

    study: Study
    outdir: Path
    manifest: dict
    summary_table: TableData
    files: list
    notes: list
    #: the run's artifacts by the study's aliases (:class:`~morsuite.studies.results.Results`)
    results: object = None

    @functools.cached_property
    def summary(self):
        return self.summary_table.frame()


def _log(quiet, msg):
    if not quiet:
        print(msg, file=sys.stderr)


def _old_manifest(outdir: Path) -> dict:
    try:
        old = json.loads((outdir / "manifest.json").read_text())
    except (OSError, ValueError):
        return {}
    return old if isinstance(old, dict) else {}


def _remove_stale(outdir: Path, old: dict, keep: set):
    """Delete files an earlier run of this study wrote that this run did not write or keep."""
    for name in old.get("files", []):
        p = outdir / name
        if name not in keep and p.is_file() and p.parent == outdir:
            p.unlink()


def run(spec, *, out="results", cache_dir=None, use_cache: bool = True, jobs: int = 1, scheduler=None,
        quiet: bool = False, formats=("png", "pdf"), rerender: bool = False, shared=None,
        render_jobs: int = 1) -> RunResult:
    """Run a study.

    Parameters
    ----------
    spec : path of a TOML file, or a :class:`Study`
    out : results root; outputs go to ``out/NAME/``
    cache_dir : artifact cache (default ``out/.cache``)
    use_cache : False recomputes everything (fresh entries overwrite the cache)
    jobs : local worker processes (1: Dask's synchronous scheduler)
    scheduler : address of a dask.distributed scheduler (``tcp://HOST:PORT``) or a Client
    quiet : no progress bars, no log lines
    formats : figure files to draw (default PNG and PDF; () writes CSV, pgfplots and tables only)
    rerender : draw every figure and write every table again, even those whose data, style and
        software did not change since the last run (default False: those are reused, their
        files left untouched). Files whose bytes come out the same are not rewritten either way.
    shared : a :class:`~morsuite.studies.batch.Shared` from
        :func:`~morsuite.studies.batch.shared_compute` over several studies (this one among
        them): its artifacts are taken from the cache, recorded as computed by the first study
        that uses them, and its failures are taken as they are; the manifest records it as
        ``shared_compute``. Default None.
    render_jobs : processes that draw the figures (default 1: this one; more fork this process,
        :func:`~morsuite.studies.outputs.realize_many`). ``morsuite run`` asks for its jobs
        when nothing timed runs beside the study.

    Cost: one sparse LU per frequency of each full-order response, the reducers' own
    LUs, the norms' (:mod:`morsuite.studies.norms`) and one LU per full-model simulation
    (:mod:`morsuite.studies.timedomain`), for what the cache does not hold; nothing for a fully cached study.
    """
    t_start = time.perf_counter()
    started = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    out = Path(out)
    cache = Cache(cache_dir if cache_dir is not None else out / ".cache", read=use_cache, write=True)
    study = spec if isinstance(spec, Study) else load_spec(spec, memo=SpecMemo(cache))
    choice = choose(jobs, scheduler)
    formats = tuple(formats)
    bad = [f for f in formats if f not in FIGURE_FORMATS]
    if bad:
        from ..errors import OptionError
        raise OptionError(f"formats: unknown figure format(s) {bad}; valid: {', '.join(FIGURE_FORMATS)}")
    if study.memo is not None:
        study.memo.flush()
    plan = build_plan(study)
    outdir = out / study.name
    bars = progress_enabled(quiet)
    t_validated = time.perf_counter()
    _log(quiet, f"morsuite run {study.name} ({study.path or 'spec'}): plan\n  " + "\n  ".join(plan.describe()))

    # -- cache lookup: what is already there is never recomputed
    foms = {}
    for fid, f in plan.foms.items():
        hit = cache.get("fom", f.key)
        if hit is not None:
            arrays, meta = hit
            foms[fid] = {**meta, **arrays, "cached": True}
    reductions, missing = _lookup(cache, "reduction", plan.reduces, lambda arrays, meta: {
        **meta, "rom": {"kind": meta["rom_kind"], "arrays": arrays}, "cached": True})
    metrics, missing_metrics = _lookup(cache, "metrics", plan.metrics,
                                       lambda arrays, meta: {**meta, **arrays, "cached": True})
    norms = {nid: {**hit, "cached": True} for nid, n in plan.norms.items()
             if (hit := cache.get_json("model_norm", n.key)) is not None}
    norm_errors, missing_norms = _lookup(cache, "norm_error", plan.norm_groups,
                                         lambda meta: {**meta, "cached": True}, json_only=True)
    sims = {sid: {**hit[1], **hit[0], "cached": True} for sid, sim in plan.sims.items()
            if (hit := cache.get("simulation", sim.key)) is not None}
    sim_errors, missing_sims = _lookup(cache, "sim_error", plan.sim_groups,
                                       lambda arrays, meta: {**meta, **arrays, "cached": True})
    from .tolerance import entry_from_cache
    tolerances = {tid: entry_from_cache(*hit) for tid, t in plan.tolerances.items()
                  if (hit := cache.get("tolerance", t.key)) is not None}
    if shared is not None:
        _take_shared(shared, plan, foms, (reductions, missing), norms, (norm_errors, missing_norms), sims, tolerances)

    # -- the graph: only what is missing (nothing at all, and no dask, for a cached study)
    t0 = time.perf_counter()
    have = {"foms": foms, "reductions": reductions, "norms": norms, "sims": sims, "tolerances": tolerances}
    todo = {"reduce": missing, "metrics": missing_metrics, "norm_error": missing_norms, "sim_error": missing_sims}
    computed = _compute_missing(plan, cache, choice, bars, study.name, have, todo)
    t_compute = time.perf_counter() - t0

    # -- assemble; on a remote cluster the workers could not write the cache: do it here
    cache_root = str(cache.root) if choice.local_files else None
    for fid in plan.foms:
        store = fid in computed and cache_root is None
        if fid in computed:
            foms[fid] = computed[fid]
        e = foms[fid]
        if "sigma_full" not in e:  # an entry from before sigma_full was stored with H: add it
            from ..analysis import sigma_max
            e["sigma_full"], store = sigma_max(e["H"]), True
        if store:
            cache.put("fom", e["key"], {k: e[k] for k in T.FOM_ARRAYS},
                      {k: v for k, v in e.items() if k not in T.FOM_ARRAYS + ("cached",)})
    for gid in missing:
        for r, e in computed[gid].items():
            reductions[gid][r] = e
            if cache_root is None and "error" not in e:
                cache.put("reduction", e["key"], e["rom"]["arrays"],
                          {**{k: v for k, v in e.items() if k not in ("rom", "cached")}, "rom_kind": e["rom"]["kind"]})
    for mid in missing_metrics:
        for r, e in computed[mid].items():
            metrics[mid][r] = {**e, "cached": False}
            if "error" not in e:  # metrics are cheap and come back here anyway: the driver stores them
                cache.put("metrics", plan.metrics[mid].keys[r], {k: e[k] for k in METRIC_ARRAYS},
                          {k: v for k, v in e.items() if k not in METRIC_ARRAYS})
    _store_new(cache, plan, computed, norms, norm_errors, missing_norms, sims, sim_errors, missing_sims)
    for tid in plan.tolerances:
        if tid in computed:
            tolerances[tid] = e = computed[tid]
            if cache_root is None and "error" not in e:
                from .tolerance import entry_arrays
                cache.put("tolerance", e["key"], entry_arrays(e), {k: v for k, v in e.items()
                                                                  if k not in ("roms", "cached")})
    res = Results(study, plan, foms, reductions, metrics, norms, norm_errors, sims, sim_errors,
                  tolerances=tolerances)
    _modes(study, res, cache)

    # -- outputs: figures and tables, each reused when its content did not change
    t1 = time.perf_counter()
    outdir.mkdir(parents=True, exist_ok=True)
    old = _old_manifest(outdir)
    previous = previous_records(old)
    files, notes, pairs = [], [], []
    for scene in study.scenes:
        for item in build(scene, study, res):
            notes += item.notes
            if not isinstance(item, TableData) and not item.curves:
                notes.append(f"scene {scene.name!r}: nothing to draw; no figure {item.name!r} written")
            pairs.append((plan.outputs[f"{'table' if isinstance(item, TableData) else 'figure'}/{item.name}"], item))
    summary = make_summary(study, plan, res, SUMMARY)
    pairs.append((plan.outputs[f"table/{SUMMARY}"], summary))
    records = realize_many(pairs, outdir, formats, previous, rerender, jobs=render_jobs)
    shown = [(item, rec) for (_, item), rec in zip(pairs[:-1], records[:-1])]
    files += [outdir / name for rec in records for name in rec["files"]]
    for gid, entries in reductions.items():
        g = plan.reduces[gid]
        who = f"{'/'.join(sorted({a[1] for a in g.aliases}))} ({g.method.reducer}) on {g.model.name}"
        for r, e in sorted(entries.items()):
            if "error" in e:
                notes.append(f"{who} at r = {r} failed: {e['error']}")
            elif not e["info"].get("converged", True):
                notes.append(f"{who} at r = {r} did not converge (status {e['info'].get('status', 'stopped')!r}, "
                             f"{e['info'].get('iterations')} iterations; best iterate returned)")
    notes += _norm_notes(plan, norms, norm_errors)
    from .tolerance_scene import save_roms, tolerance_notes
    notes += tolerance_notes(plan, tolerances)
    files += save_roms(study, res, outdir)
    t_report = time.perf_counter() - t1

    from .manifest import manifest as make_manifest

    manifest = make_manifest(study, plan, choice, cache, res, records, files, outdir, notes, started, {"validate_s": t_validated - t_start, "compute_s": t_compute,
                                       "report_s": t_report, "total_s": time.perf_counter() - t_start}, rerender)
    if shared is not None:  # what the studies of this command computed together, before this one ran
        manifest["shared_compute"] = {k: v for k, v in shared.record.items() if k != "log"}
        # the shared phase's time before this study's own run started (all of it when run after it)
        manifest["timing"]["shared_compute_s"] = shared.record.get("started_after_s", shared.record.get("wall_s"))
    _page(study, shown, summary, manifest, outdir, old, files, rerender, res.modes)
    keep = {str(p.relative_to(outdir)) for p in files} | {"manifest.json"}
    _remove_stale(outdir, old, keep)
    atomic_write_text(outdir / "manifest.json", json.dumps(strict_json(plain(manifest)), indent=1, allow_nan=False))
    files.append(outdir / "manifest.json")
    write_index(out)
    for n in notes:
        _log(quiet, "note: " + n)
    drawn = sum(1 for rec in records if rec["rendered"])
    _log(quiet, f"morsuite run {study.name}: {len(files)} files in {outdir} ({drawn} of {len(records)} figures "
                f"and tables made, the others unchanged; {manifest['timing']['total_s']:.1f} s, computing "
                f"{t_compute:.1f} s)")
    return RunResult(study, outdir, manifest, summary, files, notes, res)


def _modes(study, res, cache=None):
    """The ``modes`` scenes' data (a few LUs of the full model each, in this process), taken from ``cache``
    when it holds them (:func:`morsuite.studies.modes.modes_key`); the first is the page's modes section."""
    from .modes import compute_modes, modes_key

    for scene in study.scenes:
        if scene.kind == "modes":
            key = modes_key(scene, study, res)
            hit = cache.get_json("modes", key) if cache is not None and key is not None else None
            if hit is not None:
                data = {k: v for k, v in hit.items() if k != "key"}
                data["info"] = {**data.get("info", {}), "cached": True}
            else:
                data = compute_modes(scene, study, res)
                if cache is not None and key is not None:
                    cache.put_json("modes", key, data)
            res.modes_of[scene.name] = data
            if res.modes is None:
                res.modes = res.modes_of[scene.name]


def _page(study, shown, summary, manifest, outdir, old, files, rerender, modes=None):
    """Write (or reuse) the study's ``index.html`` and record it in the manifest (kind ``page``); ``modes``:
    the study's modes and poles for the page (``Results.modes``), or None."""
    prev = next((a for a in old.get("artifacts") or [] if isinstance(a, dict) and a.get("kind") == "page"), None)
    rec = realize_page(study_page(study, shown, summary, manifest, modes), outdir, prev, rerender)
    manifest["artifacts"].append(rec)
    manifest["reused" if rec["reused"] else "computed"].append(rec["id"])
    manifest["files"] = sorted(manifest["files"] + [PAGE])
    files.append(outdir / PAGE)


def _take_shared(shared, plan, foms, reductions, norms, norm_errors, sims, tolerances=None):
    """Mark what ``shared`` computed as computed (first study to use it), and add its failures."""
    for tid, t in plan.tolerances.items():
        if tolerances is not None and tid in tolerances and shared.claim("tolerance", t.key):
            tolerances[tid]["cached"] = False
        elif tolerances is not None and tid not in tolerances and ("tolerance", t.key) in shared.failed:
            tolerances[tid] = dict(shared.failed[("tolerance", t.key)])
    for fid, f in plan.foms.items():
        if fid in foms and shared.claim("fom", f.key):
            foms[fid]["cached"] = False
    for nid, n in plan.norms.items():
        if nid in norms and shared.claim("model_norm", n.key):
            norms[nid]["cached"] = False
        elif nid not in norms and ("model_norm", n.key) in shared.failed:
            norms[nid] = dict(shared.failed[("model_norm", n.key)])
    for sid, sim in plan.sims.items():
        if sid in sims and shared.claim("simulation", sim.key):
            sims[sid]["cached"] = False
        elif sid not in sims and ("simulation", sim.key) in shared.failed:
            sims[sid] = dict(shared.failed[("simulation", sim.key)])
    for kind, (found, missing), groups in (("reduction", reductions, plan.reduces),
                                           ("norm_error", norm_errors, plan.norm_groups)):
        for gid, g in groups.items():
            for r in g.rs:
                key = g.keys[r]
                if r in found.get(gid, {}):
                    if shared.claim(kind, key):
                        found[gid][r]["cached"] = False
                elif (kind, key) in shared.failed:
                    found.setdefault(gid, {})[r] = dict(shared.failed[(kind, key)])
                    missing[gid].remove(r)
                    if not missing[gid]:
                        del missing[gid]


def _lookup(cache, kind, groups, entry, json_only=False):
    """``({id: {r: entry(...)}}, {id: [r, ...]})``: what the cache holds of each group's
    per-r artifacts (``group.keys[r]``), and what it lacks. ``entry(arrays, meta)``, or
    ``entry(meta)`` for JSON-only entries."""
    found, missing = {}, {}
    for gid, g in groups.items():
        found[gid] = {}
        for r in g.rs:
            hit = cache.get_json(kind, g.keys[r]) if json_only else cache.get(kind, g.keys[r])
            if hit is None:
                missing.setdefault(gid, []).append(r)
            else:
                found[gid][r] = entry(hit) if json_only else entry(*hit)
    return found, missing


#: The per-frequency arrays of a metrics entry (stored as npz; the rest as JSON).
METRIC_ARRAYS = ("sigma_rom", "abs_error", "rel_error")


def _store_new(cache, plan, computed, norms, norm_errors, missing_norms, sims, sim_errors, missing_sims):
    """Put the computed norms and simulations into the results and the cache (failures are not stored)."""
    from .timedomain import SIM_ARRAYS, SIM_ERROR_ARRAYS

    def split(e, names):
        return {k: e[k] for k in names}, {k: v for k, v in e.items() if k not in names + ("cached",)}

    for nid, n in plan.norms.items():
        if nid in computed:
            norms[nid] = e = computed[nid]
            if "error" not in e:
                cache.put_json("model_norm", n.key, {k: v for k, v in e.items() if k != "cached"})
    for gid in missing_norms:
        for r, e in computed[gid].items():
            norm_errors[gid][r] = e
            if "error" not in e:
                cache.put_json("norm_error", e["key"], {k: v for k, v in e.items() if k != "cached"})
    for sid, sim in plan.sims.items():
        if sid in computed:
            sims[sid] = e = computed[sid]
            if "error" not in e:
                cache.put("simulation", sim.key, *split(e, SIM_ARRAYS))
    for gid in missing_sims:
        for r, e in computed[gid].items():
            sim_errors[gid][r] = e
            if "error" not in e:
                cache.put("sim_error", e["key"], *split(e, SIM_ERROR_ARRAYS))


def _norm_notes(plan, norms, norm_errors) -> list:
    out = []
    for nid, e in norms.items():
        if "error" in e:
            n = plan.norms[nid]
            out.append(f"the {n.kind} norm of {n.model.name} failed: {e['error']}")
    for gid, entries in norm_errors.items():
        g = plan.norm_groups[gid]
        red = plan.reduces[g.reduce]
        for r, e in sorted(entries.items()):
            who = f"{g.kind} error of {red.method.reducer} on {red.model.name} at r = {r}"
            if "error" in e:
                out.append(f"{who} failed: {e['error']}")
            elif not e.get("trusted", True) and g.kind == "hinf":
                out.append(f"{who} is the peak found (value {e.get('value')}), a lower bound not certified by an "
                           f"upper bound; shown with hinf_certified = False")
            elif not e.get("trusted", True):
                out.append(f"{who} is not accurate to four digits (value {e.get('value')}, estimated relative "
                           f"accuracy {e.get('rel_floor')}); shown with {g.kind}_trusted = False")
            elif e.get("reason"):
                out.append(f"{who} is infinite: {e['reason']}")
    return out


def _compute_missing(plan, cache, choice, bars, desc, have, todo) -> dict:
    """Build and compute the Dask graph of what the cache lacks; {} (and no dask import) when nothing does."""
    foms, reductions, norms, sims = have["foms"], have["reductions"], have["norms"], have["sims"]
    tolerances = have["tolerances"]
    if not (any(todo.values()) or len(foms) < len(plan.foms) or len(norms) < len(plan.norms)
            or len(sims) < len(plan.sims) or len(tolerances) < len(plan.tolerances)):
        return {}
    from dask import delayed

    from . import norms as N, timedomain as TD, tolerance as TOL

    cache_root = str(cache.root) if choice.local_files else None
    graph, fom_nodes, red_nodes, sim_nodes = {}, dict(foms), {}, dict(sims)

    def literal(obj, name):
        # data holding no dask object: one opaque node, so that dask does not walk its nested dicts
        # (the reductions' info): walking them took 1.6 s per metrics node on the sweep (2026-11-26)
        return delayed(obj, name=f"{name}-literal", traverse=False)

    for fid, f in plan.foms.items():
        if fid not in foms:
            lo, hi, n = f.bounds
            graph[fid] = fom_nodes[fid] = delayed(T.fom_response, pure=False)(
                f.model.source, lo, hi, n, f.key, cache_root,
                bool(bars and choice.name == "synchronous" and n >= LONG_RESPONSE), choice.name, dask_key_name=fid)
    for gid, rs in todo["reduce"].items():
        g = plan.reduces[gid]
        graph[gid] = red_nodes[gid] = delayed(T.reduce_sweep, pure=False)(
            g.model.source, g.method.reducer, g.method.options, rs, {r: g.keys[r] for r in rs}, cache_root,
            choice.name, dask_key_name=gid)
    for mid, rs in todo["metrics"].items():
        mg = plan.metrics[mid]
        fom = fom_nodes[mg.fom] if mg.fom not in foms else literal(foms[mg.fom], f"{mid}-fom")
        graph[mid] = delayed(T.metrics, pure=False)(fom, rs, literal(reductions[mg.reduce], mid),
                                                   red_nodes.get(mg.reduce, {}), dask_key_name=mid)
    def after(model):
        # the norms share the model's Gramian factors with bt: let the reductions of the model run
        # first, so that a bt reduction pays (and reports) its own LR-ADI, as it does without norms;
        # and its band responses, whose samples the H-infinity searches draw from the model's memo
        return ([red_nodes[gid] for gid in red_nodes if plan.reduces[gid].model.model_id == model.model_id]
                + [fom_nodes[fid] for fid in graph if fid in plan.foms and plan.foms[fid].model.model_id
                   == model.model_id])

    for nid, n in plan.norms.items():
        if nid not in norms:
            graph[nid] = delayed(N.model_norm, pure=False)(n.model.source, n.kind, n.options, n.key, choice.name,
                                                           after=after(n.model), dask_key_name=nid)
    for gid, rs in todo["norm_error"].items():
        g = plan.norm_groups[gid]
        red = plan.reduces[g.reduce]
        graph[gid] = delayed(N.error_norms, pure=False)(
            red.model.source, g.kind, g.options, rs, {r: g.keys[r] for r in rs}, choice.name,
            literal(reductions[g.reduce], gid), red_nodes.get(g.reduce, {}), after=after(red.model),
            dask_key_name=gid)
    for sid, sim in plan.sims.items():
        if sid not in sims:
            graph[sid] = sim_nodes[sid] = delayed(TD.full_simulation, pure=False)(
                sim.model.source, sim.settings, sim.key, choice.name, dask_key_name=sid)
    for gid, rs in todo["sim_error"].items():
        g = plan.sim_groups[gid]
        model = plan.sims[g.sim].model
        graph[gid] = delayed(TD.rom_simulations, pure=False)(
            sim_nodes[g.sim], list(model.band), model.m, g.rom_method, rs, {r: g.keys[r] for r in rs}, choice.name,
            literal(reductions[g.reduce], gid), red_nodes.get(g.reduce, {}), dask_key_name=gid)
    for tid, t in plan.tolerances.items():
        if tid in tolerances:
            continue
        fom = None
        if t.fom is not None:
            fom = fom_nodes[t.fom] if t.fom not in foms else literal(foms[t.fom], f"{tid}-fom")
        graph[tid] = delayed(TOL.tolerance_search, pure=False)(
            t.model.source, t.method.reducer, t.method.options, t.settings, t.norm_options, t.key, fom,
            plan.foms[t.fom].key if t.fom else None, cache_root, choice.name, dask_key_name=tid)
    return compute(graph, choice, progress=bars, desc=desc)
