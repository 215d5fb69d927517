"""From scenes to artifacts: what a study must compute, each thing once.

Scenes name models, methods and grids by alias; artifacts are keyed by content
(model identity, reducer and every option value, grid bounds), so two aliases of
one thing share one artifact:

- a full-order response per (model, grid), shared by every method;
- a reducer group per (model, reducer, options): ONE reducer instance runs every
  r that some scene needs, in increasing order (Gramians or a projector are
  formed once per group);
- a metrics group per (model, grid, reducer, options): reduced responses and errors,
  cached per r (keyed by the response's and the reduction's keys);
- exact norms (:mod:`morsuite.studies.norms`): the model's norm per (model, kind, options), and a norm
  group per (reducer group, kind, options) with the error norm of each r;
- time-domain comparisons (:mod:`morsuite.studies.timedomain`): the full model's simulation per (model,
  input settings), shared by the methods and scenes that simulate the same, and a
  simulation group per (simulation, reducer group, rom_method) with each r's output
  and errors;
- a tolerance search per (model, reducer, options, grid, settings) (:mod:`morsuite.studies.tolerance`):
  one reducer instance reduces at the orders the search needs, shared by every tolerance scene
  that asks the same; a band search reads the model's full-order response on its grid;
- an output per scene (a figure or a table) and the summary table: the last
  nodes of the graph, keyed by their content once their inputs exist (see
  :mod:`morsuite.studies.outputs`).

Nothing outside what :func:`morsuite.studies.kinds.needs` returns for the
study's scenes is planned.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .cache import cache_key, source_digest
from .kinds import SUMMARY, needs, output_names
from .time_options import settings as time_settings
from .tol_options import settings as tol_settings

__all__ = ["Plan", "FomArtifact", "ReduceGroup", "MetricsGroup", "NormArtifact", "NormGroup", "SimArtifact",
           "SimGroup", "ToleranceArtifact", "OutputArtifact", "build_plan", "SUMMARY"]

@dataclass
class FomArtifact:
    id: str
    model: object          # ModelEntry
    bounds: tuple          # (lo, hi, n)
    key: str
    aliases: set = field(default_factory=set)


@dataclass
class ReduceGroup:
    id: str
    model: object          # ModelEntry
    method: object         # MethodEntry (the first alias; options identical for all)
    rs: list
    keys: dict             # r -> cache key
    aliases: set = field(default_factory=set)


@dataclass
class MetricsGroup:
    id: str
    fom: str               # FomArtifact id
    reduce: str            # ReduceGroup id
    rs: list
    keys: dict = field(default_factory=dict)     # r -> cache key
    aliases: set = field(default_factory=set)


@dataclass
class NormArtifact:
    id: str
    model: object          # ModelEntry
    kind: str              # "h2" or "hinf"
    options: dict
    key: str


@dataclass
class NormGroup:
    id: str
    norm: str              # NormArtifact id (the model's norm: relative errors)
    reduce: str            # ReduceGroup id
    kind: str
    options: dict
    rs: list = field(default_factory=list)
    keys: dict = field(default_factory=dict)     # r -> cache key


@dataclass
class SimArtifact:
    id: str
    model: object          # ModelEntry
    settings: dict         # input, input_sha256, horizon, step, scheme, direction
    key: str
    scenes: list = field(default_factory=list)


@dataclass
class SimGroup:
    id: str
    sim: str               # SimArtifact id
    reduce: str            # ReduceGroup id
    rom_method: str
    rs: list = field(default_factory=list)
    keys: dict = field(default_factory=dict)     # r -> cache key
    scenes: list = field(default_factory=list)


@dataclass
class ToleranceArtifact:
    id: str
    model: object          # ModelEntry
    method: object         # MethodEntry
    settings: dict         # tol (list), error, budget_lus, budget_s, max_states (tol_options.settings)
    fom: str | None        # FomArtifact id of a band search's grid, else None
    norm_options: dict     # the study's options of the error's norm (h2, hinf searches)
    key: str
    scenes: list = field(default_factory=list)


@dataclass
class OutputArtifact:
    id: str                # "figure/NAME" or "table/NAME"
    kind: str              # "figure" or "table"
    scene: str | None      # the scene's name; None for the summary table
    inputs: list           # ids of the artifacts it reads ("reduce-.../r4", "metrics-.../r4", "fom-...")


@dataclass
class Plan:
    foms: dict
    reduces: dict
    metrics: dict
    fom_of: dict           # (model alias, grid) -> fom id
    reduce_of: dict        # (model alias, method alias) -> reduce id
    metrics_of: dict       # (model alias, grid, method alias) -> metrics id
    outputs: dict = field(default_factory=dict)  # id -> OutputArtifact, in scene order, the summary last
    norms: dict = field(default_factory=dict)        # id -> NormArtifact
    norm_groups: dict = field(default_factory=dict)  # id -> NormGroup
    sims: dict = field(default_factory=dict)         # id -> SimArtifact
    sim_groups: dict = field(default_factory=dict)   # id -> SimGroup
    norm_of: dict = field(default_factory=dict)        # (model alias, kind) -> norm id
    norm_group_of: dict = field(default_factory=dict)  # (model alias, method alias, kind) -> norm group id
    sim_of: dict = field(default_factory=dict)         # scene name -> simulation id
    sim_group_of: dict = field(default_factory=dict)   # (scene name, method alias) -> simulation group id
    tolerances: dict = field(default_factory=dict)     # id -> ToleranceArtifact
    tolerance_of: dict = field(default_factory=dict)   # (scene name, method alias) -> tolerance id

    def describe(self) -> list[str]:
        """One line per artifact the plan computes (full-order responses, reducer runs, metrics, norms, simulations, outputs), as ``morsuite run --dry-run`` prints them."""
        lines = []
        for f in self.foms.values():
            lo, hi, n = f.bounds
            lines.append(f"full-order response  {f.model.name} on [{lo:g}, {hi:g}] rad/s, {n} frequencies")
        for g in self.reduces.values():
            lines.append(f"reducer run          {g.model.name} {g.method.reducer} "
                         f"(options {g.method.options or 'default'}) r = {g.rs}")
        for g in self.metrics.values():
            lines.append(f"metrics              {self.reduces[g.reduce].model.name} "
                         f"{self.reduces[g.reduce].method.reducer} r = {g.rs}")
        for n in self.norms.values():
            lines.append(f"model norm           {n.model.name} {n.kind}")
        for g in self.norm_groups.values():
            red = self.reduces[g.reduce]
            lines.append(f"error norms          {red.model.name} {red.method.reducer} {g.kind} r = {g.rs}")
        for sim in self.sims.values():
            st = sim.settings
            lines.append(f"simulation           {sim.model.name} {st['input']} over {st['horizon']:g} s, step "
                         f"{st['step']:g} s ({st['scheme']})")
        for g in self.sim_groups.values():
            red = self.reduces[g.reduce]
            lines.append(f"reduced simulations  {red.model.name} {red.method.reducer} r = {g.rs}")
        for t in self.tolerances.values():
            st = t.settings
            lines.append(f"tolerance search     {t.model.name} {t.method.reducer} ({st['error']} error, tol "
                         f"{', '.join(f'{x:g}' for x in st['tol'])})")
        for o in self.outputs.values():
            lines.append(f"{o.kind:<20} {o.id.partition('/')[2]} (from {len(o.inputs)} artifacts; "
                         f"reused when its data did not change)")
        return lines


def _reduction_key(model, method, r):
    return cache_key("reduction", model=model.model_id, reducer=method.reducer, options=method.full_options, r=int(r))


def _metrics_key(fom_key, reduction_key):
    # tasks.py (with task_common.py) computes the metrics: a change there must not serve stale numbers
    return cache_key("metrics", fom=fom_key, reduction=reduction_key,
                     tasks=source_digest("studies/tasks.py", "studies/task_common.py"))


def _norm_key(model, kind, options):
    return cache_key("model_norm", model=model.model_id, norm=kind, options=options,
                     tasks=source_digest("studies/norms.py", "studies/task_common.py"))


def _norm_error_key(reduction_key, kind, options):
    return cache_key("norm_error", reduction=reduction_key, norm=kind, options=options,
                     tasks=source_digest("studies/norms.py", "studies/task_common.py"))


def _sim_key(model, setup):
    return cache_key("simulation", model=model.model_id, settings=setup,
                     tasks=source_digest("studies/timedomain.py", "studies/task_common.py"))


def _sim_error_key(sim_key, reduction_key, rom_method):
    return cache_key("sim_error", simulation=sim_key, reduction=reduction_key, rom_method=rom_method,
                     tasks=source_digest("studies/timedomain.py", "studies/task_common.py"))


def _tolerance_key(model, method, settings, fom_key, norm_options):
    # the search's code (analysis/tolerance.py is in the code digest of every key) and its task's
    return cache_key("tolerance", model=model.model_id, reducer=method.reducer, options=method.full_options,
                     settings=settings, fom=fom_key, norm_options=norm_options,
                     tasks=source_digest("studies/tolerance.py", "studies/task_common.py"))


def build_plan(study) -> Plan:
    """The artifacts the study's scenes need, deduplicated by content."""
    plan = Plan({}, {}, {}, {}, {}, {})
    foms, reduces, metrics, outputs = plan.foms, plan.reduces, plan.metrics, plan.outputs

    def reduce_group(model_alias, method_alias, r):
        model, method = study.models[model_alias], study.methods[method_alias]
        gid = "reduce-" + cache_key("group", model=model.model_id, reducer=method.reducer,
                                    options=method.full_options)[:16]
        g = reduces.get(gid)
        if g is None:
            g = reduces[gid] = ReduceGroup(gid, model, method, [], {})
        if r not in g.keys:
            g.keys[r] = _reduction_key(model, method, r)
            g.rs = sorted(g.keys)
        g.aliases.add((model_alias, method_alias))
        plan.reduce_of[(model_alias, method_alias)] = gid
        return g

    def norm_need(model_alias, method_alias, r, kind):
        model, opts = study.models[model_alias], study.norm_options[kind]
        key = _norm_key(model, kind, opts)
        nid = "norm-" + key[:16]
        plan.norms.setdefault(nid, NormArtifact(nid, model, kind, opts, key))
        plan.norm_of[(model_alias, kind)] = nid
        g = reduce_group(model_alias, method_alias, r)
        ngid = "normerr-" + cache_key("norm_group", group=g.id, norm=kind, options=opts)[:16]
        ng = plan.norm_groups.setdefault(ngid, NormGroup(ngid, nid, g.id, kind, opts))
        if r not in ng.keys:
            ng.keys[r] = _norm_error_key(g.keys[r], kind, opts)
            ng.rs = sorted(ng.keys)
        plan.norm_group_of[(model_alias, method_alias, kind)] = ngid
        return [nid, f"{g.id}/r{r}", f"{ngid}/r{r}"]

    def time_need(scene, method_alias, r):
        model = study.models[scene.model]
        setup = time_settings(scene.params)
        key = _sim_key(model, setup)
        sid = "sim-" + key[:16]
        sim = plan.sims.setdefault(sid, SimArtifact(sid, model, setup, key))
        if scene.name not in sim.scenes:
            sim.scenes.append(scene.name)
        plan.sim_of[scene.name] = sid
        g = reduce_group(scene.model, method_alias, r)
        rom_method = scene.params["rom_method"]
        sgid = "simerr-" + cache_key("sim_group", sim=key, group=g.id, rom_method=rom_method)[:16]
        sg = plan.sim_groups.setdefault(sgid, SimGroup(sgid, sid, g.id, rom_method))
        if r not in sg.keys:
            sg.keys[r] = _sim_error_key(key, g.keys[r], rom_method)
            sg.rs = sorted(sg.keys)
        if scene.name not in sg.scenes:
            sg.scenes.append(scene.name)
        plan.sim_group_of[(scene.name, method_alias)] = sgid
        return [sid, f"{g.id}/r{r}", f"{sgid}/r{r}"]

    def fom_need(model_alias, grid):
        model = study.models[model_alias]
        bounds = study.grids[grid].bounds_for(model)
        fkey = cache_key("fom", model=model.model_id, grid=bounds)
        fid = "fom-" + fkey[:16]
        f = foms.get(fid)
        if f is None:
            f = foms[fid] = FomArtifact(fid, model, bounds, fkey)
        f.aliases.add((model_alias, grid))
        plan.fom_of[(model_alias, grid)] = fid
        return f

    def tolerance_need(scene, method_alias):
        model, method = study.models[scene.model], study.methods[method_alias]
        setup = tol_settings(scene.params)
        f = fom_need(scene.model, scene.grid) if scene.grid else None
        nopts = study.norm_options.get(setup["error"], {}) if setup["error"] != "band" else {}
        key = _tolerance_key(model, method, setup, f.key if f else None, nopts)
        tid = "tolerance-" + key[:16]
        t = plan.tolerances.setdefault(tid, ToleranceArtifact(tid, model, method, setup, f.id if f else None,
                                                              nopts, key))
        if scene.name not in t.scenes:
            t.scenes.append(scene.name)
        plan.tolerance_of[(scene.name, method_alias)] = tid
        return [tid] + ([f.id] if f else [])

    for scene in study.scenes:
        inputs = []
        for need in needs(scene):
            if need[0] == "tolerance":
                inputs += tolerance_need(scene, need[3])
                continue
            if need[0] == "reduce":
                _, model_alias, method_alias, r = need
                inputs.append(f"{reduce_group(model_alias, method_alias, r).id}/r{r}")
                continue
            if need[0] == "norm":
                inputs += norm_need(*need[1:])
                continue
            if need[0] == "time":
                inputs += time_need(scene, need[2], need[3])
                continue
            _, model_alias, grid, method_alias, r = need
            f = fom_need(model_alias, grid)
            fid, fkey = f.id, f.key
            g = reduce_group(model_alias, method_alias, r)
            mid = "metrics-" + cache_key("metrics", fom=fkey, group=g.id)[:16]
            mg = metrics.get(mid)
            if mg is None:
                mg = metrics[mid] = MetricsGroup(mid, fid, g.id, [])
            if r not in mg.rs:
                mg.rs = sorted(mg.rs + [r])
                mg.keys[r] = _metrics_key(fkey, g.keys[r])
            mg.aliases.add((model_alias, grid, method_alias))
            plan.metrics_of[(model_alias, grid, method_alias)] = mid
            inputs += [fid, f"{g.id}/r{r}", f"{mid}/r{r}"]
        for name in output_names(scene):
            kind = "table" if scene.kind in ("table", "modes") or (scene.kind == "tolerance" and name == scene.name) \
                else "figure"
            outputs[f"{kind}/{name}"] = OutputArtifact(f"{kind}/{name}", kind, scene.name, sorted(set(inputs)))
    # the study's own norms: for every reduction some scene needs
    for (model_alias, method_alias), gid in list(plan.reduce_of.items()):
        for kind in study.norms:
            for r in reduces[gid].rs:
                norm_need(model_alias, method_alias, r, kind)
    everything = [f"{g.id}/r{r}" for groups in (reduces, metrics, plan.norm_groups, plan.sim_groups)
                  for g in groups.values() for r in g.rs] + list(plan.norms) + list(plan.sims)
    outputs[f"table/{SUMMARY}"] = OutputArtifact(f"table/{SUMMARY}", "table", None, sorted(everything))
    return plan
