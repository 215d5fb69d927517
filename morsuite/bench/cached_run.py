"""Benchmark ``cached_run``: a cached re-run of ``studies/paper_dsms.toml``, then and now (issue 17).

In a temporary results folder the study is run once (to fill the cache) and once
more (so that the summary's ``cached`` column has settled), then, alternately,
in fresh ``python`` processes (wall time, interpreter start-up included):

(a) the cached re-run as it was before figures and tables became artifacts:
    every figure and table drawn and written again (``--rerender``) after the
    imports the old package made on that path (matplotlib's Figure and Agg canvas,
    pandas, dask and distributed, scipy.sparse, the model generators, the
    reducers); with the model and reducer registries imported, spec validation
    builds the models and checks the options as it did, instead of reading the
    spec memo;
(b) the cached re-run now (``python -m morsuite run SPEC --out DIR --quiet``).

Alternating (a, b) puts the load of a shared machine on both alike; the result is
the median over the pairs. Ratios: ``t_b / t_a`` (target <= 0.3) and ``t_b`` in
seconds (target < 0.8). What (a) does not redo of the old code: the metrics (then
recomputed on every run, about 20 ms here) and the rewriting of unchanged files
(a few ms), so the ratio is, if anything, on the high side. ``control`` is not
imported in (a): the old cached run did not import it either.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from . import benchmark

#: What the old package had imported by the time a cached run had drawn its figures.
OLD_IMPORTS = ("matplotlib.figure", "matplotlib.backends.backend_agg", "pandas", "dask", "distributed",
               "scipy.sparse", "morsuite.models", "morsuite.reducers", "morsuite.analysis")
#: Modules a fully cached run must not need.
HEAVY = ("matplotlib", "pandas", "control", "dask", "scipy.sparse", "morsuite.models", "morsuite.reducers")


def _spec() -> Path:
    here = Path(__file__).resolve()
    for root in here.parents:
        spec = root / "studies" / "paper_dsms.toml"
        if spec.is_file():
            return spec
    raise FileNotFoundError("studies/paper_dsms.toml not found above " + str(here))


def _env() -> dict:
    import morsuite

    # the subprocesses must import this morsuite, not another installed copy
    pkg_root = str(Path(morsuite.__file__).resolve().parents[1])
    return {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (pkg_root, os.environ.get("PYTHONPATH")) if p)}


def _timed(code: str, env) -> float:
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    elapsed = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"cached_run: a run failed:\n{proc.stderr[-2000:]}")
    return elapsed


def _run_code(spec, out, *, old: bool, probe: bool = False) -> str:
    """A ``python -c`` program: the run (a) or (b); ``probe``: also print which of HEAVY it imported."""
    argv = ["run", str(spec), "--out", str(out), "--quiet"] + (["--rerender"] if old else [])
    imports = "".join(f"import {m}\n" for m in OLD_IMPORTS) if old else ""
    tail = f"print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))\n" if probe else ""
    return f"import json, sys\n{imports}from morsuite.cli import main\nrc = main({argv!r})\n{tail}sys.exit(rc)\n"


@benchmark("cached_run")
def bench_cached_run(quick: bool) -> dict:
    """Cached re-run of studies/paper_dsms.toml: now over before (target <= 0.3) and in seconds (target < 0.8)."""
    spec, env = _spec(), _env()
    pairs = 3 if quick else 7
    with tempfile.TemporaryDirectory(prefix="morsuite-cached-run-") as tmp:
        out = Path(tmp) / "results"
        t_fill = _timed(_run_code(spec, out, old=False), env)
        _timed(_run_code(spec, out, old=False), env)
        name = json.loads(next(out.glob("*/manifest.json")).read_text())["study"]
        t_a, t_b, computed = [], [], []
        for _ in range(pairs):
            t_a.append(_timed(_run_code(spec, out, old=True), env))
            t_b.append(_timed(_run_code(spec, out, old=False), env))
            computed.append(json.loads((out / name / "manifest.json").read_text())["computed"])
        m = json.loads((out / name / "manifest.json").read_text())
        proc = subprocess.run([sys.executable, "-c", _run_code(spec, out, old=False, probe=True)], env=env,
                              capture_output=True, text=True)
        imported = json.loads(proc.stdout.strip().splitlines()[-1]) if proc.returncode == 0 else None
    ta, tb = statistics.median(t_a), statistics.median(t_b)
    ratio = tb / ta
    try:
        load = list(os.getloadavg())
    except (AttributeError, OSError):
        load = None
    print(f"cached_run: t_a = {ta:.3f} s (before: everything re-drawn, eager imports), "
          f"t_b = {tb:.3f} s (now), ratio = {ratio:.3f}; median of {pairs} pairs; load {load}")
    outputs = [a for a in m["artifacts"] if a["kind"] in ("figure", "table")]
    return {
        "spec": str(spec), "pairs": pairs, "t_fill_s": t_fill, "t_a_s": ta, "t_b_s": tb,
        "t_a_all_s": t_a, "t_b_all_s": t_b, "load_average": load,
        "computed_in_b": computed, "outputs": len(outputs), "outputs_reused": sum(a["reused"] for a in outputs),
        "imported_in_b": imported,
        "ratios": {
            "cached_run": {"value": ratio, "target": 0.3,
                           "what": f"t_b / t_a: {tb:.3f} s now over {ta:.3f} s before, median of {pairs} pairs"},
            "cached_run_s": {"value": tb, "target": 0.8, "what": "t_b: wall time of the cached re-run (s)"},
        },
    }
