"""Several studies computed together on worker processes, one core each, before their reports.

``morsuite run A.toml B.toml ... --jobs N`` (N > 1; by default the usable cores as far as
memory holds them, :func:`~morsuite.studies.workers.default_jobs`) first computes what any of
the studies lacks, all at once, with :func:`shared_compute`:

- every artifact is planned per study (:func:`~morsuite.studies.plan.build_plan`) and keyed by
  content, so what several studies or scenes share (a reduced model of the same model,
  method, options and r, its exact norms, the model's norms, a full-order response, a
  full-model simulation) is one unit of work, done once;
- units run on ``jobs`` worker processes, each pinned to a core of its own (so the
  reducers' automatic thread counts, e.g. IRKA's ``solver_threads``, resolve to 1: every
  timing of such a run is a single-threaded run on a core of its own, the other cores
  running other single-threaded units; the manifest records this as ``shared_compute``);
- a reducer group's orders run in increasing order on one reducer instance, as in a study's
  own graph, except for reducers with no r-independent work (``irka``) or a small one
  (``irka-projected``: its projector), whose orders are split into chunks
  (:data:`SPLIT`) that run side by side;
- a model's norm units start when its Gramian factors (below) and their own reductions have
  finished (in a study's own graph they wait for all of the model's reductions: there a ``bt``
  reduction pays, and reports, the Gramian factors it computed);
- the Gramian factors' units start first, then the longest units (their times in the results folder's
  manifests when a previous run left them, unknown units first), each on the first free worker (stopped, the
  run stops them: :mod:`~morsuite.studies.workers`); a study's own run (figures, tables, page) is a unit, which starts as
  soon as the units it reads are done; when only study runs are left, it draws its figures on
  ``jobs`` processes (:func:`~morsuite.studies.outputs.realize_many`: nothing timed shares the
  cores then, and the last study's figures are the run's tail).

Every result goes into the artifact cache. Each study runs as usual
(:func:`~morsuite.studies.runner.run` with ``shared=``): it finds its artifacts in the
cache, and the first study (in command-line order) that reads an artifact computed here
records it as computed, the later ones as reused, as in a sequential run. Failures are not
cached; they are handed to the studies from memory, so that no study computes them again.

A model's LR-ADI Gramian factors, which the ``bt``, ``so-h2`` and ``irka-fo`` reductions (their
descriptions say so: :func:`gramian_use`) and the H2 norms read, are a unit of their own (:func:`~morsuite.studies.gramian_store.compute_factors`)
that starts first; the units that read them wait for it and load them from the artifact cache
(:class:`~morsuite.studies.gramian_store.GramianStore`, set in every worker; the model's Hinf norms
wait for it too, and their start grid uses the factors' shifts, as in a study's own graph, where
they run after the reductions), so that a run pays them once, not once per worker (at n1 = 20,577 they are 204 LUs and 26 minutes).
The paper's IRKA reads them only to score its shortlist when it does not converge
(:func:`gramian_use` "waits"): it waits for the unit when there is one, but does not call for one.

Cost: the units' own; each worker process builds the models it meets (once) and reads a model's
Gramian factors from the store when a unit needs them (once per worker and model).
"""

from __future__ import annotations

import json
import multiprocessing
import os
import sys
import time
import uuid
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path

from .plan import build_plan
from .unit_times import previous_times as _previous_times, report_estimate as _report_estimate
from .workers import cpu_seconds, terminate_on_exit, usable_cores, watch_parent

__all__ = ["Shared", "shared_compute", "split_claims", "SPLIT", "usable_cores"]

#: Reducers whose orders are split into chunks run side by side: r-independent work none
#: (``irka``) or small (``irka-projected``: its projector, 0.3 s on dsms(1000), paid per chunk).
SPLIT = {"irka": 1, "irka-projected": 3}

RUN_BY = "processes (shared)"

