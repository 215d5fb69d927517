"""What earlier runs of the studies took: the estimates that order a shared run's units.

:func:`previous_times` reads every study manifest under a results folder for the reductions' and
error norms' times, :func:`report_estimate` a study's report time; :mod:`morsuite.studies.batch`
starts the longest units first with them. Cost: reading the manifests (JSON).
"""

from __future__ import annotations

import json
from pathlib import Path

__all__ = ["previous_times", "report_estimate"]


def previous_times(out: Path) -> dict:
    """(model name, reducer, options JSON, r) -> time (s) of the reductions, ("norm", model, reducer,
    options, r, kind) of the error norms and ("tolerance", key) of the tolerance searches, in the manifests
    under ``out``."""
    times = {}
    for path in sorted(Path(out).glob("*/manifest.json")):
        try:
            arts = json.loads(path.read_text()).get("artifacts") or []
        except (OSError, ValueError):
            continue
        arts = [a for a in arts if isinstance(a, dict)]
        opts = {a.get("id"): json.dumps(a.get("options"), sort_keys=True) for a in arts if a.get("kind") == "reduction"}
        for a in arts:
            if a.get("kind") == "reduction" and a.get("reducer"):
                k = (a.get("model"), a["reducer"], opts[a.get("id")], a.get("r_requested"))
            elif a.get("kind") == "norm_error" and a.get("reduction") in opts:
                k = ("norm", a.get("model"), a.get("reducer"), opts[a["reduction"]], a.get("r_requested"), a.get("norm"))
            elif a.get("kind") == "tolerance" and a.get("key"):  # a search: its cache key says what it was
                k = ("tolerance", a["key"])
            else:
                continue
            t = a.get("wall_s") or a.get("time_s")
            if isinstance(t, (int, float)):
                times[k] = max(times.get(k, 0.0), float(t))
    return times


def report_estimate(out, name) -> float:
    """The last run's ``report_s`` of study ``name`` under ``out`` (inf when unknown)."""
    try:
        return float(json.loads((Path(out) / name / "manifest.json").read_text())["timing"]["report_s"])
    except (OSError, ValueError, KeyError, TypeError):
        return float("inf")
