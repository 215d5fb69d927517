"""The study's HTML page (``OUT/NAME/index.html``) and the results folder's (``OUT/index.html``).

:func:`study_page` gathers, as plain data, what a reader of a study needs on one page: its
description, a scoreboard per size each table compares (:func:`scoreboards`) and a one-line
headline, the study's key figure (the thumbnail on the results folder's page), the modes and
poles when the study has them, the verdicts of its tables ("which method wins, by how much, in which norm"),
the figures it drew, every table with the trusted/certified marks and convergence flags,
the timings beside the LU counts that are their floor, and the run's facts from the
manifest (versions, machine, scheduler, every method's options, what came from the cache).
:mod:`morsuite.report.html` renders it with Jinja2.

A page is an output like a figure: its key is the SHA-256 of that data, the templates and
Jinja2's version and this module's and the renderer's source. :func:`realize_page` reuses
the file when the key equals the previous run's record and the file still holds the
recorded bytes (nothing rendered, Jinja2 not imported); otherwise it renders and writes
the file atomically, and only when its bytes changed. The results folder's page
(:func:`write_index`) links every study folder holding a ``manifest.json`` of a study and
carries its key in its first line, so an unchanged index is neither rendered nor touched.

The page holds nothing that changes from run to run by itself (no start time, no run
time): an unchanged re-run leaves it as it was. What the cache served is counted, so the
first re-run after a computing run rewrites it once (as it marks the summary's rows
``cached``).
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import json
import time
from pathlib import Path

from ..report.files import sha256_file, write_text
from ..utils import to_plain as plain
from .cache import source_digest

__all__ = ["PAGE", "study_page", "scoreboards", "page_key", "realize_page", "write_index", "index_entries"]

#: the page's file name in a study folder and in the results folder
PAGE = "index.html"
_TIMING_COLUMNS = ("model", "method", "r_requested", "states", "converged", "time_s", "time_standalone_s",
                   "lu_count", "s_per_lu", "cached")
_KEY_PREFIX = "<!-- morsuite page key "


@functools.lru_cache(maxsize=1)
def _software() -> dict:
    try:
        jinja = importlib.metadata.version("jinja2")
    except importlib.metadata.PackageNotFoundError:
        jinja = None
    from ..report.html import template_digest  # no jinja2 import: only the templates' bytes

    return {"jinja2": jinja, "templates": template_digest(),
            "code": source_digest("report/html.py", "studies/pages.py")}


def page_key(data: dict) -> str:
    """SHA-256 of a page's plain ``data``, the templates, Jinja2's version and the page code."""
    blob = json.dumps(plain({"page": data, **_software()}), sort_keys=True, allow_nan=True)
    return hashlib.sha256(blob.encode()).hexdigest()


def _flags(rows) -> list:
    """What a reader must not miss, counted from the summary's rows."""
    out = []
    ok = [r for r in rows if r.get("status") == "ok"]
    for col, what in (("converged", "did not converge (best iterate shown)"), ("stable", "is unstable")):
        bad = [r for r in ok if r.get(col) is False]
        if bad:
            out.append(f"{len(bad)} reduction(s) {what}: " + ", ".join(
                f"{r['method']} r = {r['r_requested']}" for r in bad[:8]) + (" ..." if len(bad) > 8 else ""))
    failed = [r for r in rows if r.get("status") != "ok"]
    if failed:
        out.append(f"{len(failed)} reduction(s) failed: " + ", ".join(
            f"{r['method']} r = {r['r_requested']}" for r in failed[:8]))
    for col in sorted({c for r in rows for c in r if c.endswith("_trusted")}):
        bad = [r for r in ok if r.get(col) is False]
        if bad:
            out.append(f"{len(bad)} {col.replace('_trusted', '')} value(s) not accurate to four digits")
    grew = [r for r in ok if r.get("growth") is True]
    if grew:
        out.append(f"{len(grew)} reduced model(s) whose simulated output grows")
    return out