def gramian_use(reducer: str):
    """How ``reducer`` uses the model's LR-ADI Gramian factors, as its description says
    (``Description.gramians``): "reads" (bt, so-h2, irka-fo: they and the model's norm units start after
    the model's Gramian factors' unit), "waits" (the paper's IRKA and irka-projected read the factors only
    to score their shortlist when they do not converge: they wait for the unit when there is one, but do
    not call for one; at n1 = 20,577 the paper's IRKA stalled before the unit had finished and paid the
    factors a second time: 171 LUs, 1,085 s, 2026-11-28), or None (an unknown reducer too)."""
    from .. import reducers
    return reducers.describe(reducer).gramians if reducer in reducers.available() else None


@dataclass
class Shared:
    """What :func:`shared_compute` did: the keys it computed, failures, and its record.

    ``fresh``: ``(kind, key)`` of the entries computed here and not yet claimed by a study;
    ``failed``: ``(kind, key)`` -> the failure entry (kept in memory, never cached).
    """

    jobs: int
    fresh: set = field(default_factory=set)
    failed: dict = field(default_factory=dict)
    record: dict = field(default_factory=dict)

    def claim(self, kind: str, key: str) -> bool:
        """True (and forgotten) the first time a study asks for an entry computed here."""
        if (kind, key) in self.fresh:
            self.fresh.discard((kind, key))
            return True
        return False


# -- workers -----------------------------------------------------------------
def _pin(counter, cores, store=None):
    """Worker initializer: pin this process to the next core of ``cores``; compile the kernels; set
    the Gramian factors' store (``store``: the cache's root, write flag and the key's salt)."""
    if store is not None:
        from ..linalg.gramians import use_store
        from .cache import Cache
        from .gramian_store import GramianStore
        root, write, salt = store
        use_store(GramianStore(Cache(root, write=write), salt=salt))
    watch_parent()  # a run killed outright takes its workers with it
    with counter.get_lock():
        i = counter.value
        counter.value += 1
    try:
        os.sched_setaffinity(0, {cores[i % len(cores)]})
    except (AttributeError, OSError):
        pass
    from ..linalg.warmup import warm_kernels
    warm_kernels(first=i)  # numba's compile or cache load before any unit is timed; each worker its half first


def _run_unit(fn_name, args, kwargs):
    """Run one unit in a worker: the task function ``fn_name`` (module:function), its wall time and its
    CPU time (``cpu_s``, :func:`~morsuite.studies.workers.cpu_seconds`: far less load-dependent than wall time)."""
    import importlib

    mod, _, fn = fn_name.partition(":")
    started, t0, c0 = time.time(), time.perf_counter(), cpu_seconds()
    out = getattr(importlib.import_module(mod), fn)(*args, **kwargs)
    cores = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    return out, {"wall_s": time.perf_counter() - t0, "cpu_s": cpu_seconds() - c0, "pid": os.getpid(), "cores": cores,
                 "started": started}


@dataclass
class _Unit:
    id: str
    fn: str
    args: tuple
    kind: str                 # what it stores: fom, reduction, model_norm, norm_error, simulation, gramians
    model: str                # model_id: norm units wait for the model's reductions
    estimate: float
    deps: set = field(default_factory=set)
    rom_from: list = field(default_factory=list)   # (reduce unit ids or None, {r: key}) whose entries it needs
    keys: dict = field(default_factory=dict)       # r -> key (group units) or {None: key}
    label: str = ""
    gramians: bool = False    # reads the model's Gramian factors (gramian_use "reads", the H2 norms)


