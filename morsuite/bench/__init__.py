"""Benchmarks: timings judged against a floor measured in the same run.

A benchmark is a function ``f(quick: bool) -> dict`` of plain data registered
with :func:`benchmark` in a module of this package; importing the package
imports every module of it (:func:`available`), so a new benchmark is one file
``morsuite/bench/NAME.py``::

    from . import benchmark

    @benchmark("NAME")
    def bench_NAME(quick: bool) -> dict:
        \"\"\"One line for ``morsuite bench --list``.\"\"\"
        ...
        return {"rows": [...], "ratios": {...}}

Its result may hold ``"ratios"``, a mapping ``name -> {"value": float,
"target": float | None, "what": str}`` (lower is better; ``value <= target``
passes); :func:`run` prints one line per ratio and writes
``<out_dir>/<name>.json`` and ``<out_dir>/manifest.json`` (machine, versions,
thread settings) atomically. A benchmark that writes more files asks
:func:`~morsuite.bench.output.resolve_out_dir` where. The long benchmarks
(``pareto``, ``peers``, ``scaling``) also have a function
``bench_NAME(quick, out_dir=None, *, plan=None, echo=print)``: ``quick`` picks
the plan of the module docstring (``plan`` replaces it), tables and figures go
to ``out_dir``, progress lines to ``echo`` (None: silent).

Timings are compared with a floor measured on the same machine in the same
process, never with a number from elsewhere: the floor of a sparse LU is
``splu`` of the saddle-point matrix with its solves (:mod:`morsuite.bench.floor`).
Shared pieces: :mod:`~morsuite.bench.floor`, :mod:`~morsuite.bench.output`
(machine, code state, JSON, tables, figures), :mod:`~morsuite.bench.profiler`,
:mod:`~morsuite.bench.memory`, :mod:`~morsuite.bench.readme`.
"""

from __future__ import annotations

import json
import time
from datetime import datetime, timezone
from pathlib import Path

from ..errors import OptionError
from .output import CURRENT_OUT_DIR, code_state, machine_info, write_json

__all__ = ["BENCHMARKS", "benchmark", "available", "describe", "run", "machine_info"]

#: name -> benchmark function ``f(quick: bool) -> dict``
BENCHMARKS: dict = {}


def benchmark(name: str):
    """Register ``f(quick: bool) -> dict`` under ``name``."""
    if not isinstance(name, str) or not name:
        raise OptionError(f"benchmark name must be a non-empty string; got {name!r}")

    def deco(fn):
        if name in BENCHMARKS and BENCHMARKS[name] is not fn:
            raise OptionError(f"benchmark {name!r} is already registered")
        BENCHMARKS[name] = fn
        fn.benchmark_name = name
        return fn

    return deco


def _discover():
    """Import every module of this package (not ``_private`` ones): each benchmark module registers
    its benchmarks, the shared modules register nothing.

    A module that cannot be imported (e.g. a missing optional dependency) is
    skipped with a warning, so that the other benchmarks still run.
    """
    import importlib
    import pkgutil
    import warnings

    from ..errors import MorsuiteWarning

    for mod in pkgutil.iter_modules(__path__):
        if not mod.name.startswith("_"):
            try:
                importlib.import_module(f"{__name__}.{mod.name}")
            except ImportError as exc:
                warnings.warn(f"benchmark module {__name__}.{mod.name} not loaded: {exc}",
                              MorsuiteWarning, stacklevel=3)


def available() -> list[str]:
    """Names of the registered benchmarks (every module of ``morsuite.bench`` imported)."""
    _discover()
    return sorted(BENCHMARKS)


def describe(name: str) -> str:
    """First line of the benchmark's docstring."""
    doc = (BENCHMARKS[name].__doc__ or "").strip()
    return doc.splitlines()[0] if doc else ""


def _ratio_line(name, key, r) -> str:
    value, target = float(r["value"]), r.get("target")
    line = f"{name}: {key} = {value:.3f}"
    if target is not None:
        line += f" (target <= {target}) " + ("ok" if value <= target else "ABOVE TARGET")
    if r.get("what"):
        line += f"  [{r['what']}]"
    return line


def run(names=None, out_dir="results/bench", quick: bool = False, echo=print) -> dict:
    """Run benchmarks ``names`` (all when empty), write their JSON and a manifest.

    Returns ``{name: result}``. Unknown names raise :class:`OptionError`
    before anything runs. ``manifest.json`` keeps the entries of benchmarks
    not run this time. Every result records the code it ran (``code_start`` and ``code``:
    :func:`~morsuite.bench.output.code_state`, git HEAD, uncommitted files and the timed
    modules' digests, before and after), unless the benchmark recorded its own.
    """
    avail = available()
    names = list(names or avail)
    unknown = [n for n in names if n not in BENCHMARKS]
    if unknown:
        raise OptionError(f"unknown benchmark {', '.join(map(repr, unknown))}; available: {', '.join(avail)}")
    out = Path(out_dir)
    results = {}
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")
    for name in names:
        t0 = time.perf_counter()
        code_start = code_state()
        token = CURRENT_OUT_DIR.set(out)
        try:
            res = dict(BENCHMARKS[name](bool(quick)))
        finally:
            CURRENT_OUT_DIR.reset(token)
        res.setdefault("benchmark", name)
        # the code it ran, for every benchmark (a benchmark may record its own, e.g. per case)
        res.setdefault("code_start", code_start)
        res.setdefault("code", code_state())
        res["quick"] = bool(quick)
        res["wall_time_s"] = time.perf_counter() - t0
        res["finished"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
        for key, r in (res.get("ratios") or {}).items():
            if r.get("target") is not None:
                r["pass"] = bool(float(r["value"]) <= float(r["target"]))
            if echo:
                echo(_ratio_line(name, key, r))
        write_json(out / f"{name}.json", res)
        results[name] = res
    manifest_path = out / "manifest.json"
    manifest = {}
    if manifest_path.is_file():
        try:
            manifest = json.loads(manifest_path.read_text())
        except (OSError, ValueError):
            manifest = {}
    entries = manifest.get("benchmarks", {}) if isinstance(manifest.get("benchmarks"), dict) else {}
    for name, res in results.items():
        entries[name] = {"file": f"{name}.json", "quick": res["quick"], "finished": res["finished"],
                         "wall_time_s": res["wall_time_s"],
                         "ratios": {k: {"value": r["value"], "target": r.get("target"), "pass": r.get("pass")}
                                    for k, r in (res.get("ratios") or {}).items()}}
    manifest = {"machine": machine_info(), "started": started, "benchmarks": entries}
    write_json(manifest_path, manifest)
    return results


_discover()
