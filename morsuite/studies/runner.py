"""The study runner: spec -> plan -> cache lookup -> Dask graph -> results folder.

``run("studies/paper_dsms.toml")`` validates the spec (nothing is computed if it
is wrong), plans the artifacts its scenes need, takes what the cache holds,
computes the rest as a Dask graph (synchronous by default), and writes
``OUT/NAME/``: a CSV per curve, PNG, PDF and pgfplots per figure, tables,
``summary.csv``/``summary.md`` (every reduction computed) and ``manifest.json``.

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
from ..utils import atomic_write_text
from . import tasks as T
from .cache import Cache
from .execute import choose, compute, progress_enabled
from .memo import SpecMemo
from .outputs import previous_records, realize
from .plan import SUMMARY, build_plan
from .scenes import build
from .spec import Study, load_spec, plain

__all__ = ["run", "RunResult", "SUMMARY_COLUMNS", "H2_NOTE"]

SUMMARY_COLUMNS = ["model", "method", "reducer", "r_requested", "r", "states", "converged", "iterations",
                   "stable", "time_s", "time_standalone_s", "lu_count", "max_abs_error", "max_rel_error",
                   "h2_error_grid", "error_bound", "grid", "cached", "status"]

H2_NOTE = ("h2_error_grid is NOT the H2 error: it is sqrt((1/pi) * trapezoid over the grid of "
           "||T(jw) - T_r(jw)||_F^2 dw), the H2 error restricted to the grid's band and approximated by the "
           "trapezoidal rule on the grid. The exact H2 error of a ROM against the full index-3 model is not "
           "computed.")

TIME_NOTE = ("time_s is the reducer's own timing of reduce(r) (info['time_s']); when one reducer instance "
             "serves several r, work that does not depend on r (Gramians, a projector) is done in its first "
             "call only. time_standalone_s adds that shared work back: what reducing to this r alone costs.")

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

    @functools.cached_property
    def summary(self):
        return self.summary_table.frame()


class Results:
    """Read access to a run's artifacts by the study's aliases (what scenes see)."""

    def __init__(self, study, plan, foms, reductions, metrics):
        self.study, self.plan = study, plan
        self._foms, self._red, self._met = foms, reductions, metrics

    def fom(self, model, grid):
        fid = self.plan.fom_of.get((model, grid))
        return self._foms.get(fid)

    def reduction(self, model, method, r):
        gid = self.plan.reduce_of.get((model, method))
        return self._red.get(gid, {}).get(r)

    def metrics(self, model, grid, method, r):
        mid = self.plan.metrics_of.get((model, grid, method))
        return self._met.get(mid, {}).get(r) if mid else None

    def summary_row(self, model, method, r, grid=None) -> dict:
        red = self.reduction(model, method, r)
        met = self.metrics(model, grid, method, r) if grid else None
        m = self.study.methods[method]
        row = dict.fromkeys(SUMMARY_COLUMNS)
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
                   iterations=int(info.get("iterations", 0)), stable=bool(info.get("stable")),
                   time_s=float(red["time_s"]), time_standalone_s=float(red["time_standalone_s"]),
                   lu_count=info.get("lu_count"), status="ok")
        bound = info.get("error_bound")
        if isinstance(bound, (int, float)) and not isinstance(bound, bool):
            row["error_bound"] = float(bound)  # the reducer's own a-priori bound (BT), when it has one
        if met is not None and "error" not in met:
            row.update(max_abs_error=met["max_abs_error"], max_rel_error=met["max_rel_error"],
                       h2_error_grid=met["h2_error_grid"])
        return row


def _summary(study, plan, res) -> TableData:
    rows = []
    grids_of = {}
    for (model, grid, method) in plan.metrics_of:
        grids_of.setdefault((model, method), []).append(grid)
    for (model, method), gid in sorted(plan.reduce_of.items()):
        for r in plan.reduces[gid].rs:
            grids = [g for g in sorted(grids_of.get((model, method), [])) if res.metrics(model, g, method, r)]
            for grid in grids or [None]:  # one row per grid with errors, or one without
                rows.append(res.summary_row(model, method, r, grid))
    return TableData(SUMMARY, f"{study.title}: every reduction of this run", rows, columns=list(SUMMARY_COLUMNS),
                     int_columns=("r", "states", "iterations", "lu_count"), note=H2_NOTE + "\n\n" + TIME_NOTE)


def _strict(x):
    """Non-finite floats as strings ("inf", "nan"): the manifest is strict JSON."""
    if isinstance(x, dict):
        return {k: _strict(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_strict(v) for v in x]
    if isinstance(x, float) and not np.isfinite(x):
        return str(x)
    return x


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
        quiet: bool = False, formats=("png", "pdf"), rerender: bool = False) -> RunResult:
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

    Cost: one sparse LU per frequency of each full-order response and the reducers' own
    LUs, for what the cache does not hold; nothing for a fully cached study.
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

    # -- the graph: only what is missing (nothing at all, and no dask, for a cached study)
    t0 = time.perf_counter()
    computed = _compute_missing(plan, cache, choice, bars, study.name, foms, reductions, missing, missing_metrics)
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
    res = Results(study, plan, foms, reductions, metrics)

    # -- outputs: figures and tables, each reused when its content did not change
    t1 = time.perf_counter()
    outdir.mkdir(parents=True, exist_ok=True)
    old = _old_manifest(outdir)
    previous = previous_records(old)
    files, notes, records = [], [], []
    for scene in study.scenes:
        item = build(scene, study, res)
        notes += item.notes
        if not isinstance(item, TableData) and not item.curves:
            notes.append(f"scene {scene.name!r}: nothing to draw; no figure written")
        output = plan.outputs[f"{'table' if isinstance(item, TableData) else 'figure'}/{scene.name}"]
        records.append(realize(output, item, outdir, formats, previous, rerender))
    summary = _summary(study, plan, res)
    records.append(realize(plan.outputs[f"table/{SUMMARY}"], summary, outdir, formats, previous, rerender))
    files += [outdir / name for rec in records for name in rec["files"]]
    for gid, entries in reductions.items():
        g = plan.reduces[gid]
        who = f"{'/'.join(sorted({a[1] for a in g.aliases}))} ({g.method.reducer}) on {g.model.name}"
        for r, e in sorted(entries.items()):
            if "error" in e:
                notes.append(f"{who} at r = {r} failed: {e['error']}")
            elif not e["info"].get("converged", True):
                notes.append(f"{who} at r = {r} did not converge ({e['info'].get('iterations')} iterations; "
                             f"best iterate returned)")
    t_report = time.perf_counter() - t1

    from .manifest import manifest as make_manifest

    manifest = make_manifest(study, plan, choice, cache, foms, reductions, metrics, records, files, outdir, notes,
                             started, {"validate_s": t_validated - t_start, "compute_s": t_compute,
                                       "report_s": t_report, "total_s": time.perf_counter() - t_start}, rerender)
    keep = {str(p.relative_to(outdir)) for p in files} | {"manifest.json"}
    _remove_stale(outdir, old, keep)
    atomic_write_text(outdir / "manifest.json", json.dumps(_strict(plain(manifest)), indent=1, allow_nan=False))
    files.append(outdir / "manifest.json")
    for n in notes:
        _log(quiet, "note: " + n)
    drawn = sum(1 for rec in records if rec["rendered"])
    _log(quiet, f"morsuite run {study.name}: {len(files)} files in {outdir} ({drawn} of {len(records)} figures "
                f"and tables made, the others unchanged; {manifest['timing']['total_s']:.1f} s, computing "
                f"{t_compute:.1f} s)")
    return RunResult(study, outdir, manifest, summary, files, notes)


def _lookup(cache, kind, groups, entry):
    """``({id: {r: entry(arrays, meta)}}, {id: [r, ...]})``: what the cache holds of each
    group's per-r artifacts (``group.keys[r]``), and what it lacks."""
    found, missing = {}, {}
    for gid, g in groups.items():
        found[gid] = {}
        for r in g.rs:
            hit = cache.get(kind, g.keys[r])
            if hit is None:
                missing.setdefault(gid, []).append(r)
            else:
                found[gid][r] = entry(*hit)
    return found, missing


