"""Reports: figures (matplotlib and pgfplots) and tables from plain data; never solves.

:mod:`~morsuite.report.figures` draws :class:`FigureData` and writes pgfplots;
:mod:`~morsuite.report.tables` writes CSV and Markdown tables;
:mod:`~morsuite.report.writer` writes one study's outputs (CSV per curve, figures,
tables) into its results folder; :mod:`~morsuite.report.files` writes a file only
when its bytes change. Nothing here imports matplotlib or pandas before a figure
is drawn or a table written.
"""

from .figures import Curve, CsvSource, FigureData, pgfplots_tex, plot, save
from .tables import TableData, read_markdown, to_markdown, write_table

__all__ = ["Curve", "CsvSource", "FigureData", "TableData", "plot", "save", "pgfplots_tex", "to_markdown",
           "read_markdown", "write_table"]
