"""From scenes to artifacts: what a study must compute, each thing once.

Scenes name models, methods and grids by alias; artifacts are keyed by content
(model identity, reducer and every option value, grid bounds), so two aliases of
one thing share one artifact:

- a full-order response per (model, grid), shared by every method;
- a reducer group per (model, reducer, options): ONE reducer instance runs every
  r that some scene needs, in increasing order (Gramians or a projector are
  formed once per group);
- a metrics group per (model, grid, reducer, options): reduced responses and errors.

Nothing outside what :func:`morsuite.studies.scenes.needs` returns for the
study's scenes is planned.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .cache import cache_key
from .scenes import needs

__all__ = ["Plan", "FomArtifact", "ReduceGroup", "MetricsGroup", "build_plan"]


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
    aliases: set = field(default_factory=set)


@dataclass
class Plan:
    foms: dict
    reduces: dict
    metrics: dict
    fom_of: dict           # (model alias, grid) -> fom id
    reduce_of: dict        # (model alias, method alias) -> reduce id
    metrics_of: dict       # (model alias, grid, method alias) -> metrics id

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
        return lines


def _reduction_key(model, method, r):
    return cache_key("reduction", model=model.model_id, reducer=method.reducer, options=method.full_options, r=int(r))


def build_plan(study) -> Plan:
    """The artifacts the study's scenes need, deduplicated by content."""
    foms, reduces, metrics = {}, {}, {}
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
        for need in needs(scene):
            if need[0] == "reduce":
                _, model_alias, method_alias, r = need
                reduce_group(model_alias, method_alias, r)
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
            mg.aliases.add((model_alias, grid, method_alias))
            metrics_of[(model_alias, grid, method_alias)] = mid
    return Plan(foms, reduces, metrics, fom_of, reduce_of, metrics_of)
