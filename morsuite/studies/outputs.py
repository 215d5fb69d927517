"""Figures and tables as artifacts: keyed by what they show, drawn only when that changed.

A scene's figure or table (and the summary table) is the last node of a study's
graph. Its key is the SHA-256 of

- its plain data: for a figure the title, axis labels and scales and, per curve,
  name, label, style, x and annotation columns and each column's dtype and bytes
  (a paper overlay: its file's SHA-256); for a table its rows, columns, title, note;
- its style: :func:`morsuite.report.figures.style` (``STYLE_VERSION``, the rc
  settings on top of matplotlib's defaults, size, margins, dpi, file metadata);
- the figure formats asked for;
- the versions of numpy, pandas and matplotlib (they make the bytes) and a digest
  of ``morsuite/report/*.py`` (as :func:`~morsuite.studies.cache.code_digest` does
  for the numerics).

Each run records, per output, the key and the SHA-256 of each of its files in the
study's ``manifest.json`` (artifacts of kind ``figure`` and ``table``). The next run
reuses an output when its key equals the record's and every file still holds the
recorded bytes: nothing is drawn and no file is touched (same bytes, same mtime),
and neither matplotlib nor pandas is imported for it. Otherwise the files that are
missing or changed are made again (all of them when the key changed, or with
``rerender=True``); drawing is deterministic and each file is written, atomically,
only when its bytes differ, so a re-drawn figure whose data did not change leaves
its files as they were.

Cost of a reused output: building its data (no solving) and hashing its files.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import json
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from ..report.figures import CsvSource, style
from ..report.files import sha256_file
from ..report.tables import TableData
from .cache import source_digest
from .spec import plain
from .workers import terminate_on_exit, watch_parent

__all__ = ["figure_key", "table_key", "realize", "realize_many", "previous_records", "OUTPUT_KINDS"]

OUTPUT_KINDS = ("figure", "table")
_WRITERS = ("numpy", "pandas", "matplotlib")


@functools.lru_cache(maxsize=1)
def _software() -> dict:
    def version(pkg):
        try:
            return importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            return None
    # versions from the package metadata: knowing them must not import matplotlib
    return {"versions": {p: version(p) for p in _WRITERS}, "report": source_digest("report")}


def _digest(material) -> str:
    blob = json.dumps(plain({**material, **_software()}), sort_keys=True, allow_nan=True)
    return hashlib.sha256(blob.encode()).hexdigest()


def _column(values) -> list:
    if isinstance(values, CsvSource):
        return ["csv", values.digest(), values.x]
    a = np.asarray(values)
    if a.dtype.kind in "biufc":
        return [a.dtype.str, list(a.shape), hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()]
    return ["values", plain(a.tolist())]


def _curve(c) -> dict:
    data = c.data
    cols = ["csv", data.digest(), data.x] if isinstance(data, CsvSource) else \
        [[name, _column(data[name])] for name in (list(data.columns) if hasattr(data, "columns") else list(data))]
    return {"name": c.name, "label": c.label, "x": c.x, "style": c.style, "annotate": c.annotate, "columns": cols}


def figure_key(fig, formats) -> str:
    """Key of a :class:`~morsuite.report.figures.FigureData` drawn in ``formats``."""
    return _digest({"kind": "figure", "name": fig.name, "title": fig.title, "xlabel": fig.xlabel,
                    "ylabel": fig.ylabel, "xscale": fig.xscale, "yscale": fig.yscale,
                    "curves": [_curve(c) for c in fig.curves], "style": style(), "formats": list(formats)})


def table_key(table: TableData) -> str:
    """Key of a :class:`~morsuite.report.tables.TableData`."""
    return _digest({"kind": "table", "name": table.name, "title": table.title, "note": table.note,
                    "columns": table.columns, "int_columns": list(table.int_columns), "rows": table.rows})


def previous_records(manifest: dict | None) -> dict:
    """id -> record of the outputs in an earlier run's manifest (empty without one)."""
    arts = (manifest or {}).get("artifacts") or []
    return {a["id"]: a for a in arts if isinstance(a, dict) and a.get("kind") in OUTPUT_KINDS and "id" in a}


def realize(output, item, outdir: Path, formats, previous: dict, rerender: bool = False) -> dict:
    """Make (or reuse) the files of ``item`` (FigureData or TableData) for the plan's ``output``.

    Returns the manifest record: key, ``reused``, the SHA-256 of each file,
    ``rendered`` (the files made again) and ``changed`` (those whose bytes changed).
    """
    from ..report.writer import figure_files, table_files, write_figure, write_table_data

    t0 = time.perf_counter()
    rec = {"id": output.id, "kind": output.kind, "scene": output.scene, "inputs": output.inputs}
    if isinstance(item, TableData):
        names, key = table_files(item), table_key(item)
    elif item.curves:
        names, key = figure_files(item, formats), figure_key(item, formats)
        rec["formats"] = list(formats)
    else:  # nothing to draw: no files (the scene's notes say why)
        return {**rec, "key": None, "reused": False, "cached": False, "files": {}, "rendered": [], "changed": []}
    prev = previous.get(output.id) or {}
    before = {n: sha256_file(outdir / n) for n in names}
    if rerender or prev.get("key") != key:
        todo = list(names)
    else:
        recorded = prev.get("files") or {}
        todo = [n for n in names if before[n] is None or before[n] != recorded.get(n)]
    after = before
    if todo:
        if isinstance(item, TableData):
            write_table_data(item, outdir)
        else:
            write_figure(item, outdir, formats, only=todo)
        after = {n: sha256_file(outdir / n) for n in names}
    return {**rec, "key": key, "reused": not todo, "cached": not todo, "files": after, "rendered": todo,
            "changed": [n for n in names if after[n] != before[n]], "time_s": time.perf_counter() - t0}


def realize_many(pairs, outdir: Path, formats, previous: dict, rerender: bool = False, jobs: int = 1) -> list:
    """:func:`realize` for each ``(output, item)`` of ``pairs``; the records in the same order.

    ``jobs`` > 1 (default 1) draws the figures on up to ``jobs`` processes forked from this one
    (where the platform forks; elsewhere, and for tables, here): the study runner asks for it when
    no timed computation shares the machine (the last studies of ``morsuite run``, whose figures are
    the run's tail, ``docs/design/reports.md``). The files and records are those of the serial loop:
    each figure is drawn by one process, deterministically.

    Cost: that of the serial loop divided by up to ``jobs``, plus a fork and the pickling of each
    figure's data.
    """
    pairs = list(pairs)
    figures = [k for k, (_, item) in enumerate(pairs) if not isinstance(item, TableData) and item.curves]
    if jobs <= 1 or len(figures) < 2 or "fork" not in multiprocessing.get_all_start_methods():
        return [realize(o, item, outdir, formats, previous, rerender) for o, item in pairs]
    out = [None] * len(pairs)
    with ProcessPoolExecutor(max_workers=min(jobs, len(figures)), mp_context=multiprocessing.get_context("fork"),
                             initializer=watch_parent) as pool, terminate_on_exit(pool):
        futures = {k: pool.submit(realize, pairs[k][0], pairs[k][1], outdir, formats,
                                  {pairs[k][0].id: previous[pairs[k][0].id]} if pairs[k][0].id in previous else {},
                                  rerender) for k in figures}
        for k, (o, item) in enumerate(pairs):
            if k not in futures:
                out[k] = realize(o, item, outdir, formats, previous, rerender)
        for k, fut in futures.items():
            out[k] = fut.result()
    return out