def _timings(rows) -> dict:
    from ..report.html import table_view

    out = []
    for r in rows:
        lus, t = r.get("lu_count"), r.get("time_s")
        per = t / lus if isinstance(lus, int) and not isinstance(lus, bool) and lus > 0 and \
            isinstance(t, float) else None
        out.append({**{c: r.get(c) for c in _TIMING_COLUMNS if c != "s_per_lu"}, "s_per_lu": per})
    return table_view(_TIMING_COLUMNS, out)


def _cache_counts(artifacts) -> dict:
    kinds = {}
    for a in artifacts:
        if a.get("kind") in ("figure", "table", "page"):
            continue
        k = kinds.setdefault(a["kind"], {"reused": 0, "total": 0})
        k["total"] += 1
        k["reused"] += bool(a.get("reused") or a.get("cached"))
    reused = sum(k["reused"] for k in kinds.values())
    total = sum(k["total"] for k in kinds.values())
    return {"reused": reused, "computed": total - reused, "total": total, "kinds": kinds}


#: the summary columns a scoreboard row carries (what :func:`morsuite.report.html.scoreboard_view` reads)
_BOARD_COLUMNS = ("method", "r_requested", "r", "states", "status", "converged", "stable", "max_abs_error",
                  "max_rel_error", "h2_error", "h2_rel_error", "h2_trusted", "hinf_error", "hinf_rel_error",
                  "hinf_certified", "max_output_error", "max_output_rel_error", "time_standalone_s", "time_s",
                  "lu_count_standalone", "lu_count", "worse_than_zero")
#: a table with more sizes than this shows only its largest size's scoreboard open, the others folded
_OPEN_SIZES = 3
#: scene kinds whose figure is a study's key figure (its thumbnail on the results folder's page), in preference
_KEY_KINDS = ("tolerance", "sigma", "compare", "error", "error_vs_r", "pareto")


def scoreboards(study, tables) -> list:
    """One scoreboard per size compared in each table scene of two or more methods: ``{"table", "title",
    "where", "folded", "rows"}``, the rows those of the table (the summary's values, not recomputed)
    grouped as the table's verdict groups them (:func:`morsuite.studies.scenes.order_groups`). A table of
    more than :data:`_OPEN_SIZES` sizes shows its largest open and the others ``folded``."""
    from .scenes import order_groups

    out = []
    for t in tables:
        if len({row.get("method") for row in t["rows"]}) < 2:
            continue
        groups = [(where, rows) for where, rows in order_groups(t["rows"]) if len(rows) >= 2]
        for i, (where, rows) in enumerate(groups):
            out.append({"table": t["name"], "title": t["title"], "where": where,
                        "folded": len(groups) > _OPEN_SIZES and i < len(groups) - 1,
                        "rows": [{**{c: row.get(c) for c in _BOARD_COLUMNS},
                                  "label": study.methods[row["method"]].label if row["method"] in study.methods
                                  else row["method"]} for row in rows]})
    return out


def _tolerance_sections(study, tables, figures) -> list:
    """The page's first section, one per ``tolerance`` scene: its title, headline (the table's note up to
    its definitions), its "to reach" table and its three figures (``{"name", "title", "src"}``)."""
    out = []
    for scene in study.scenes:
        if scene.kind != "tolerance":
            continue
        t = next((t for t in tables if t["name"] == scene.name), None)
        if t is None:
            continue
        note = t["note"] or ""
        cut = note.find(" Error: ")
        figs = [f for f in figures if f["name"] in (f"{scene.name}_states", f"{scene.name}_time", f"{scene.name}_bode")]
        out.append({"name": scene.name, "title": t["title"], "headline": note[:cut] if cut >= 0 else note,
                    "definitions": note[cut + 1:] if cut >= 0 else "", "columns": t["columns"], "rows": t["rows"],
                    "files": t["files"], "figures": figs})
    return out