def _units(plans, cache, prev):
    """The units of work the plans lack, deduplicated by content, with their dependencies."""
    cache_root = str(cache.root)

    def have(kind, key):
        return cache.read and cache.has(kind, key)
    units, todo, reduce_unit, planned = {}, {}, {}, set()

    def add(u):
        units[u.id] = u

    for plan in plans:
        for f in plan.foms.values():
            uid = "fom-" + f.key
            if uid not in units and not have("fom", f.key):
                lo, hi, n = f.bounds
                add(_Unit(uid, "morsuite.studies.tasks:fom_response",
                          (f.model.source, lo, hi, n, f.key, cache_root, False, RUN_BY), "fom", f.model.model_id,
                          float(n) * 0.01, keys={None: f.key}, label=f"response {f.model.name}"))
        for sim in plan.sims.values():
            uid = "sim-" + sim.key
            if uid not in units and not have("simulation", sim.key):
                add(_Unit(uid, "morsuite.studies.timedomain:full_simulation",
                          (sim.model.source, sim.settings, sim.key, RUN_BY), "simulation", sim.model.model_id, 10.0,
                          keys={None: sim.key}, label=f"simulation {sim.model.name}"))
        for gid, g in plan.reduces.items():
            for r in g.rs:
                if not have("reduction", g.keys[r]):
                    todo.setdefault(gid, (g, {}))[1][r] = g.keys[r]
    for gid, (g, keys) in todo.items():
        rs = sorted(keys)
        opts = json.dumps(g.method.full_options, sort_keys=True)
        est = {r: prev.get((g.model.name, g.method.reducer, opts, r)) for r in rs}
        chunks = SPLIT.get(g.method.reducer)
        parts = [rs] if chunks is None else _chunks(rs, est, chunks if chunks > 1 else len(rs))
        for part in parts:
            uid = f"{gid}/r{part[0]}-r{part[-1]}"
            known = [est[r] for r in part if est[r] is not None]
            add(_Unit(uid, "morsuite.studies.tasks:reduce_sweep",
                      (g.model.source, g.method.reducer, g.method.options, part, {r: keys[r] for r in part},
                       cache_root, RUN_BY), "reduction", g.model.model_id,
                      float("inf") if len(known) < len(part) else sum(known), keys={r: keys[r] for r in part},
                      label=f"{g.method.reducer} {g.model.name} r = {part}",
                      gramians=gramian_use(g.method.reducer) == "reads"))
            for r in part:
                reduce_unit[(gid, r)] = uid
    for plan in plans:
        for n in plan.norms.values():
            uid = "norm-" + n.key
            if uid not in units and cache.get_json("model_norm", n.key) is None:
                add(_Unit(uid, "morsuite.studies.norms:model_norm", (n.model.source, n.kind, n.options, n.key, RUN_BY),
                          "model_norm", n.model.model_id, 1.0, keys={None: n.key}, label=f"{n.kind} norm {n.model.name}",
                          gramians=n.kind == "h2"))
        for ng in plan.norm_groups.values():
            red = plan.reduces[ng.reduce]
            by_src = {}  # the norms of a reduce unit's orders (None: cached reductions) form one unit
            for r in ng.rs:
                if ng.keys[r] not in planned and cache.get_json("norm_error", ng.keys[r]) is None:
                    planned.add(ng.keys[r])
                    by_src.setdefault(reduce_unit.get((ng.reduce, r)), []).append(r)
            opts = json.dumps(red.method.full_options, sort_keys=True)
            for src, part in by_src.items():
                est = [prev.get(("norm", red.model.name, red.method.reducer, opts, r, ng.kind)) for r in part]
                add(_Unit(f"normerr-{ng.keys[part[0]]}", "morsuite.studies.norms:error_norms",
                          (red.model.source, ng.kind, ng.options, part, {r: ng.keys[r] for r in part}, RUN_BY),
                          "norm_error", red.model.model_id, float("inf") if None in est else sum(est),
                          keys={r: ng.keys[r] for r in part}, rom_from=[(src, {r: red.keys[r] for r in part})],
                          label=f"{ng.kind} errors {red.method.reducer} {red.model.name} r = {part}",
                          gramians=ng.kind == "h2"))
    for plan in plans:
        for t in plan.tolerances.values():
            uid = "tolerance-" + t.key
            if uid in units or have("tolerance", t.key):
                continue
            fkey = plan.foms[t.fom].key if t.fom else None
            add(_Unit(uid, "morsuite.studies.tolerance:tolerance_search",
                      (t.model.source, t.method.reducer, t.method.options, t.settings, t.norm_options, t.key, None,
                       fkey, cache_root, RUN_BY), "tolerance", t.model.model_id,
                      prev.get(("tolerance", t.key), float("inf")), keys={None: t.key},
                      label=f"tolerance {t.method.reducer} {t.model.name} ({t.settings['error']} "
                            f"{', '.join(f'{x:g}' for x in t.settings['tol'])})",
                      gramians=gramian_use(t.method.reducer) == "reads" or t.settings["error"] == "h2",
                      deps={f"fom-{fkey}"} if fkey and f"fom-{fkey}" in units else set()))
    # a model's error norms wait for their reductions
    for u in units.values():
        if u.kind == "norm_error":
            u.deps = {src for src, _ in u.rom_from if src is not None}
    # the Gramian factors of each model that a unit reads: a unit of their own, first, read from the store;
    # the model's Hinf norms wait for it too (their start grid uses the factors' shifts when they exist)
    sources = {u.model: u.args[0] for u in units.values() if u.gramians}
    for model, source in sources.items():
        uid = "gramians-" + model
        for u in units.values():
            if u.model == model and (u.gramians or u.kind in ("model_norm", "norm_error")
                                     or (u.kind == "reduction" and gramian_use(u.args[1]) == "waits")):
                u.deps.add(uid)
        add(_Unit(uid, "morsuite.studies.gramian_store:compute_factors", (source, RUN_BY), "gramians",
                  model, float("inf"), keys={None: uid}, label=f"Gramian factors {model}"))
    return units