#: The per-frequency arrays of a metrics entry (stored as npz; the rest as JSON).
METRIC_ARRAYS = ("sigma_rom", "abs_error", "rel_error")


def _compute_missing(plan, cache, choice, bars, desc, foms, reductions, missing, missing_metrics) -> dict:
    """Build and compute the Dask graph of what the cache lacks; {} (and no dask import) when nothing does."""
    if not (missing or missing_metrics or len(foms) < len(plan.foms)):
        return {}
    from dask import delayed

    cache_root = str(cache.root) if choice.local_files else None
    graph, fom_nodes, red_nodes = {}, dict(foms), {}
    for fid, f in plan.foms.items():
        if fid not in foms:
            lo, hi, n = f.bounds
            graph[fid] = fom_nodes[fid] = delayed(T.fom_response, pure=False)(
                f.model.source, lo, hi, n, f.key, cache_root,
                bool(bars and choice.name == "synchronous" and n >= LONG_RESPONSE), choice.name, dask_key_name=fid)
    for gid, rs in missing.items():
        g = plan.reduces[gid]
        graph[gid] = red_nodes[gid] = delayed(T.reduce_sweep, pure=False)(
            g.model.source, g.method.reducer, g.method.options, rs, {r: g.keys[r] for r in rs}, cache_root,
            choice.name, dask_key_name=gid)
    for mid, rs in missing_metrics.items():
        mg = plan.metrics[mid]
        graph[mid] = delayed(T.metrics, pure=False)(fom_nodes[mg.fom], rs, reductions[mg.reduce],
                                                   red_nodes.get(mg.reduce, {}), dask_key_name=mid)
    return compute(graph, choice, progress=bars, desc=desc)
