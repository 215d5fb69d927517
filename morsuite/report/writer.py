"""Write one figure or table into a results folder.

A figure NAME becomes

- one CSV per curve: ``NAME.csv`` when the figure has one computed curve, else
  ``NAME__CURVE.csv`` (CURVE is ``full``, a method alias, ``ALIAS_rR``, or
  ``paper_...`` for a paper overlay, ``flagged_...`` for rings around points not to be
  read as exact); columns ``omega,value`` over frequency,
  ``r,value`` or ``states,value`` against the reduced order (plus the other
  order columns and ``cached``), ``iteration,value``, ``index,value``, or
  ``<measure>,value`` for a Pareto plot (value = time in s);
- ``NAME.png`` and ``NAME.pdf`` (matplotlib, Agg);
- ``NAME.tex``: a pgfplots picture reading the CSVs.

A table NAME becomes ``NAME.csv`` and ``NAME.md``. Every write is atomic, and a
file that already holds the new bytes is not touched (:mod:`.files`).

:func:`figure_files` and :func:`table_files` name the files without making them, so
a caller can check which exist; ``only=`` makes just those (a figure is drawn only
when an image is among them, and then only in the formats asked for).
"""

from __future__ import annotations

from pathlib import Path

from .figures import FigureData, plot, render, write_pgfplots
from .files import write_bytes, write_text
from .tables import TableData, write_table

__all__ = ["write_figure", "write_table_data", "csv_names", "figure_files", "table_files"]


def csv_names(figdata: FigureData) -> dict:
    """File name of each curve's CSV: curve name -> ``NAME.csv`` or ``NAME__CURVE.csv``.

    A figure with a single curve of its own writes ``NAME.csv``; otherwise, and for the
    overlaid curves (the paper's data, flagged points), each curve gets
    ``NAME__CURVE.csv``.
    """
    overlay = ("paper", "flagged")
    own = [c for c in figdata.curves if c.style not in overlay]
    single = len(own) == 1
    return {c.name: (f"{figdata.name}.csv" if single and c.style not in overlay else f"{figdata.name}__{c.name}.csv")
            for c in figdata.curves}


def figure_files(figdata: FigureData, formats=("png", "pdf")) -> list[str]:
    """Names of the files :func:`write_figure` makes: CSVs, images, the .tex."""
    names = csv_names(figdata)
    return [names[c.name] for c in figdata.curves] + [f"{figdata.name}.{ext}" for ext in formats] + \
        [f"{figdata.name}.tex"]


def write_figure(figdata: FigureData, outdir, formats=("png", "pdf"), *, only=None) -> list[Path]:
    """CSV per curve, PNG, PDF (``formats``; none: skip drawing) and pgfplots .tex in ``outdir``.

    ``only``: the file names (of :func:`figure_files`) to make; default all.
    Returns the paths of all the figure's files.
    """
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    names = csv_names(figdata)
    wanted = set(figure_files(figdata, formats) if only is None else only)
    for c in figdata.curves:
        if names[c.name] in wanted:
            write_text(outdir / names[c.name], c.frame().to_csv(index=False))
    images = [ext for ext in formats if f"{figdata.name}.{ext}" in wanted]
    if images:
        fig, _ = plot(figdata)
        for ext in images:
            write_bytes(outdir / f"{figdata.name}.{ext}", render(fig, ext))
    if f"{figdata.name}.tex" in wanted:
        write_pgfplots(figdata, names, outdir / f"{figdata.name}.tex")
    return [outdir / n for n in figure_files(figdata, formats)]


def table_files(table: TableData) -> list[str]:
    """Names of the files :func:`write_table_data` makes."""
    return [f"{table.name}.csv", f"{table.name}.md"]


def write_table_data(table: TableData, outdir, *, only=None) -> list[Path]:
    """``NAME.csv`` and ``NAME.md`` of ``table`` in ``outdir`` (both: they come from one DataFrame)."""
    return write_table(table.frame(), Path(outdir) / table.name, title=table.title, note=table.note)
