r"""Scene kinds: the keys each takes, what it needs computed, and the names of its outputs.

The table :data:`KINDS` (one :class:`Kind` per scene kind), :func:`needs` (the artifacts a
scene reads) and :func:`output_names` are what the spec validates against and the plan
builds from; how a scene is drawn from results is :mod:`morsuite.studies.scenes`, which
re-exports these names. This module imports only the validators and option tables
(:mod:`morsuite.studies.checks`, :mod:`morsuite.studies.norm_options`, :mod:`morsuite.studies.time_options`), so that spec -> plan ->
tasks -> outputs import one way.
"""

from __future__ import annotations

from dataclasses import dataclass

from .checks import subset_of
from .norm_options import NORM_KINDS, NORM_MEASURES
from .time_options import TIME_KEYS
from .tol_options import TOL_KEYS

__all__ = ["KINDS", "COMMON_KEYS", "Kind", "needs", "output_names", "orders_text", "check_output_names",
           "MEASURES", "AXES", "TIMES", "MAX_POINTS", "SUMMARY"]

#: Name of the summary table (``summary.csv``, ``summary.md``): every reduction of the run.
SUMMARY = "summary"

COMMON_KEYS = ("name", "kind", "title", "model", "methods", "r_by_method")
MEASURES = ("max_abs", "max_rel") + tuple(NORM_MEASURES)
#: a time-domain curve is thinned to at most this many samples for its figure and CSV
MAX_POINTS = 4000
AXES = ("r", "states")
TIMES = ("standalone", "call")

_R = (None, None)          # placeholders: validated by the spec module itself
_GRID = (None, None)
_PAPER = (None, None)


@dataclass(frozen=True)
class Kind:
    doc: str
    keys: dict                 # kind-specific key -> (default, choices or None for a positive int)
    uses_grid: bool
    one_r: bool
    min_methods: int = 1
    with_full: bool = False
    needs_r: bool = True       # False: the scene has no ``r`` (a tolerance scene finds its orders)

    def curve_names(self, methods) -> list:
        """The scene's curves: ``"full"`` first if the kind draws the full model, then one per method alias."""
        return (["full"] if self.with_full else []) + list(methods)

    def grid_needed(self, params) -> bool:
        """A grid unless the scene's measure is an exact norm (over the whole axis), or its
        tolerance's error is one."""
        return self.uses_grid and params.get("measure") not in NORM_MEASURES and params.get("error") not in NORM_KINDS


KINDS = {
    "sigma": Kind("sigma_max of the full and the reduced models over frequency",
                  {"r": _R, "grid": _GRID, "paper_csv": _PAPER}, True, True, with_full=True),
    "error": Kind("absolute or relative error over frequency",
                  {"r": _R, "grid": _GRID, "paper_csv": _PAPER, "error": ("abs", ("abs", "rel"))}, True, True),
    "compare": Kind("method against method at one r: error over frequency",
                    {"r": _R, "grid": _GRID, "paper_csv": _PAPER, "error": ("abs", ("abs", "rel"))}, True, True,
                    min_methods=2),
    "error_vs_r": Kind("an error measure (band maximum on a grid, or a norm over the whole axis) against r",
                       {"r": _R, "grid": _GRID, "paper_csv": _PAPER, "measure": ("max_abs", MEASURES),
                        "axis": ("r", AXES)}, True, False),
    "time_vs_r": Kind("reduction time against r",
                      {"r": _R, "paper_csv": _PAPER, "axis": ("r", AXES), "time": ("standalone", TIMES)},
                      False, False),
    "pareto": Kind("time against error, one point per method and r",
                   {"r": _R, "grid": _GRID, "measure": ("max_abs", MEASURES), "time": ("standalone", TIMES),
                    "axis": ("r", AXES)},
                   True, False),
    "convergence": Kind("IRKA convergence history (shift change per iteration)", {"r": _R}, False, False),
    "hsv": Kind("Hankel singular value decay", {"r": _R, "count": (None, None)}, False, True),
    "table": Kind("summary table of the scene's reductions",
                  {"r": _R, "grid": _GRID, "norms": ([], subset_of(NORM_KINDS))}, True, False),
    "modes": Kind("eigenfrequencies, damping ratios and MAC of the full and the reduced models in the band, "
                  "and the reduced models' structure checks", {"r": _R, "grid": _GRID}, True, True, with_full=True),
    "time": Kind("output of the full and reduced models over time, and the output error",
                 {"r": _R, **TIME_KEYS}, False, True),
    "tolerance": Kind("for each method, the smallest reduced model whose error meets each tolerance, and its cost",
                      {"grid": _GRID, **TOL_KEYS}, True, False, needs_r=False),
}


def needs(scene):
    """Artifacts the scene reads: ("metrics", model, grid, method, r), ("reduce", model, method, r),
    ("norm", model, method, r, kind) (an exact error norm and the model's norm),
    ("time", model, method, r) (the scene's simulations) or ("tolerance", model, grid, method) (a
    tolerance scene's search; grid None for a norm's tolerance)."""
    if scene.kind == "tolerance":
        for m in scene.methods:
            yield ("tolerance", scene.model, scene.grid, m)
        return
    norms = list(scene.params.get("norms") or [])
    if scene.params.get("measure") in NORM_MEASURES:
        norms.append(NORM_MEASURES[scene.params["measure"]][0])
    for m in scene.methods:
        for r in scene.rs_of(m):
            yield ("metrics", scene.model, scene.grid, m, r) if scene.grid else ("reduce", scene.model, m, r)
            for n in norms:
                yield ("norm", scene.model, m, r, n)
            if scene.kind == "time":
                yield ("time", scene.model, m, r)


def output_names(scene) -> list:
    """The names of the scene's outputs (figures or a table)."""
    if scene.kind == "modes":
        return [scene.name, f"{scene.name}_structure"]
    if scene.kind == "tolerance":
        return [scene.name, f"{scene.name}_states", f"{scene.name}_time", f"{scene.name}_bode"]
    return [scene.name, f"{scene.name}_error"] if scene.kind == "time" else [scene.name]


def orders_text(scene) -> str:
    """'r = 30' for a one-r scene, with the methods of other orders: 'r = 30 (fo: 60)'."""
    own = {m: scene.rs_of(m)[0] for m in scene.methods if scene.rs_of(m)[0] != scene.rs[0]}
    return f"r = {scene.rs[0]}" + (" (" + ", ".join(f"{m}: {r}" for m, r in own.items()) + ")" if own else "")


def check_output_names(ctx, scenes):
    """Each scene's figures and tables (a time scene makes NAME and NAME_error) have names of their own."""
    seen = {SUMMARY: "the summary table"}
    for i, s in enumerate(scenes):
        for out in output_names(s):
            if out in seen:
                ctx.fail(f"scenes[{i}] ({s.name!r}).name", f"its output {out!r} has the name of {seen[out]}; "
                                                           "rename the scene")
            seen[out] = f"scene {s.name!r}"