def _chunks(rs, est, n):
    """``rs`` (increasing) in at most ``n`` consecutive chunks of about equal estimated time."""
    n = max(1, min(n, len(rs)))
    w = [est[r] if est[r] is not None else 1.0 for r in rs]
    total, out, cur, acc = sum(w), [], [], 0.0
    for r, wi in zip(rs, w):
        cur.append(r)
        acc += wi
        if len(out) < n - 1 and acc >= total * (len(out) + 1) / n:
            out.append(cur)
            cur = []
    if cur:
        out.append(cur)
    return out


def _rom_entries(cache, rom_from, results):
    """{r: reduction entry} for a norm unit: from the reduce units' results, else from the cache."""
    out = {}
    for src, keys in rom_from:
        done = results.get(src) or {}
        for r, key in keys.items():
            if r in done:
                out[r] = done[r]
                continue
            hit = cache.get("reduction", key)
            if hit is not None:
                arrays, meta = hit
                out[r] = {**meta, "rom": {"kind": meta["rom_kind"], "arrays": arrays}, "cached": True}
    return out


def _store(cache, shared, u, value):
    """Put a unit's result into the cache (the reducers and responses stored themselves) and note its keys."""
    from .timedomain import SIM_ARRAYS

    entries = value if u.kind in ("reduction", "norm_error") else {None: value}
    for r, e in entries.items():
        key = u.keys[r]
        if "error" in e:
            shared.failed[(u.kind, key)] = e
            continue
        if u.kind == "model_norm":
            cache.put_json("model_norm", key, {k: v for k, v in e.items() if k != "cached"})
        elif u.kind == "norm_error":
            cache.put_json("norm_error", key, {k: v for k, v in e.items() if k != "cached"})
        elif u.kind == "simulation":
            cache.put("simulation", key, {k: e[k] for k in SIM_ARRAYS},
                      {k: v for k, v in e.items() if k not in SIM_ARRAYS + ("cached",)})
        shared.fresh.add((u.kind, key))