def _key_figure(study, figures):
    """The figure a reader looks at first: the last of the first scene kind of :data:`_KEY_KINDS` that
    drew one (for ``morsuite compare``: the Bode magnitude plot at the most states), else the first."""
    kind = {s.name: s.kind for s in study.scenes}
    for k in _KEY_KINDS:
        hits = [f for f in figures if kind.get(f["name"]) == k]
        if hits:
            return hits[-1]["src"]
    return figures[0]["src"] if figures else None


def study_page(study, outputs, summary, manifest: dict, modes=None) -> dict:
    """The plain data of a study's page.

    ``outputs``: ``(item, record)`` pairs of the run's figures and tables in scene order
    (``item`` a FigureData or TableData, ``record`` its :func:`~morsuite.studies.outputs.realize` record);
    ``summary``: the summary TableData; ``manifest``: the run's manifest (its facts); ``modes``: the
    study's modes and poles (``{"rows", "poles", "note"}``, docs/design/reports.md "Modes and poles"),
    or None (then the page has no modes section).
    """
    from ..report.html import headline

    figures, tables, verdicts = [], [], []
    for item, rec in outputs + [(summary, None)]:
        files = sorted((rec or {}).get("files") or [])
        if rec is None:
            files = [f"{summary.name}.csv", f"{summary.name}.md"]
        if hasattr(item, "curves"):
            img = next((f"{item.name}.{ext}" for ext in ("png", "svg") if f"{item.name}.{ext}" in files), None)
            if img is not None:
                figures.append({"name": item.name, "title": item.title, "src": img, "files": files})
            continue
        tables.append({"name": item.name, "title": item.title, "note": item.note, "files": files,
                       "columns": list(item.columns or (list(item.rows[0]) if item.rows else [])),
                       "rows": item.rows})
        if item.note and rec is not None:  # a table scene's note is its verdict (scenes._verdict)
            verdicts.append({"title": item.title, "text": item.note})
    models = [{"name": m["name"], "n1": m["n1"], "n2": m["n2"], "m": m["m"], "p": m["p"], "band": m["band"]}
              for m in manifest["models"].values()]
    used = {sc.get("grid") for sc in manifest.get("scenes") or []}
    grids = [{"name": g, "band": v.get("band"), "n": v.get("n")} for g, v in (manifest.get("grids") or {}).items()
             if g in used]
    methods = [{"alias": a, **{k: m[k] for k in ("label", "reducer", "options_given", "options")}}
               for a, m in manifest["methods"].items()]
    threads = manifest.get("threads") or {}
    facts = {"versions": manifest["versions"], "blas": manifest.get("blas") or {},
             "host": {k: (manifest.get("host") or {}).get(k) for k in ("platform", "machine")},
             "cpus": threads.get("affinity") or threads.get("cpu_count"),
             "scheduler": (manifest.get("scheduler") or {}).get("name"), "spec_sha256": manifest.get("spec_sha256"),
             "cache": _cache_counts(manifest["artifacts"]), "norms": manifest["norms"]["summary"],
             "norm_options": {k: v for k, v in manifest["norms"]["options"].items()
                              if k in manifest["norms"]["summary"]}}
    reach = _tolerance_sections(study, tables, figures)
    summaries = {s.name for s in study.scenes if s.kind == "table"}  # the reductions' tables, not modes tables
    boards = scoreboards(study, [t for t in tables if t["name"] != summary.name and t["name"] in summaries])
    heads = [h for h in (headline(b) for b in boards if b["table"] == boards[0]["table"]) if h]
    head = heads[-1] if heads else ""
    if reach:  # a tolerance scene leads: its headline is the study's (results folder's page too)
        head = reach[0]["headline"]
    return plain({
        "tolerance": reach,
        "scoreboards": boards, "headline": head, "key_figure": _key_figure(study, figures),
        "modes": modes or None,
        "study": study.name, "title": study.title, "description": study.description,
        "spec": study.path.name if study.path is not None else None,
        "models": models, "grids": grids, "methods": methods, "verdicts": verdicts, "flags": _flags(summary.rows),
        "figures": figures, "formats": sorted({f.rsplit(".", 1)[-1] for x in figures for f in x["files"]}),
        "tables": tables, "timings": _timings(summary.rows),
        "timing_note": "time_s is the call's own time (work shared across r done once), time_standalone_s "
                       "what this r alone costs; a study does not time one LU bare (morsuite bench does).",
        "facts": facts, "notes": list(manifest.get("notes") or []),
    })


