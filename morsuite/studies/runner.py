"""The study runner: spec -> plan -> cache lookup -> Dask graph -> results folder.

``run("studies/paper_dsms.toml")`` validates the spec (nothing is computed if it
is wrong), plans the artifacts its scenes need, takes what the cache holds,
computes the rest as a Dask graph (synchronous by default), and writes
``OUT/NAME/``: a CSV per curve, PNG, PDF and pgfplots per figure, tables,
``summary.csv``/``summary.md`` (every reduction computed) and ``manifest.json``.
"""

from __future__ import annotations

import datetime
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .. import __version__
from ..utils import atomic_write_text
from . import tasks as T
from .cache import Cache
from .execute import choose, compute, progress_enabled
from .plan import build_plan
from .scenes import TableData, build
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
    study: Study
    outdir: Path
    manifest: dict
    summary: pd.DataFrame
    files: list
    notes: list


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


def _summary(study, plan, res) -> pd.DataFrame:
    rows = []
    grids_of = {}
    for (model, grid, method) in plan.metrics_of:
        grids_of.setdefault((model, method), []).append(grid)
    for (model, method), gid in sorted(plan.reduce_of.items()):
        for r in plan.reduces[gid].rs:
            grids = [g for g in sorted(grids_of.get((model, method), [])) if res.metrics(model, g, method, r)]
            for grid in grids or [None]:  # one row per grid with errors, or one without
                rows.append(res.summary_row(model, method, r, grid))
    df = pd.DataFrame(rows, columns=SUMMARY_COLUMNS)
    for col in ("r", "states", "iterations", "lu_count"):
        df[col] = df[col].astype("Int64")
    return df


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


def _remove_stale(outdir: Path, keep: set):
    """Delete files an earlier run of this study wrote that this run did not rewrite."""
    old = outdir / "manifest.json"
    if not old.is_file():
        return
    try:
        files = json.loads(old.read_text()).get("files", [])
    except (OSError, ValueError):
        return
    for name in files:
        p = outdir / name
        if name not in keep and p.is_file() and p.parent == outdir:
            p.unlink()


def run(spec, *, out="results", cache_dir=None, use_cache: bool = True, jobs: int = 1, scheduler=None,
        quiet: bool = False, formats=("png", "pdf")) -> RunResult:
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
    """
    t_start = time.perf_counter()
    started = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    study = spec if isinstance(spec, Study) else load_spec(spec)
    choice = choose(jobs, scheduler)
    formats = tuple(formats)
    bad = [f for f in formats if f not in FIGURE_FORMATS]
    if bad:
        from ..errors import OptionError
        raise OptionError(f"formats: unknown figure format(s) {bad}; valid: {', '.join(FIGURE_FORMATS)}")
    plan = build_plan(study)
    out = Path(out)
    outdir = out / study.name
    cache = Cache(cache_dir if cache_dir is not None else out / ".cache", read=use_cache, write=True)
    bars = progress_enabled(quiet)
    t_validated = time.perf_counter()
    _log(quiet, f"morsuite run {study.name} ({study.path or 'spec'}): plan\n  " + "\n  ".join(plan.describe()))

    # -- cache lookup: what is already there is never recomputed
    foms, reductions, missing = {}, {}, {}
    for fid, f in plan.foms.items():
        hit = cache.get("fom", f.key)
        if hit is not None:
            arrays, meta = hit
            foms[fid] = {**meta, "omega": arrays["omega"], "H": arrays["H"], "cached": True}
    for gid, g in plan.reduces.items():
        reductions[gid] = {}
        for r in g.rs:
            hit = cache.get("reduction", g.keys[r])
            if hit is None:
                missing.setdefault(gid, []).append(r)
                continue
            arrays, meta = hit
            reductions[gid][r] = {**meta, "rom": {"kind": meta["rom_kind"], "arrays": arrays}, "cached": True}

    # -- the graph: only what is missing, plus the (cheap) metrics
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
    for mid, mg in plan.metrics.items():
        graph[mid] = delayed(T.metrics, pure=False)(fom_nodes[mg.fom], mg.rs, reductions[mg.reduce],
                                                   red_nodes.get(mg.reduce, {}), dask_key_name=mid)
    t0 = time.perf_counter()
    computed = compute(graph, choice, progress=bars, desc=study.name)
    t_compute = time.perf_counter() - t0

    # -- assemble; on a remote cluster the workers could not write the cache: do it here
    from ..analysis import sigma_max

    for fid in plan.foms:
        if fid in computed:
            foms[fid] = computed[fid]
            if cache_root is None:
                e = foms[fid]
                cache.put("fom", e["key"], {"omega": e["omega"], "H": e["H"]},
                          {k: v for k, v in e.items() if k not in ("omega", "H", "cached")})
        foms[fid]["sigma_full"] = sigma_max(foms[fid]["H"])
    for gid in missing:
        for r, e in computed[gid].items():
            reductions[gid][r] = e
            if cache_root is None and "error" not in e:
                cache.put("reduction", e["key"], e["rom"]["arrays"],
                          {**{k: v for k, v in e.items() if k not in ("rom", "cached")}, "rom_kind": e["rom"]["kind"]})
    metrics = {mid: computed[mid] for mid in plan.metrics}
    res = Results(study, plan, foms, reductions, metrics)

    # -- outputs
    from ..report.writer import write_figure, write_table_data

    t1 = time.perf_counter()
    outdir.mkdir(parents=True, exist_ok=True)
    files, notes = [], []
    for scene in study.scenes:
        item = build(scene, study, res)
        notes += item.notes
        if isinstance(item, TableData):
            files += write_table_data(item, outdir)
        elif not item.curves:
            notes.append(f"scene {scene.name!r}: nothing to draw; no figure written")
        else:
            files += write_figure(item, outdir, formats)
    summary = _summary(study, plan, res)
    from ..report.tables import write_table
    files += write_table(summary, outdir / "summary", title=f"{study.title}: every reduction of this run",
                         note=H2_NOTE + "\n\n" + TIME_NOTE)
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

    manifest = _manifest(study, plan, choice, cache, foms, reductions, metrics, files, outdir, notes,
                         started, {"validate_s": t_validated - t_start, "compute_s": t_compute,
                                   "report_s": t_report, "total_s": time.perf_counter() - t_start})
    keep = {str(p.relative_to(outdir)) for p in files} | {"manifest.json"}
    _remove_stale(outdir, keep)
    atomic_write_text(outdir / "manifest.json", json.dumps(_strict(plain(manifest)), indent=1, allow_nan=False))
    files.append(outdir / "manifest.json")
    for n in notes:
        _log(quiet, "note: " + n)
    _log(quiet, f"morsuite run {study.name}: wrote {len(files)} files to {outdir} "
                f"({manifest['timing']['total_s']:.1f} s, computing {t_compute:.1f} s)")
    return RunResult(study, outdir, manifest, summary, files, notes)


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
                         "reduction": f"{mg.reduce}/r{r}", "cached": False, "time_s": e.get("time_s"),
                         "error": e.get("error")})
    return arts


def _manifest(study, plan, choice, cache, foms, reductions, metrics, files, outdir, notes, started, timing):
    from .environment import environment

    spec_text = study.path.read_text() if study.path is not None else None
    import hashlib
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
        "artifacts": _artifacts(plan, foms, reductions, metrics),
        "files": sorted(str(p.relative_to(outdir)) for p in files),
        "notes": notes, "definitions": {"h2_error_grid": H2_NOTE, "time": TIME_NOTE},
        "timing": timing,
    }