def shared_compute(studies, cache, jobs: int = 2, out=None, quiet: bool = True, run_kwargs=None,
                   jobs_rule=None) -> Shared:
    """Compute what ``studies`` lack, all at once, on ``jobs`` pinned worker processes (module docstring).

    Parameters
    ----------
    studies : list of :class:`~morsuite.studies.spec.Study`
    cache : :class:`~morsuite.studies.cache.Cache` (entries are written there)
    jobs : worker processes (at least 1), each pinned to one of the usable cores in turn
    out : results root whose ``*/manifest.json`` give the previous run's times (the longest units
        start first); None: no estimates
    quiet : no log lines
    run_kwargs : None (default): compute only. A dict of keyword arguments of
        :func:`~morsuite.studies.runner.run` (``out`` required): each study (from a spec file,
        ``study.path``) is also run, on the same workers, as soon as what it reads is computed
        (figures and tables while other units still compute), with its share of what was
        computed (:func:`split_claims`); the results folder's index and ``run.json`` (the run's
        record below) are written at the end.
    jobs_rule : dict or None
        How ``jobs`` was chosen (:func:`~morsuite.studies.workers.default_jobs`' record), kept in the
        record; None: given by the caller.

    Returns
    -------
    Shared
        the keys computed (for the studies' manifests), failures, and ``record``: jobs, cores,
        units, wall time, the workers' summed busy time (``busy_s``: wall s of the computing units), the CPU
        time of every unit (``cpu_s``, study runs too), of this process (``cpu_main_s``) and of the workers
        from spawn to exit (``cpu_workers_s``), and each unit's label, worker, wall and CPU time.
    """
    t0, main0, kids0 = time.perf_counter(), cpu_seconds("self"), cpu_seconds("children")
    plans = [build_plan(s) for s in studies]
    units = _units(plans, cache, _previous_times(out) if out is not None else {})
    n_units = len(units)
    shared = Shared(jobs)
    cores = usable_cores()
    shared.record = {"jobs": jobs, "cores": cores, "pinned": True, "units": n_units, "run_by": RUN_BY,
                     "jobs_rule": jobs_rule if jobs_rule is not None else "given"}
    log, owners = [], {}
    if run_kwargs is not None and not units:  # all cached: the reports in this process, as without workers
        from .runner import run
        for study in studies:
            run(study, **{"render_jobs": jobs, **run_kwargs})
        return shared
    if run_kwargs is not None:
        owners = _add_study_units(units, studies, plans, run_kwargs)
    if units:
        _schedule(units, cache, shared, jobs, cores, log, quiet, owners, t0)
    busy = sum(e["wall_s"] for e in log if e["kind"] != "study")
    wall = time.perf_counter() - t0
    shared.record = {**shared.record, "wall_s": wall, "busy_s": busy, "cpu_s": sum(e["cpu_s"] for e in log),
                     "cpu_main_s": cpu_seconds("self") - main0, "cpu_workers_s": cpu_seconds("children") - kids0,
                     "log": log}
    if run_kwargs is not None:
        from .pages import write_index
        write_index(run_kwargs["out"])
        _write_run_record(run_kwargs["out"], studies, shared.record)
    if not quiet:
        print(f"morsuite run: {n_units} units of work shared by {len(studies)} studies on {jobs} worker "
              f"processes: {wall:.1f} s ({busy:.1f} s busy)", file=sys.stderr)
    return shared


def _write_run_record(out, studies, record) -> None:
    """``OUT/run.json``: the run's studies, when it finished, its wall and busy time, jobs and each unit's
    label, worker and time (the figures the README quotes for the main job's run)."""
    import datetime

    from ..utils import atomic_write_text, load_average, to_plain

    rec = {"studies": [s.name for s in studies],
           "finished": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
           "load_average": load_average(),
           **record}
    atomic_write_text(Path(out) / "run.json", json.dumps(to_plain(rec), indent=1, sort_keys=True))


def _add_study_units(units, studies, plans, run_kwargs) -> dict:
    """Add each study's own run to ``units``: it depends on every unit computing something it reads
    (also what another study claims: otherwise it could start first and compute that itself, seen
    when the workers' start was slow); returns study unit id -> the computed entries it claims
    (fresh for the first study in order that reads them)."""
    planned = {(u.kind, k) for u in units.values() for k in u.keys.values()}
    unclaimed, owners = set(planned), {}
    for study, plan in zip(studies, plans):
        reads = {c for c in _claims(plan) if c in planned}
        own, unclaimed = reads & unclaimed, unclaimed - reads
        uid = f"study-{study.name}"
        units[uid] = _Unit(uid, "morsuite.studies.batch:_run_study", (str(study.path), dict(run_kwargs)),
                           "study", "", _report_estimate(run_kwargs["out"], study.name),
                           deps={u.id for u in units.values() if u.kind != "study"
                                 and any((u.kind, k) in reads for k in u.keys.values())},
                           label=f"study {study.name}")
        owners[uid] = own
    return owners