def realize_page(data: dict, outdir: Path, previous: dict | None, rerender: bool = False) -> dict:
    """Write (or reuse) ``outdir/index.html`` from ``data``; the manifest record of kind ``page``.

    ``previous``: the previous run's record of the page (or None). The record holds
    the key, the file's SHA-256, ``reused``, and the table verdicts and flags that the
    results folder's page shows.
    """
    t0 = time.perf_counter()
    key = page_key(data)
    path = Path(outdir) / PAGE
    before = sha256_file(path)
    prev = previous or {}
    reused = not rerender and prev.get("key") == key and before is not None and \
        before == (prev.get("files") or {}).get(PAGE)
    if not reused:
        from ..report.html import render_study
        write_text(path, render_study(data))
    after = sha256_file(path) if not reused else before
    return {"id": "page/index", "kind": "page", "scene": None, "model": None, "reducer": None, "key": key, "reused": reused, "cached": reused,
            "files": {PAGE: after}, "rendered": [] if reused else [PAGE],
            "changed": [PAGE] if after != before else [], "flags": data["flags"],
            "verdicts": [v["text"] for v in data["verdicts"]], "headline": data.get("headline") or "",
            "key_figure": data.get("key_figure"), "time_s": time.perf_counter() - t0}


def index_entries(root: Path) -> list:
    """One entry per study folder of ``root`` that holds a study's ``manifest.json`` and page."""
    out = []
    for d in sorted(p for p in Path(root).iterdir() if p.is_dir() and not p.name.startswith(".")):
        try:
            man = json.loads((d / "manifest.json").read_text())
        except (OSError, ValueError):
            continue
        if not isinstance(man, dict) or "study" not in man or "artifacts" not in man or not (d / PAGE).is_file():
            continue
        arts = [a for a in man["artifacts"] if isinstance(a, dict)]
        page = next((a for a in arts if a.get("kind") == "page"), {})
        out.append({"name": d.name, "href": f"{d.name}/{PAGE}", "title": man.get("title") or d.name,
                    "description": man.get("description") or "",
                    "models": [m.get("name", a) for a, m in (man.get("models") or {}).items()],
                    "methods": [m.get("label", a) for a, m in (man.get("methods") or {}).items()],
                    "reductions": sum(1 for a in arts if a.get("kind") == "reduction"),
                    "figures": sum(1 for a in arts if a.get("kind") == "figure" and a.get("files")),
                    "tables": sum(1 for a in arts if a.get("kind") == "table"),
                    "flags": "; ".join(page.get("flags") or []), "headline": page.get("headline") or "",
                    "thumbnail": f"{d.name}/{page['key_figure']}" if page.get("key_figure") and
                    (d / page["key_figure"]).is_file() else None,
                    "verdicts": " ".join(page.get("verdicts") or [])[:600]})
    return out


def write_index(root, title: str = "morsuite results") -> bool:
    """Write ``root/index.html`` linking every study page under ``root``; True if written.

    Rendered only when its data, the templates or Jinja2 changed (its key is its first line).
    """
    root = Path(root)
    data = {"title": title, "studies": index_entries(root)}
    key = page_key(data)
    path = root / PAGE
    try:
        with open(path, encoding="utf-8") as fh:
            if fh.readline().strip() == f"{_KEY_PREFIX}{key} -->":
                return False
    except OSError:
        pass
    from ..report.html import render_index
    return write_text(path, f"{_KEY_PREFIX}{key} -->\n" + render_index(data))
