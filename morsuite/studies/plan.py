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
- an output per scene (a figure or a table) and the summary table: the last
  nodes of the graph, keyed by their content once their inputs exist (see
  :mod:`morsuite.studies.outputs`).

Nothing outside what :func:`morsuite.studies.scenes.needs` returns for the
study's scenes is planned.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .cache import cache_key, source_digest
from .scenes import needs

__all__ = ["Plan", "FomArtifact", "ReduceGroup", "MetricsGroup", "OutputArtifact", "build_plan", "SUMMARY"]

#: Name of the summary table (``summary.csv``, ``summary.md``): every reduction of the run.
SUMMARY = "summary"


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

    def describe(self) -> list[str]:
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
        for o in self.outputs.values():
            lines.append(f"{o.kind:<20} {o.scene or SUMMARY} (from {len(o.inputs)} artifacts; "
                         f"reused when its data did not change)")
        return lines


def _reduction_key(model, method, r):
    return cache_key("reduction", model=model.model_id, reducer=method.reducer, options=method.full_options, r=int(r))


def _metrics_key(fom_key, reduction_key):
    # tasks.py computes the metrics: a change there must not serve stale numbers
    return cache_key("metrics", fom=fom_key, reduction=reduction_key, tasks=source_digest("studies/tasks.py"))


def build_plan(study) -> Plan:
    """The artifacts the study's scenes need, deduplicated by content."""
    foms, reduces, metrics, outputs = {}, {}, {}, {}
    fom_of, reduce_of, metrics_of = {}, {}, {}

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
        reduce_of[(model_alias, method_alias)] = gid
        return g

    for scene in study.scenes:
        inputs = []
        for need in needs(scene):
            if need[0] == "reduce":
                _, model_alias, method_alias, r = need
                inputs.append(f"{reduce_group(model_alias, method_alias, r).id}/r{r}")
                continue
            _, model_alias, grid, method_alias, r = need
            model = study.models[model_alias]
            bounds = study.grids[grid].bounds_for(model)
            fkey = cache_key("fom", model=model.model_id, grid=bounds)
            fid = "fom-" + fkey[:16]
            f = foms.get(fid)
            if f is None:
                f = foms[fid] = FomArtifact(fid, model, bounds, fkey)
            f.aliases.add((model_alias, grid))
            fom_of[(model_alias, grid)] = fid
            g = reduce_group(model_alias, method_alias, r)
            mid = "metrics-" + cache_key("metrics", fom=fkey, group=g.id)[:16]
            mg = metrics.get(mid)
            if mg is None:
                mg = metrics[mid] = MetricsGroup(mid, fid, g.id, [])
            if r not in mg.rs:
                mg.rs = sorted(mg.rs + [r])
                mg.keys[r] = _metrics_key(fkey, g.keys[r])
            mg.aliases.add((model_alias, grid, method_alias))
            metrics_of[(model_alias, grid, method_alias)] = mid
            inputs += [fid, f"{g.id}/r{r}", f"{mid}/r{r}"]
        kind = "table" if scene.kind == "table" else "figure"
        outputs[f"{kind}/{scene.name}"] = OutputArtifact(f"{kind}/{scene.name}", kind, scene.name,
                                                         sorted(set(inputs)))
    everything = [f"{g.id}/r{r}" for g in reduces.values() for r in g.rs] + \
        [f"{m.id}/r{r}" for m in metrics.values() for r in m.rs]
    outputs[f"table/{SUMMARY}"] = OutputArtifact(f"table/{SUMMARY}", "table", None, sorted(everything))
    return Plan(foms, reduces, metrics, fom_of, reduce_of, metrics_of, outputs)