def _schedule(units, cache, shared, jobs, cores, log, quiet, owners, t0):
    """List scheduling: the longest ready unit goes to the first free worker."""
    ctx = multiprocessing.get_context("spawn")
    counter = ctx.Value("i", 0)
    # the workers share the Gramian factors through the cache; a run that does not read the cache
    # reads only the factors it makes itself (a salt of its own in their keys)
    salt = "" if cache.read else uuid.uuid4().hex
    wall0 = time.time() - (time.perf_counter() - t0)  # the run's start on the workers' clock
    results, done, running = {}, set(), {}
    pending = dict(units)
    with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_pin,
                             initargs=(counter, cores, (str(cache.root), cache.write, salt))) as pool, \
            terminate_on_exit(pool):
        while pending or running:
            # the Gramian factors first (their readers wait for them), then the longest units
            ready = sorted((u for u in pending.values() if u.deps <= done),
                           key=lambda u: (u.kind != "gramians", -u.estimate))
            for u in ready[: max(0, jobs - len(running))]:
                if u.kind == "study":  # its share: what it claims of what was computed, the failures it may meet
                    part = Shared(shared.jobs, owners[u.id] & shared.fresh, dict(shared.failed),
                                  {**shared.record, "started_after_s": time.perf_counter() - t0})
                    # nothing timed left to run or running: its figures may take every core
                    alone = all(x.kind == "study" for x in [*pending.values(), *running.values()])
                    extra = {"render_jobs": jobs, "render_cores": list(cores)} if alone else {}
                    args = (u.args[0], {**u.args[1], **extra}, part)
                else:
                    args = u.args + ((_rom_entries(cache, u.rom_from, results),) if u.kind == "norm_error" else ())
                running[pool.submit(_run_unit, u.fn, args, {})] = u
                del pending[u.id]
            if not running:  # nothing ready and nothing running: a dependency never ran
                raise RuntimeError(f"shared_compute: units wait for units that do not exist: {sorted(pending)}")
            finished, _ = wait(list(running), return_when=FIRST_COMPLETED)
            for fut in finished:
                u = running.pop(fut)
                value, rec = fut.result()
                done.add(u.id)
                if u.kind != "study":
                    results[u.id] = value
                    _store(cache, shared, u, value)
                rec["start_s"] = rec.pop("started") - wall0
                log.append({"unit": u.label, "kind": u.kind, **rec})
                if not quiet:
                    print(f"  {rec['wall_s']:7.1f} s ({rec['cpu_s']:6.1f} s CPU)  core {rec['cores']}  at "
                          f"{rec['start_s']:6.1f} s  {u.label}", file=sys.stderr)


# -- the studies' own runs ---------------------------------------------------------
def _claims(plan) -> list:
    """``(kind, key)`` of every computed artifact ``plan`` reads, in the order a study claims them."""
    out = [("fom", f.key) for f in plan.foms.values()]
    out += [("reduction", g.keys[r]) for g in plan.reduces.values() for r in g.rs]
    out += [("model_norm", n.key) for n in plan.norms.values()]
    out += [("norm_error", g.keys[r]) for g in plan.norm_groups.values() for r in g.rs]
    out += [("simulation", s.key) for s in plan.sims.values()]
    out += [("tolerance", t.key) for t in plan.tolerances.values()]
    return out


def split_claims(studies, shared: Shared) -> list:
    """One :class:`Shared` per study: each artifact computed by :func:`shared_compute` is
    fresh for the first study (in the given order) that reads it, reused for the others."""
    left, out = set(shared.fresh), []
    for study in studies:
        own = {c for c in _claims(build_plan(study)) if c in left}
        left -= own
        out.append(Shared(shared.jobs, own, shared.failed, shared.record))
    return out


def _run_study(path, kwargs, shared):
    """Worker: load the spec (validation memo from the cache) and run it; its manifest's timing."""
    from .cache import Cache
    from .memo import SpecMemo
    from .runner import run
    from .spec import load_spec

    cache_dir = kwargs.get("cache_dir") or Path(kwargs["out"]) / ".cache"
    study = load_spec(path, memo=SpecMemo(Cache(cache_dir)))
    cores = kwargs.pop("render_cores", None)
    pinned = os.sched_getaffinity(0) if cores and hasattr(os, "sched_getaffinity") else None
    if pinned is not None:  # its figures' processes (forked from this one) may use every core
        os.sched_setaffinity(0, set(cores))
    try:
        res = run(study, shared=shared, **kwargs)
    finally:
        if pinned is not None:
            os.sched_setaffinity(0, pinned)
    return {"name": study.name, "timing": res.manifest["timing"], "files": len(res.files)}
