"""Write one figure or table into a results folder.

A figure NAME becomes

- one CSV per curve: ``NAME.csv`` when the figure has one computed curve, else
  ``NAME__CURVE.csv`` (CURVE is ``full``, a method alias, ``ALIAS_rR``, or
  ``paper_...`` for a paper overlay); columns ``omega,value`` over frequency,
  ``r,value`` or ``states,value`` against the reduced order (plus the other
  order columns and ``cached``), ``iteration,value``, ``index,value``, or
  ``<measure>,value`` for a Pareto plot (value = time in s);
- ``NAME.png`` and ``NAME.pdf`` (matplotlib, Agg);
- ``NAME.tex``: a pgfplots picture reading the CSVs.

A table NAME becomes ``NAME.csv`` and ``NAME.md``. Every write is atomic.
"""

from __future__ import annotations

from pathlib import Path

from ..utils import atomic_write_text
from .figures import FigureData, plot, save, write_pgfplots
from .tables import write_table

__all__ = ["write_figure", "write_table_data", "csv_names"]


def csv_names(figdata: FigureData) -> dict:
    own = [c for c in figdata.curves if c.style != "paper"]
    single = len(own) == 1
    return {c.name: (f"{figdata.name}.csv" if single and c.style != "paper" else f"{figdata.name}__{c.name}.csv")
            for c in figdata.curves}


def write_figure(figdata: FigureData, outdir, formats=("png", "pdf")) -> list[Path]:
    """CSV per curve, PNG, PDF (``formats``; none: skip drawing) and pgfplots .tex in ``outdir``."""
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    names = csv_names(figdata)
    files = []
    for c in figdata.curves:
        path = outdir / names[c.name]
        atomic_write_text(path, c.data.to_csv(index=False))
        files.append(path)
    if formats:
        fig, _ = plot(figdata)
        files += save(fig, outdir / figdata.name, formats)
    files.append(write_pgfplots(figdata, names, outdir / f"{figdata.name}.tex"))
    return files


def write_table_data(table, outdir) -> list[Path]:
    return write_table(table.df, Path(outdir) / table.name, title=table.title)
